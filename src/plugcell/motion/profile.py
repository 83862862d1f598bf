"""The jerk-limited rest-to-rest time law: the double-S (7-segment S-curve) profile.

Biagiotti & Melchiorri, *Trajectory Planning for Automatic Machines and Robots*
(Springer 2008), §3.4, with zero initial and final velocity and acceleration.  A
displacement ``h ≥ 0`` is covered in minimum time under ``|v| ≤ v_max`` and, in the
acceleration phase, ``|a| ≤ a₁``, ``|j| ≤ j₁``, in the deceleration phase ``|a| ≤ a₂``,
``|j| ≤ j₂`` (a blend halves the limits of the phase it overlaps,
:mod:`plugcell.motion.planner`).

A phase that brings the speed from 0 to ``v`` with limits ``(a, j)`` in minimum time
lasts (eq. 3.30)::

    v·j ≥ a²:   T_j = a/j,      T_a = T_j + v/a      (the acceleration a is reached)
    otherwise:  T_j = √(v/j),   T_a = 2·T_j

and covers ``v·T_a/2``.  The cruise lasts ``T_v = h/v_max − (T_a1 + T_a2)/2``.  If
``T_v < 0`` the speed ``v_max`` is not reached: ``T_v = 0`` and the reached speed
``v_lim`` solves ``v·(T_a1(v) + T_a2(v))/2 = h`` — for equal phases in closed form
(eq. 3.32)::

    h ≥ 2·a³/j²:  T_j = a/j,  T_a = T_j/2 + √((T_j/2)² + h/a)
    otherwise:    T_j = (h/(2·j))^(1/3),  T_a = 2·T_j

and otherwise by bisection (the left side increases with ``v``).  The total time is
``T = T_a1 + T_v + T_a2``.  With ``a_lim = j·T_j`` (so ``v_lim = (T_a − T_j)·a_lim``)
the acceleration phase is (eq. 3.30a–c with ``v0 = 0``, ``0 ≤ τ ≤ T_a``)::

    τ ≤ T_j:            s = j τ³/6,                       v = j τ²/2,         a = j τ
    T_j ≤ τ ≤ T_a−T_j:  s = a_lim (3τ² − 3T_j τ + T_j²)/6, v = a_lim (τ − T_j/2), a = a_lim
    T_a−T_j ≤ τ ≤ T_a:  s = v_lim T_a/2 − v_lim (T_a−τ) + j (T_a−τ)³/6,
                        v = v_lim − j (T_a−τ)²/2,        a = j (T_a−τ)

the cruise ``s = v_lim T_a1/2 + v_lim (t − T_a1)``, and the deceleration mirrors an
acceleration phase with its own ``(T_j2, T_a2, j₂)``: ``s(t) = h − s_acc(T − t)``,
``v(t) = v_acc(T − t)``, ``a(t) = −a_acc(T − t)``, ``j(t) = j_acc(T − t)``.  Every
phase joins the next with equal position, velocity and acceleration (the profile is
C², its jerk piecewise constant).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]

__all__ = ["DoubleS", "ProfileSample", "double_s", "unit_ramp"]


@dataclass(frozen=True)
class ProfileSample:
    """Position, velocity, acceleration and jerk of a time law at the sampled times.

    Attributes
    ----------
    s, v, a, j : array, shape of the times
        In the units of the displacement (m, rad or a path fraction) per s⁰, s¹, s², s³.
    """

    s: Array
    v: Array
    a: Array
    j: Array


def _phase(v: float, a: float, j: float) -> tuple[float, float]:
    """``(T_j, T_a)`` of the minimum-time phase from speed 0 to ``v`` (eq. 3.30)."""
    if v * j >= a * a:
        return a / j, a / j + v / a
    tj = math.sqrt(v / j)
    return tj, 2.0 * tj


@dataclass(frozen=True)
class DoubleS:
    """A rest-to-rest double-S profile over ``h`` (module docstring for the equations).

    Build it with :meth:`plan`; sample it with :meth:`sample`.

    Attributes
    ----------
    h : float
        Displacement, ≥ 0.
    t_j, t_a, j_max : float
        Acceleration phase: jerk-phase duration (s), phase duration (s), jerk.
    t_v : float, s
        Cruise duration.
    t_j2, t_a2, j_max2 : float
        The same of the deceleration phase.
    """

    h: float
    t_j: float
    t_a: float
    t_v: float
    j_max: float
    t_j2: float
    t_a2: float
    j_max2: float

    @property
    def duration(self) -> float:
        """``T = T_a1 + T_v + T_a2`` (s)."""
        return self.t_a + self.t_v + self.t_a2

    @property
    def v_lim(self) -> float:
        """Reached speed ``v_lim = (T_a − T_j)·j·T_j``."""
        return (self.t_a - self.t_j) * self.j_max * self.t_j

    @classmethod
    def plan(cls, h: float, v_max: float, a_max: float, j_max: float,
             a_max2: float | None = None, j_max2: float | None = None) -> DoubleS:
        """The minimum-time profile over ``h`` under the limits (eqs. 3.30–3.32).

        Parameters
        ----------
        h : float
            Displacement, ≥ 0 (m, rad or a path fraction).
        v_max, a_max, j_max : float
            Positive limits in the displacement's unit per s, s², s³ (``a_max``,
            ``j_max`` of the acceleration phase).
        a_max2, j_max2 : float, optional
            Of the deceleration phase (default: the same).

        Returns
        -------
        DoubleS

        Raises
        ------
        ValueError
            A negative or non-finite ``h`` or a limit that is not positive and finite.
        """
        a2 = a_max if a_max2 is None else a_max2
        j2 = j_max if j_max2 is None else j_max2
        if not (math.isfinite(h) and h >= 0.0):
            raise ValueError(f"displacement must be finite and ≥ 0, got {h}")
        for name, lim in (("v_max", v_max), ("a_max", a_max), ("j_max", j_max),
                          ("a_max2", a2), ("j_max2", j2)):
            if not (math.isfinite(lim) and lim > 0.0):
                raise ValueError(f"{name} must be positive and finite, got {lim}")
        if h == 0.0:
            return cls(0.0, 0.0, 0.0, 0.0, j_max, 0.0, 0.0, j2)
        tj1, ta1 = _phase(v_max, a_max, j_max)
        tj2, ta2 = _phase(v_max, a2, j2)
        t_v = h / v_max - 0.5 * (ta1 + ta2)
        if t_v >= 0.0:
            return cls(float(h), tj1, ta1, t_v, j_max, tj2, ta2, j2)
        if a2 == a_max and j2 == j_max:
            if h >= 2.0 * a_max**3 / j_max**2:
                tj = a_max / j_max
                ta = 0.5 * tj + math.sqrt(0.25 * tj * tj + h / a_max)
            else:
                tj = (h / (2.0 * j_max)) ** (1.0 / 3.0)
                ta = 2.0 * tj
            return cls(float(h), tj, ta, 0.0, j_max, tj, ta, j_max)
        lo, hi = 0.0, v_max
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            if mid * (_phase(mid, a_max, j_max)[1] + _phase(mid, a2, j2)[1]) / 2.0 < h:
                lo = mid
            else:
                hi = mid
            if hi - lo <= 1e-16 * v_max:
                break
        v = 0.5 * (lo + hi)
        tj1, ta1 = _phase(v, a_max, j_max)
        tj2, ta2 = _phase(v, a2, j2)
        # the remainder (≈ 1e-16 relative) as cruise, so the profile ends exactly at h
        t_v = max(0.0, (h - v * (ta1 + ta2) / 2.0) / v)
        return cls(float(h), tj1, ta1, t_v, j_max, tj2, ta2, j2)

    def sample(self, t: ArrayLike) -> ProfileSample:
        """Position, velocity, acceleration and jerk at times ``t`` (s, any shape).

        Before 0 the profile rests at 0, after ``T`` at ``h``.

        Parameters
        ----------
        t : array_like, s

        Returns
        -------
        ProfileSample
            Arrays of the shape of ``t``.
        """
        return double_s(t, self.h, self.t_j, self.t_a, self.t_v, self.j_max, self.t_j2,
                        self.t_a2, self.j_max2)

    def time_at(self, s: float) -> float:
        """The time at which the profile reaches ``s`` (0 ≤ s ≤ h), by bisection.

        ``s(t)`` is non-decreasing, so 60 halvings of ``[0, T]`` give the time to
        ``T·2⁻⁶⁰``.

        Parameters
        ----------
        s : float
            A position of the profile.

        Returns
        -------
        float, s
        """
        lo, hi = 0.0, self.duration
        if s <= 0.0:
            return 0.0
        if s >= self.h:
            return hi
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            if float(self.sample(mid).s) < s:
                lo = mid
            else:
                hi = mid
        return 0.5 * (lo + hi)

    def speed_at(self, t: float) -> float:
        """``v(t)`` (the displacement's unit per s).

        Parameters
        ----------
        t : float, s

        Returns
        -------
        float
        """
        return float(self.sample(t).v)


def _accel(tau: Array, t_j: Array, t_a: Array, j_max: Array) -> tuple[Array, ...]:
    """Acceleration phase at ``0 ≤ τ ≤ T_a`` (clipped), eq. (3.30a–c) with v0 = 0."""
    a_lim = j_max * t_j
    v_lim = (t_a - t_j) * a_lim
    tau = np.clip(tau, 0.0, t_a)
    r = t_a - tau
    p1, p3 = tau <= t_j, tau >= t_a - t_j
    s = np.where(p1, j_max * tau**3 / 6.0,
                 np.where(p3, v_lim * t_a / 2.0 - v_lim * r + j_max * r**3 / 6.0,
                          a_lim * (3.0 * tau**2 - 3.0 * t_j * tau + t_j * t_j) / 6.0))
    v = np.where(p1, j_max * tau**2 / 2.0,
                 np.where(p3, v_lim - j_max * r**2 / 2.0, a_lim * (tau - t_j / 2.0)))
    a = np.where(p1, j_max * tau, np.where(p3, j_max * r, a_lim))
    j = np.where(p1, j_max, np.where(p3, -j_max, 0.0))
    return s, v, a, j


def double_s(
    t: ArrayLike, h: ArrayLike, t_j: ArrayLike, t_a: ArrayLike, t_v: ArrayLike,
    j_max: ArrayLike, t_j2: ArrayLike, t_a2: ArrayLike, j_max2: ArrayLike,
) -> ProfileSample:
    """Sample double-S profiles given by their parameters (all arguments broadcast).

    The equations of the module docstring; before 0 a profile rests at 0, after
    ``T = T_a1 + T_v + T_a2`` at ``h``, with zero velocity, acceleration and jerk.

    Parameters
    ----------
    t : array_like, s
        Times since each profile's start.
    h, t_j, t_a, t_v, j_max, t_j2, t_a2, j_max2 : array_like
        The profiles' :class:`DoubleS` fields.

    Returns
    -------
    ProfileSample
        Arrays of the broadcast shape.
    """
    t, h, t_j, t_a, t_v, j_max, t_j2, t_a2, j_max2 = np.broadcast_arrays(
        *(np.asarray(x, dtype=float) for x in (t, h, t_j, t_a, t_v, j_max, t_j2, t_a2,
                                                j_max2)))
    T = t_a + t_v + t_a2
    v_lim = (t_a - t_j) * j_max * t_j
    s1, v1, a1, j1 = _accel(t, t_j, t_a, j_max)
    s3, v3, a3, j3 = _accel(T - t, t_j2, t_a2, j_max2)
    cruise = (t > t_a) & (t < t_a + t_v)
    decel = t >= t_a + t_v
    s = np.where(decel, h - s3, np.where(cruise, v_lim * t_a / 2.0 + v_lim * (t - t_a), s1))
    v = np.where(decel, v3, np.where(cruise, v_lim, v1))
    a = np.where(decel, -a3, np.where(cruise, 0.0, a1))
    j = np.where(decel, j3, np.where(cruise, 0.0, j1))
    before, after = t <= 0.0, t >= T
    s = np.where(before, 0.0, np.where(after, h, s))
    moving = ~(before | after)
    return ProfileSample(s, np.where(moving, v, 0.0), np.where(moving, a, 0.0),
                         np.where(moving, j, 0.0))


def unit_ramp(duration: float) -> DoubleS:
    """The jerk-limited ramp of a blend factor from 0 to 1 in ``duration`` seconds.

    A double-S (:mod:`plugcell.motion.profile`) over ``h = 1`` made of jerk phases only
    (``T_j = T_a/2``, no constant acceleration, no cruise): with ``D`` the duration,
    ``v = 2/D``, ``a = 8/D²``, ``j = 32/D³`` — the least peak jerk of a double-S of that
    duration.  Its peak rate is ``2/D`` (1/s).

    Parameters
    ----------
    duration : float
        ``D`` (s), > 0.

    Returns
    -------
    DoubleS
        The ramp; ``sample(t).s`` is the blend factor.
    """
    if not (np.isfinite(duration) and duration > 0):
        raise ValueError(f"ramp duration must be a finite number of seconds > 0, "
                         f"got {duration!r}")
    return DoubleS.plan(1.0, 2.0 / duration, 8.0 / duration**2, 32.0 / duration**3)
