"""Simulated laser tracker (Leica AT901-class with T-MAC), thesis 2.3.1.1, 3.2.2.2, 8.3–8.4.

The tracker knows nothing about robots. Whoever simulates the world hands it the
**true** pose of a reflector in the tracker frame (4×4, metres) and it returns
what a tracker would report: the pose (6-DOF, T-MAC) or the position (3-DOF,
SMR) with realistic errors — or refuses, when the beam is not locked on the
reflector.

Error model (per measurement; details and sources in ``docs/tracker-model.md``)
--------------------------------------------------------------------------------
Position errors are drawn in the *beam frame* of the reflector: radial (along
the beam: interferometer/ADM distance) and two lateral directions (azimuth and
elevation: angle encoders × range). The total 1-σ error of a measurement of
the reference duration (1 s) is the spec's MPE divided by its coverage factor::

    σ_lateral(r) = (15 µm + 6 µm/m · r) / 2        σ_radial(r) = (15 µm + 0.5 µm/m · r) / 2
    σ_orientation = 0.01° / 2   (per axis, T-MAC)

and that variance is split into three parts that behave differently with the
measuring time ``t`` (``N(t) = sample_rate · t`` internal samples, 3000 in 1 s,
thesis 3.2.2.2)::

    σ²(t) = σ²(1 s) · [ share_systematic + share_floor + share_white · N(1 s) / N(t) ]

* **systematic** (85 %): a fixed, smooth function of the beam direction drawn
  once per tracker instance from its seed (encoder, mirror and ADM calibration
  residuals). Repeating a measurement does not change it.
* **floor** (12 %): drawn afresh for each measurement but not reduced by
  averaging within one (air turbulence, short-term thermal drift).
* **white** (3 % at 1 s): sample noise, averaged over the ``N`` samples.

A 50 ms measurement (150 samples) therefore has a repeatability about 2.2×
worse than a 1 s one; at 3 m a 50 ms reading differs from a 1 s reading of the
same static target by ≈ 0.02 mm (3-D, thesis 8.3.3: "0.02 mm in Δp"), and
readings under 10 ms often differ by more than 0.05 mm (thesis 3.2.2.2).

Beam lock
---------
* The beam points along the ray from the tracker origin through its *aim
  point*. A reflector is *capturable* when its perpendicular distance from that
  ray is within the capture radius (10 mm, thesis 8.4.3).
* :meth:`LaserTracker.point_at` (the thesis's ``Move``) slews the beam to an
  expected reflector position and leaves it unlocked. The next
  :meth:`~LaserTracker.measure` acquires the reflector by ADM (costs
  ``adm_acquisition_s``) if it is capturable, else raises
  :class:`BeamNotLockedError` (and costs ``acquisition_timeout_s``).
* Once locked, the beam follows the reflector: after each measurement the aim
  point is the reflector's position. Between measurements the world either
  reports the motion with :meth:`~LaserTracker.track` (continuous motion is
  followed up to 5 m/s, thesis 2.3.1.1) or not at all — then a reflector that
  has *jumped* more than the capture radius off the beam axis has lost the lock
  (the next measurement raises; the beam stays where it was). Moves along the
  beam, or smaller than the capture radius, keep the lock.
* :meth:`~LaserTracker.block_line_of_sight` breaks the beam (thesis 3.4 fault
  injection): measurements raise and the lock is lost; once unblocked the beam,
  still aimed at the last position, re-acquires by ADM if the reflector is
  still capturable.

Time is simulated: every call returns or records the time it took and
advances :attr:`LaserTracker.clock_s`; nothing sleeps.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "BeamNotLockedError",
    "LaserTracker",
    "TargetOutOfRangeError",
    "TrackerError",
    "TrackerMeasurement",
    "TrackerSpec",
]

FloatArray = NDArray[np.float64]
Mode = Literal["6dof", "3dof"]

# Harmonics (azimuth order k, elevation frequency m) of the systematic error field.
_FIELD_HARMONICS = np.array(
    [(k, m) for k in range(4) for m in range(3)], dtype=float
)  # 12 terms, (0, 0) is a constant offset


class TrackerError(RuntimeError):
    """The tracker cannot deliver a measurement (device state, not bad input)."""


class BeamNotLockedError(TrackerError):
    """The beam is not locked on the reflector.

    Attributes:
        reason: ``"not_pointed"`` (beam never aimed), ``"capture"`` (reflector
            outside the capture radius of the beam axis), ``"line_of_sight"``
            (beam blocked) or ``"tracking_speed"`` (reflector moved faster than
            the tracker can follow).
        offset_m: perpendicular distance of the reflector from the beam axis
            (m), when known.
        capture_radius_m: the capture radius (m).
    """

    def __init__(
        self, message: str, *, reason: str, offset_m: float | None, capture_radius_m: float
    ) -> None:
        super().__init__(message)
        self.reason = reason
        self.offset_m = offset_m
        self.capture_radius_m = capture_radius_m


class TargetOutOfRangeError(TrackerError):
    """The reflector is outside the tracker's working range (distance or elevation)."""


