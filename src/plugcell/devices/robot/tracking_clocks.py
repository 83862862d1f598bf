"""The clocks of a tracked move: the tracker's time and the robot's, both onto the PC's.

A tracker sample carries its acquisition time on the *instrument's* clock; the correction
loop needs it on the *robot's* (the joint feedback it is compared with).  Both are mapped
through the PC's clock (``time.time()``), from stamps taken as things happen:

* :class:`OneWayClock` — the instrument's clock, which runs at a crystal's rate: each
  row says when the tracker took it (device time) and when the driver got it (PC time);
  the lower envelope of ``pc − device`` is the map (the smallest transport delay in it);
* :class:`CycleClock` — the robot's cycle clock, from the PC time each cycle's packet was
  handled: linear between the stamps around a PC time, rate 1 beyond them.  Not an
  envelope: a controller's cycle clock counts cycles, and one that falls behind on a
  loaded PC (the twin's resynchronises when its process was not scheduled) stands still
  while the PC's runs on — as does its arm, so a sample taken then belongs to that robot
  time.  A constant envelope would put later samples into the robot's future (never
  late, however late they came); the interpolation follows the slip cycle by cycle.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

__all__ = ["CycleClock", "InOrder", "OneWayClock"]


class OneWayClock:
    """Device time → PC time from one-way stamps: ``pc = device + min_i(pc_i − device_i)``
    (the lower envelope at rate 1 — :func:`plugcell.metrology.timing.fit_clock_map` with
    the rate fixed, online; over one move a clock's drift is negligible).  The smallest
    transport delay is in the offset: the time is that much early."""

    def __init__(self) -> None:
        self.offset = np.inf

    def see(self, device_s: float, pc_s: float) -> None:
        """One stamp: the event of device time ``device_s`` arrived at PC time ``pc_s``."""
        self.offset = min(self.offset, pc_s - device_s)

    def pc(self, device_s: float) -> float:
        """PC time of device time ``device_s``."""
        return device_s + self.offset


class CycleClock:
    """PC time → robot time from the PC times the robot's cycles were handled (module
    docstring)::

        t(p) = t_k + (p − p_k) (t_{k+1} − t_k) / (p_{k+1} − p_k)   p_k ≤ p ≤ p_{k+1}
        t(p) = t_N + (p − p_N)                                      p > p_N (rate 1)

    Parameters
    ----------
    span_s : float
        How long stamps are kept (s of PC time): older samples map at rate 1 from the
        oldest kept.
    """

    def __init__(self, span_s: float = 2.0) -> None:
        if not (math.isfinite(span_s) and span_s > 0):
            raise ValueError(f"span_s must be > 0 s, got {span_s!r}")
        self.span_s = float(span_s)
        self._pc: deque[float] = deque()
        self._t: deque[float] = deque()

    def see(self, robot_s: float, pc_s: float) -> None:
        """The cycle of robot time ``robot_s`` was handled at PC time ``pc_s`` (stamps
        out of order in either clock are ignored)."""
        if self._pc and (pc_s <= self._pc[-1] or robot_s <= self._t[-1]):
            return
        self._pc.append(pc_s)
        self._t.append(robot_s)
        while self._pc[0] < pc_s - self.span_s:
            self._pc.popleft()
            self._t.popleft()

    def robot(self, pc_s: float) -> float:
        """Robot time at PC time ``pc_s`` (NaN before the first stamp)."""
        if not self._pc:
            return math.nan
        if pc_s >= self._pc[-1]:
            return self._t[-1] + (pc_s - self._pc[-1])
        if pc_s <= self._pc[0]:
            return self._t[0] + (pc_s - self._pc[0])
        return float(np.interp(pc_s, self._pc, self._t))


class InOrder:
    """Sample times handed on in increasing order: ``t' = max(t, next(t_last))``,
    ``next`` the next float after the last time handed on.

    The two clocks' maps move as they learn (:class:`OneWayClock`'s offset falls when a
    faster delivery is seen), so a sample mapped after such a step can land before one
    mapped before it — by the step, rarely more than a millisecond; a tracked move's
    samples must stay in the order the tracker took them (CI of 2026-11-28: one of 3 289
    samples out of order)."""

    def __init__(self) -> None:
        self.last = -math.inf

    def __call__(self, t: float) -> float:
        """``t``, or just after the last time handed on where ``t`` is not after it."""
        if not t > self.last:
            t = math.nextafter(self.last, math.inf)
        self.last = t
        return t
