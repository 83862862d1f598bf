"""ABB's path coordinate system: the frame an EGM path correction is applied in.

With EGM path correction (``EGMActMove`` / ``EGMMoveL``: the robot runs its own path, a
sensor corrects it) the controller takes the correction ``c = (c_x, c_y, c_z)`` in the
*path coordinate system* (ABB, Application manual Externally Guided Motion,
3HAC073318-001, §1.4 "Introduction to EGM Path Correction")::

    x = t / |t|                         the path's tangent (its direction of motion)
    y = (x × z_tool) / |x × z_tool|     z_tool: the active tool frame's z axis
    z = x × y

— a right-handed orthonormal frame ``R = [x y z]`` (columns, in the base frame), defined
wherever the tangent is not parallel to the tool's z.  The controller corrects only y
and z: "It is not possible to perform orientation corrections, nor corrections in x
(which is the path direction)" (same manual, §1.1, *Limitations for EGM Path
Correction*), so the displacement it applies is::

    d = R · (0, c_y, c_z)ᵀ = c_y y + c_z z

A displacement ``d`` wanted in the base frame is ``c = Rᵀ d`` in path coordinates
(:func:`to_path`), and ``R c = d`` (:func:`from_path`); of it the controller applies
``d − (d·x) x`` (:func:`applied_displacement`): the component along the path is lost.
With the tool's z pointing down (−z of the base) and the path along the base's +x, the
path frame is the base frame.

:func:`path_tangents` gives a sampled path's tangents (central differences; where it
stands still, the last direction it moved in, or before it first moves the first), and
:class:`TangentTracker` follows the tangent of a path seen one sample at a time (a sensor
watching the controller's path).  Pure numpy, SI units.
"""

from __future__ import annotations

from collections import deque

import numpy as np
from numpy.typing import ArrayLike, NDArray

from plugcell.kinematics.transforms import cross

__all__ = ["MIN_STEP_M", "TangentTracker", "applied_displacement", "from_path",
           "path_frame", "path_tangents", "to_path"]

Array = NDArray[np.float64]

#: The smallest motion (m) a tangent is taken from: below it a path stands still (a
#: sampled path's steps are then dominated by the rounding of its inverse kinematics).
MIN_STEP_M = 1e-6
#: ``|x × z_tool|`` below this: the tangent runs along the tool's z (no path frame).
_PARALLEL = 1e-6


def path_frame(tangent: ArrayLike, tool_z: ArrayLike) -> Array:
    """``R = [x y z]``: ABB's path coordinate system (module docstring).

    ``x = t/|t|``, ``y = (x × z_tool)/|x × z_tool|``, ``z = x × y``.

    Parameters
    ----------
    tangent : array_like, shape (..., 3)
        The path's direction of motion ``t`` (any length > 0), base frame.
    tool_z : array_like, shape (..., 3)
        The active tool frame's z axis ``z_tool`` (any length > 0), base frame.

    Returns
    -------
    ndarray, shape (..., 3, 3)
        ``R``, its columns the path frame's x, y and z in the base frame (orthonormal,
        ``det R = +1``).

    Raises
    ------
    ValueError
        A tangent of zero length, or one along the tool's z (``|x × z_tool| < 10⁻⁶``):
        no path frame there.
    """
    t = np.asarray(tangent, dtype=float)
    zt = np.asarray(tool_z, dtype=float)
    t, zt = np.broadcast_arrays(t, zt)
    if t.shape[-1] != 3:
        raise ValueError(f"a tangent and a tool z are 3-vectors, got shape {t.shape}")
    nt = np.linalg.norm(t, axis=-1, keepdims=True)
    nz = np.linalg.norm(zt, axis=-1, keepdims=True)
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(zt))):
        raise ValueError("a path frame of a tangent or tool z that is not finite")
    if np.any(nt == 0) or np.any(nz == 0):
        raise ValueError("no path frame where the path does not move (a zero tangent) or "
                         "of a zero tool z")
    x = t / nt
    y = cross(x, zt / nz)
    ny = np.linalg.norm(y, axis=-1, keepdims=True)
    if np.any(ny < _PARALLEL):
        raise ValueError("no path frame where the path runs along the tool's z axis "
                         "(y = x × z_tool vanishes)")
    y = y / ny
    z = cross(x, y)
    return np.stack([x, y, z], axis=-1)