@dataclass(frozen=True)
class TrackerSpec:
    """Specification of a Leica AT901-MR-class tracker with T-MAC (defaults documented).

    Accuracy
        ``mpe_constant_m`` + ``mpe_per_metre``·r: position MPE ±(15 µm + 6 µm/m),
        thesis Table 2-2; read as a ``mpe_coverage`` = 2 σ bound on the lateral
        coordinates of a ``reference_duration_s`` = 1 s measurement. Radial
        (distance) errors use ``mpe_constant_m`` + ``mpe_radial_per_metre``·r
        (interferometer/ADM ±0.5 µm/m). ``orientation_mpe_rad``: T-MAC ±0.01°
        (thesis 8.2.1), same coverage, per axis.
    Noise split (variance shares at the reference duration, sum 1)
        ``share_systematic`` fixed field over beam direction,
        ``share_floor`` per measurement, not averaged,
        ``share_white`` averaged over ``sample_rate_hz``·t samples (3000 Hz:
        "a single measurement taken in one second actually is the average of
        3000 samples", thesis 3.2.2.2).
    Beam
        ``capture_radius_m`` 10 mm (thesis 8.4.3); ``max_tracking_speed_m_s``
        5 m/s (2.3.1.1); ``max_slew_rate_rad_s`` 180°/s and ``settle_time_s``
        for a ``Move``; ``adm_acquisition_s`` to (re-)establish the distance by
        ADM (2.3.1.1); ``acquisition_timeout_s`` spent on a failed search;
        ``report_latency_s`` 10 ms (data sent in packets of 10 at 1 kHz,
        3.2.2.2); ``min_duration_s`` 1 ms (1 kHz output rate, Table 2-2).
    Working range
        ``min_range_m``–``max_range_m`` (40 m: AT901-MR's 80 m diameter),
        ``max_range_6dof_m`` (T-Cam), elevation ``±max_elevation_rad`` (±45°).
        ``tmac_acceptance_rad``: if set, a 6-DOF measurement also requires the
        T-MAC's facing axis ``tmac_facing_axis`` (reflector frame) within this
        angle of the direction to the tracker; ``None`` (default) skips the check.
    """

    mpe_constant_m: float = 15e-6
    mpe_per_metre: float = 6e-6
    mpe_radial_per_metre: float = 0.5e-6
    mpe_coverage: float = 2.0
    orientation_mpe_rad: float = float(np.deg2rad(0.01))
    reference_duration_s: float = 1.0
    sample_rate_hz: float = 3000.0
    share_systematic: float = 0.85
    share_floor: float = 0.12
    share_white: float = 0.03
    capture_radius_m: float = 0.010
    max_tracking_speed_m_s: float = 5.0
    max_slew_rate_rad_s: float = float(np.deg2rad(180.0))
    settle_time_s: float = 0.05
    adm_acquisition_s: float = 0.2
    acquisition_timeout_s: float = 1.0
    report_latency_s: float = 0.01
    min_duration_s: float = 0.001
    min_range_m: float = 0.5
    max_range_m: float = 40.0
    max_range_6dof_m: float = 15.0
    max_elevation_rad: float = float(np.deg2rad(45.0))
    tmac_acceptance_rad: float | None = None
    tmac_facing_axis: tuple[float, float, float] = (0.0, 0.0, 1.0)

    def __post_init__(self) -> None:
        shares = (self.share_systematic, self.share_floor, self.share_white)
        if min(shares) < 0 or abs(sum(shares) - 1.0) > 1e-9:
            raise ValueError(
                f"TrackerSpec: variance shares must be >= 0 and sum to 1, got {shares}"
            )
        positive = {
            "mpe_coverage": self.mpe_coverage,
            "reference_duration_s": self.reference_duration_s,
            "sample_rate_hz": self.sample_rate_hz,
            "capture_radius_m": self.capture_radius_m,
            "max_tracking_speed_m_s": self.max_tracking_speed_m_s,
            "max_slew_rate_rad_s": self.max_slew_rate_rad_s,
            "min_duration_s": self.min_duration_s,
            "max_range_m": self.max_range_m,
        }
        for k, v in positive.items():
            if not v > 0:
                raise ValueError(f"TrackerSpec: {k} must be > 0, got {v}")

    # -- accuracy helpers ---------------------------------------------------------

    def position_mpe(self, range_m: ArrayLike) -> FloatArray:
        """Lateral position MPE ``15 µm + 6 µm/m · r`` (m)."""
        return self.mpe_constant_m + self.mpe_per_metre * np.asarray(range_m, dtype=float)

    def samples(self, duration_s: float) -> int:
        """Number of internal samples averaged in a measurement of ``duration_s``."""
        return max(1, int(np.floor(self.sample_rate_hz * duration_s + 1e-9)))

    def _duration_factor(self, duration_s: float, include_systematic: bool) -> float:
        n_ref = self.samples(self.reference_duration_s)
        f = self.share_floor + self.share_white * n_ref / self.samples(duration_s)
        if include_systematic:
            f += self.share_systematic
        return float(np.sqrt(f))

    def position_sigma(
        self, range_m: ArrayLike, duration_s: float = 1.0, *, include_systematic: bool = True
    ) -> tuple[FloatArray, FloatArray]:
        """Per-axis 1-σ position error ``(radial, lateral)`` at ``range_m`` (m).

        ``include_systematic=False`` gives the repeatability (scatter of repeated
        measurements of a static reflector).
        """
        r = np.asarray(range_m, dtype=float)
        f = self._duration_factor(duration_s, include_systematic)
        radial = (self.mpe_constant_m + self.mpe_radial_per_metre * r) / self.mpe_coverage
        lateral = self.position_mpe(r) / self.mpe_coverage
        return radial * f, lateral * f

    def orientation_sigma(
        self, duration_s: float = 1.0, *, include_systematic: bool = True
    ) -> float:
        """Per-axis 1-σ orientation error of a T-MAC measurement (rad)."""
        f = self._duration_factor(duration_s, include_systematic)
        return self.orientation_mpe_rad / self.mpe_coverage * f


