"""The correction law of dynamic path correction: model feed-forward, lead, tracker term.

The robot's controller runs its own path (mode (b), docs/kuka-rsi.md "The robot drives,
plugcell corrects"); each cycle :meth:`TrackingLoop.cycle` is given the robot time
``t``, the joint feedback ``q(t)`` and the path's own (uncorrected) pose ``T_p(t)`` of
the controller's TCP, and answers the offset ``o = [Δp; φ]`` (base frame F0, m and
rad) to superimpose: the controller then aims at ``T_c = (p_p + Δp, exp(φ)·R_p)``.

The law — three terms, each for an error of a different kind::

    T_lead = (p_p + Δp_lead, R_p),      Δp_lead = v̂ τ + â τ²/2        (1) lead
    T_tgt  = (p_lead − c_p + u(t), exp(−c_φ) R_lead)                   (3) tracker term,
                                                                        (4) learned offset
    q*     = argmin ‖e(T_tgt, T_model(q))‖,   T_c = T_nominal(q*)          (2) model FF

1. **Lead** (feed-forward of the controller's lag, optional ``lead_s = τ``): the arm
   reaches a commanded pose a dead time later (interpolation, transfer to the drives,
   the interface's own cycle — 8–12 ms on the twin); on a path at speed ``v`` that is
   ``v τ`` *along* the path (0.8 mm at 100 mm/s).  No measurement can correct it after
   the fact — a correction computed from the error now arrives ``τ`` late too — so it is
   fed forward: the target is advanced by ``τ`` along the path's own motion, ``v̂``,
   ``â`` the finite differences of the last three ``T_p``.  Estimate ``τ`` from the
   commanded and the actual joints (:func:`plugcell.metrology.timing.estimate_delay`).
2. **Model-based feed-forward** (thesis 6.5.1 along the path): the calibrated model's
   inverse (:func:`~plugcell.compensation.model_based.compensate_joints`, warm-started
   from the last cycle's solution: one or two Newton steps) gives the joints ``q*`` at
   which the *calibrated* model puts the tool on the target; the controller reaches
   them when it aims at its own nominal pose of ``q*``.  This removes the static error
   of the nominal model (millimetres) with no measurement at all.
3. **Tracker term** ``c``: the residual ``x̂`` the tracker sees beyond the model
   (:class:`~.estimator.ResidualFilter` on ``z = e(T_meas, T_model(q(t_s)))``, the
   sample's age compensated by the joint feedback), subtracted from the target.
   Because ``x̂`` is measured against the model *at the measured joints*, moving the
   joints does not change it: the term is a disturbance feed-forward, not a feedback
   through the arm, and no integral action is needed or wanted (an integrator on a
   quantity the correction does not change would wind up).  Its only error is the
   residual's change over the sample's age plus the dead time — small for the slowly
   varying part (model residual, payload and gravity deflection, thermal drift), not
   for vibration above a few hertz, which is why ``q`` (the filter's drift intensity)
   is chosen so the term's bandwidth stays below the arm's first modes.

4. **Learned offset** ``u(t)`` (optional, a repeated path): what the previous runs of the
   same path measured, learned by :class:`~.learning.IterativeLearning` and given as
   ``learned`` (a function of the robot time, m in F0; zero when not given).

The estimate is low-passed (``H``, a causal second-order Butterworth of cut-off
``output_cutoff_hz``, below the arm's first structural modes: the estimate's noise is
white, and a lightly damped mode amplified what of it reached 9–12 Hz into a ringing of
the arm), weighted by ``w ∈ [0, 1]`` and bounded (:class:`~.limiter.RateLimiter`: speed,
acceleration and total per axis), ``c = limit(w · H(x̂))``: ``w`` fades out (a jerk-limited
ramp of ``fade_s``, :func:`~plugcell.motion.profile.unit_ramp`) when the estimate is not
fresh — no sample ``ok`` within ``max_age_s`` (a beam break: the sample's status says
why; a late or silent tracker) — so the path goes on with the model-based compensation
alone; the window is recorded (:class:`HoldWindow`); after ``resume_s`` of good samples
the filter restarts from them (the residual may have moved) and ``w`` fades back in.
All of it runs in the robot's time: a cycle ``n`` robot cycles after the last one
(a loop that fell behind skipped some) holds ``H``'s input over them, and the bounds
scale the step with ``n`` while speed and acceleration stay bounded in robot time
(:class:`~.limiter.RateLimiter`); in simulated time ``n`` is always 1.
Without orientation samples (an SMR) or with ``correct_orientation=False`` only the
position is corrected.  Blending the whole offset in and out at the path's start and end
is the correction source's (:class:`~plugcell.devices.robot.stream.source.PathOffset`).

Pure math: SI units, no I/O, no clock of its own; thread-safe :meth:`TrackingLoop.add`.
"""

