"""The controller's side of an arm: its nominal kinematics and the language's moves.

What every controller does with its arm, whatever moves it — the twin
(:class:`plugcell.sim.controller.arm.TwinArm`) or a real robot driven from the PC
(:class:`plugcell.devices.robot.planned_motion.PlannedMotion`):

* Cartesian targets go through the controller's *nominal* inverse kinematics,
  POS_TO_JNTP (:func:`plugcell.kinematics.inverse`, seeded with the current joints,
  inside the description's joint limits);
* ARM_POS is the nominal forward kinematics of the joint *readings* — what a real
  controller reports, not where the arm truly is;
* MOVE RELATIVE translates the TCP in the BASE or TOOL frame.

Poses are PDL POSITIONs of the TCP in the robot base frame: millimetres and Comau ZYZ
degrees.  A subclass says where the readings come from (:meth:`joint_readings`) and
how the arm moves (``move_joints``, ``move_to``).  Thread-safe: the program thread and
the service's requests share one arm.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Sequence

import numpy as np

from plugcell.devices.robot.poses import pose_matrix, pose_values
from plugcell.kinematics import RobotDescription, forward, inverse
from plugcell.kinematics.errors import KinematicsError
from plugcell.pdl.interfaces import MotionError
from plugcell.pdl.values import JointPos, Position

__all__ = ["IK_TOL", "ControllerArm", "matrix_from_position", "position_from_tcp"]

#: Convergence tolerance of POS_TO_JNTP (m and rad).
IK_TOL = 1e-9


def matrix_from_position(pose: Position) -> np.ndarray:
    """A POSITION (mm, ZYZ degrees) → 4×4 homogeneous transform in metres."""
    try:
        return pose_matrix(pose.as_tuple())
    except ValueError as exc:
        raise MotionError(str(exc)) from None


def position_from_tcp(T: np.ndarray) -> Position:
    """4×4 homogeneous transform in metres → POSITION (mm, ZYZ degrees)."""
    return Position(*pose_values(T))


class ControllerArm:
    """The kinematic half of a :class:`~plugcell.pdl.interfaces.Motion` (module docstring).

    Subclasses implement :meth:`joint_readings`, ``move_joints`` and ``move_to``.
    """

    def __init__(self, description: RobotDescription) -> None:
        self.description = description
        self._lock = threading.RLock()

    def joint_readings(self) -> np.ndarray:
        """The arm's joint readings (rad), as its encoders report them."""
        raise NotImplementedError

    def move_to(self, pose: Position, linear: bool = False) -> float | None:
        """Move to a Cartesian pose (joint-interpolated, or straight if ``linear``)."""
        raise NotImplementedError

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
            seed = self.joint_readings()
        try:
            result = inverse(self.description, None, T, seed=seed, target="tcp",
                             closure="nominal", tol=IK_TOL)
        except KinematicsError as exc:
            raise MotionError(f"POS_TO_JNTP{_short(pose)}: {exc}") from None
        return JointPos(tuple(float(v) for v in np.degrees(result.q)))

    def arm_jntp(self) -> JointPos:
        """ARM_JNTP: the joint readings (encoder counts), degrees."""
        with self._lock:
            q = self.joint_readings()
        return JointPos(tuple(float(v) for v in np.degrees(q)))

    def arm_pos(self) -> Position:
        """ARM_POS: nominal forward kinematics of the readings."""
        return self.jntp_to_pos(self.arm_jntp())

    def move_relative(self, offset_mm: Sequence[float], frame: str) -> float | None:
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
