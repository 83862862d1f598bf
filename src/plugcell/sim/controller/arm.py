"""The simulated controller's arm: the language's :class:`Motion` on the digital twin.

What a real controller does with its arm (thesis 2.2.2), and only that:

* joint moves go to the servos — here :meth:`RobotTwin.move_joints`, whose true
  pose carries the twin's geometric errors, deflections and noise; a move takes
  the time of its largest joint travel at :data:`JOINT_SPEED_DEG_S` plus
  :data:`RAMP_S` for acceleration and deceleration (simulated seconds);
* Cartesian targets, ARM_POS and MOVE RELATIVE are the controller's nominal model,
  common to every arm (:class:`plugcell.devices.robot.arm_model.ControllerArm`).

That arm teleports: the twin is at the target at once and the move's time only passes on
the clock.  :class:`DynamicArm` is the arm that moves in time (``--dynamics`` of the
simulated controller): every move planned and checked as on a PC
(:class:`~plugcell.devices.robot.planned_motion.PlannedMotion`, :mod:`plugcell.motion`),
then followed by the dynamic twin (:class:`~plugcell.sim.twin.dynamics.DynamicTwin`)
cycle by cycle (:class:`DynamicDrive`), paced by the clock's speed, up to an exact stop.

After every move the true T-MAC pose in the tracker frame is handed to
``on_move(pose, duration_s)`` — the simulated controller publishes it to the
sim-only world (``plugcell.sim.world``); nothing else reads it.
Thread-safe: the program thread and the service's requests share one arm.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Sequence

import numpy as np

from plugcell.devices.robot.arm_model import (
    IK_TOL,
    ControllerArm,
    matrix_from_position,
    position_from_tcp,
)
from plugcell.devices.robot.planned_motion import PlannedMotion
from plugcell.motion import CartesianLimits, JointLimits, Move, Trajectory
from plugcell.pdl import MotionError, SimClock
from plugcell.pdl.values import JointPos, Position
from plugcell.sim.twin.dynamics import DynamicTwin
from plugcell.sim.twin.robot import RobotTwin

__all__ = [
    "IK_TOL",
    "JOINT_SPEED_DEG_S",
    "RAMP_S",
    "DynamicArm",
    "DynamicDrive",
    "TwinArm",
    "TwinDrive",
    "matrix_from_position",
    "position_from_tcp",
]

#: Joint speed of the simulated moves (the twin's measurement campaigns use 40°/s).
JOINT_SPEED_DEG_S = 40.0
#: Time added to every move for acceleration and deceleration (simulated seconds).
RAMP_S = 0.25
#: The dynamic arm's exact stop: every joint reading within this of the target (rad) …
IN_POSITION_RAD = math.radians(0.001)
#: … waited for at most this long after the trajectory's end (simulated seconds).
SETTLE_MAX_S = 1.0
#: The clock's lag behind the wall clock below which the dynamic arm does not sleep (s).
PACING_SLACK_S = 0.002

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


class DynamicDrive:
    """A :class:`~plugcell.devices.robot.planned_motion.Drive` that moves the dynamic twin
    in time: the trajectory's setpoints, one a cycle ``T``, into :meth:`DynamicTwin.step`,
    then the end held until the exact stop — every reading within
    :data:`IN_POSITION_RAD` of the target, at most :data:`SETTLE_MAX_S` — as a
    controller's fine interpolator and servos do.  Cycle ``k`` is not computed before
    ``k·T/speed`` real seconds from the move's start (the clock's speed; never sleeping
    at speed inf): others see the arm move at the simulation's pace.

    :meth:`halt` stops a move at its next cycle: the command freezes where it is (the
    servos stop the arm) and :meth:`follow` raises MotionError.
    """

    def __init__(self, arm: DynamicTwin, clock: SimClock) -> None:
        self.arm = arm
        self.clock = clock
        self.followed = 0
        self.last_duration = 0.0
        self._halt = threading.Event()

    def joint_readings(self) -> np.ndarray:
        """The twin's joint readings now (rad, encoder counts), also while it moves."""
        return self.arm.measured

    def halt(self) -> None:
        """Stop the running move (from any thread)."""
        self._halt.set()

    def follow(self, trajectory: Trajectory) -> None:
        """Run the trajectory and the exact stop; ``last_duration`` is their simulated time.

        Raises
        ------
        MotionError
            :meth:`halt` was called during the move.
        """
        self._halt.clear()
        T = self.arm.params.cycle
        _, q = trajectory.setpoints(T)
        settle = round(SETTLE_MAX_S / T)
        speed = self.clock.speed
        start = time.monotonic()
        k, target = 0, q[0]
        for k in range(1, len(q) + settle):
            if self._halt.is_set():
                self.arm.step(target)  # the command freezes where it is: the servos stop
                self.last_duration = k * T
                raise MotionError("the move was stopped")
            target = q[min(k, len(q) - 1)]
            self.arm.step(target)
            if k >= len(q) + self.arm.params.dead_time_cycles and \
                    float(np.max(np.abs(self.arm.measured - target))) <= IN_POSITION_RAD:
                break
            if math.isfinite(speed):
                ahead = start + k * T / speed - time.monotonic()
                if ahead > PACING_SLACK_S:
                    self._halt.wait(ahead)
        self.last_duration = k * T
        self.followed += 1


class DynamicArm(PlannedMotion):
    """The simulated controller's arm that moves in time (module docstring).

    Moves are planned with the joint speed ``joint_speed_deg_s`` (acceleration 3×, jerk
    30× it per second, as the RSI robot service plans) and ``tcp_speed_mm_s`` for linear
    moves; each lasts its trajectory plus the exact stop, and advances ``clock`` by that
    itself (the interpreter is told ``None``: it must not wait a second time).
    ARM_JNTP reads the moving arm.
    """

    def __init__(self, arm: DynamicTwin, clock: SimClock,
                 joint_speed_deg_s: float = JOINT_SPEED_DEG_S,
                 tcp_speed_mm_s: float = 250.0) -> None:
        n = arm.twin.description.n_readings
        v, s = math.radians(joint_speed_deg_s), tcp_speed_mm_s / 1000.0
        super().__init__(arm.twin.description, DynamicDrive(arm, clock),
                         JointLimits.uniform(n, v, 3 * v, 30 * v),
                         CartesianLimits(s, 5 * s, 50 * s, math.radians(30),
                                         math.radians(120), math.radians(1200)))
        self.arm = arm
        self.clock = clock
        self.moves = 0

    def _run(self, move: Move) -> float:
        super()._run(move)
        self.moves += 1
        self.clock.advance(self.drive.last_duration)
        return None  # type: ignore[return-value]

    def arm_jntp(self) -> JointPos:
        """ARM_JNTP: the readings now, also during a move (degrees)."""
        return JointPos(tuple(float(v) for v in np.degrees(self.joint_readings())))

    def halt(self) -> None:
        """Stop the running move (a dropped connection, STOP of a MOVE)."""
        self.drive.halt()
