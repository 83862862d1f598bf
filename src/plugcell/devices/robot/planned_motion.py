"""The language's :class:`~plugcell.pdl.interfaces.Motion` for a robot moved from the PC.

Every move of a program is planned on the PC as a trajectory (:mod:`plugcell.motion`):
``MOVE TO``/``MOVE JOINT TO`` a synchronised, jerk-limited PTP; ``MOVE LINEAR TO`` a
straight line of the TCP through the controller's nominal inverse kinematics; ``MOVE
RELATIVE`` as ``MOVE TO`` of the shifted pose (as :class:`ControllerArm`).  Each is
checked before motion — joint limits, joint speeds, singularities, reachability — and a
failed check is a :class:`~plugcell.pdl.interfaces.MotionError` whose message says why
(the interpreter adds the program line).  The planned trajectory goes to a
:class:`Drive`: what streams it to the robot — a real-time link (KUKA RSI, ABB EGM,
sampled every 4 ms) or the twin (:class:`plugcell.sim.controller.arm.TwinDrive`) — so
the same program runs unchanged on a real robot and on the twin.  A move lasts the
trajectory's duration.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol, runtime_checkable

import numpy as np

from plugcell.devices.robot.arm_model import ControllerArm, matrix_from_position
from plugcell.kinematics import RobotDescription
from plugcell.motion import (
    LIN,
    PTP,
    CartesianLimits,
    JointLimits,
    Move,
    Trajectory,
    TrajectoryError,
    plan,
)
from plugcell.pdl.interfaces import MotionError
from plugcell.pdl.values import Position

__all__ = ["Drive", "PlannedMotion"]


@runtime_checkable
class Drive(Protocol):
    """What executes a planned trajectory on an arm."""

    def joint_readings(self) -> np.ndarray:
        """The arm's joint readings now (rad)."""
        ...

    def follow(self, trajectory: Trajectory) -> None:
        """Run ``trajectory`` from its start to its end; raise if the arm cannot."""
        ...


class PlannedMotion(ControllerArm):
    """Program moves as planned, checked trajectories handed to a :class:`Drive`.

    Parameters
    ----------
    description : RobotDescription
        The robot (the controller's nominal model).
    drive : Drive
        What executes the trajectories.
    joint_limits : JointLimits
        Joint speed, acceleration and jerk limits (rad/s, rad/s², rad/s³).
    cartesian_limits : CartesianLimits
        TCP limits of linear moves (m/s…, rad/s…).
    speed : float
        Override in (0, 1] of every move's speed (as ``$GEN_OVR``).
    """

    def __init__(self, description: RobotDescription, drive: Drive, joint_limits: JointLimits,
                 cartesian_limits: CartesianLimits, speed: float = 1.0) -> None:
        super().__init__(description)
        self.drive = drive
        self.joint_limits = joint_limits
        self.cartesian_limits = cartesian_limits
        self.speed = speed
        self.last: Trajectory | None = None

    def joint_readings(self) -> np.ndarray:
        """The drive's joint readings (rad)."""
        return np.asarray(self.drive.joint_readings(), dtype=float)

    def plan_move(self, move: Move) -> Trajectory:
        """``move`` planned and checked from the joint readings now (MotionError: why not)."""
        q0 = self.joint_readings()
        try:
            return plan(self.description, q0, [move], self.joint_limits, self.cartesian_limits)
        except TrajectoryError as exc:  # the program line is the interpreter's to add
            where = (f" at {100.0 * exc.fraction:.1f} % of the {move.kind}"
                     if exc.fraction is not None and 0.0 < exc.fraction < 1.0 else "")
            raise MotionError(f"{move.kind}{where}: {exc.reason}") from None

    def _run(self, move: Move) -> float:
        with self._lock:
            traj = self.plan_move(move)
            self.drive.follow(traj)
            self.last = traj
            return traj.duration

    def move_joints(self, q_deg: Sequence[float]) -> float:
        """Joint move (PTP); returns its duration (s)."""
        q = self._joints_rad(q_deg)
        self._check_limits(q)
        return self._run(PTP(target=q, speed=self.speed))

    def move_to(self, pose: Position, linear: bool = False) -> float:
        """MOVE TO (POS_TO_JNTP, then a PTP) or MOVE LINEAR TO (a LIN of the TCP)."""
        if linear:
            return self._run(LIN(target=matrix_from_position(pose), speed=self.speed))
        return self.move_joints(self.pos_to_jntp(pose).joints)
