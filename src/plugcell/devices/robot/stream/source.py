"""What a correction source is and gets, and two sources for a first contact.

The link asks its :class:`CorrectionSource` once a cycle for a :class:`Correction`, giving
it the cycle's :class:`CycleState`; a trajectory streamer or a tracker's correction loop
plugs in the same way, whatever the vendor.  :class:`Hold` and :class:`SineOffset` only
prove a stream works (``plugcell rsi run``, ``plugcell egm run``).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]

__all__ = ["Correction", "CorrectionSource", "CycleState", "Hold", "SineOffset",
           "SourceLike", "as_source"]


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
