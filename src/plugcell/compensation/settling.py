"""Sensor-based correction while the robot settles (issue 38 §3; thesis 6.5.2, 8.3.2).

The thesis's static correction (:mod:`.sensor_based`) stops, waits for the arm to come
to rest, measures, moves, and again: 8.3.3 reports ~6 s a point on the C3G, and the
thesis names the cause of the residual's spread — the 50 ms reading taken "when the
robot still oscillates a small amount from a full stop".  With a tracker that streams
(up to 1 kHz, each sample stamped with its acquisition time) the static error can be
estimated *during* the settling: the structural modes make the tool oscillate about
its rest pose, and a suitably weighted mean over a window of a few of their periods
is that rest pose.

**The estimate** (:func:`estimate_rest_pose`).  Samples ``x_i`` at times ``t_i`` since
the last commanded motion ended (plus a guard), of which the last ``W`` seconds
(``W_min ≤ W ≤ W_max``, growing with the data), give the errors
``e_i = x^d ⊖ x_i`` (6-vectors ``[Δp; φ]``, the project's pose error) and::

    w_i  = sin²(π (t_i − t₀)/W)                       (Hann window over [t₀, t₀ + W])
    ê    = Σ w_i e_i / Σ w_i                          (the rest pose's error)
    e_i ≈ ê + b (t_i − t_c) + Σ_m m_m(t_i)            (weighted least squares: a drift,
                                                       t_c the window's weighted centre,
                                                       and ringing modes, below)
    u²   = κ s²_B / B + (W/2)² max(0, b² − 4 σ_b²) + (Σ_m m̄_m)²     (per component)

The Hann window's sidelobes lie 31 dB below its main lobe, whose half-width is
``2/W``: an oscillation above ``2/W`` Hz (the robot's first modes, 9–25 Hz on the
Smart H4 twin; ``W ≥ 0.25 s``) leaves ≤ 2.7 % of its amplitude in ``ê``.  Up to two
ringing modes ``m_m(t) = (α + α'τ) cos 2πf_m t + (β + β'τ) sin 2πf_m t`` (decaying:
the amplitude changes linearly over the window) are found as peaks of the residual's
periodogram between ``2/W`` and 60 Hz and taken out of it (:func:`_remove_modes`);
``m̄_m``, their Hann-weighted mean, is what they leave in ``ê``.  ``s²_B`` is the
variance of ``B`` consecutive batch means of what remains, with ``B − 2 − 4M`` degrees
of freedom (the batch-means estimate of a correlated series' mean variance: the
tracker's floor noise is correlated over tens of ms — without the modes taken out, a
ringing arm's oscillation would count as noise), ``κ = N Σw²/(Σw)²`` the window's
variance inflation (1.5 for Hann), ``σ_b²`` the slope's variance from the same batches;
``b W/2`` is the bias of a mean that still drifts (the arm still creeping to rest: the
window's centre lags its end by ``W/2``), counted where the slope exceeds twice its
standard error, so a transient that has not decayed is *waited out*: the estimate is
accepted only when ``‖u_p‖ ≤ ū_p`` and ``‖u_φ‖ ≤ ū_φ`` (the norms over the three
components).  Limit: a noise without a white part whose spectrum rises steeply below
60 Hz would be taken for a mode and its uncertainty underestimated; the tracker's
samples are white-dominated at their rate (tests compare the stated uncertainty with the
scatter of the estimates on the stream model).

**The loop** (:func:`correct_while_settling`): command the model-compensated joints
``θ_c``; stream; when the estimate is accepted,

* stop when ``‖Δp̂‖ < tol_p`` and ``‖Δφ̂‖ < tol_φ`` (converged);
* else a bounded step ``α = min(1, s_p/‖Δp̂‖, s_φ/‖Δφ̂‖)``,
  ``δθ = J(θ_c)⁻¹ α Δx̂`` (the identified model's Jacobian at the commanded joints;
  pseudo-inverse where singular), ``θ_c ← θ_c + δθ``, commanded at once but over at
  least ``correction_duration_s`` (so that it does not ring the structure); the window
  restarts after the new motion ends.

It fails with :class:`~plugcell.compensation.errors.CorrectionError` (and the record
so far) — ``noisy``: even the longest window leaves the uncertainty above ``ū`` (the
samples are too noisy to decide at the tolerance); ``sparse``: a full window holds too
few samples for the batches (a stream too slow); ``not_settled``: no accepted
estimate within ``max_time_s`` (the transient never died out); ``sensor:<status>``:
no valid sample for ``max_gap_s`` (the beam broke and did not come back; a shorter
break only restarts the window); ``max_corrections``; ``joint_limit`` (nothing moved);
``robot`` (the robot refused a command).  Pure math: the devices are the
:class:`~plugcell.compensation.protocols.MovingRobot` and
:class:`~plugcell.compensation.protocols.PoseStream` protocols.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from plugcell.compensation.errors import CorrectionError
from plugcell.compensation.model_based import joint_step
from plugcell.compensation.pose_model import PoseModel
from plugcell.compensation.protocols import MovingRobot, PoseStream, StreamReading
from plugcell.compensation.sensor_based import _target_pose
from plugcell.kinematics.pose_error import pose_error_exact

Array = NDArray[np.float64]

__all__ = [
    "RestEstimate",
    "SettlingResult",
    "SettlingSettings",
    "SettlingStep",
    "bounded_step",
    "correct_while_settling",
    "estimate_rest_pose",
]


@dataclass(frozen=True)
class SettlingSettings:
    """Parameters of :func:`correct_while_settling` (module docstring).

    Attributes
    ----------
    position_tol_m, orientation_tol_rad : float, m and rad
        ``tol_p``, ``tol_φ``: stop when the estimate is inside (0.05 mm — the robot's
        resolution the thesis measured, 8.3.2 — and 0.05°).
    max_uncertainty_m, max_uncertainty_rad : float, m and rad
        ``ū_p``, ``ū_φ``: accept an estimate whose uncertainty is at most this.
    window_min_s, window_max_s : float, s
        ``W_min``, ``W_max``: the shortest window an estimate is taken from, and the
        longest it grows to when the samples are noisy.
    guard_s : float, s
        Samples are used from this long after a commanded motion ends.
    poll_s : float, s
        How often the estimate is looked at.
    batches : int
        ``B`` of the batch-means noise estimate.
    max_step_m, max_step_rad : float, m and rad
        ``s_p``, ``s_φ``: the largest correction commanded at once.
    correction_duration_s : float, s
        The shortest time a correction may take (``MovingRobot.command_joints``): about
        two periods of the lowest structural mode, so that it does not ring it (on the
        Smart H4 twin a 0.2 mm step rings 0.18 mm, over 0.1 s 0.11 mm, over 0.2 s
        0.02 mm).
    max_corrections : int
        Corrective commands before giving up.
    max_time_s : float, s
        Per point, from the first command.
    max_gap_s : float, s
        The longest time without a valid sample before giving up.
    check_limits : bool
        Refuse a correction that leaves the joint limits.

    Raises
    ------
    ValueError
        A non-positive value, ``window_min_s > window_max_s`` or fewer than 11 batches.
    """

    position_tol_m: float = 0.05e-3
    orientation_tol_rad: float = math.radians(0.05)
    max_uncertainty_m: float = 0.02e-3
    max_uncertainty_rad: float = math.radians(0.01)
    window_min_s: float = 0.25
    window_max_s: float = 1.0
    guard_s: float = 0.02
    poll_s: float = 0.02
    batches: int = 16
    max_step_m: float = 1.0e-3
    max_step_rad: float = math.radians(0.2)
    correction_duration_s: float = 0.2
    max_corrections: int = 10
    max_time_s: float = 10.0
    max_gap_s: float = 1.0
    check_limits: bool = True

    def __post_init__(self) -> None:
        for name in ("position_tol_m", "orientation_tol_rad", "max_uncertainty_m",
                     "max_uncertainty_rad", "window_min_s", "window_max_s", "poll_s",
                     "max_step_m", "max_step_rad", "max_time_s", "max_gap_s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"SettlingSettings.{name} must be a finite number > 0, "
                                 f"got {v!r}")
        for name in ("guard_s", "correction_duration_s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"SettlingSettings.{name} must be ≥ 0, got {v!r}")
        if self.window_min_s > self.window_max_s:
            raise ValueError(f"SettlingSettings: window_min_s {self.window_min_s} s > "
                             f"window_max_s {self.window_max_s} s")
        if self.batches < 3 + 4 * MAX_MODES:
            raise ValueError(f"SettlingSettings.batches must be ≥ {3 + 4 * MAX_MODES} (the "
                             f"line and {MAX_MODES} modes leave one degree of freedom), got "
                             f"{self.batches}")
        if self.max_corrections < 0:
            raise ValueError("SettlingSettings.max_corrections must be ≥ 0, got "
                             f"{self.max_corrections}")


@dataclass(frozen=True, eq=False)
class RestEstimate:
    """The rest pose's error estimated from a window of samples (module docstring).

    Attributes
    ----------
    error : (6,) array
        ``ê = [Δp̂ (m); Δφ̂ (rad)]``, target ⊖ rest pose.
    uncertainty : (6,) array
        ``u`` per component (m, rad).
    noise : (6,) array
        Its noise part ``√(κ s²_B / B)``.
    trend : (6,) array
        ``b`` (m/s, rad/s), the drift still in the window.
    window_s : float, s
        ``W``.
    samples : int
        ``N``.
    """

    error: Array
    uncertainty: Array
    noise: Array
    trend: Array
    window_s: float
    samples: int

    @property
    def position_uncertainty_m(self) -> float:
        return float(np.linalg.norm(self.uncertainty[:3]))

    @property
    def orientation_uncertainty_rad(self) -> float:
        return float(np.linalg.norm(self.uncertainty[3:]))

    @property
    def noise_position_m(self) -> float:
        return float(np.linalg.norm(self.noise[:3]))

    @property
    def noise_orientation_rad(self) -> float:
        return float(np.linalg.norm(self.noise[3:]))


#: The band searched for ringing modes (Hz): from the window's main lobe ``2/W`` up to
#: this, and how many modes are taken out of the residual at most.
MODE_BAND_MAX_HZ, MAX_MODES = 60.0, 2
#: A periodogram peak counts as a mode above this multiple of the median level.
MODE_SIGNIFICANCE = 6.0


def _remove_modes(t: Array, R: Array, w: Array, W: float
                  ) -> tuple[Array, list[tuple[float, Array]]]:
    """Take up to :data:`MAX_MODES` ringing modes out of the residual ``R`` (N, k): the
    peak of the Hann-weighted periodogram ``P(f) = Σ_k |Σ_i w_i r_ik e^{−i2πft_i}|² / σ_k²``
    over ``2/W ≤ f ≤ MODE_BAND_MAX_HZ`` (step ``1/(4W)``), if it stands
    :data:`MODE_SIGNIFICANCE` × above the median, is fitted per component as a mode whose
    amplitude changes linearly over the window (it decays),
    ``r ≈ (α + α' τ) cos 2πft + (β + β' τ) sin 2πft``, ``τ = t − t_c`` (weighted least
    squares), and subtracted.

    Returns the cleaned residual and, per mode, ``(f, leak)``: its frequency and its
    Hann-weighted mean ``Σ w_i m_i / Σ w_i`` per component — what the fitted mode ``m``
    leaves in ``ê``.
    """
    f_hi = min(MODE_BAND_MAX_HZ, 0.25 / float(np.median(np.diff(t))))
    freqs = np.arange(2.0 / W, f_hi, 0.25 / W)
    modes: list[tuple[float, Array]] = []
    if freqs.size < 4:
        return R, modes
    sw = float(w.sum())
    tau = t - float(w @ t) / sw
    ph = 2 * np.pi * np.outer(freqs, t - t[0])
    C, S = np.cos(ph) * w, np.sin(ph) * w
    for _ in range(MAX_MODES):
        scale = np.maximum(np.sqrt((w @ R ** 2) / sw), 1e-300)
        P = ((C @ (R / scale)) ** 2 + (S @ (R / scale)) ** 2).sum(axis=1)
        j = int(np.argmax(P))
        if P[j] < MODE_SIGNIFICANCE * float(np.median(P)):
            break
        c, s_ = np.cos(ph[j]), np.sin(ph[j])
        X = np.stack([c, s_, tau * c, tau * s_], axis=1)
        coef = np.linalg.lstsq(X * np.sqrt(w)[:, None], R * np.sqrt(w)[:, None], rcond=None)[0]
        fit = X @ coef
        R = R - fit
        modes.append((float(freqs[j]), w @ fit / sw))
    return R, modes


def estimate_rest_pose(times: ArrayLike, errors: ArrayLike, batches: int = 16
                       ) -> RestEstimate:
    """The Hann-weighted rest-pose estimate and its uncertainty (module docstring).

    Parameters
    ----------
    times : (N,) array_like, s
        Sample times, increasing; the window is ``[times[0], times[-1]]``.
    errors : (N, k) array_like
        ``e_i`` (m and rad).
    batches : int
        ``B`` (≥ 11); every batch must hold at least two samples.

    Returns
    -------
    RestEstimate

    Raises
    ------
    ValueError
        Mismatched shapes, non-finite values, times not increasing, or too few samples
        for the batches.
    """
    t = np.asarray(times, dtype=float)
    E = np.asarray(errors, dtype=float)
    if t.ndim != 1 or E.ndim != 2 or E.shape[0] != t.size:
        raise ValueError(f"times (N,) and errors (N, k) expected, got {t.shape}, {E.shape}")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(E))):
        raise ValueError("times and errors must be finite")
    if t.size < 2 * batches or np.any(np.diff(t) <= 0):
        raise ValueError(f"need ≥ {2 * batches} samples at increasing times, got {t.size}")
    W = float(t[-1] - t[0])
    # Hann weights on the window, the end points just inside so that none is zero
    x = (t - t[0] + 0.5 * W / t.size) / (W * (1 + 1.0 / t.size))
    w = np.sin(np.pi * x) ** 2
    sw = w.sum()
    est = w @ E / sw
    tc = float(w @ t / sw)
    dt = t - tc
    b = (w * dt) @ (E - est) / float(w @ dt ** 2)
    # batch means about the fitted line
    edges = np.linspace(t[0], t[-1], batches + 1)
    idx = np.clip(np.searchsorted(edges, t, side="right") - 1, 0, batches - 1)
    counts = np.bincount(idx, minlength=batches)
    if np.any(counts < 2):
        raise ValueError(f"a batch holds fewer than 2 samples ({counts.min()}): the samples "
                         "are too sparse for the window")
    resid, modes = _remove_modes(t, E - est - np.outer(dt, b), w, W)
    means = np.stack([resid[idx == k].mean(axis=0) for k in range(batches)])
    dof = batches - 2 - 4 * len(modes)
    s2 = (means ** 2).sum(axis=0) / max(dof, 1)
    kappa = t.size * float(w @ w) / sw ** 2
    noise = np.sqrt(kappa * s2 / batches)
    # the slope's own variance, from the batches (weights ω_k, centres τ_k)
    om = np.bincount(idx, weights=w, minlength=batches)
    tau = np.bincount(idx, weights=w * t, minlength=batches) / om
    d = tau - float(om @ tau / om.sum())
    var_b = s2 * float((om * d) @ (om * d)) / float(om @ d ** 2) ** 2
    bias = 0.5 * W * np.sqrt(np.maximum(b ** 2 - 4.0 * var_b, 0.0))
    leak = np.abs(sum(m for _, m in modes)) if modes else np.zeros_like(est)
    u = np.sqrt(noise ** 2 + bias ** 2 + leak ** 2)
    return RestEstimate(est, u, noise, b, W, int(t.size))


def bounded_step(error: ArrayLike, max_step_m: float, max_step_rad: float) -> Array:
    """``α Δx`` with ``α = min(1, s_p/‖Δp‖, s_φ/‖Δφ‖)``: the correction scaled, direction
    kept, so that neither its translation nor its rotation exceeds its bound.

    Parameters
    ----------
    error : (6,) array_like
        ``Δx = [Δp (m); Δφ (rad)]``.
    max_step_m, max_step_rad : float
        ``s_p`` (m), ``s_φ`` (rad).

    Returns
    -------
    (6,) array
    """
    dx = np.asarray(error, dtype=float)
    ep, er = float(np.linalg.norm(dx[:3])), float(np.linalg.norm(dx[3:]))
    alpha = min(1.0, max_step_m / ep if ep > 0 else 1.0, max_step_rad / er if er > 0 else 1.0)
    return alpha * dx


@dataclass(frozen=True, eq=False)
class SettlingStep:
    """One accepted estimate and what the loop did with it.

    Attributes
    ----------
    index : int
        0 for the first.
    time_s : float, s
        The loop clock when it was accepted (from the first command).
    q_command : (n,) array, rad
        The commanded joints the estimate is of.
    estimate : RestEstimate
    position_error_m, orientation_error_rad : float
        ``‖Δp̂‖``, ``‖Δφ̂‖``.
    move : (n,) array or None
        ``δθ`` commanded (rad), ``None`` if none.
    motion_end_s : float, s
        When the commanded correction's motion ends (NaN without one).
    """

    index: int
    time_s: float
    q_command: Array
    estimate: RestEstimate
    position_error_m: float
    orientation_error_rad: float
    move: Array | None
    motion_end_s: float

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready summary in mm, degrees and seconds."""
        e = self.estimate
        return {"index": self.index, "time_s": self.time_s,
                "position_error_mm": self.position_error_m * 1e3,
                "orientation_error_deg": math.degrees(self.orientation_error_rad),
                "uncertainty_mm": e.position_uncertainty_m * 1e3,
                "uncertainty_deg": math.degrees(e.orientation_uncertainty_rad),
                "window_s": e.window_s, "samples": e.samples,
                "move": None if self.move is None else self.move.tolist()}