from __future__ import annotations

import math
import threading
from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field, fields

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.signal import butter

from plugcell.kinematics.pose_error import pose_error_exact
from plugcell.kinematics.transforms import so3_exp, so3_log
from plugcell.motion.profile import unit_ramp

from ..model_based import compensate_joints
from ..pose_model import NominalModel, PoseModel
from .estimator import JointHistory, ResidualFilter, TrackerMeasurement
from .limiter import RateLimiter

Array = NDArray[np.float64]

__all__ = ["CycleOutput", "HoldWindow", "TrackingLoop", "TrackingSettings", "TrackingStats"]


@dataclass(frozen=True)
class TrackingSettings:
    """How the loop estimates and corrects (module docstring); SI units.

    Attributes
    ----------
    cycle_s : float
        The robot's interface cycle ``T`` (s).
    position_noise_m, orientation_noise_rad : float
        ``r``: one tracker sample's noise (the filter's measurement noise); defaults: an
        AT960-class tracker's 1 kHz sample at 3 m — 90 µm lateral, 0.5 mrad (0.03°) for
        the T-MAC's orientation (the streaming model's white share,
        docs/tracker-model.md).
    position_drift, orientation_drift : float
        ``q``: how fast the residual may change (m/√s, rad/√s); larger follows faster
        and passes more noise.  Defaults: time constants ≈ 0.3 s (position: ``K∞ ≈
        0.0035``, ≈ 4 µm of noise) and 0.3 s (orientation) — slow on purpose: on the
        twin the fast part of the residual is backlash and vibration, which a correction
        that chases it only excites (each reversal of a joint flips its gears across the
        lost motion); on the 1 m line at 250 mm/s ``q`` = 1e-5 gave 0.100 mm perpendicular
        3σ, 3e-5 gave 0.357 mm and 3e-6 0.125 mm (docs/results/dynamic-correction.md).
    gate_sigma : float
        Innovation gate in standard deviations.
    lead_s : float
        ``τ`` of the lead (0: none).
    max_age_s : float
        The estimate is fresh while its newest good sample is at most this old (s).
    fade_s : float
        Duration of the tracker term's fade out and in (s).
    resume_s : float
        Good samples needed, without a gap, before tracking resumes after a hold (s).
    max_speed_m_s, max_speed_rad_s, max_accel_m_s2, max_accel_rad_s2 : float
        Bounds on the tracker term's rate of change.
    max_correction_m, max_correction_rad : float
        Bounds on the tracker term itself, per axis.
    correct_orientation : bool
        Correct the orientation too when samples carry it (T-MAC).  Off by default: on
        the twin it moved the wrist back and forth across its backlash and made both
        orientation (0.029° → 0.054° 3σ) and position worse than the model alone.
    history_s : float
        Joint feedback kept (s): older samples cannot be used.
    max_lead_m, max_lead_speed_m_s, max_lead_accel_m_s2 : float
        Bounds on the lead (per axis): far above a planned path's (at 250 mm/s and
        2 m/s², 20 m/s³ the lead of 10 ms moves at ≤ 20 mm/s and 0.2 m/s²), they keep a
        path pose recovered wrongly — the controller applied another offset than the
        one sent, after a late answer — from throwing the lead.
    output_cutoff_hz : float
        Cut-off of the tracker term's low-pass ``H`` (Hz; 0: none), below the arm's
        first structural mode (9 Hz on the twin): the estimate's noise is white, and a
        mode of damping ζ amplifies what reaches it ≈ 1/(2ζ) times.
    feedforward_step_m : float
        The model-based feed-forward is solved anew when the target has moved this far
        from where it was last solved (m); in between it is extrapolated linearly from
        the last two solutions (it changes by millimetres per metre of path: the
        extrapolation's error is of the order of a micrometre).
    """

    cycle_s: float = 0.004
    position_noise_m: float = 90e-6
    orientation_noise_rad: float = 5e-4
    position_drift: float = 1e-5
    orientation_drift: float = 5e-5
    gate_sigma: float = 8.0
    lead_s: float = 0.0
    max_age_s: float = 0.05
    fade_s: float = 0.2
    resume_s: float = 0.05
    max_speed_m_s: float = 0.01
    max_speed_rad_s: float = math.radians(0.5)
    max_accel_m_s2: float = 0.5
    max_accel_rad_s2: float = math.radians(20.0)
    max_correction_m: float = 2e-3
    max_correction_rad: float = math.radians(0.2)
    correct_orientation: bool = False
    history_s: float = 1.0
    feedforward_step_m: float = 0.002
    max_lead_m: float = 0.01
    max_lead_speed_m_s: float = 0.05
    max_lead_accel_m_s2: float = 2.0
    output_cutoff_hz: float = 2.0

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, bool):
                continue
            ok = math.isfinite(v) and (v >= 0 if f.name in ("lead_s", "position_drift",
                                                            "orientation_drift",
                                                            "resume_s",
                                                            "output_cutoff_hz") else v > 0)
            if not ok:
                raise ValueError(f"TrackingSettings.{f.name} must be a finite number "
                                 f"{'≥' if f.name in ('lead_s', 'resume_s') else '>'} 0, "
                                 f"got {v!r}")
        if self.output_cutoff_hz >= 0.5 / self.cycle_s:
            raise ValueError(f"TrackingSettings.output_cutoff_hz {self.output_cutoff_hz!r} "
                             f"must lie below the Nyquist rate {0.5 / self.cycle_s:g} Hz")


