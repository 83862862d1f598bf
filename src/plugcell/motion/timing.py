"""A chain of time laws that may overlap: the timing of a section of moves.

Each move ``k`` of a section runs a double-S profile ``σ_k(τ)`` from 0 to 1 (a path
fraction, :mod:`plugcell.motion.profile`) starting at ``t0_k``.  Without a blend the
next move starts when this one ends, ``t0_{k+1} = t0_k + T_k``; a blend lets it start
``d_k`` earlier, ``t0_{k+1} = t0_k + T_k − d_k``, and the section's state is the
*superposition* of both moves (Biagiotti & Melchiorri §4.x "trajectory blending by
superposition"): each profile has zero velocity and acceleration at its ends, so the
sum is C² and passes from one move to the next without stopping.  Overlaps are
limited to ``d_k ≤ T_k/2`` and ``d_k ≤ T_{k+1}/2``, so at any time at most two moves
are active: the last one started (``k``) and its predecessor.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from plugcell.motion.profile import DoubleS, ProfileSample, double_s

Array = NDArray[np.float64]

__all__ = ["Timing"]


@dataclass(frozen=True)
class Timing:
    """The start times and profiles of a section's moves (arrays over moves, ``(K,)``).

    Attributes
    ----------
    start : (K,) array, s
        ``t0_k``, non-decreasing.
    h, t_j, t_a, t_v, j_max, t_j2, t_a2, j_max2 : (K,) arrays
        The :class:`~plugcell.motion.profile.DoubleS` fields of each profile
        (``h`` = 1, or 0 for a move that goes nowhere).
    """

    start: Array
    h: Array
    t_j: Array
    t_a: Array
    t_v: Array
    j_max: Array
    t_j2: Array
    t_a2: Array
    j_max2: Array

    @classmethod
    def chain(cls, profiles: list[DoubleS], overlaps: ArrayLike) -> Timing:
        """Profiles one after the other, move ``k+1`` starting ``overlaps[k]`` early.

        Parameters
        ----------
        profiles : list of DoubleS, length K
        overlaps : (K − 1,) array_like, s
            ``d_k`` (module docstring).

        Returns
        -------
        Timing
        """
        d = np.asarray(overlaps, dtype=float).reshape(-1)
        if d.size != max(len(profiles) - 1, 0):
            raise ValueError(f"{len(profiles)} profiles need {len(profiles) - 1} overlaps")
        start = np.zeros(len(profiles))
        for k in range(1, len(profiles)):
            start[k] = start[k - 1] + profiles[k - 1].duration - d[k - 1]
        return cls(start, *(np.array([getattr(p, f) for p in profiles], dtype=float)
                            for f in ("h", "t_j", "t_a", "t_v", "j_max", "t_j2", "t_a2",
                                      "j_max2")))

    @property
    def durations(self) -> Array:
        """``T_k = T_a1 + T_v + T_a2`` per move (s)."""
        return self.t_a + self.t_v + self.t_a2

    @property
    def end(self) -> float:
        """When the last move ends (s)."""
        return float(np.max(self.start + self.durations)) if self.start.size else 0.0

    def profile(self, k: int) -> DoubleS:
        """Move ``k``'s profile."""
        return DoubleS(*(float(getattr(self, f)[k]) for f in (
            "h", "t_j", "t_a", "t_v", "j_max", "t_j2", "t_a2", "j_max2")))

    def last_started(self, t: Array) -> NDArray[np.intp]:
        """Index of the last move started at each time (0 before the first)."""
        k = np.searchsorted(self.start, t, side="right") - 1
        return np.clip(k, 0, self.start.size - 1)

    def sample(self, t: Array, k: NDArray[np.intp]) -> ProfileSample:
        """Profile ``k[i]`` at time ``t[i]`` (section time, s)."""
        return double_s(t - self.start[k], self.h[k], self.t_j[k], self.t_a[k], self.t_v[k],
                        self.j_max[k], self.t_j2[k], self.t_a2[k], self.j_max2[k])

    def fraction(self, t: Array) -> tuple[NDArray[np.intp], Array]:
        """The last started move at each time and its path fraction ``σ ∈ [0, 1]``."""
        t = np.asarray(t, dtype=float)
        k = self.last_started(t)
        s = self.sample(t, k).s
        return k, np.where(self.h[k] > 0.0, s / np.where(self.h[k] > 0.0, self.h[k], 1.0), 1.0)