@dataclass(frozen=True, eq=False)
class SettlingResult:
    """The record of one point: every accepted estimate, beam breaks, the outcome.

    Attributes
    ----------
    target : (4, 4) array, m
    settings : SettlingSettings
    steps : tuple of SettlingStep
    converged : bool
    reason : str
        ``""`` or why the loop stopped.
    time_s : float, s
        From the first command to the end (converged or failed).
    move_end_s : float, s
        When the first commanded motion ended (from the first command).
    breaks : tuple of (float, float, str)
        ``(start_s, end_s, status)`` of each run of empty samples.
    q_final : (n,) array, rad
        The joints last commanded.
    """

    target: Array
    settings: SettlingSettings
    steps: tuple[SettlingStep, ...] = field(default=())
    converged: bool = False
    reason: str = ""
    time_s: float = 0.0
    move_end_s: float = math.nan
    breaks: tuple[tuple[float, float, str], ...] = field(default=())
    q_final: Array | None = None

    @property
    def corrections(self) -> int:
        """Corrective commands made."""
        return sum(1 for s in self.steps if s.move is not None)

    @property
    def final_position_error_m(self) -> float:
        return self.steps[-1].position_error_m if self.steps else math.nan

    @property
    def final_orientation_error_rad(self) -> float:
        return self.steps[-1].orientation_error_rad if self.steps else math.nan

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready summary with every step (mm, degrees, seconds)."""
        return {"converged": self.converged, "reason": self.reason,
                "corrections": self.corrections, "time_s": self.time_s,
                "move_end_s": self.move_end_s,
                "breaks": [list(b) for b in self.breaks],
                "steps": [s.as_dict() for s in self.steps]}


class _Run:
    """One point's bookkeeping: the window of valid samples, breaks, the record."""

    def __init__(self, target: Array, settings: SettlingSettings, t0: float) -> None:
        self.target, self.s, self.t0 = target, settings, t0
        self.times: list[float] = []
        self.errors: list[Array] = []
        self.valid_from = math.inf
        self.last_ok = t0
        self.last_status = "line_of_sight"
        self.open_break: tuple[float, str] | None = None
        self.breaks: list[tuple[float, float, str]] = []
        self.steps: list[SettlingStep] = []
        self.move_end = math.nan

    def restart(self, valid_from: float) -> None:
        """Forget the window; use samples from ``valid_from`` on."""
        self.valid_from = valid_from
        self.times, self.errors = [], []

    def take(self, samples: list[StreamReading]) -> None:
        """Record breaks; keep the valid samples after ``valid_from`` (their errors)."""
        poses, times = [], []
        for r in samples:
            if r.status != "ok" or r.pose is None:
                self.last_status = r.status if r.status != "ok" else "empty"
                if self.open_break is None:
                    self.open_break = (r.time_s, self.last_status)
                self.restart(max(self.valid_from, r.time_s + self.s.guard_s))
                poses, times = [], []
                continue
            if self.open_break is not None:
                self.breaks.append((self.open_break[0] - self.t0, r.time_s - self.t0,
                                    self.open_break[1]))
                self.open_break = None
            self.last_ok = r.time_s
            last = times[-1] if times else (self.times[-1] if self.times else -math.inf)
            if r.time_s >= self.valid_from and r.time_s > last:
                times.append(r.time_s)
                poses.append(r.pose)
        if times:
            self.times.extend(times)
            self.errors.extend(pose_error_exact(self.target, np.asarray(poses)))

    def estimate(self, now: float) -> RestEstimate | None:
        """The estimate over the last ``W_max`` of valid samples, once they span ``W_min``."""
        if not self.times:
            return None
        t = np.asarray(self.times)
        keep = t >= now - self.s.window_max_s
        t = t[keep]
        if t.size < 2 * self.s.batches or t[-1] - t[0] < self.s.window_min_s:
            return None
        E = np.asarray(self.errors)[keep]
        try:
            return estimate_rest_pose(t, E, self.s.batches)
        except ValueError:  # samples too sparse for the batches: wait for more
            return None

    def check_sparse(self, now: float, q: Array) -> None:
        """``sparse``: a full window (``W_max`` since the samples became valid) holds fewer
        than the ``2B`` samples an estimate needs."""
        s = self.s
        if now - self.valid_from < s.window_max_s:
            return
        n = int(np.count_nonzero(np.asarray(self.times) >= now - s.window_max_s))
        if n < 2 * s.batches:
            raise self.fail(f"only {n} valid samples in {s.window_max_s:g} s: the stream is "
                            f"too sparse for an estimate (≥ {2 * s.batches} a window, "
                            f"{s.batches} batches); raise its rate", "sparse", now, q)

    def result(self, converged: bool, reason: str, now: float, q: Array) -> SettlingResult:
        breaks = list(self.breaks)
        if self.open_break is not None:
            breaks.append((self.open_break[0] - self.t0, now - self.t0, self.open_break[1]))
        return SettlingResult(self.target, self.s, tuple(self.steps), converged, reason,
                              now - self.t0, self.move_end - self.t0, tuple(breaks), q.copy())

    def fail(self, message: str, reason: str, now: float, q: Array) -> CorrectionError:
        return CorrectionError(message, reason=reason,
                               result=self.result(False, reason, now, q))

    def command(self, robot: MovingRobot, q: Array, now: float, q_old: Array,
                duration_s: float = 0.0) -> float:
        try:
            return float(robot.command_joints(q, duration_s))
        except Exception as exc:
            raise self.fail(f"the robot refused the command: {exc}", "robot", now,
                            q_old) from exc

    def record(self, now: float, q: Array, est: RestEstimate, move: Array | None,
               end: float) -> None:
        e = est.error
        self.steps.append(SettlingStep(
            len(self.steps), now - self.t0, q.copy(), est, float(np.linalg.norm(e[:3])),
            float(np.linalg.norm(e[3:])), move, end - self.t0 if move is not None else math.nan))


