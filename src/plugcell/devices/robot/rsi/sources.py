"""Correction sources: a first contact with a robot, and path corrections.

:class:`Hold` and :class:`SineOffset` prove the stream works (``plugcell rsi run``);
:class:`PathOffset` is mode (b) of issue 37, *the robot drives, plugcell corrects*: the
controller runs its own program (LIN/PTP with ``RSI_MOVECORR``) and plugcell
superimposes an offset, blended in and out by a jerk-limited ramp.  A trajectory
streamer or a tracker's correction loop plugs into the link the same way
(:class:`~.link.CorrectionSource`).
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from plugcell.motion.profile import DoubleS

from .link import Correction, CycleState

__all__ = ["Hold", "PathOffset", "SineOffset"]


class Hold:
    """No motion: every answer carries a zero correction (relative) or a zero offset."""

    def correction(self, state: CycleState) -> Correction:
        """Zero offset.

        Parameters
        ----------
        state : CycleState
            Unused.

        Returns
        -------
        Correction
            The zero offset.
        """
        return Correction(offset=np.zeros(6))


@dataclass(frozen=True)
class SineOffset:
    """One axis swings ``o(t) = a · (1 − cos(2π t / P)) / 2`` for ``n`` periods, then rests.

    The offset and its speed are zero at the start and at the end of every period, so the
    motion starts and stops smoothly; the peak speed is ``π a / P``.

    Attributes
    ----------
    axis : int
        0..5 (A1..A6, or X..C).
    amplitude : float
        ``a`` in SI (rad or m).
    period : float
        ``P`` in seconds.
    periods : int
        ``n``; after ``n · P`` the offset stays zero.
    """

    axis: int
    amplitude: float
    period: float
    periods: int = 1

    def offset(self, t: float) -> np.ndarray:
        """The offset at ``t`` seconds (all six axes, SI).

        Parameters
        ----------
        t : float
            Seconds since the stream started.

        Returns
        -------
        ndarray, shape (6,)
            The offset.
        """
        o = np.zeros(6)
        if 0.0 <= t < self.periods * self.period:
            o[self.axis] = self.amplitude * (1 - np.cos(2 * np.pi * t / self.period)) / 2
        return o

    def correction(self, state: CycleState) -> Correction:
        """The offset at the cycle's time (the controller's IPOC clock).

        Parameters
        ----------
        state : CycleState
            The cycle.

        Returns
        -------
        Correction
            ``offset(state.t)``.
        """
        return Correction(offset=self.offset(state.t))


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


OffsetLike = ArrayLike | Callable[[CycleState], ArrayLike]


class PathOffset:
    """An offset superimposed on the robot's own path, blended in and out (mode (b)).

    Each cycle the source asks for the offset ``o(t) = b(t) · g(t)``: ``g`` the offset
    wanted — a constant, a function of the cycle's state (time, the robot's reported
    position), or the latest value given to :meth:`set_offset` from any thread (the
    hook of a tracker's correction loop) — and ``b`` the blend factor, ramped from 0 to
    1 by :func:`unit_ramp` from the first cycle it is asked, and from its value then to
    0 after :meth:`finish` (or at ``finish_at``).  Once ramped out it asks for a zero
    offset: relative corrections end with zero steps (docs/kuka-rsi.md, HOLDON).

    The link holds every request to its limits (:class:`~.limits.OffsetLimiter`): a
    ramp too steep, a jump of ``g`` or an offset beyond ``max_offset`` is clamped and
    counted, or refused, there.  The ramp's peak speed is ``2·|g_i|/ramp`` per axis.

    Parameters
    ----------
    offset : array_like, shape (6,), or callable, optional
        ``g``: SI (joint: rad; Cartesian: X, Y, Z in m, A, B, C in rad, in the config's
        frame), or ``g(state)`` returning one.  Default zero (set it later).
    ramp : float
        Duration of the ramp in and of the ramp out (s).
    finish_at : float, optional
        Start the ramp out this many seconds after the first cycle.

    Raises
    ------
    ValueError
        A ramp that is not a positive duration, or an offset that is not six finite
        numbers.
    """

    def __init__(self, offset: OffsetLike | None = None, *, ramp: float = 0.5,
                 finish_at: float | None = None) -> None:
        self._ramp = unit_ramp(ramp)
        self._lock = threading.Lock()
        self._goal: OffsetLike = np.zeros(6) if offset is None else offset
        if not callable(self._goal):
            self._goal = _six(self._goal)
        self.finish_at = finish_at
        self._t0: float | None = None
        self._t_finish: float | None = None
        self._b_finish = 1.0
        self._finish_asked = False
        self._blend = 0.0
        self._ended = False

    def set_offset(self, offset: ArrayLike) -> None:
        """Ask for ``offset`` from the next cycle on (thread-safe; replaces a callable).

        Parameters
        ----------
        offset : array_like, shape (6,)
            ``g`` in SI.
        """
        g = _six(offset)
        with self._lock:
            self._goal = g

    def finish(self) -> None:
        """Ramp out from the next cycle (thread-safe)."""
        with self._lock:
            self._finish_asked = True

    @property
    def blend(self) -> float:
        """The blend factor ``b`` of the last cycle, 0..1."""
        return self._blend

    def ended(self, state: CycleState | None = None) -> bool:
        """Whether the ramp out is over (a ``done`` for :meth:`RsiLink.follow`).

        Parameters
        ----------
        state : CycleState, optional
            Unused (the signature ``follow`` calls).

        Returns
        -------
        bool
            The offset asked for is zero again, for good.
        """
        return self._ended

    def _factor(self, t: float) -> float:
        """``b(t)``: up the ramp, down after the finish."""
        if self._t0 is None:
            self._t0 = t
        tau = t - self._t0
        with self._lock:
            asked = self._finish_asked
        if self._t_finish is None and (asked or (self.finish_at is not None
                                                 and tau >= self.finish_at)):
            self._t_finish, self._b_finish = tau, self._blend
        if self._t_finish is None:
            return float(self._ramp.sample(tau).s)
        down = float(self._ramp.sample(tau - self._t_finish).s)
        if down >= 1.0:
            self._ended = True
        return self._b_finish * (1.0 - down)

    def correction(self, state: CycleState) -> Correction:
        """This cycle's offset ``b(t) · g(t)``.

        Parameters
        ----------
        state : CycleState
            The cycle (its ``t``, by the controller's IPOC clock).

        Returns
        -------
        Correction
            ``offset=b·g`` (the link sends the step or the offset its mode needs).
        """
        self._blend = b = self._factor(state.t)
        with self._lock:
            goal = self._goal
        if b == 0.0:
            return Correction(offset=np.zeros(6))
        g = _six(goal(state)) if callable(goal) else goal
        return Correction(offset=b * g)


def _six(values: ArrayLike) -> np.ndarray:
    g = np.asarray(values, dtype=float).reshape(-1)
    if g.shape != (6,) or not np.all(np.isfinite(g)):
        raise ValueError(f"an offset is six finite numbers (SI), got {values!r}")
    return g
