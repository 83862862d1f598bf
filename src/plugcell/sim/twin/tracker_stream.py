"""The laser tracker streaming a moving reflector: servo, noise at rate, latency, breaks.

:class:`TrackerStream` samples a reflector whose true pose is a function of (true)
time, as a tracker's real-time output does (up to 1 kHz): every output sample
integrates the ``n = ⌈F/f⌉`` internal samples (``F`` = 3 kHz, thesis 3.2.2.2) of its
period ``1/f``, and is stamped with the *tracker's* clock at the middle of that window.
Parameters and their sources: docs/tracker-model.md, "Streaming".

Beam servo (per axis, azimuth and elevation, every internal sample ``h = 1/(n f)``)::

    e = angle(target) − angle(beam)                       (wrapped to ±π)
    ω ← clip(K e, ω − α h, ω + α h),   |ω| ≤ ω_max        (type-1 loop, rate- and
    beam ← beam + ω h                                       acceleration-limited)

A type-1 loop follows a constant angular rate with the lag ``e = ω/K``: a reflector
moving laterally at ``v`` sits ``v/K`` off the beam, so the lock breaks at
``v > K · w`` (``w``: the position detector's tracking window) — 5 m/s for the
defaults (thesis 2.3.1.1).  Radially the distance meter loses count beyond
``max_radial_speed``.  A break (lateral offset beyond the window, radial speed, line
of sight lost) invalidates every sample whose window it touches; with
``auto_reacquire`` the tracker finds the reflector again ``reacquire_s`` after the
line of sight is back (camera-assisted search and ADM), else it stays broken.

Reading of one sample (window mean of the true positions ``p̄``, beam frame axes ``A``)::

    p_meas = p̄ + Aᵀ σ_ref ⊙ ( √s_sys · φ(dir) + √s_floor · u_k + √(s_white N_ref / n) · ε )
    u_k    = ρ u_{k−1} + √(1 − ρ²) η,    ρ = exp(−1 / (f τ_floor))

the static model's three variance shares (:mod:`plugcell.sim.twin.tracker`) with the
floor made a first-order Gauss–Markov process (correlation time ``τ_floor``) instead
of fresh per reading: successive 1 ms samples share their air turbulence.  Orientation
(T-MAC) the same way, at the window's middle.

Clocks: true time ``t`` (the simulation's), the tracker's clock
``t_tr = offset + (1 + drift) t``; a sample leaves the tracker ``latency`` after its
window closes (:attr:`StreamSample.available_s`, true time).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from plugcell.kinematics.transforms import so3_exp
from plugcell.sim.twin.tracker import BeamNotLockedError, LaserTracker, TargetOutOfRangeError

Array = NDArray[np.float64]

__all__ = ["StreamSample", "StreamSpec", "TrackerStream"]

#: Status of a sample: ``ok`` or why it holds no measurement.
STATUSES = ("ok", "line_of_sight", "tracking_speed", "out_of_range", "reacquiring")


@dataclass(frozen=True)
class StreamSpec:
    """The streaming tracker's dynamics (defaults: AT901/AT960 class; docs/tracker-model.md).

    Attributes
    ----------
    max_rate_hz : float
        Highest output rate (1000 Hz, Leica datasheets).
    latency_s : float
        From the end of a sample's window to the sample leaving the tracker (estimate).
    servo_gain_per_s : float
        ``K`` of the pointing loop (1/s).
    tracking_window_m : float
        ``w``: how far off the beam the reflector may sit before the lock breaks (m).
    max_angular_speed_rad_s, max_angular_accel_rad_s2 : float
        ``ω_max``, ``α_max`` of each axis.
    max_radial_speed_m_s : float
        Fastest radial motion the distance meter follows.
    floor_correlation_s : float
        ``τ_floor`` of the floor noise.
    auto_reacquire : bool
        Find the reflector again by itself after a break (camera-assisted, AT960
        PowerLock class) ``reacquire_s`` after the line of sight is back.
    clock_offset_s, clock_drift_ppm : float
        The tracker clock against true time.
    """

    max_rate_hz: float = 1000.0
    latency_s: float = 0.002
    servo_gain_per_s: float = 1000.0
    tracking_window_m: float = 0.005
    max_angular_speed_rad_s: float = math.pi
    max_angular_accel_rad_s2: float = 10.0
    max_radial_speed_m_s: float = 6.0
    floor_correlation_s: float = 0.05
    auto_reacquire: bool = True
    reacquire_s: float = 0.3
    clock_offset_s: float = 0.0
    clock_drift_ppm: float = 0.0

    def __post_init__(self) -> None:
        for name in ("max_rate_hz", "servo_gain_per_s", "tracking_window_m",
                     "max_angular_speed_rad_s", "max_angular_accel_rad_s2",
                     "max_radial_speed_m_s", "floor_correlation_s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"StreamSpec: {name} must be > 0, got {v}")
        for name in ("latency_s", "reacquire_s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"StreamSpec: {name} must be >= 0, got {v}")

    @property
    def max_lateral_speed_m_s(self) -> float:
        """``K · w``: the fastest steady lateral motion the beam follows (m/s)."""
        return self.servo_gain_per_s * self.tracking_window_m

    def tracker_clock(self, true_s: float) -> float:
        """The tracker's clock at true time ``true_s``."""
        return self.clock_offset_s + (1.0 + self.clock_drift_ppm * 1e-6) * true_s


