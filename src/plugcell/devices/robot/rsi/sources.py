"""Small correction sources for first contact with a robot (``plugcell rsi run``).

A trajectory streamer or a tracker's correction loop plugs into the link the same way
(:class:`~.link.CorrectionSource`); these two only prove the stream works.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .link import Correction, CycleState

__all__ = ["Hold", "SineOffset"]


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