def _accepted(est: RestEstimate, s: SettlingSettings) -> bool:
    return (est.position_uncertainty_m <= s.max_uncertainty_m
            and est.orientation_uncertainty_rad <= s.max_uncertainty_rad)


def _check_time(run: _Run, now: float, q: Array) -> None:
    """The gap and time limits (module docstring's ``sensor:…`` and ``not_settled``)."""
    s = run.s
    if now - run.last_ok > s.max_gap_s:
        raise run.fail(f"no valid tracker sample for {now - run.last_ok:.2f} s (last: "
                       f"{run.last_status})", f"sensor:{run.last_status}", now, q)
    if now - run.t0 > s.max_time_s:
        raise run.fail(f"no estimate with uncertainty ≤ {s.max_uncertainty_m * 1e3:.3f} mm / "
                       f"{math.degrees(s.max_uncertainty_rad):.4f}° within {s.max_time_s} s: "
                       "the arm did not settle", "not_settled", now, q)


def _check_noise(run: _Run, est: RestEstimate, now: float, q: Array) -> None:
    """``noisy``: the window cannot grow any more and its noise alone is above ``ū``."""
    s = run.s
    if est.window_s >= s.window_max_s - 2 * s.poll_s and (
            est.noise_position_m > s.max_uncertainty_m
            or est.noise_orientation_rad > s.max_uncertainty_rad):
        raise run.fail(
            f"the samples are too noisy: {est.noise_position_m * 1e3:.4f} mm / "
            f"{math.degrees(est.noise_orientation_rad):.4f}° over {est.window_s:.2f} s "
            f"({est.samples} samples), above the accepted {s.max_uncertainty_m * 1e3:.4f} mm"
            f" / {math.degrees(s.max_uncertainty_rad):.4f}°", "noisy", now, q)


