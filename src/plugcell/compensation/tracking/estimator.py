"""The tracker's view of the robot, made current: joint history and the residual filter.

A tracker sample is old when it is used — its acquisition time ``t_s`` lies a few
milliseconds (instrument latency, transport, batching; tens on a loaded PC) before the
robot cycle that uses it.  Instead of the pose itself the loop estimates what changes
slowly: the **residual** of the calibrated model at the joints the robot had at ``t_s``,

    z(t_s) = e(T_meas(t_s), T_model(q(t_s)))      e(T_t, T_a) = [p_t − p_a; vee(R_t R_aᵀ − I)]

(:func:`plugcell.kinematics.pose_error`, base frame F0, the tool point), with ``q(t_s)``
the joint feedback interpolated linearly between the robot cycles around ``t_s``
(:class:`JointHistory`).  Everything the joints already show — the path's motion, the
controller's following error — is in ``T_model(q)``; ``z`` is what the model misses
(its residual error, link deflections, structural vibration, backlash) and the
tracker's noise.  The TCP *now* is then ``T_model(q_now) ⊕ x̂``: the sample's age is
compensated by the joints and the model, not by extrapolating the measurement.

:class:`ResidualFilter` is a Kalman filter on ``x``, one independent local-level
(random-walk) model per axis ``i``::

    x_i(t + Δ) = x_i(t) + w,   w ~ N(0, q_i² Δ)         (process: the residual drifts)
    z_i        = x_i + v,      v ~ N(0, r_i²)           (measurement: one tracker sample)

    predict:  P_i ← P_i + q_i² (t_s − t_prev)
    update:   S_i = P_i + r_i²,  K_i = P_i / S_i,  x_i ← x_i + K_i (z_i − x_i),
              P_i ← (1 − K_i) P_i

with a diffuse start (the first accepted sample sets ``x = z``, ``P = r²``) and an
innovation gate: a sample with ``|z_i − x_i| > g √S_i`` on any axis is rejected and
counted (an outlier, or a beam that re-locked on a wrong reflector); after
``max_rejections`` rejections in a row the residual has really moved, and the filter
starts again, diffusely, from the sample.  At a constant rate
``1/Δ`` the gain tends to ``K∞ = (−λ + √(λ² + 4λ))/2``, ``λ = q² Δ / r²``: the filter
is an exponential smoother of time constant ``≈ Δ/K∞``.  The axes are independent
because the tracker's noise is nearly so in F0 at the cell's distances and the
residual's axes are driven by different effects; a full covariance would add
nothing the gate and the gains do not already give.  Pure math, SI units, no I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]

__all__ = ["JointHistory", "ResidualFilter", "TrackerMeasurement", "steady_state_gain"]


@dataclass(frozen=True)
class TrackerMeasurement:
    """One tracker sample, as the loop takes it.

    Attributes
    ----------
    time_s : float
        Acquisition time on the *robot's* clock (s): the middle of the sample's
        integration window, mapped from the tracker's clock (e.g. with
        :func:`plugcell.metrology.timing.fit_clock_map` and
        :func:`~plugcell.metrology.timing.estimate_delay`).
    pose : (4, 4) array or None, m
        The tool point's pose in the robot base frame F0 (a tracker reading brought into
        F0 with the identified BASE and PROBE, ``BASE⁻¹ · T_meas · PROBE⁻¹ · tool``);
        for a 3-DoF reflector only the position is used.  ``None`` when ``status`` is
        not ``"ok"``.
    six_dof : bool
        The sample has an orientation (T-MAC) or only a position (SMR).
    status : str
        ``"ok"`` or why the sample holds no measurement (``"line_of_sight"``,
        ``"tracking_speed"``, ``"out_of_range"``, ``"reacquiring"``, …).
    """

    time_s: float
    pose: Array | None
    six_dof: bool = True
    status: str = "ok"

    @property
    def ok(self) -> bool:
        """The sample holds a finite pose."""
        return self.status == "ok" and self.pose is not None and \
            bool(np.all(np.isfinite(self.pose)))


class JointHistory:
    """The robot's joint feedback of the last ``span_s`` seconds, for ``q(t)``.

    Parameters
    ----------
    span_s : float
        How long samples are kept (s); a tracker sample older than this cannot be used.
    """

    def __init__(self, span_s: float = 1.0) -> None:
        if not (math.isfinite(span_s) and span_s > 0):
            raise ValueError(f"span_s must be > 0 seconds, got {span_s!r}")
        self.span_s = float(span_s)
        # the kept samples are rows lo…hi−1 of two arrays that grow by doubling and are
        # compacted when full: no per-cycle allocation, and :meth:`at` reads slices
        self._tb = np.empty(0)
        self._qb = np.empty((0, 0))
        self._lo = self._hi = 0

    def __len__(self) -> int:
        return self._hi - self._lo

    @property
    def latest_time(self) -> float | None:
        """Time of the newest feedback (s), ``None`` when empty."""
        return float(self._tb[self._hi - 1]) if self._hi > self._lo else None

    @property
    def earliest_time(self) -> float | None:
        """Time of the oldest feedback kept (s), ``None`` when empty."""
        return float(self._tb[self._lo]) if self._hi > self._lo else None

    def add(self, t: float, q: ArrayLike) -> None:
        """Record the joints ``q`` (rad) read at robot time ``t`` (s).

        Raises
        ------
        ValueError
            ``t`` not after the previous one, or ``q`` not finite or of another size.
        """
        qa = np.asarray(q, dtype=float).reshape(-1)
        empty = self._hi == self._lo
        if not np.all(np.isfinite(qa)) or (not empty and qa.shape[0] != self._qb.shape[1]):
            raise ValueError(f"joint feedback must be finite and of one size, got {q!r}")
        if not empty and not t > self._tb[self._hi - 1]:
            raise ValueError(f"joint feedback at {t} s is not after the last one "
                             f"({float(self._tb[self._hi - 1])} s)")
        if empty and (self._qb.shape[1] != qa.shape[0]):
            self._tb, self._qb, self._lo, self._hi = np.empty(64), np.empty((64, qa.size)), 0, 0
        if self._hi == len(self._tb):  # full: compact, and grow when half is still in use
            live = self._hi - self._lo
            if 2 * live > len(self._tb):
                tb, qb = np.empty(2 * len(self._tb)), np.empty((2 * len(self._tb), qa.size))
            else:
                tb, qb = self._tb, self._qb
            tb[:live] = self._tb[self._lo:self._hi]
            qb[:live] = self._qb[self._lo:self._hi]
            self._tb, self._qb, self._lo, self._hi = tb, qb, 0, live
        self._tb[self._hi] = t
        self._qb[self._hi] = qa
        self._hi += 1
        tb = self._tb
        while tb[self._hi - 1] - tb[self._lo] > self.span_s:
            self._lo += 1

    def at(self, t: ArrayLike) -> Array:
        """Joints at times ``t``, linear between the recorded cycles.

        ``q(t) = q_k + (t − t_k)/(t_{k+1} − t_k) · (q_{k+1} − q_k)`` for
        ``t_k ≤ t ≤ t_{k+1}``.

        Parameters
        ----------
        t : float or (M,) array_like, s

        Returns
        -------
        (n,) or (M, n) array, rad

        Raises
        ------
        ValueError
            A time outside the recorded span (the caller keeps such a sample for later,
            or drops it as too old).
        """
        ts = np.atleast_1d(np.asarray(t, dtype=float))
        if self._hi == self._lo:
            raise ValueError("no joint feedback recorded yet")
        tt = self._tb[self._lo:self._hi]
        lo, hi = float(tt[0]), float(tt[-1])
        if np.any(ts < lo) or np.any(ts > hi) or not np.all(np.isfinite(ts)):
            raise ValueError(f"time outside the joint feedback's span [{lo}, {hi}] s")
        Q = self._qb[self._lo:self._hi]
        out = np.stack([np.interp(ts, tt, Q[:, j]) for j in range(Q.shape[1])], axis=-1)
        return out[0] if np.ndim(t) == 0 else out


def steady_state_gain(q: float, r: float, dt: float) -> float:
    """``K∞`` of the local-level filter sampled every ``dt`` (module docstring).

    Parameters
    ----------
    q : float
        Process noise intensity (unit/√s).
    r : float
        Measurement noise (unit), > 0.
    dt : float
        Sample spacing (s).

    Returns
    -------
    float
        ``(−λ + √(λ² + 4λ))/2`` with ``λ = q² dt / r²``.
    """
    lam = q * q * dt / (r * r)
    return (-lam + math.sqrt(lam * lam + 4.0 * lam)) / 2.0


class ResidualFilter:
    """Independent local-level Kalman filters on the residual's axes (module docstring).

    Parameters
    ----------
    process : (d,) array_like
        ``q_i``: how fast the residual may drift (m/√s, rad/√s).
    noise : (d,) array_like
        ``r_i``: one sample's measurement noise (m, rad), > 0.
    gate : float
        Innovation gate ``g`` in standard deviations (``inf``: none).
    max_rejections : int
        Gated samples in a row after which the filter restarts from the next one.
    """

    def __init__(self, process: ArrayLike, noise: ArrayLike, gate: float = 8.0,
                 max_rejections: int = 50) -> None:
        self.q = np.array(process, dtype=float).reshape(-1)
        self.r = np.array(noise, dtype=float).reshape(-1)
        if self.q.shape != self.r.shape or not np.all(self.q >= 0) or \
                not np.all(self.r > 0) or not np.all(np.isfinite(self.q)):
            raise ValueError(f"process ≥ 0 and noise > 0 per axis, of one size; got "
                             f"{process!r}, {noise!r}")
        if not gate > 0:
            raise ValueError(f"gate must be > 0 standard deviations, got {gate!r}")
        self.gate = float(gate)
        self.max_rejections = int(max_rejections)
        self._in_a_row = 0
        self.x = np.zeros_like(self.r)
        self.P = np.full_like(self.r, np.inf)
        self.t: float | None = None
        self.accepted = 0
        self.rejected = 0

    @property
    def initialised(self) -> bool:
        """At least one sample has been accepted since the last reset."""
        return self.t is not None

    def reset(self) -> None:
        """Forget the estimate (diffuse again): after a break the residual may have moved."""
        self.x = np.zeros_like(self.r)
        self.P = np.full_like(self.r, np.inf)
        self.t = None

    def variance(self, t: float) -> Array:
        """``P`` predicted to time ``t`` (s), per axis (``inf`` before the first sample)."""
        if self.t is None:
            return self.P.copy()
        return self.P + self.q ** 2 * max(0.0, t - self.t)

    def update(self, t: float, z: ArrayLike) -> bool:
        """Predict to ``t`` and take the measurement ``z`` (module docstring).

        Parameters
        ----------
        t : float
            The sample's time (s); a sample older than the last one is rejected.
        z : (d,) array_like
            The measured residual.

        Returns
        -------
        bool
            Accepted (False: gated, out of order or not finite; counted in ``rejected``).
        """
        zz = np.asarray(z, dtype=float).reshape(-1)
        if zz.shape != self.r.shape or not np.all(np.isfinite(zz)) or \
                (self.t is not None and t < self.t):
            self.rejected += 1
            return False
        if self.t is None:
            self.x, self.P, self.t = zz.copy(), self.r ** 2, float(t)
            self.accepted += 1
            return True
        P = self.variance(t)
        S = P + self.r ** 2
        innov = zz - self.x
        if np.any(np.abs(innov) > self.gate * np.sqrt(S)):
            self.rejected += 1
            self._in_a_row += 1
            if self._in_a_row >= self.max_rejections:  # not an outlier: the residual moved
                self.reset()
                self._in_a_row = 0
            return False
        self._in_a_row = 0
        K = P / S
        self.x = self.x + K * innov
        self.P = (1.0 - K) * P
        self.t = float(t)
        self.accepted += 1
        return True