def to_path(d: ArrayLike, R: ArrayLike) -> Array:
    """``c = Rᵀ d``: a base-frame displacement in path coordinates.

    Parameters
    ----------
    d : array_like, shape (..., 3)
        The displacement in the base frame (m).
    R : array_like, shape (..., 3, 3)
        The path frame (:func:`path_frame`).

    Returns
    -------
    ndarray, shape (..., 3)
        ``(c_x, c_y, c_z)`` (m): along the path, and across it along y and z.
    """
    return np.einsum("...ji,...j->...i", np.asarray(R, dtype=float), np.asarray(d, dtype=float))


def from_path(c: ArrayLike, R: ArrayLike) -> Array:
    """``d = R c``: path coordinates in the base frame (all three, x included).

    Parameters
    ----------
    c : array_like, shape (..., 3)
        ``(c_x, c_y, c_z)`` (m).
    R : array_like, shape (..., 3, 3)
        The path frame (:func:`path_frame`).

    Returns
    -------
    ndarray, shape (..., 3)
        The displacement in the base frame (m).
    """
    return np.einsum("...ij,...j->...i", np.asarray(R, dtype=float), np.asarray(c, dtype=float))


def applied_displacement(c: ArrayLike, R: ArrayLike) -> Array:
    """``d = R · (0, c_y, c_z)ᵀ``: what a controller does with the path correction ``c`` —
    y and z, never x (the path direction; module docstring).

    Parameters
    ----------
    c : array_like, shape (..., 3)
        The path correction (m, path coordinates).
    R : array_like, shape (..., 3, 3)
        The path frame.

    Returns
    -------
    ndarray, shape (..., 3)
        The displacement of the TCP in the base frame (m).
    """
    c = np.array(c, dtype=float)
    c[..., 0] = 0.0
    return from_path(c, R)


def path_tangents(positions: ArrayLike, min_step: float = MIN_STEP_M) -> Array:
    """The unit tangents of a sampled path: ``t_k = (p_{k+1} − p_{k−1}) / |…|`` (one-sided
    at the ends); where the path stands still (``|p_{k+1} − p_{k−1}| < 2·min_step``, one
    ``min_step`` at the ends) the last direction it moved in, and before it first moves
    the first — as a controller keeps the frame of the motion it is in.

    Parameters
    ----------
    positions : array_like, shape (n, 3)
        The path's positions, one a sample (m), ``n ≥ 2``.
    min_step : float
        The smallest motion a tangent is taken from (m).

    Returns
    -------
    ndarray, shape (n, 3)
        Unit tangents.

    Raises
    ------
    ValueError
        A path that never moves (no direction at all).
    """
    p = np.asarray(positions, dtype=float)
    if p.ndim != 2 or p.shape[1] != 3 or len(p) < 2:
        raise ValueError(f"a path's positions are (n ≥ 2, 3), got shape {p.shape}")
    g = np.gradient(p, axis=0)  # (p_{k+1} − p_{k−1}) / 2 inside, one-sided at the ends
    n = np.linalg.norm(g, axis=1)
    moving = n >= min_step
    if not moving.any():
        raise ValueError("the path never moves: no tangent, no path frame")
    idx = np.where(moving, np.arange(len(p)), -1)
    idx = np.maximum.accumulate(idx)  # the last moving sample at or before each
    idx[idx < 0] = int(np.flatnonzero(moving)[0])  # before the first: the first
    return g[idx] / n[idx, None]