def _correction(run: _Run, model: PoseModel, q: Array, est: RestEstimate, now: float,
                payload_kg: float) -> Array | None:
    """On an accepted estimate: ``None`` when it is within the tolerances (recorded),
    else the bounded step ``δθ = J⁻¹ α Δx̂``; ``max_corrections`` and ``joint_limit``
    raise."""
    s = run.s
    ep, er = float(np.linalg.norm(est.error[:3])), float(np.linalg.norm(est.error[3:]))
    if ep < s.position_tol_m and er < s.orientation_tol_rad:
        run.record(now, q, est, None, math.nan)
        return None
    if s.max_corrections <= sum(1 for st in run.steps if st.move is not None):
        run.record(now, q, est, None, math.nan)
        raise run.fail(f"tolerance not met after {s.max_corrections} corrections: "
                       f"‖Δp̂‖ = {ep * 1e3:.4f} mm, ‖Δφ̂‖ = {math.degrees(er):.4f}°",
                       "max_corrections", now, q)
    dq = joint_step(model.evaluate(q, payload_kg)[1][0],
                    bounded_step(est.error, s.max_step_m, s.max_step_rad))
    if s.check_limits and not bool(model.description.within_limits(q + dq)):
        run.record(now, q, est, None, math.nan)
        raise run.fail("the correction would leave the joint limits", "joint_limit", now, q)
    return dq


