"""A planned trajectory: sections one after the other, sampled at any time or cycle.

:func:`plugcell.motion.plan` builds it; :meth:`Trajectory.sample` gives the joint
readings (and their rates) at any times — a vector of times at once — and
:meth:`Trajectory.at_cycle` the setpoint of interpolation cycle ``k`` (``t = k·Δt``),
which is what a real-time link (KUKA RSI every 4 ms, ABB EGM) streams.  Before 0 the
trajectory rests at its start, after its duration at its end.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from plugcell.motion.moves import Move
from plugcell.motion.sections import CartesianSection, Section

Array = NDArray[np.float64]

__all__ = ["JointSample", "Trajectory"]


@dataclass(frozen=True)
class JointSample:
    """Joint setpoints at sampled times (leading shape that of the times).

    Attributes
    ----------
    t : (...) array, s
    q : (..., n) array, rad
    qd, qdd : (..., n) arrays or None, rad/s, rad/s²
        Present up to the requested order.
    move : (...) int array
        Index of the move running (the last one started, in a blend).
    fraction : (...) array
        That move's path fraction in [0, 1].
    """

    t: Array
    q: Array
    qd: Array | None
    qdd: Array | None
    move: NDArray[np.intp]
    fraction: Array


@dataclass(frozen=True)
class Trajectory:
    """Sections of moves that follow each other (module docstring).

    Attributes
    ----------
    sections : tuple of Section
    starts : (S,) array, s
        Trajectory time at which each section starts.
    moves : tuple of Move
        The planned moves, as given.
    q_start : (n,) array, rad
    """

    sections: tuple[Section, ...]
    starts: Array
    moves: tuple[Move, ...]
    q_start: Array

    @property
    def duration(self) -> float:
        """Total time (s)."""
        if not self.sections:
            return 0.0
        return float(self.starts[-1] + self.sections[-1].duration)

    def _split(self, t: Array) -> tuple[Array, NDArray[np.intp], Array]:
        t = np.asarray(t, dtype=float)
        flat = np.clip(t.reshape(-1), 0.0, self.duration)
        if not self.sections:
            return t, np.zeros(flat.size, dtype=np.intp), flat
        i = np.clip(np.searchsorted(self.starts, flat, side="right") - 1, 0,
                    len(self.sections) - 1)
        return t, i, flat - self.starts[i]

    def sample(self, t: ArrayLike, order: int = 2) -> JointSample:
        """Joint readings at times ``t`` (s, any shape), with rates up to ``order``.

        Parameters
        ----------
        t : array_like, s
        order : {0, 1, 2}
            0: positions only; 1: and velocities; 2: and accelerations.

        Returns
        -------
        JointSample
        """
        t, sec, local = self._split(t)
        n = self.q_start.size
        B = local.size
        q = np.tile(self.q_start, (B, 1))
        qd = np.zeros((B, n)) if order >= 1 else None
        qdd = np.zeros((B, n)) if order >= 2 else None
        move = np.zeros(B, dtype=np.intp)
        frac = np.zeros(B)
        for s in np.unique(sec) if self.sections else np.array([], dtype=np.intp):
            rows = np.flatnonzero(sec == s)
            section = self.sections[s]
            a, b, c = section.joints(local[rows], order)
            q[rows] = a
            if qd is not None and b is not None:
                qd[rows] = b
            if qdd is not None and c is not None:
                qdd[rows] = c
            move[rows], frac[rows] = section.locate(local[rows])
        shape = t.shape
        return JointSample(
            t, q.reshape(*shape, n), None if qd is None else qd.reshape(*shape, n),
            None if qdd is None else qdd.reshape(*shape, n), move.reshape(shape),
            frac.reshape(shape))

    def tcp(self, t: ArrayLike) -> Array:
        """TCP poses at times ``t`` (..., 4, 4), m, robot base frame.

        Raises
        ------
        ValueError
            The trajectory has no moves (the poses need a section's robot model).
        """
        if not self.sections:
            raise ValueError("a trajectory without moves has no TCP path; plan a move")
        t, sec, local = self._split(t)
        out = np.zeros((local.size, 4, 4))
        for s in np.unique(sec):
            rows = np.flatnonzero(sec == s)
            out[rows] = self.sections[s].tcp(local[rows])
        return out.reshape(*t.shape, 4, 4)

    def cycle_times(self, dt: float) -> Array:
        """``k·Δt`` for every cycle from 0 until the trajectory has ended (s)."""
        if not dt > 0.0:
            raise ValueError(f"cycle time must be positive, got {dt}")
        return np.arange(int(np.ceil(self.duration / dt - 1e-9)) + 1) * dt

    def setpoints(self, dt: float) -> tuple[Array, Array]:
        """Every cycle's joint setpoint at once: ``(cycle_times(dt), q)``, q (K, n) rad.

        One vectorised call — far cheaper per cycle than :meth:`at_cycle` in a loop —
        for a real-time link to compute before the move starts and then send one row
        per cycle.

        Parameters
        ----------
        dt : float, s
            The interpolation cycle.

        Returns
        -------
        t : (K,) array, s
        q : (K, n) array, rad
        """
        t = self.cycle_times(dt)
        return t, self.sample(t, 0).q

    def at_cycle(self, k: int, dt: float, order: int = 0) -> JointSample:
        """The setpoint of interpolation cycle ``k``: :meth:`sample` at ``t = k·Δt``."""
        return self.sample(np.array([k * dt]), order)

    @property
    def blends(self) -> dict[int, float]:
        """Overlap (s) each move with a blend radius got with its successor; 0.0 where no
        overlap keeps the limits and the move stops exactly at its target."""
        out: dict[int, float] = {}
        for sec in self.sections:
            tm = sec.path.timing
            for i, k in enumerate(sec.moves[:-1]):
                if self.moves[k].blend > 0.0:
                    out[k] = float(tm.start[i] + tm.durations[i] - tm.start[i + 1])
        for k, m in enumerate(self.moves):
            if m.blend > 0.0:
                out.setdefault(k, 0.0)
        return out

    @property
    def cartesian(self) -> bool:
        """Whether any section is Cartesian (sampling then runs inverse kinematics)."""
        return any(isinstance(s, CartesianSection) for s in self.sections)