@dataclass(frozen=True)
class TrackerMeasurement:
    """One tracker reading, in the tracker frame.

    Attributes:
        position: measured reflector position (m), ``(3,)``.
        pose: measured T-MAC pose (4×4) in ``"6dof"`` mode, else ``None``.
        mode: ``"6dof"`` or ``"3dof"``.
        duration_s: integration time.
        timestamp_s: tracker clock at the middle of the integration.
        elapsed_s: time the call took (ADM acquisition + integration + report).
        range_m: measured distance to the reflector (m).
        samples: internal samples averaged.
    """

    position: FloatArray
    pose: FloatArray | None
    mode: Mode
    duration_s: float
    timestamp_s: float
    elapsed_s: float
    range_m: float
    samples: int


def _beam_frame(p: FloatArray) -> tuple[float, float, float, FloatArray]:
    """Range, azimuth, elevation and the beam-frame axes (rows: radial, az, el)."""
    r = float(np.linalg.norm(p))
    az = float(np.arctan2(p[1], p[0]))
    el = float(np.arctan2(p[2], np.hypot(p[0], p[1])))
    ca, sa, ce, se = np.cos(az), np.sin(az), np.cos(el), np.sin(el)
    axes = np.array(
        [[ce * ca, ce * sa, se], [-sa, ca, 0.0], [-se * ca, -se * sa, ce]]
    )
    return r, az, el, axes


