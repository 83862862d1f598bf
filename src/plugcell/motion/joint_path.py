"""Joint (PTP) moves: straight lines in joint space with synchronised axes.

A PTP move from ``q_s`` to ``q_e`` is ``q(t) = q_s + Δq·σ(t)``, ``Δq = q_e − q_s``, with
one double-S time law ``σ`` (0 → 1) for all joints, so every joint starts and ends
together and the joints' velocities stay proportional (the path is a straight line in
joint space, as KUKA's and Comau's synchronised PTP).  ``σ``'s limits are the tightest
of the joints' (``|Δq_j|·σ̇ ≤ v_j`` etc.)::

    v_σ = min_j v_j/|Δq_j|,   a_σ = min_j a_j/|Δq_j|,   j_σ = min_j jerk_j/|Δq_j|

which makes the move the fastest synchronised one within every joint's limits, the
leading joint at its limit.  A chain of PTP moves is the superposition of the moves'
displacements (:mod:`plugcell.motion.timing`): with ``k`` the last move started,

    q(t) = q_start,k + Δq_k·σ_k + Δq_{k−1}·(σ_{k−1} − 1)

and the velocity, acceleration and jerk are the same sums of ``Δq·σ̇``, ``Δq·σ̈``,
``Δq·σ⃛``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from plugcell.motion.limits import JointLimits
from plugcell.motion.profile import DoubleS
from plugcell.motion.timing import Timing

Array = NDArray[np.float64]

__all__ = ["JointPath", "ptp_profile"]


def ptp_profile(dq: Array, limits: JointLimits, soft_start: bool = False,
                soft_end: bool = False) -> DoubleS:
    """The synchronised time law ``σ`` of a PTP move by ``dq`` (module docstring).

    Parameters
    ----------
    dq : (n,) array, rad
        ``Δq = q_e − q_s``.
    limits : JointLimits
        With the move's overrides applied.
    soft_start, soft_end : bool
        Halve the acceleration and jerk limits of the acceleration (deceleration)
        phase — the phase a blend overlaps with the neighbouring move.

    Returns
    -------
    DoubleS
        Over ``h = 1`` (``h = 0``, duration 0, for ``Δq = 0``).
    """
    m = np.abs(dq)
    if not np.any(m > 0.0):
        return DoubleS.plan(0.0, 1.0, 1.0, 1.0)
    moving = m > 0.0
    v = float(np.min(limits.velocity[moving] / m[moving]))
    a = float(np.min(limits.acceleration[moving] / m[moving]))
    j = float(np.min(limits.jerk[moving] / m[moving]))
    f1, f2 = (0.5 if soft_start else 1.0), (0.5 if soft_end else 1.0)
    return DoubleS.plan(1.0, v, a * f1, j * f1, a * f2, j * f2)


@dataclass(frozen=True)
class JointPath:
    """A chain of PTP moves (module docstring).

    Attributes
    ----------
    q0 : (n,) array, rad
        Start readings.
    ends : (K, n) array, rad
        Each move's target.
    timing : Timing
        Start times and time laws.
    """

    q0: Array
    ends: Array
    timing: Timing

    @property
    def deltas(self) -> Array:
        """``Δq_k`` (K, n)."""
        return np.diff(np.vstack([self.q0, self.ends]), axis=0)

    @property
    def duration(self) -> float:
        """Section duration (s)."""
        return self.timing.end

    def sample(self, t: Array) -> tuple[Array, Array, Array, Array]:
        """Readings and their first three derivatives at section times ``t`` (B,).

        Returns
        -------
        q, qd, qdd, qddd : (B, n) arrays
            rad, rad/s, rad/s², rad/s³.
        """
        t = np.asarray(t, dtype=float).reshape(-1)
        k = self.timing.last_started(t)
        d = self.deltas
        ps = self.timing.sample(t, k)
        starts = np.vstack([self.q0, self.ends[:-1]])
        done = (ps.s >= self.timing.h[k])[:, None]
        q = np.where(done, self.ends[k], starts[k] + d[k] * ps.s[:, None])
        qd, qdd, qddd = (d[k] * x[:, None] for x in (ps.v, ps.a, ps.j))
        prev = k >= 1
        if np.any(prev):
            kp = np.maximum(k - 1, 0)
            pp = self.timing.sample(t, kp)
            w = prev.astype(float)[:, None]
            q = q + w * d[kp] * (pp.s - self.timing.h[kp])[:, None]
            qd = qd + w * d[kp] * pp.v[:, None]
            qdd = qdd + w * d[kp] * pp.a[:, None]
            qddd = qddd + w * d[kp] * pp.j[:, None]
        return q, qd, qdd, qddd
