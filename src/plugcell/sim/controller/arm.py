"""The simulated controller's arm: the language's :class:`Motion` on the digital twin.

What a real controller does with its arm (thesis 2.2.2), and only that:

* joint moves go to the servos — here :meth:`RobotTwin.move_joints`, whose true
  pose carries the twin's geometric errors, deflections and noise; a move takes
  the time of its largest joint travel at :data:`JOINT_SPEED_DEG_S` plus
  :data:`RAMP_S` for acceleration and deceleration (simulated seconds);
* Cartesian targets, ARM_POS and MOVE RELATIVE are the controller's nominal model,
  common to every arm (:class:`plugcell.devices.robot.arm_model.ControllerArm`).

After every move the true T-MAC pose in the tracker frame is handed to
``on_move(pose, duration_s)`` — the simulated controller publishes it to the
sim-only world (``plugcell.sim.world``); nothing else reads it.
Thread-safe: the program thread and the service's requests share one arm.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from plugcell.devices.robot.arm_model import (
    IK_TOL,
    ControllerArm,
    matrix_from_position,
    position_from_tcp,
)
from plugcell.motion import Trajectory
from plugcell.pdl.values import Position
from plugcell.sim.twin.robot import RobotTwin

__all__ = [
    "IK_TOL",
    "JOINT_SPEED_DEG_S",
    "RAMP_S",
    "TwinArm",
    "TwinDrive",
    "matrix_from_position",
    "position_from_tcp",
]

#: Joint speed of the simulated moves (the twin's measurement campaigns use 40°/s).
JOINT_SPEED_DEG_S = 40.0
#: Time added to every move for acceleration and deceleration (simulated seconds).
RAMP_S = 0.25

MoveListener = Callable[[np.ndarray, float], None]


class TwinArm(ControllerArm):
    """A :class:`~plugcell.pdl.interfaces.Motion` driving a RobotTwin."""

    def __init__(self, twin: RobotTwin, on_move: MoveListener | None = None) -> None:
        super().__init__(twin.description)
        self.twin = twin
        self.on_move = on_move
        self.moves = 0

    def joint_readings(self) -> np.ndarray:
        """The twin's joint readings (rad, encoder-quantised)."""
        return self.twin.joint_readings()

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


class TwinDrive:
    """A :class:`~plugcell.devices.robot.planned_motion.Drive` on the twin: what a
    program planned on the PC moves when it runs on the twin.

    The twin does not move in time yet (issue 37, section 2): following a trajectory
    puts it at the trajectory's end pose — with its geometric errors, deflections and
    noise, as :meth:`RobotTwin.move_joints` — and reports the true T-MAC pose to
    ``on_move(pose, duration_s)``.
    """

    def __init__(self, twin: RobotTwin, on_move: MoveListener | None = None) -> None:
        self.twin = twin
        self.on_move = on_move
        self.followed = 0

    def joint_readings(self) -> np.ndarray:
        """The twin's joint readings (rad, encoder-quantised)."""
        return self.twin.joint_readings()

    def follow(self, trajectory: Trajectory) -> None:
        """Put the twin at the trajectory's end."""
        q_end = trajectory.sample(trajectory.duration, 0).q
        self.twin.move_joints(q_end)
        self.followed += 1
        if self.on_move is not None:
            self.on_move(self.twin.true_reflector_in_tracker(), trajectory.duration)
