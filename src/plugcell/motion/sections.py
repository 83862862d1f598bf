"""Sections of a trajectory: a chain of PTP moves, or a chain of LIN/CIRC moves.

Moves of one kind that follow each other form a section and may blend; a section ends
with the robot at rest, so sections simply follow each other in time.  Both kinds
answer the same questions at section times ``t`` (B,): the joint readings and their
rates, the TCP pose, and which move runs with what path fraction.

* :class:`JointSection` — :class:`~plugcell.motion.joint_path.JointPath`; the TCP by
  forward kinematics.
* :class:`CartesianSection` — :class:`~plugcell.motion.cartesian_path.CartesianPath`;
  the joints by inverse kinematics at every sample, seeded from the table of joint
  solutions the planner computed along the path (``times``, ``q_table``, one solution
  every few milliseconds, each tracked from the previous, so on one branch): the seed
  is the table interpolated linearly at ``t``, then
  :func:`~plugcell.motion.tracking.track` converges to the exact solution on the same
  branch, whatever order the times are sampled in.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from plugcell.kinematics.description import RobotDescription
from plugcell.kinematics.forward import forward
from plugcell.kinematics.parameters import GeometricParameters
from plugcell.motion.cartesian_path import CartesianPath, CartesianState
from plugcell.motion.joint_path import JointPath
from plugcell.motion.tracking import joint_rates, track

Array = NDArray[np.float64]

__all__ = ["CartesianSection", "JointSection", "Section"]


@dataclass(frozen=True)
class _Robot:
    desc: RobotDescription
    params: GeometricParameters
    closure: str


@dataclass(frozen=True)
class JointSection:
    """PTP moves along a joint path.

    Attributes
    ----------
    robot : _Robot
        Description, parameters and closure (for the TCP by forward kinematics).
    path : JointPath
    moves : tuple of int
        The moves' indices in the planner's list.
    """

    robot: _Robot
    path: JointPath
    moves: tuple[int, ...]

    @property
    def duration(self) -> float:
        return self.path.duration

    def joints(self, t: Array, order: int = 2) -> tuple[Array, Array | None, Array | None]:
        """Readings (B, n) and, up to ``order``, velocities and accelerations."""
        q, qd, qdd, _ = self.path.sample(t)
        return q, qd if order >= 1 else None, qdd if order >= 2 else None

    def tcp(self, t: Array) -> Array:
        """TCP poses (B, 4, 4), m, by forward kinematics of the readings."""
        q = self.path.sample(t)[0]
        r = self.robot
        return forward(r.desc, r.params, q, r.closure).tcp

    def locate(self, t: Array) -> tuple[NDArray[np.intp], Array]:
        """Move index (planner's list) and path fraction at each time."""
        k, frac = self.path.timing.fraction(t)
        return np.asarray(self.moves)[k], frac


@dataclass(frozen=True)
class CartesianSection:
    """LIN/CIRC moves ``moves`` along ``path``, mapped to joints by IK (module docstring).

    Attributes
    ----------
    robot : _Robot
        Description, parameters and closure of the inverse kinematics.
    path : CartesianPath
    moves : tuple of int
        The moves' indices in the planner's list.
    times : (N,) array, s
        Section times of the joint table, increasing, from 0 to the duration.
    q_table : (N, n) array, rad
        Joint solutions at ``times``, all on the start's branch.
    qd_table : (N, n) array, rad/s
        Their rates ``J⁺·[v; ω]``.
    """

    robot: _Robot
    path: CartesianPath
    moves: tuple[int, ...]
    times: Array
    q_table: Array
    qd_table: Array

    @property
    def duration(self) -> float:
        return self.path.duration

    def state(self, t: Array) -> CartesianState:
        """The TCP's pose and rates at section times ``t``."""
        return self.path.sample(t)

    def tcp(self, t: Array) -> Array:
        """TCP poses (B, 4, 4), m."""
        return self.path.sample(t).T

    def seed(self, t: Array) -> Array:
        """The joint table's cubic Hermite interpolation at ``t`` (B, n).

        On ``[t_i, t_i + h]`` with ``x = (t − t_i)/h``:
        ``q = h₀₀ q_i + h₁₀ h q̇_i + h₀₁ q_{i+1} + h₁₁ h q̇_{i+1}``, ``h₀₀ = 2x³ − 3x² + 1``,
        ``h₁₀ = x³ − 2x² + x``, ``h₀₁ = −2x³ + 3x²``, ``h₁₁ = x³ − x²``.
        """
        t = np.clip(np.asarray(t, dtype=float).reshape(-1), self.times[0], self.times[-1])
        if self.times.size == 1:
            return np.tile(self.q_table[0], (t.size, 1))
        i = np.clip(np.searchsorted(self.times, t, side="right") - 1, 0, self.times.size - 2)
        t0, t1 = self.times[i], self.times[i + 1]
        h = np.where(t1 > t0, t1 - t0, 1.0)[:, None]
        x = (t - t0)[:, None] / h
        x2, x3 = x * x, x * x * x
        return ((2 * x3 - 3 * x2 + 1) * self.q_table[i] + (x3 - 2 * x2 + x) * h * self.qd_table[i]
                + (3 * x2 - 2 * x3) * self.q_table[i + 1] + (x3 - x2) * h * self.qd_table[i + 1])

    def joints(self, t: Array, order: int = 2) -> tuple[Array, Array | None, Array | None]:
        """Readings by IK at each time (B, n); velocities and accelerations by the
        Jacobian (:func:`~plugcell.motion.tracking.joint_rates`) up to ``order``.

        Raises
        ------
        RuntimeError
            The tracking does not converge at some sample — impossible on a path the
            planner checked (the table holds a solution every few milliseconds).
        """
        t = np.asarray(t, dtype=float).reshape(-1)
        st = self.path.sample(t)
        r = self.robot
        q, ok = track(r.desc, r.params, st.T, self.seed(t), r.closure)
        if not np.all(ok):
            bad = float(t[np.flatnonzero(~ok)[0]])
            raise RuntimeError(f"inverse kinematics did not converge at section time {bad} s")
        if order <= 0:
            return q, None, None
        twist = np.concatenate([st.v, st.omega], axis=-1)
        rate = np.concatenate([st.a, st.alpha], axis=-1) if order >= 2 else None
        qd, qdd, _ = joint_rates(r.desc, r.params, q, twist, rate, r.closure)
        return q, qd, qdd

    def locate(self, t: Array) -> tuple[NDArray[np.intp], Array]:
        """Move index (planner's list) and path fraction at each time."""
        k, frac = self.path.timing.fraction(t)
        return np.asarray(self.moves)[k], frac


Section = JointSection | CartesianSection