@dataclass
class _Field:
    """Unit-variance random smooth field over beam direction (6 channels)."""

    amp: FloatArray  # (6, J)
    phase: FloatArray  # (6, J)
    harmonics: FloatArray = field(default_factory=lambda: _FIELD_HARMONICS.copy())

    @classmethod
    def draw(cls, rng: np.random.Generator) -> _Field:
        J = len(_FIELD_HARMONICS)
        amp = rng.standard_normal((6, J)) * np.sqrt(2.0 / J)
        phase = rng.uniform(0.0, 2.0 * np.pi, (6, J))
        return cls(amp=amp, phase=phase)

    def __call__(self, az: float, el: float) -> FloatArray:
        arg = self.harmonics[:, 0] * az + self.harmonics[:, 1] * el
        return np.sum(self.amp * np.cos(arg[None, :] + self.phase), axis=1)


class LaserTracker:
    """A simulated tracker device: beam state, clock and a seeded error model.

    Args:
        spec: the tracker's specification.
        seed: seed of the tracker's private random streams. The systematic error
            field is drawn once from it at construction; measurement noise from a
            separate stream, so equal seeds and equal call sequences give equal
            readings.
    """

    def __init__(self, spec: TrackerSpec | None = None, *, seed: int | None = 0) -> None:
        self.spec = spec if spec is not None else TrackerSpec()
        field_seq, noise_seq = np.random.SeedSequence(seed).spawn(2)
        self._field = _Field.draw(np.random.default_rng(field_seq))
        self._rng = np.random.default_rng(noise_seq)
        self._clock = 0.0
        self._aim: FloatArray | None = None
        self._locked = False
        self._blocked = False
        self._lost_speed: float | None = None  # speed of the motion that broke the lock

    # -- state -----------------------------------------------------------------------

    @property
    def clock_s(self) -> float:
        """Simulated time accumulated by the tracker (s)."""
        return self._clock

    @property
    def locked(self) -> bool:
        """Whether the beam is locked on a reflector."""
        return self._locked

    @property
    def aim_point(self) -> FloatArray | None:
        """Where the beam points (a point on the beam axis), or ``None`` before any aim."""
        return None if self._aim is None else self._aim.copy()

    @property
    def line_of_sight_blocked(self) -> bool:
        """Whether the beam is currently blocked (fault injection)."""
        return self._blocked

    def block_line_of_sight(self, blocked: bool = True) -> None:
        """Block (or clear) the beam's line of sight; blocking breaks the lock."""
        self._blocked = bool(blocked)
        if self._blocked:
            self._locked = False

    # -- commands --------------------------------------------------------------------

    def point_at(self, expected_position: ArrayLike) -> float:
        """Slew the beam to an expected reflector position (the thesis's ``Move``).

        ``expected_position`` is a 3-vector or a 4×4 pose (its translation), in the
        tracker frame — typically ``BASE · T_n^0 · PROBE`` from the robot's model
        (eq. 7.1). The lock is released; the next :meth:`measure` acquires the
        reflector by ADM if it lies within the capture radius of the new beam axis.

        Returns:
            Simulated time taken (s): slew angle / slew rate + settle time.
        """
        p = _position_of(expected_position, "expected_position")
        if np.linalg.norm(p) < 1e-9:
            raise ValueError("expected_position: the tracker origin has no beam direction")
        if self._aim is None:
            angle = np.pi / 2.0  # from the home position: assume a quarter turn
        else:
            u0 = self._aim / np.linalg.norm(self._aim)
            u1 = p / np.linalg.norm(p)
            angle = float(np.arctan2(np.linalg.norm(np.cross(u0, u1)), u0 @ u1))
        dt = angle / self.spec.max_slew_rate_rad_s + self.spec.settle_time_s
        self._aim = p.copy()
        self._locked = False
        self._lost_speed = None
        self._clock += dt
        return float(dt)

    def track(self, true_pose: ArrayLike, elapsed_s: float) -> None:
        """Report that the reflector moved continuously to ``true_pose`` in ``elapsed_s``.

        A locked beam follows a continuous motion whose mean speed is within
        ``max_tracking_speed_m_s``; a faster motion, or a blocked beam, loses the
        lock (the beam stays at the last position). Unlocked: nothing follows.
        Advances the clock by ``elapsed_s``.
        """
        p = _position_of(true_pose, "true_pose")
        if not elapsed_s >= 0:
            raise ValueError(f"elapsed_s: must be >= 0, got {elapsed_s}")
        self._clock += float(elapsed_s)
        if not self._locked or self._aim is None:
            return
        if self._blocked:
            self._locked = False
            return
        dist = float(np.linalg.norm(p - self._aim))
        if dist <= self.spec.capture_radius_m or (
            elapsed_s > 0 and dist / elapsed_s <= self.spec.max_tracking_speed_m_s
        ):
            self._aim = p.copy()
        else:
            self._locked = False
            self._lost_speed = dist / elapsed_s if elapsed_s > 0 else float("inf")

    def measure(
        self, true_pose: ArrayLike, duration_s: float = 1.0, mode: Mode = "6dof"
    ) -> TrackerMeasurement:
        """Measure the reflector whose true pose (tracker frame) is ``true_pose``.

        Args:
            true_pose: 4×4 true pose of the T-MAC (``"6dof"``), or a 4×4 pose or
                3-vector position of the SMR (``"3dof"``), metres.
            duration_s: integration time (≥ ``min_duration_s``); the thesis uses
                1 s for calibration/verification and 50 ms inside the correction
                loop (8.3.2).
            mode: ``"6dof"`` (T-MAC pose) or ``"3dof"`` (position only).

        Raises:
            BeamNotLockedError: beam blocked, never pointed, or the reflector not
                within the capture radius of the beam axis (lock is lost).
            TargetOutOfRangeError: reflector outside the working range.
            ValueError: malformed arguments.
        """
        spec = self.spec
        if mode not in ("6dof", "3dof"):
            raise ValueError(f"mode: must be '6dof' or '3dof', got {mode!r}")
        if not (np.isfinite(duration_s) and duration_s >= spec.min_duration_s):
            raise ValueError(
                f"duration_s: must be >= {spec.min_duration_s} s (1 kHz output), got {duration_s}"
            )
        T = _pose_of(true_pose, "true_pose") if mode == "6dof" else None
        p = T[:3, 3] if T is not None else _position_of(true_pose, "true_pose")
        self.check_range(p, T)

        elapsed = self._lock_on(p)
        t_mid = self._clock + elapsed + duration_s / 2.0
        elapsed += duration_s + spec.report_latency_s
        measured_p, pose, n = self._reading(p, T, duration_s)

        self._aim = p.copy()  # the beam follows the reflector
        self._clock += elapsed
        return TrackerMeasurement(
            position=measured_p, pose=pose, mode=mode, duration_s=float(duration_s),
            timestamp_s=float(t_mid), elapsed_s=float(elapsed),
            range_m=float(np.linalg.norm(measured_p)), samples=n,
        )

    # -- helpers ---------------------------------------------------------------------

    def _lock_on(self, p: FloatArray) -> float:
        """Lock the beam on the reflector at ``p`` (tracker frame, m), or say why it cannot.

        The reflector is acquired by ADM when it lies within ``capture_radius_m`` of the
        beam axis (:meth:`beam_offset`) and the line of sight is clear.

        Parameters
        ----------
        p : (3,) array, m
            True reflector position.

        Returns
        -------
        float, s
            Acquisition time: ``adm_acquisition_s`` if the beam was not locked, else 0.

        Raises
        ------
        BeamNotLockedError
            Beam blocked, never pointed, or the reflector beyond the capture radius (an
            unlocked beam then also spends ``acquisition_timeout_s`` searching).
        """
        spec = self.spec
        if self._blocked:
            self._locked = False
            raise BeamNotLockedError(
                "beam not locked: line of sight to the reflector is blocked",
                reason="line_of_sight", offset_m=None, capture_radius_m=spec.capture_radius_m,
            )
        if self._aim is None:
            raise BeamNotLockedError(
                "beam not locked: the beam has not been pointed at a reflector; call point_at",
                reason="not_pointed", offset_m=None, capture_radius_m=spec.capture_radius_m,
            )
        d = self.beam_offset(p)
        if d > spec.capture_radius_m:
            was_locked = self._locked
            self._locked = False
            if not was_locked:
                self._clock += spec.acquisition_timeout_s
            what = "jumped to" if was_locked else "is"
            cause, reason = "", "capture"
            if self._lost_speed is not None:
                cause = (
                    f"lock lost when the reflector moved at {self._lost_speed:.2f} m/s, faster "
                    f"than the {spec.max_tracking_speed_m_s:g} m/s the tracker follows; "
                )
                reason = "tracking_speed"
            raise BeamNotLockedError(
                f"beam not locked: {cause}reflector {what} {d * 1e3:.2f} mm from the beam axis, "
                f"beyond the {spec.capture_radius_m * 1e3:.1f} mm capture radius; "
                "point the beam at it (point_at) first",
                reason=reason, offset_m=d, capture_radius_m=spec.capture_radius_m,
            )
        elapsed = 0.0
        if not self._locked:
            elapsed += spec.adm_acquisition_s
            self._locked = True
            self._lost_speed = None
        return elapsed

    def _reading(
        self, p: FloatArray, T: FloatArray | None, duration_s: float
    ) -> tuple[FloatArray, FloatArray | None, int]:
        """The error model: one reading of the reflector at ``p`` (pose ``T``) over ``duration_s``.

        In the beam frame (radial, azimuth, elevation; rows ``A`` of :func:`_beam_frame`)
        the position error is

        ``e = σ_ref ∘ (√s_sys · f(az, el) + √(s_floor + s_white · n_ref / n) · ξ)``,
        ``p̂ = p + Aᵀ e``

        with ``σ_ref = (σ_r, σ_l, σ_l)`` the spec's σ at the reference duration, ``f`` the
        tracker's unit-variance systematic field, ``n`` (``n_ref``) the samples averaged in
        ``duration_s`` (the reference duration) and ``ξ ~ N(0, I₃)``.  In ``"6dof"`` the
        orientation error is the rotation vector ``δφ = σ_o (√s_sys f₃…₅ + √(…) ξ')``,
        ``σ_o = orientation_mpe / coverage``, applied as ``R̂ = exp(δφ) R``.

        Parameters
        ----------
        p : (3,) array, m
            True reflector position (tracker frame).
        T : (4, 4) array or None
            True T-MAC pose (``"6dof"``), ``None`` for ``"3dof"``.
        duration_s : float, s
            Integration time.

        Returns
        -------
        position : (3,) array, m
            Measured position ``p̂``.
        pose : (4, 4) array or None
            Measured pose ``[R̂, p̂]`` in ``"6dof"``.
        samples : int
            ``n``, the samples averaged.
        """
        spec = self.spec
        r, az, el, axes = _beam_frame(p)
        sys_unit = self._field(az, el)
        sr_ref, sl_ref = spec.position_sigma(r, spec.reference_duration_s)
        # reference-duration total σ split into systematic / floor / white parts
        n = spec.samples(duration_s)
        n_ref = spec.samples(spec.reference_duration_s)
        f_sys = np.sqrt(spec.share_systematic)
        f_rand = np.sqrt(spec.share_floor + spec.share_white * n_ref / n)
        sig_ref = np.array([sr_ref, sl_ref, sl_ref])  # total σ at the reference duration
        e_beam = sig_ref * (f_sys * sys_unit[:3] + f_rand * self._rng.standard_normal(3))
        measured_p = p + e_beam @ axes

        pose = None
        if T is not None:
            so = spec.orientation_mpe_rad / spec.mpe_coverage
            dphi = so * (f_sys * sys_unit[3:] + f_rand * self._rng.standard_normal(3))
            pose = np.eye(4)
            pose[:3, :3] = _rotvec_matrix(dphi) @ T[:3, :3]
            pose[:3, 3] = measured_p
        return measured_p, pose, n

    def beam_offset(self, position: ArrayLike) -> float:
        """Perpendicular distance of ``position`` from the current beam axis (m).

        ``inf`` before the beam has been aimed; the full distance for points
        behind the tracker.
        """
        p = _position_of(position, "position")
        if self._aim is None:
            return float("inf")
        u = self._aim / np.linalg.norm(self._aim)
        along = float(p @ u)
        if along <= 0.0:
            return float(np.linalg.norm(p))
        return float(np.linalg.norm(p - along * u))

    def systematic_unit(self, position: ArrayLike) -> FloatArray:
        """The unit-variance systematic field at the direction of ``position``, ``(6,)``:
        beam-frame position channels (radial, azimuth, elevation) then orientation —
        scaled by the spec's σ and √share_systematic it is the fixed error there (for
        the streaming model, :mod:`plugcell.sim.twin.tracker_stream`)."""
        _, az, el, _ = _beam_frame(_position_of(position, "position"))
        return self._field(az, el)

    def systematic_error(self, position: ArrayLike) -> FloatArray:
        """The tracker's fixed position error at ``position`` (m, tracker frame).

        The part of every measurement there that no averaging removes (test
        and documentation aid; a real tracker does not tell you this).
        """
        p = _position_of(position, "position")
        r, az, el, axes = _beam_frame(p)
        sr, sl = self.spec.position_sigma(r, self.spec.reference_duration_s)
        e = np.array([sr, sl, sl]) * np.sqrt(self.spec.share_systematic) * self._field(az, el)[:3]
        return e @ axes

    def check_range(self, p: FloatArray, T: FloatArray | None) -> None:
        """Raise :class:`TargetOutOfRangeError` if position ``p`` (and a T-MAC pose ``T``)
        lies outside the working range."""
        spec = self.spec
        r = float(np.linalg.norm(p))
        max_r = spec.max_range_6dof_m if T is not None else spec.max_range_m
        if not spec.min_range_m <= r <= max_r:
            raise TargetOutOfRangeError(
                f"reflector at {r:.3f} m is outside the working range "
                f"{spec.min_range_m:g}–{max_r:g} m" + (" (6-DOF)" if T is not None else "")
            )
        el = float(np.arctan2(p[2], np.hypot(p[0], p[1])))
        if abs(el) > spec.max_elevation_rad:
            raise TargetOutOfRangeError(
                f"reflector elevation {np.rad2deg(el):.1f}° is outside "
                f"±{np.rad2deg(spec.max_elevation_rad):.1f}°"
            )
        if T is not None and spec.tmac_acceptance_rad is not None:
            facing = T[:3, :3] @ np.asarray(spec.tmac_facing_axis, dtype=float)
            facing /= np.linalg.norm(facing)
            to_tracker = -p / r
            ang = float(np.arccos(np.clip(facing @ to_tracker, -1.0, 1.0)))
            if ang > spec.tmac_acceptance_rad:
                raise TargetOutOfRangeError(
                    f"T-MAC faces {np.rad2deg(ang):.1f}° away from the tracker, beyond its "
                    f"±{np.rad2deg(spec.tmac_acceptance_rad):.1f}° acceptance"
                )