@dataclass(frozen=True)
class StreamSample:
    """One output sample (tracker frame, metres).

    ``true_time_s``: middle of its window, true time (tests only);
    ``tracker_time_s``: the same instant on the tracker's clock (what it reports);
    ``available_s``: true time it leaves the tracker; ``status``: ``ok`` or the reason
    it holds no measurement (then ``pose`` is None); ``pose``: 4×4 (identity rotation
    for 3-DOF); ``lateral_offset_m``: the reflector's largest distance off the beam
    during the window (the servo's lag); ``seq``: the sample's number from 0.
    """

    true_time_s: float
    tracker_time_s: float
    available_s: float
    status: str
    pose: Array | None
    six_dof: bool
    lateral_offset_m: float
    seq: int = 0


def _angles(p: Array) -> tuple[float, float, float]:
    r = float(np.linalg.norm(p))
    return r, math.atan2(p[1], p[0]), math.atan2(p[2], math.hypot(p[0], p[1]))


def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


class TrackerStream:
    """A tracker streaming a moving reflector (module docstring).

    Parameters
    ----------
    tracker : LaserTracker
        The instrument (its spec's accuracy, capture radius and range, its systematic
        field); its beam must be locked on (within the capture radius of) the
        reflector at ``start_s``.
    target : callable
        ``target(t) -> 4×4`` true reflector pose in the tracker frame at true time
        ``t`` (s), or None when there is no reflector.
    rate_hz : float
        Output rate, 1…``spec.max_rate_hz``.
    six_dof : bool
        T-MAC (pose) or SMR (position).
    blocked : callable, optional
        ``blocked(t) -> bool``: the line of sight is interrupted at true time ``t``.
    """

    def __init__(self, tracker: LaserTracker, target: Callable[[float], Array | None],
                 rate_hz: float, *, six_dof: bool = True, spec: StreamSpec | None = None,
                 blocked: Callable[[float], bool] | None = None, start_s: float = 0.0,
                 seed: int = 0) -> None:
        self.spec = spec if spec is not None else StreamSpec()
        if not (math.isfinite(rate_hz) and 1.0 <= rate_hz <= self.spec.max_rate_hz):
            raise ValueError(f"rate {rate_hz} Hz outside 1…{self.spec.max_rate_hz:g} Hz "
                             "(the tracker's output rate)")
        self.tracker = tracker
        self.target = target
        self.rate_hz = float(rate_hz)
        self.six_dof = bool(six_dof)
        self.blocked = blocked if blocked is not None else (lambda t: False)
        ts = tracker.spec
        self.n = max(1, math.ceil(ts.sample_rate_hz / self.rate_hz - 1e-9))
        self.h = 1.0 / (self.rate_hz * self.n)
        self._rng = np.random.default_rng(np.random.SeedSequence([seed, 38]))
        self._floor = np.zeros(6)
        self._rho = math.exp(-1.0 / (self.rate_hz * self.spec.floor_correlation_s))
        self._k = 0
        self._t0 = float(start_s)
        pose = target(self._t0)
        if pose is None or tracker.aim_point is None or \
                tracker.beam_offset(np.asarray(pose)[:3, 3]) > ts.capture_radius_m:
            raise BeamNotLockedError(
                "beam not locked: no reflector within the capture radius of the beam; "
                "point the beam at it first", reason="capture", offset_m=None,
                capture_radius_m=ts.capture_radius_m)
        r, az, el = _angles(np.asarray(pose)[:3, 3])
        self._beam = [az, el]
        self._rate = [0.0, 0.0]
        self._range = r
        self.locked = True
        self._reason = ""
        self._clear_since: float | None = None

    # -- the servo ------------------------------------------------------------------------

    def _servo(self, t: float, p: Array) -> float:
        """One internal sample at true time ``t`` with the reflector at ``p``; returns the
        reflector's distance off the beam (m)."""
        spec = self.spec
        r, az, el = _angles(p)
        # the position detector sees the offset, then the axes act on it
        dz, de = _wrap(az - self._beam[0]) * math.cos(el), el - self._beam[1]
        offset = r * math.hypot(dz, de)
        if self.locked:
            lim_v, lim_a = spec.max_angular_speed_rad_s, spec.max_angular_accel_rad_s2 * self.h
            for i, target in enumerate((az, el)):
                e = _wrap(target - self._beam[i])
                w = min(max(spec.servo_gain_per_s * e, self._rate[i] - lim_a),
                        self._rate[i] + lim_a)
                self._rate[i] = min(max(w, -lim_v), lim_v)
                self._beam[i] += self._rate[i] * self.h
        radial_speed = abs(r - self._range) / self.h
        self._range = r
        if self.blocked(t):
            self._break("line_of_sight")
            self._clear_since = None
        elif self.locked and (offset > spec.tracking_window_m
                              or radial_speed > spec.max_radial_speed_m_s):
            self._break("tracking_speed")
        elif not self.locked and spec.auto_reacquire:
            if self._clear_since is None:
                self._clear_since = t
            elif t - self._clear_since >= spec.reacquire_s:  # found again: lock on it
                self._beam, self._rate = [az, el], [0.0, 0.0]
                self.locked, self._reason, self._clear_since = True, "", None
                offset = 0.0
        return offset

    def _break(self, reason: str) -> None:
        if self.locked:
            self.locked, self._reason = False, reason
            self._rate = [0.0, 0.0]  # no signal on the detector: the beam holds

    # -- samples --------------------------------------------------------------------------

    def next_time(self) -> float:
        """True time at which the next sample leaves the tracker."""
        return self._t0 + (self._k + 1) / self.rate_hz + self.spec.latency_s

    def advance(self, until_s: float, limit: int | None = None) -> list[StreamSample]:
        """Every sample that has left the tracker by true time ``until_s``, in order —
        or only the first ``limit`` of them (the others at the next call)."""
        out: list[StreamSample] = []
        while self.next_time() <= until_s and (limit is None or len(out) < limit):
            out.append(self._sample())
        return out

    def _sample(self) -> StreamSample:
        spec = self.spec
        start = self._t0 + self._k / self.rate_hz
        self._k += 1
        positions, ok, worst, mid_pose = [], True, 0.0, None
        status = ""
        for i in range(self.n):
            t = start + (i + 0.5) * self.h
            pose = self.target(t)
            if pose is None:
                self._break("line_of_sight")
                ok = False
                continue
            pose = np.asarray(pose, dtype=float)
            worst = max(worst, self._servo(t, pose[:3, 3]))
            ok = ok and self.locked
            positions.append(pose[:3, 3])
            if i == self.n // 2:
                mid_pose = pose
        t_mid = start + 0.5 / self.rate_hz
        common = dict(true_time_s=t_mid, tracker_time_s=spec.tracker_clock(t_mid),
                      available_s=start + 1.0 / self.rate_hz + spec.latency_s,
                      six_dof=self.six_dof, lateral_offset_m=worst, seq=self._k - 1)
        if not ok or mid_pose is None:
            status = self._reason or "line_of_sight"
            return StreamSample(status=status, pose=None, **common)
        p = np.mean(positions, axis=0)
        try:
            self.tracker.check_range(p, mid_pose if self.six_dof else None)
        except TargetOutOfRangeError:
            return StreamSample(status="out_of_range", pose=None, **common)
        return StreamSample(status="ok", pose=self._reading(p, mid_pose), **common)

    def _reading(self, p: Array, mid_pose: Array) -> Array:
        """The measured pose: window mean + the three noise parts (module docstring)."""
        ts = self.tracker.spec
        r = float(np.linalg.norm(p))
        _, az, el = _angles(p)
        ca, sa, ce, se = math.cos(az), math.sin(az), math.cos(el), math.sin(el)
        axes = np.array([[ce * ca, ce * sa, se], [-sa, ca, 0.0], [-se * ca, -se * sa, ce]])
        sr, sl = ts.position_sigma(r, ts.reference_duration_s)
        sig = np.array([sr, sl, sl, *(3 * [ts.orientation_mpe_rad / ts.mpe_coverage])])
        n_ref = ts.samples(ts.reference_duration_s)
        self._floor = self._rho * self._floor + math.sqrt(1.0 - self._rho ** 2) * \
            self._rng.standard_normal(6)
        unit = (math.sqrt(ts.share_systematic) * self.tracker.systematic_unit(p)
                + math.sqrt(ts.share_floor) * self._floor
                + math.sqrt(ts.share_white * n_ref / self.n) * self._rng.standard_normal(6))
        e = sig * unit
        out = np.eye(4)
        out[:3, 3] = p + e[:3] @ axes
        if self.six_dof:
            out[:3, :3] = so3_exp(e[3:]) @ mid_pose[:3, :3]
        return out
