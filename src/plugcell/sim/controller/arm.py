"""The simulated controller's arm: the language's :class:`Motion` on the digital twin.

What a real controller does with its arm (thesis 2.2.2), and only that:

* joint moves go to the servos — here :meth:`RobotTwin.move_joints`, whose true
  pose carries the twin's geometric errors, deflections and noise; a move takes
  the time of its largest joint travel at :data:`JOINT_SPEED_DEG_S` plus
  :data:`RAMP_S` for acceleration and deceleration (simulated seconds);
* Cartesian targets (``MOVE TO``) go through the controller's *nominal* inverse
  kinematics, POS_TO_JNTP (:func:`plugcell.kinematics.inverse`, seeded with the
  current joints, inside the description's joint limits);
* ARM_POS is the nominal forward kinematics of the joint *readings* — what a
  real controller reports, not where the arm truly is.

Poses are PDL POSITIONs of the TCP in the robot base frame: millimetres and Comau
ZYZ degrees.  After every move the true T-MAC pose in the tracker frame is handed
to ``on_move(pose, duration_s)`` — the simulated controller publishes it to the
sim-only world (``plugcell.sim.world``); nothing else reads it.
Thread-safe: the program thread and the service's requests share one arm.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable, Sequence

import numpy as np

from plugcell.devices.robot.poses import pose_matrix, pose_values
from plugcell.kinematics import forward, inverse
from plugcell.kinematics.errors import KinematicsError
from plugcell.pdl.interfaces import MotionError
from plugcell.pdl.values import JointPos, Position
from plugcell.sim.twin.robot import RobotTwin

__all__ = [
    "JOINT_SPEED_DEG_S",
    "RAMP_S",
    "TwinArm",
    "matrix_from_position",
    "position_from_tcp",
]

#: Joint speed of the simulated moves (the twin's measurement campaigns use 40°/s).
JOINT_SPEED_DEG_S = 40.0
#: Time added to every move for acceleration and deceleration (simulated seconds).
RAMP_S = 0.25
#: Convergence tolerance of POS_TO_JNTP (m and rad).
IK_TOL = 1e-9

MoveListener = Callable[[np.ndarray, float], None]


def matrix_from_position(pose: Position) -> np.ndarray:
    """A POSITION (mm, ZYZ degrees) → 4×4 homogeneous transform in metres."""
    try:
        return pose_matrix(pose.as_tuple())
    except ValueError as exc:
        raise MotionError(str(exc)) from None


def position_from_tcp(T: np.ndarray) -> Position:
    """4×4 homogeneous transform in metres → POSITION (mm, ZYZ degrees)."""
    return Position(*pose_values(T))


class TwinArm:
    """A :class:`~plugcell.pdl.interfaces.Motion` driving a RobotTwin."""

    def __init__(self, twin: RobotTwin, on_move: MoveListener | None = None) -> None:
        self.twin = twin
        self.description = twin.description
        self.on_move = on_move
        self._lock = threading.RLock()
        self.moves = 0

    # ------------------------------------------------------------------ kinematics
    @property
    def axes(self) -> int:
        return int(self.description.n_readings)

    def _joints_rad(self, joints: Sequence[float]) -> np.ndarray:
        q = np.radians(np.asarray([float(v) for v in joints], dtype=float))
        if q.shape != (self.axes,):
            raise MotionError(f"{self.description.name} has {self.axes} axes, got {q.size} angles")
        if not np.all(np.isfinite(q)):
            raise MotionError("joint angles must be finite")
        return q

    def _check_limits(self, q: np.ndarray) -> None:
        problems = self.description.limit_violations(q, tol=1e-9)
        if problems:
            raise MotionError("outside the joint limits: " + "; ".join(problems))

    def jntp_to_pos(self, joints: JointPos) -> Position:
        """JNTP_TO_POS: nominal forward kinematics of ``joints`` (degrees)."""
        q = self._joints_rad(joints.joints)
        return position_from_tcp(forward(self.description, None, q, closure="nominal").tcp)

    def pos_to_jntp(self, pose: Position) -> JointPos:
        """POS_TO_JNTP: nominal inverse kinematics, the solution nearest the current joints."""
        T = matrix_from_position(pose)
        with self._lock:
            seed = self.twin.joint_readings()
        try:
            result = inverse(self.description, None, T, seed=seed, target="tcp",
                             closure="nominal", tol=IK_TOL)
        except KinematicsError as exc:
            raise MotionError(f"POS_TO_JNTP{_short(pose)}: {exc}") from None
        return JointPos(tuple(float(v) for v in np.degrees(result.q)))

    def arm_jntp(self) -> JointPos:
        """ARM_JNTP: the joint readings (encoder counts), degrees."""
        with self._lock:
            q = self.twin.joint_readings()
        return JointPos(tuple(float(v) for v in np.degrees(q)))

    def arm_pos(self) -> Position:
        """ARM_POS: nominal forward kinematics of the readings."""
        return self.jntp_to_pos(self.arm_jntp())

    # ------------------------------------------------------------------ moves
    def move_joints(self, q_deg: Sequence[float]) -> float:
        """Joint move; returns its simulated duration (s)."""
        q = self._joints_rad(q_deg)
        self._check_limits(q)
        with self._lock:
            start = self.twin.joint_readings()
            self.twin.move_joints(q)
            travel = float(np.max(np.abs(np.degrees(q - start)))) if q.size else 0.0
            duration = travel / JOINT_SPEED_DEG_S + (RAMP_S if travel > 0 else 0.0)
            self.moves += 1
            pose = self.twin.true_reflector_in_tracker()
        if self.on_move is not None:
            self.on_move(pose, duration)
        return duration

    def move_to(self, pose: Position, linear: bool = False) -> float:
        """MOVE TO / MOVE LINEAR TO: POS_TO_JNTP, then a joint move.

        Only the end pose matters to the twin, so a linear move takes the joint
        move's path and time (the simulation does not interpolate paths).
        """
        return self.move_joints(self.pos_to_jntp(pose).joints)

    def move_relative(self, offset_mm: Sequence[float], frame: str) -> float:
        """MOVE RELATIVE: translate the TCP in the BASE or TOOL frame."""
        offset = np.asarray([float(v) for v in offset_mm], dtype=float) / 1000.0
        if offset.shape != (3,) or not np.all(np.isfinite(offset)):
            raise MotionError(f"MOVE RELATIVE needs 3 finite offsets, got {offset_mm!r}")
        T = matrix_from_position(self.arm_pos())
        if frame.upper() == "TOOL":
            T[:3, 3] += T[:3, :3] @ offset
        elif frame.upper() == "BASE":
            T[:3, 3] += offset
        else:
            raise MotionError(f"unknown frame {frame!r} (BASE or TOOL)")
        return self.move_to(position_from_tcp(T))


def _short(pose: Position) -> str:
    vals = ", ".join(f"{v:g}" for v in pose.as_tuple())
    return f"({vals})" if all(math.isfinite(v) for v in pose.as_tuple()) else ""
