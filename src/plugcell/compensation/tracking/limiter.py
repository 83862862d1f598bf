"""A jerk-free bound on how the tracker's correction may move: speed, acceleration, total.

Per axis the term ``c`` moves towards its target ``c*``; its state is the step a robot
cycle ``s`` (the speed times ``T``), bounded by ``v = v_max T``, whose change is bounded
by ``a = a_max T²`` a robot cycle.  An update is computed for a cycle ``n ≥ 1`` robot
cycles after the last one (``n = 1`` when no cycle was skipped; a loop that fell behind
skips some: the bounds hold in the *robot's* time, not per computed update)::

    d     = clip(c*, −c_max, c_max) − c                (the target inside the total bound)
    s_brk = a (√((n − 1/2)² + 2|d|/a) − (n − 1/2))     (the largest step a cycle from which
                                                         n cycles at it, then steps
                                                         shrinking by a each cycle, stop
                                                         within |d|)
    s'    = clip(sgn(d) · min(v, s_brk, |d|/n),  s − n a,  s + n a)
    s'    = clip(s', −v, v)
    c    ← c + n s'

The braking bound solves ``n s + s (s − a)/(2a) ≤ |d|``; for ``n = 1`` it is the familiar
``a (√(1/4 + 2|d|/a) − 1/2)`` (the steps ``s, s − a, …`` sum to at most ``|d|``).  The
lower end ``s − n a`` of the clip satisfies it when the last update's step did (n cycles
at ``s − n a`` cover no more than the n cycles ``s − a, …, s − n a``), so the term comes
to a constant target without overshoot — but for the closed form's rounding of the
last braking step: the tail ``x (x − a)/(2a)`` undercounts a last step ``x < a`` by at
most ``a/8``, so the term may pass its target (and ``c_max``) by at most ``a/8``, 1 µm
with the loop's defaults.  The outputs ``c_i`` at robot times ``t_i`` satisfy, per axis,
in robot time::

    |c_i − c_{i−1}| / (t_i − t_{i−1}) ≤ v_max                      (speed)
    |u_i − u_{i−1}| / (t_i − t_{i−1}) ≤ a_max,  u_i = (c_i − c_{i−1}) / (t_i − t_{i−1})
    |c_i| ≤ c_max + a/8

whatever cycles were skipped (a target that jumps, reverses or vanishes — a beam break,
a wild sample — moves the robot at bounded speed and acceleration).  Pure math, SI units.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]

__all__ = ["RateLimiter"]


class RateLimiter:
    """Per-axis speed, acceleration and total bound of a correction (module docstring).

    Parameters
    ----------
    cycle_s : float
        ``T`` (s).
    max_speed : (d,) array_like
        ``v_max`` per axis (m/s or rad/s), > 0.
    max_accel : (d,) array_like
        ``a_max`` per axis (m/s² or rad/s²), > 0.
    max_total : (d,) array_like
        ``c_max`` per axis (m or rad), ≥ 0; ``inf``: no bound on the total (a limiter of
        the rate alone, e.g. the correction on the wire:
        :class:`~plugcell.devices.robot.stream.adjusting.WireLimits`).
    """

    def __init__(self, cycle_s: float, max_speed: ArrayLike, max_accel: ArrayLike,
                 max_total: ArrayLike) -> None:
        v = np.array(max_speed, dtype=float).reshape(-1)
        a = np.array(max_accel, dtype=float).reshape(-1)
        c = np.array(max_total, dtype=float).reshape(-1)
        if not (cycle_s > 0 and np.isfinite(cycle_s)):
            raise ValueError(f"cycle_s must be > 0 seconds, got {cycle_s!r}")
        if not (v.shape == a.shape == c.shape) or not np.all(np.isfinite(np.r_[v, a])) \
                or np.any(v <= 0) or np.any(a <= 0) or not np.all(c >= 0):
            raise ValueError(f"max_speed > 0, max_accel > 0 (finite), max_total ≥ 0 per axis, "
                             f"of one size; got {max_speed!r}, {max_accel!r}, {max_total!r}")
        self.T = float(cycle_s)
        self.v_step = v * cycle_s
        self.a_step = a * cycle_s ** 2
        self.max_total = c
        self.value = np.zeros_like(v)
        self.step = np.zeros_like(v)

    def reset(self) -> None:
        """At rest at zero."""
        self.value = np.zeros_like(self.value)
        self.step = np.zeros_like(self.step)

    def apply(self, target: ArrayLike, cycles: float = 1.0) -> Array:
        """One update towards ``target``, ``cycles`` robot cycles after the last; the new
        value (module docstring).

        Parameters
        ----------
        target : (d,) array_like
            ``c*`` (non-finite entries hold that axis where it is).
        cycles : float
            ``n ≥ 1``: the robot cycles since the last update (1: none skipped).

        Returns
        -------
        (d,) array
            ``c`` after this update.
        """
        tgt = np.array(target, dtype=float).reshape(-1)
        if tgt.shape != self.value.shape:
            raise ValueError(f"target has {tgt.size} axes, the limiter {self.value.size}")
        n = float(cycles)
        if not (n >= 1.0 and np.isfinite(n)):
            raise ValueError(f"cycles must be a finite number ≥ 1, got {cycles!r}")
        tgt = np.where(np.isfinite(tgt), tgt, self.value)
        d = np.clip(tgt, -self.max_total, self.max_total) - self.value
        a = self.a_step
        ad = np.abs(d)
        h = n - 0.5  # n = 1: the steps' familiar a (√(1/4 + 2|d|/a) − 1/2)
        brake = a * (np.sqrt(h * h + 2.0 * ad / a) - h)
        want = np.sign(d) * np.minimum(np.minimum(self.v_step, brake), ad / n)
        s = np.clip(want, self.step - n * a, self.step + n * a)
        s = np.clip(s, -self.v_step, self.v_step)
        self.value = self.value + n * s
        self.step = s
        return self.value.copy()