@dataclass
class HoldWindow:
    """A stretch of the path corrected by the model alone.

    Attributes
    ----------
    start_s : float
        Robot time the tracker term began to fade out (s).
    end_s : float or None
        Robot time it began to fade back in (``None``: not resumed).
    reason : str
        Why: the samples' status (``"line_of_sight"``, …) or ``"late"`` (no sample
        within ``max_age_s``), or what the caller gave :meth:`TrackingLoop.hold` —
        appended (``"late, then tracker stopped: …"``) when it came during a hold.
    """

    start_s: float
    end_s: float | None
    reason: str


@dataclass
class TrackingStats:
    """What the loop counted."""

    cycles: int = 0
    #: cycles whose estimate took at least one new sample
    fresh_cycles: int = 0
    #: cycles with the tracker term fully on (``w = 1``)
    tracking_cycles: int = 0
    samples_used: int = 0
    samples_bad: int = 0
    #: samples older than the joint history, or arriving out of order
    samples_stale: int = 0
    #: model-based feed-forward that did not converge (the previous one kept)
    feedforward_failures: int = 0
    #: robot time minus acquisition time of the newest sample, per fresh cycle (s)
    ages_s: list[float] = field(default_factory=list)


@dataclass(frozen=True)
class CycleOutput:
    """One cycle's answer (F0, SI).

    Attributes
    ----------
    offset : (6,) array
        ``[Δp; φ]``: the controller aims at ``(p_p + Δp, exp(φ)·R_p)``.
    feedforward : (6,) array
        The model-based part (at the lead and tracker-corrected target).
    lead : (3,) array
        ``Δp_lead``.
    tracker : (6,) array
        The tracker term ``c`` after its bounds (subtracted from the target).
    residual : (6,) array
        ``x̂``: the filter's estimate (NaN before the first sample).
    weight : float
        ``w``.
    state : str
        ``"tracking"`` (the term on, or fading in: see ``weight``), ``"holding"`` (fading
        out or off: the model alone), ``"acquiring"`` (no sample yet) or ``"model"``
        (tracking switched off).
    fresh : bool
        This cycle took at least one new sample.
    learned : (3,) array
        The learned offset ``u(t)`` added to the target (zeros without learning).
    """

    offset: Array
    feedforward: Array
    lead: Array
    tracker: Array
    residual: Array
    weight: float
    state: str
    fresh: bool
    learned: Array = field(default_factory=lambda: np.zeros(3))


