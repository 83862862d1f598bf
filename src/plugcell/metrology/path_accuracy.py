"""Path accuracy per segment and per window, as ISO 9283 judges a path.

For every cycle ``k`` on segment ``i`` (from ``P_i`` to ``P_{i+1}``, direction
``u_i = (P_{i+1} − P_i)/‖·‖``) with the actual TCP position ``x_k`` and the commanded
one ``c_k``::

    d_k = ‖(x_k − P_i) − ((x_k − P_i)·u_i) u_i‖      perpendicular to the segment
    a_k = (x_k − c_k)·u_i                            along it (the following error)

and for a set of cycles (a segment, or the cycles of a segment in one window state:
*tracked*, *break*, *off*): ``max d``, ``3σ = mean(d) + 3 std(d)`` (the ISO 9283 path
accuracy figure with its spread, as ``benchmarks/twin_path_deviation.py``),
``max |a|`` and ``3σ_a = mean(|a|) + 3 std(|a|)``.  Lengths in metres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]

__all__ = ["PathAccuracy", "SegmentAccuracy", "perpendicular", "segment_accuracy"]


@dataclass(frozen=True)
class SegmentAccuracy:
    """The accuracy of one set of cycles (module docstring).

    Attributes
    ----------
    segment : int
        The segment's index (-1: the whole path).
    state : str
        The window state (``"all"`` for every cycle).
    n : int
        The cycles.
    duration_s : float
        Their time (s).
    perpendicular_max, perpendicular_3sigma, along_max : float
        ``max d``, ``mean(d) + 3 std(d)``, ``max |a|`` (m).
    along_3sigma : float
        ``mean(|a|) + 3 std(|a|)`` (m).
    """

    segment: int
    state: str
    n: int
    duration_s: float
    perpendicular_max: float
    perpendicular_3sigma: float
    along_max: float
    along_3sigma: float = float("nan")


@dataclass(frozen=True)
class PathAccuracy:
    """Per segment and state, and for the whole path.

    Attributes
    ----------
    rows : tuple of SegmentAccuracy
        Each segment's rows (state ``"all"`` first), then the path's (``segment == -1``).
    """

    rows: tuple[SegmentAccuracy, ...]

    def of(self, segment: int, state: str = "all") -> SegmentAccuracy | None:
        """The row of ``segment`` (-1: whole path) in ``state``, if it has cycles."""
        for r in self.rows:
            if r.segment == segment and r.state == state:
                return r
        return None


def perpendicular(x: ArrayLike, p0: ArrayLike, p1: ArrayLike) -> Array:
    """``d_k``: distances of points from the line through two points.

    Parameters
    ----------
    x : (K, 3) array_like, m
    p0, p1 : (3,) array_like, m
        Two distinct points of the line.

    Returns
    -------
    (K,) array, m
    """
    x, p0, p1 = (np.asarray(v, dtype=float) for v in (x, p0, p1))
    u = p1 - p0
    norm = float(np.linalg.norm(u))
    if norm == 0.0:
        raise ValueError("a segment of length zero has no direction")
    u = u / norm
    r = x - p0
    return np.linalg.norm(r - np.outer(r @ u, u), axis=1)


def _row(segment: int, state: str, d: Array, a: Array, cycle_s: float) -> SegmentAccuracy:
    m = np.abs(a)
    return SegmentAccuracy(segment, state, int(d.size), d.size * cycle_s, float(d.max()),
                           float(d.mean() + 3.0 * d.std()), float(m.max()),
                           float(m.mean() + 3.0 * m.std()))


def segment_accuracy(actual: ArrayLike, commanded: ArrayLike, points: ArrayLike,
                     segment: ArrayLike, state: ArrayLike, cycle_s: float) -> PathAccuracy:
    """The accuracy of a run, per segment and window state (module docstring).

    Parameters
    ----------
    actual, commanded : (K, 3) array, m
        The TCP's actual and commanded positions each cycle.
    points : (N, 3) array, m
        The path's points.
    segment : (K,) int array
        The segment each cycle is on (``-1``: not on the path — before or after it).
    state : (K,) array of str
        Each cycle's window state.
    cycle_s : float
        The cycle (s), for the durations.

    Returns
    -------
    PathAccuracy
        Rows for every segment (state ``"all"`` and each state it had) and for the path.
    """
    x, c, P = (np.asarray(v, dtype=float) for v in (actual, commanded, points))
    seg, st = np.asarray(segment, dtype=int), np.asarray(state, dtype=str)
    d, a = np.full(len(x), np.nan), np.full(len(x), np.nan)
    for i in range(len(P) - 1):
        on = seg == i
        if not on.any():
            continue
        u = (P[i + 1] - P[i]) / np.linalg.norm(P[i + 1] - P[i])
        d[on] = perpendicular(x[on], P[i], P[i + 1])
        a[on] = (x[on] - c[on]) @ u
    rows = []
    for i in [*range(len(P) - 1), -1]:
        on = seg == i if i >= 0 else seg >= 0
        if not on.any():
            continue
        rows.append(_row(i, "all", d[on], a[on], cycle_s))
        for s in sorted(set(st[on].tolist())):
            m = on & (st == s)
            rows.append(_row(i, s, d[m], a[m], cycle_s))
    return PathAccuracy(tuple(rows))