def correct_while_settling(
    robot: MovingRobot,
    stream: PoseStream,
    model: PoseModel,
    target: ArrayLike,
    q: ArrayLike,
    settings: SettlingSettings | None = None,
    *,
    payload_kg: float = 0.0,
) -> SettlingResult:
    """Move to ``q`` and correct towards ``target`` while the arm settles (module docstring).

    Parameters
    ----------
    robot : MovingRobot
        Takes the joint commands (the move to ``q`` and the corrections).
    stream : PoseStream
        The tool pose in the robot base frame, streamed with time stamps.
    model : PoseModel
        Supplies ``J(θ)`` (the identified model) and the joint limits.
    target : (4, 4) array_like, m
        Desired tool pose, robot base frame.
    q : (n,) array_like, rad
        Joints to move to first (the model-based compensation's, 6.5.1).
    settings : SettlingSettings, optional
    payload_kg : float, kg
        Payload for the model's Jacobian.

    Returns
    -------
    SettlingResult
        Once an accepted estimate lies within the tolerances.

    Raises
    ------
    CorrectionError
        ``noisy``, ``sparse``, ``not_settled``, ``sensor:<status>``, ``max_corrections``,
        ``joint_limit``, ``robot`` — with the record so far (module docstring).
    ValueError
        A malformed target or joints.
    """
    s = settings or SettlingSettings()
    Td = _target_pose(target)
    qc = np.asarray(q, dtype=float)
    if qc.ndim != 1 or not np.all(np.isfinite(qc)):
        raise ValueError(f"q: expected finite joint values, got {q!r}")
    run = _Run(Td, s, stream.now())
    run.move_end = run.command(robot, qc, run.t0, qc)
    run.restart(run.move_end + s.guard_s)
    while True:
        run.take(stream.receive(s.poll_s))
        now = stream.now()
        _check_time(run, now, qc)
        est = run.estimate(now)
        if est is None:
            run.check_sparse(now, qc)
            continue
        if not _accepted(est, s):
            _check_noise(run, est, now, qc)
            continue
        dq = _correction(run, model, qc, est, now, payload_kg)
        if dq is None:
            return run.result(True, "", now, qc)
        end = run.command(robot, qc + dq, now, qc, s.correction_duration_s)
        run.record(now, qc, est, dq, end)
        qc = qc + dq
        run.restart(end + s.guard_s)
