"""A jerk-free bound on how the tracker's correction may move: speed, acceleration, total.

Per axis, every cycle ``T``, the term ``c`` moves towards its target ``c*`` by the step
``s_k``, with the step's bound ``v = v_max T`` and its change's bound ``a = a_max T²``::

    d     = clip(c*, −c_max, c_max) − c                (the target inside the total bound)
    s_brk = a (√(1/4 + 2|d|/a) − 1/2)                  (the largest step from which
                                                         steps shrinking by a each cycle
                                                         stop within |d|)
    s_k   = clip(sgn(d) · min(v, s_brk, |d|),  s_{k−1} − a,  s_{k−1} + a)
    c    ← c + s_k

The braking bound solves ``s (s/a + 1)/2 ≤ |d|`` (the steps ``s, s − a, …`` sum to at
most ``|d|``), so the term reaches a constant target without overshoot, and every
output satisfies ``|s_k| ≤ v``, ``|s_k − s_{k−1}| ≤ a`` and ``|c| ≤ c_max`` (a target
that jumps, reverses or vanishes — a beam break, a wild sample — moves the robot at
bounded speed and acceleration).  Pure math, SI units.
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
        ``c_max`` per axis (m or rad), ≥ 0.
    """

    def __init__(self, cycle_s: float, max_speed: ArrayLike, max_accel: ArrayLike,
                 max_total: ArrayLike) -> None:
        v = np.array(max_speed, dtype=float).reshape(-1)
        a = np.array(max_accel, dtype=float).reshape(-1)
        c = np.array(max_total, dtype=float).reshape(-1)
        if not (cycle_s > 0 and np.isfinite(cycle_s)):
            raise ValueError(f"cycle_s must be > 0 seconds, got {cycle_s!r}")
        if not (v.shape == a.shape == c.shape) or not np.all(np.isfinite(np.r_[v, a, c])) \
                or np.any(v <= 0) or np.any(a <= 0) or np.any(c < 0):
            raise ValueError(f"max_speed > 0, max_accel > 0, max_total ≥ 0 per axis, of one "
                             f"size; got {max_speed!r}, {max_accel!r}, {max_total!r}")
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

    def apply(self, target: ArrayLike) -> Array:
        """One cycle towards ``target``; the new value (module docstring).

        Parameters
        ----------
        target : (d,) array_like
            ``c*`` (non-finite entries hold that axis where it is).

        Returns
        -------
        (d,) array
            ``c`` after this cycle.
        """
        tgt = np.array(target, dtype=float).reshape(-1)
        if tgt.shape != self.value.shape:
            raise ValueError(f"target has {tgt.size} axes, the limiter {self.value.size}")
        tgt = np.where(np.isfinite(tgt), tgt, self.value)
        d = np.clip(tgt, -self.max_total, self.max_total) - self.value
        a = self.a_step
        brake = a * (np.sqrt(0.25 + 2.0 * np.abs(d) / a) - 0.5)
        want = np.sign(d) * np.minimum(np.minimum(self.v_step, brake), np.abs(d))
        s = np.clip(want, self.step - a, self.step + a)
        s = np.clip(s, -self.v_step, self.v_step)
        self.value = self.value + s
        self.step = s
        return self.value.copy()
