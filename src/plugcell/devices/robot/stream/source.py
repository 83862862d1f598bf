"""What a correction source is and gets, and two sources for a first contact.

The link asks its :class:`CorrectionSource` once a cycle for a :class:`Correction`, giving
it the cycle's :class:`CycleState`; a trajectory streamer or a tracker's correction loop
plugs in the same way, whatever the vendor.  :class:`Hold` and :class:`SineOffset` only
prove a stream works (``plugcell rsi run``, ``plugcell egm run``).
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from plugcell.motion.profile import unit_ramp

Array = NDArray[np.float64]

__all__ = ["Correction", "CorrectionSource", "CycleState", "Hold", "PathOffset", "SineOffset",
           "SourceLike", "as_source", "unit_ramp"]


@dataclass(frozen=True)
class Correction:
    """What a correction source wants this cycle (SI).

    Give ``offset`` (the whole offset from where the stream started: the absolute-mode
    view, natural for a trajectory) or ``step`` (the change this cycle: the relative
    view, natural for a tracker's correction), not both; neither: no motion.  The link
    sends whichever its mode needs.

    Attributes
    ----------
    offset : array_like, shape (6,), optional
        Joint: the six joints (rad); Cartesian: X, Y, Z (m), then three rotations (rad:
        RSI's A, B, C; EGM's rotation vector).
    step : array_like, shape (6,), optional
        Like ``offset``, the change of this cycle.
    outputs : mapping of str to int
        New values of the configured output words (RSI: ``{"DiO": 5}``); they stay until
        set again.
    """

    offset: ArrayLike | None = None
    step: ArrayLike | None = None
    outputs: Mapping[str, int] = field(default_factory=dict)

    def target(self, current: Array) -> Array | None:
        """The whole offset this correction asks for, given the offset so far.

        ``offset`` as it is, or ``current + step``; a step of the wrong size is passed on
        as is (the limiter refuses it with the reason).

        Parameters
        ----------
        current : ndarray, shape (6,)
            The offset commanded so far (SI).

        Returns
        -------
        ndarray or None
            The wanted offset (SI); ``None``: no motion asked.

        Raises
        ------
        ValueError
            Both an offset and a step.
        """
        if self.offset is not None and self.step is not None:
            raise ValueError("give an offset or a step, not both")
        if self.offset is not None:
            return np.asarray(self.offset, dtype=float).reshape(-1)
        if self.step is None:
            return None
        step = np.asarray(self.step, dtype=float).reshape(-1)
        return current + step if step.shape == (6,) else step


@dataclass(frozen=True)
class CycleState:
    """What a correction source is given each cycle.

    Attributes
    ----------
    robot : object
        The robot's packet of this cycle, in SI: RSI's :class:`~..rsi.codec.RobotState`,
        EGM's :class:`~..egm.messages.EgmState`.
    offset : ndarray, shape (6,)
        The offset the link has commanded so far in this session (SI).
    session : int
        Counts the streams since the link started (1 for the first).
    cycle : int
        Packets answered in this session before this one.
    t : float
        Seconds since the session's first packet, by the controller's clock (RSI's
        IPOC, EGM's header ``tm``).
    """

    robot: Any
    offset: Array
    session: int
    cycle: int
    t: float


@runtime_checkable
class CorrectionSource(Protocol):
    """Anything that gives a correction per cycle (a trajectory streamer, a tracker loop)."""

    def correction(self, state: CycleState) -> Correction | None:
        """The correction of this cycle; ``None``: no motion."""


SourceLike = CorrectionSource | Callable[[CycleState], "Correction | None"]


def as_source(source: SourceLike | None) -> Callable[[CycleState], Correction | None]:
    """``source`` as the callable the link calls each cycle (``None``: no motion)."""
    if source is None:
        return lambda state: None
    if isinstance(source, CorrectionSource):
        return source.correction
    if callable(source):
        return source
    raise TypeError(f"a correction source has correction(state) or is callable, got "
                    f"{type(source).__name__}")


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
        """Whether the ramp out is over (a ``done`` for a link's ``follow``).

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