def _rotvec_matrix(v: FloatArray) -> FloatArray:
    """Rotation matrix of a rotation vector (Rodrigues)."""
    th = float(np.linalg.norm(v))
    K = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    if th < 1e-12:
        return np.eye(3) + K
    K /= th
    return np.eye(3) + np.sin(th) * K + (1.0 - np.cos(th)) * (K @ K)


def _position_of(x: ArrayLike, name: str) -> FloatArray:
    a = np.asarray(x, dtype=float)
    if a.shape == (4, 4):
        a = a[:3, 3]
    if a.shape != (3,):
        raise ValueError(f"{name}: expected a 3-vector or a 4x4 pose, got shape {a.shape}")
    if not np.isfinite(a).all():
        raise ValueError(f"{name}: non-finite value (NaN or inf)")
    return a.copy()


def _pose_of(x: ArrayLike, name: str) -> FloatArray:
    a = np.asarray(x, dtype=float)
    if a.shape != (4, 4):
        raise ValueError(f"{name}: 6-DOF mode needs a 4x4 pose, got shape {a.shape}")
    if not np.isfinite(a).all():
        raise ValueError(f"{name}: non-finite value (NaN or inf)")
    R = a[:3, :3]
    if np.abs(R.T @ R - np.eye(3)).max() > 1e-6 or np.linalg.det(R) <= 0:
        raise ValueError(f"{name}: rotation block is not a proper rotation")
    return a.copy()