class TrackingLoop:
    """Estimator and correction law of one tracked path (module docstring).

    Parameters
    ----------
    model : PoseModel
        The calibrated model (e.g. ``IdentifiedModel(result.model)``, tool = the
        identified PROBE: the point the tracker measures).
    settings : TrackingSettings
    payload_kg : float
        The payload carried (kg).
    tracking : bool
        ``False``: model-based feed-forward (and lead) only — the same code without the
        tracker, for comparison or while no tracker is available.
    controller : PoseModel, optional
        The controller's own model with its TCP (default: the nominal model of
        ``model``'s robot with ``model.tool`` as the TCP — the controller's ``$TOOL`` is
        the calibrated reflector).
    learned : callable, optional
        ``u(t)``: the learned offset (3,) (m, F0) at robot time ``t``, added to the target
        (:meth:`~.learning.IterativeLearning.feedforward`); with or without the tracker.

    API note: ``add(measurements)`` from any thread; ``cycle(t, q, T_path)`` once per
    robot cycle from the correction source; ``windows``, ``stats`` afterwards.
    """

    def __init__(self, model: PoseModel, settings: TrackingSettings | None = None, *,
                 payload_kg: float = 0.0, tracking: bool = True,
                 controller: PoseModel | None = None,
                 learned: Callable[[float], ArrayLike] | None = None) -> None:
        s = self.settings = settings if settings is not None else TrackingSettings()
        self.model = model
        self.controller = controller if controller is not None else \
            NominalModel(model.description, model.tool)
        self.payload_kg = float(payload_kg)
        self.tracking = bool(tracking)
        self.learned = learned
        self._sos = butter(2, s.output_cutoff_hz, fs=1.0 / s.cycle_s, output="sos") \
            if s.output_cutoff_hz > 0 else None
        self._sos_z = np.zeros((len(self._sos) if self._sos is not None else 0, 2, 6))
        self._pos = ResidualFilter([s.position_drift] * 3, [s.position_noise_m] * 3,
                                   s.gate_sigma)
        self._rot = ResidualFilter([s.orientation_drift] * 3, [s.orientation_noise_rad] * 3,
                                   s.gate_sigma)
        self._limiter = RateLimiter(
            s.cycle_s, [s.max_speed_m_s] * 3 + [s.max_speed_rad_s] * 3,
            [s.max_accel_m_s2] * 3 + [s.max_accel_rad_s2] * 3,
            [s.max_correction_m] * 3 + [s.max_correction_rad] * 3)
        self._ramp = unit_ramp(s.fade_s)
        self._ramp_end = self._ramp.duration
        self._joints = JointHistory(s.history_s)
        self._lock = threading.Lock()
        self._pending: deque[TrackerMeasurement] = deque()
        self._paths: deque[tuple[float, Array]] = deque(maxlen=3)
        self._lead_limiter = RateLimiter(s.cycle_s, [s.max_lead_speed_m_s] * 3,
                                         [s.max_lead_accel_m_s2] * 3,
                                         [s.max_lead_m] * 3)
        self._q_ff: Array | None = None
        self._ff = np.zeros(6)
        self._anchors: deque[tuple[Array, Array]] = deque(maxlen=2)
        self._last_ok: float | None = None   # time of the newest good sample
        self._good_since: float | None = None  # start of the current run of good samples
        self._bad_reason = ""
        self._held: str | None = None  # the caller's reason to hold (hold())
        self._w, self._w_from, self._w_to, self._w_t0 = 0.0, 0.0, 0.0, 0.0
        self._state = "acquiring" if self.tracking else "model"
        self.windows: list[HoldWindow] = []
        self.stats = TrackingStats()

    # ------------------------------------------------------------------ input
    def add(self, measurements: Iterable[TrackerMeasurement]) -> None:
        """Queue tracker samples (any thread); used from the next :meth:`cycle` on.

        Parameters
        ----------
        measurements : iterable of TrackerMeasurement
            In acquisition order.
        """
        items = list(measurements)
        with self._lock:
            self._pending.extend(items)

    def hold(self, reason: str) -> None:
        """Stop using the tracker for good (e.g. ``"tracker stopped"``): the term fades
        out and the path goes on with the model alone; the window records ``reason``."""
        with self._lock:
            self._held = str(reason)

    @property
    def state(self) -> str:
        """The last cycle's state (:class:`CycleOutput`)."""
        return self._state

    # ------------------------------------------------------------------ the cycle
    def cycle(self, t: float, q: ArrayLike, T_path: ArrayLike) -> CycleOutput:
        """One robot cycle: take the feedback and new samples, answer the offset.

        Parameters
        ----------
        t : float
            Robot time of the feedback (s), increasing.
        q : (n,) array_like
            Joint feedback (rad), the controller's actual axis positions.
        T_path : (4, 4) array_like
            The path's own pose of the controller's TCP now (F0, m), without the offset.

        Returns
        -------
        CycleOutput
        """
        s = self.settings
        Tp = np.asarray(T_path, dtype=float)
        n = self._elapsed_cycles(t)
        self._joints.add(t, q)
        self.stats.cycles += 1
        fresh = self._take_samples() if self.tracking else False
        if fresh:
            self.stats.fresh_cycles += 1
            assert self._last_ok is not None
            self.stats.ages_s.append(t - self._last_ok)
        weight_target = self._update_state(t)
        w = self._weight(t, weight_target)
        xhat = np.full(6, np.nan)
        if self._pos.initialised:
            xhat[:3] = self._pos.x
        if self._rot.initialised and s.correct_orientation:
            xhat[3:] = self._rot.x
        smooth = np.nan_to_num(xhat)
        if self._sos is not None and self.tracking:  # held over skipped robot cycles
            for _ in range(n):
                y = _sos_step(self._sos, self._sos_z, smooth)
            smooth = y
        goal = np.where(np.isfinite(xhat), w * smooth, 0.0) if self.tracking else np.zeros(6)
        c = self._limiter.apply(goal, n)
        if self._state == "tracking" and w >= 1.0:
            self.stats.tracking_cycles += 1
        lead = self._lead(t, Tp, n)
        T_tgt = Tp.copy()
        u = np.zeros(3) if self.learned is None else \
            np.asarray(self.learned(t), dtype=float).reshape(3)
        T_tgt[:3, 3] += lead - c[:3] + u
        if np.any(c[3:]):  # (exp(0) = I: nothing to turn)
            T_tgt[:3, :3] = so3_exp(-c[3:]) @ Tp[:3, :3]
        ff = self._feedforward(T_tgt, np.asarray(q, dtype=float))
        T_c = T_tgt.copy()
        T_c[:3, 3] += ff[:3]
        T_c[:3, :3] = so3_exp(ff[3:]) @ T_tgt[:3, :3]
        offset = np.concatenate([T_c[:3, 3] - Tp[:3, 3], so3_log(T_c[:3, :3] @ Tp[:3, :3].T)])
        return CycleOutput(offset, ff, lead, c, xhat, w, self._state, fresh, u)

    # ------------------------------------------------------------------ parts
    def _take_samples(self) -> bool:
        """Residuals of the pending samples the joint history covers; the filters' update."""
        latest, earliest = self._joints.latest_time, self._joints.earliest_time
        assert latest is not None and earliest is not None
        with self._lock:
            ready = []
            while self._pending and self._pending[0].time_s <= latest:
                ready.append(self._pending.popleft())
        good = []
        for m in ready:
            if m.time_s < earliest or (self._last_ok is not None and m.time_s <= self._last_ok):
                self.stats.samples_stale += 1
            elif not m.ok:
                self.stats.samples_bad += 1
                self._bad_reason = m.status
                self._good_since = None
            else:
                good.append(m)
                if self._good_since is None:
                    self._good_since = m.time_s
        if not good:
            return False
        ts = np.array([m.time_s for m in good])
        T_model = _poses(self.model, self._joints.at(ts), self.payload_kg)
        resume = self._state == "holding" and \
            self._good_since is not None and ts[0] <= self._good_since
        if resume:  # a new run of good samples after a hold: the residual may have moved
            self._pos.reset()
            self._rot.reset()
        measured = np.stack([m.pose for m in good])
        if self.settings.correct_orientation:
            z = pose_error_exact(measured, T_model)
        else:  # the position's part of it: the orientation's estimate would not be used
            z = measured[:, :3, 3] - T_model[:, :3, 3]
        for m, zm in zip(good, z, strict=True):
            self._pos.update(m.time_s, zm[:3])
            if m.six_dof and self.settings.correct_orientation:
                self._rot.update(m.time_s, zm[3:])
        self.stats.samples_used += len(good)
        self._last_ok = float(ts[-1])
        return True

    def _update_state(self, t: float) -> float:
        """The state machine of the tracker term; the weight it aims at (0 or 1)."""
        if not self.tracking:
            return 0.0
        s = self.settings
        with self._lock:
            held = self._held
        fresh = self._last_ok is not None and t - self._last_ok <= s.max_age_s
        resumed = fresh and self._good_since is not None and \
            self._last_ok is not None and self._last_ok - self._good_since >= s.resume_s
        on = self._state in ("tracking", "acquiring")
        if held is not None:
            if self._state != "holding":
                self._open_window(t, held)
            elif self.windows[-1].end_s is None and \
                    not self.windows[-1].reason.endswith(held):  # silent first, then gone
                self.windows[-1].reason += f", then {held}"
            self._state = "holding"
            return 0.0
        if self._state == "acquiring":
            if fresh and self._pos.initialised:
                self._state = "tracking"
                return 1.0
            return 0.0
        if on and not fresh:
            self._open_window(t, self._bad_reason if self._bad_reason and
                              (self._good_since is None) else "late")
            self._state = "holding"
            return 0.0
        if self._state == "holding" and resumed:
            self.windows[-1].end_s = t
            self._state = "tracking"
            return 1.0
        return 1.0 if self._state == "tracking" else 0.0

    def _open_window(self, t: float, reason: str) -> None:
        self.windows.append(HoldWindow(t, None, reason or "late"))

    def _weight(self, t: float, target: float) -> float:
        """``w``: a jerk-limited ramp from its value to ``target`` over ``fade_s``."""
        if target != self._w_to:
            self._w_from, self._w_to, self._w_t0 = self._w, target, t
        r = 1.0 if t - self._w_t0 >= self._ramp_end else \
            float(self._ramp.sample(t - self._w_t0).s)  # (1 exactly after the ramp's end)
        self._w = self._w_from + (self._w_to - self._w_from) * r
        return self._w

    def _elapsed_cycles(self, t: float) -> int:
        """``n``: the robot cycles since the last :meth:`cycle` (1 when none was skipped,
        as in simulated time; more when the loop fell behind on a loaded PC): the
        bounds and filters run in the robot's time."""
        last = self._joints.latest_time
        if last is None:
            return 1
        return max(1, round((t - last) / self.settings.cycle_s))

    def _lead(self, t: float, Tp: Array, n: int) -> Array:
        """``Δp_lead = v̂ τ + â τ²/2`` from the last three path positions (their robot
        times ``t_i``: ``v̂`` the last difference quotient, ``â`` the second divided
        difference ``2 (v_2 − v_1)/(t_2 − t_0)``), bounded."""
        self._paths.append((t, Tp[:3, 3].copy()))
        tau = self.settings.lead_s
        if tau == 0.0 or len(self._paths) < 3:
            return self._lead_limiter.apply(np.zeros(3), n)
        (t0, p0), (t1, p1), (t2, p2) = self._paths
        T = self.settings.cycle_s
        if round((t2 - t0) / T) == 2:  # no cycle skipped: as it always was computed
            v = (p2 - p1) / T
            a = (p2 - 2.0 * p1 + p0) / T ** 2
        else:
            v = (p2 - p1) / (t2 - t1)
            a = 2.0 * (v - (p1 - p0) / (t1 - t0)) / (t2 - t0)
        return self._lead_limiter.apply(v * tau + 0.5 * a * tau ** 2, n)

    def _feedforward(self, T_tgt: Array, q: Array) -> Array:
        """``e(T_nominal(q*), T_tgt)`` with ``q*`` the calibrated model's inverse, solved at
        anchors ``feedforward_step_m`` apart and extrapolated linearly between them:
        ``ff(p) = ff_a + (ff_a − ff_b) · ((p − p_a)·(p_a − p_b)) / |p_a − p_b|²``."""
        p = T_tgt[:3, 3]
        anchors = self._anchors
        if anchors:
            p_a, ff_a = anchors[-1]
            if np.linalg.norm(p - p_a) < self.settings.feedforward_step_m:
                if len(anchors) < 2:
                    return ff_a
                p_b, ff_b = anchors[-2]
                d = p_a - p_b
                s = float((p - p_a) @ d / (d @ d))
                return ff_a + (ff_a - ff_b) * min(max(s, -1.0), 1.0)
        start = self._q_ff if self._q_ff is not None else q
        res = compensate_joints(self.model, T_tgt[None], start, self.payload_kg,
                                check_limits=False, raise_errors=False)
        if not bool(np.all(res.ok)):
            self.stats.feedforward_failures += 1
            return self._ff
        self._q_ff = res.q[0]
        T_nom = _poses(self.controller, self._q_ff, self.payload_kg)[0]
        self._ff = pose_error_exact(T_nom, T_tgt)
        anchors.append((p.copy(), self._ff))
        return self._ff


def _poses(model: PoseModel, q: ArrayLike, payload_kg: float) -> Array:
    """``T_model(q)`` (N, 4, 4): the model's ``pose`` when it has one (no Jacobian computed),
    else the first result of ``evaluate``."""
    pose = getattr(model, "pose", None)
    return np.asarray(pose(q, payload_kg) if pose is not None else
                      model.evaluate(q, payload_kg)[0])


def _sos_step(sos: Array, z: Array, x: Array) -> Array:
    """One sample of second-order sections in direct form II transposed, the state ``z``
    (sections, 2, d) updated in place — :func:`scipy.signal.sosfilt`'s recursion per
    section ``y = b0 x + z0``, ``z0 ← b1 x − a1 y + z1``, ``z1 ← b2 x − a2 y`` without its
    call's overhead (a few µs instead of tens, each cycle)."""
    y = x
    for (b0, b1, b2, _, a1, a2), zs in zip(sos, z, strict=True):
        xin = y
        y = b0 * xin + zs[0]
        zs[0] = b1 * xin - a1 * y + zs[1]
        zs[1] = b2 * xin - a2 * y
    return y
