"""Line-of-sight breaks of a simulated tracker, from text: ``START:DURATION`` in seconds.

``plugcell path run --beam-break START:DURATION …`` (times from the path's start) and
``plugcell serve tracker --param beam_breaks=START:DURATION[,START:DURATION…]`` (times
from each stream's start) both read them here; :func:`blocked` turns them into the
``blocked(t)`` of :class:`~plugcell.sim.twin.tracker_stream.TrackerStream`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable

__all__ = ["blocked", "parse_beam_breaks"]


def parse_beam_breaks(texts: Iterable[str]) -> tuple[tuple[float, float], ...]:
    """``(start s, duration s)`` of each ``START:DURATION``.

    Raises
    ------
    ValueError
        A text that is not two numbers with ``START ≥ 0`` and ``DURATION > 0``, named.
    """
    out = []
    for text in texts:
        start, sep, duration = text.partition(":")
        try:
            pair = (float(start), float(duration))
        except ValueError:
            pair = (math.nan, math.nan)
        if not sep or not all(math.isfinite(v) for v in pair) or pair[0] < 0 or pair[1] <= 0:
            raise ValueError(f"{text!r}: expected START:DURATION in seconds "
                             "(START ≥ 0, DURATION > 0)")
        out.append(pair)
    return tuple(out)


def blocked(breaks: Iterable[tuple[float, float]]) -> Callable[[float], bool]:
    """``blocked(t)``: whether ``t`` (s) falls in one of the breaks ``[start, start +
    duration)``."""
    windows = tuple(breaks)
    return lambda t: any(a <= t < a + d for a, d in windows)