class TangentTracker:
    """The tangent of a path seen one sample at a time, where something else may move the
    point too (a correction being applied): the chord from the point it was last taken
    at, ``t = (p − a)/|p − a|`` (then ``a ← p``), accepted when

    * ``|p − a| ≥ min_step`` — a motion, not rounding;
    * it took at most ``max_chord_s`` — a path moving (≥ ``min_step/max_chord_s``), not
      a standing one creeping (the second-order error of a correction taken off);
    * ``|p − a| ≥ ratio · (|e − e_a| + m(t) + m(t_a))`` — the chord is the path's, not
      the correction's change.  ``e`` is what was taken off ``p`` (the correction as the
      sender assumes it applied), and ``m(s) = max |e(s) − e(s')|`` over
      ``s' ∈ [s − lag_s, s]``: the controller may apply a correction up to ``lag_s``
      later than assumed, so that ``p`` is off by up to ``m`` at either end of the
      chord.  (Without ``m``, a controller catching up with a correction that has
      stopped changing — ``e − e_a = 0`` — moved a standing point by the catch-up, and
      that was taken for the path's tangent.)

    Two chords are tried each sample: a short one, dropped (``a ← p``) when it fails the
    ratio, so that a correction's step does not stay in the next chord, and a long one,
    kept until it is accepted or outlasts ``max_chord_s``, so that a slow path under a
    changing correction still gives chords long enough (either kind's error from the
    correction is at most ``1/ratio`` of its length).  An accepted chord, or one that
    outlasts ``max_chord_s``, starts the next.  ``None`` before the first accepted chord.

    Parameters
    ----------
    min_step : float
        The chord's least length (m).
    max_chord_s : float
        The longest a chord may take (s).
    ratio : float
        How much longer than the correction's change (and possible lag) a chord must be.
    lag_s : float
        The longest the controller may apply a correction later than assumed (s).
    """

    def __init__(self, min_step: float = 10 * MIN_STEP_M, max_chord_s: float = 0.1,
                 ratio: float = 4.0, lag_s: float = 0.05) -> None:
        self.min_step, self.max_chord_s, self.ratio = float(min_step), max_chord_s, ratio
        self.lag_s = float(lag_s)
        #: the short and the long chord's start: its point, time, what was taken off and
        #: ``m`` there
        self._anchor: tuple[Array, float, Array, float] | None = None
        self._long: tuple[Array, float, Array, float] | None = None
        #: what was taken off in the last ``lag_s``: ``(t, e)``, oldest first
        self._recent: deque[tuple[float, Array]] = deque()
        self.tangent: Array | None = None

    def _lag_bound(self, t: float, e: Array) -> float:
        """``m(t) = max |e(t) − e(s')|`` over the samples ``s' ∈ [t − lag_s, t]``."""
        recent = self._recent
        recent.append((t, e))
        while recent and recent[0][0] < t - self.lag_s:
            recent.popleft()
        return max(float(np.linalg.norm(e - e_s)) for _, e_s in recent)

    def update(self, p: ArrayLike, t: float, taken_off: ArrayLike = (0.0, 0.0, 0.0)
               ) -> Array | None:
        """Take the next position.

        Parameters
        ----------
        p : array_like, shape (3,)
            The path's position (m).
        t : float
            Its time (s).
        taken_off : array_like, shape (3,)
            What was taken off the point to give ``p`` (m).

        Returns
        -------
        ndarray, shape (3,), or None
            The tangent now (unit), ``None`` before the first.
        """
        p = np.array(p, dtype=float).reshape(3)
        e = np.array(taken_off, dtype=float).reshape(3)
        now = (p, float(t), e, self._lag_bound(float(t), e))
        if self._anchor is None or self._long is None:
            self._anchor = self._long = now
            return self.tangent
        short, long_ = self._chord(self._anchor, now), self._chord(self._long, now)
        for verdict, d in (short, long_):
            if verdict == "path":
                self.tangent = d / np.linalg.norm(d)
                self._anchor = self._long = now
                return self.tangent
        if short[0] != "short":  # failed the ratio, or too old: dropped
            self._anchor = now
        if long_[0] == "old":
            self._long = now
        return self.tangent

    def _chord(self, anchor: tuple[Array, float, Array, float],
               now: tuple[Array, float, Array, float]) -> tuple[str, Array]:
        """The chord from ``anchor`` to ``now`` and what it is: ``"path"`` (accepted),
        ``"old"`` (longer than ``max_chord_s``), ``"short"`` (under ``min_step``) or
        ``"correction"`` (failed the ratio)."""
        (a, t_a, e_a, m_a), (p, t, e, m) = anchor, now
        d = p - a
        n = float(np.linalg.norm(d))
        if t - t_a > self.max_chord_s:
            return "old", d
        if n < self.min_step:
            return "short", d
        if n >= self.ratio * (float(np.linalg.norm(e - e_a)) + m + m_a):
            return "path", d
        return "correction", d
        a, t_a, e_a, m_a = self._anchor
        d = p - a
        n = float(np.linalg.norm(d))
        if t - t_a > self.max_chord_s:
            self._anchor = (p, t, e, m)  # standing (or too slow to tell): start again
        elif n >= self.min_step:
            if n >= self.ratio * (float(np.linalg.norm(e - e_a)) + m + m_a):
                self.tangent = d / n
            self._anchor = (p, t, e, m)
        return self.tangent
        a, t_a, e_a = self._anchor
        d = p - a
        n = float(np.linalg.norm(d))
        if t - t_a > self.max_chord_s:
            self._anchor = (p, t, e)  # standing (or too slow to tell): start again
        elif n >= self.min_step:
            if n >= self.ratio * float(np.linalg.norm(e - e_a)):
                self.tangent = d / n
            self._anchor = (p, t, e)
        return self.tangent
