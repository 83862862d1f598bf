"""The digital twin and the tracker model behind the compensation protocols.

:class:`TwinCell` is the simulated world of one robot and one laser tracker: it
moves the twin, reports the reflector's motion to the tracker (a locked beam
follows continuous motion, thesis 2.3.1.1) and hands out two device faces that
implement the :mod:`plugcell.compensation.protocols` interfaces:

* :class:`TwinRobot` — ``read_joints``/``move_joints``/``move_relative`` (the latter
  with the controller's *nominal* model, as a C3G executes a relative move);
* :class:`TwinTracker` — a raw sensor reading the T-MAC in the tracker frame; wrap it
  in :class:`~plugcell.compensation.frames.RobotFrameSensor` with the identified
  BASE/PROBE to get robot-frame readings.  ``BeamNotLockedError`` and
  ``TargetOutOfRangeError`` become :class:`~plugcell.compensation.errors.SensorError`
  with the tracker's reason.

Time is simulated (:class:`TwinTiming`): a joint move takes the largest joint
travel at the joint speed plus a settling time; the tracker reports its own
acquisition, integration and transfer time.  The settling time of the small
corrective moves is an **assumption** (documented in docs/compensation.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from plugcell.compensation.errors import SensorError
from plugcell.compensation.protocols import Reading
from plugcell.kinematics import forward, inverse
from plugcell.kinematics.errors import KinematicsError
from plugcell.sim.twin.campaign import JOINT_SPEED, SETTLE_S
from plugcell.sim.twin.robot import RobotTwin
from plugcell.sim.twin.tracker import BeamNotLockedError, LaserTracker, TargetOutOfRangeError

Array = NDArray[np.float64]

__all__ = ["TwinCell", "TwinRobot", "TwinTiming", "TwinTracker"]


@dataclass(frozen=True)
class TwinTiming:
    """Simulated durations of robot moves.

    ``joint_speed_rad_s``: joint speed of every move (the campaign's 40°/s);
    ``settle_s``: settling after a move between targets (the campaign's 2 s);
    ``small_move_rad``: a move whose largest joint travel is below this is a
    corrective move, which settles in ``correction_settle_s`` (assumption: a small
    increment of a few encoder counts, no acceleration phase to speak of).
    """

    joint_speed_rad_s: float = float(JOINT_SPEED)
    settle_s: float = SETTLE_S
    small_move_rad: float = math.radians(0.1)
    correction_settle_s: float = 0.3

    def move_time(self, q_from: Array, q_to: Array) -> float:
        travel = float(np.max(np.abs(np.asarray(q_to) - np.asarray(q_from))))
        settle = self.correction_settle_s if travel < self.small_move_rad else self.settle_s
        return travel / self.joint_speed_rad_s + settle


class TwinCell:
    """One :class:`RobotTwin` and one :class:`LaserTracker` in the same simulated cell."""

    def __init__(self, robot: RobotTwin, tracker: LaserTracker,
                 timing: TwinTiming | None = None) -> None:
        self.robot = robot
        self.tracker = tracker
        self.timing = timing or TwinTiming()
        self.clock_s = 0.0
        self.moves = 0

    def reflector(self) -> Array:
        """True T-MAC pose in the tracker frame (simulator only)."""
        return self.robot.true_reflector_in_tracker()

    def catch_beam(self) -> float:
        """The operator points the beam at the T-MAC (once, at the start)."""
        dt = self.tracker.point_at(self.reflector()[:3, 3])
        self.clock_s += dt
        return dt

    def move(self, q: ArrayLike) -> float:
        """Move the twin to ``q``; the tracker is told about the continuous motion."""
        q = np.asarray(q, dtype=float)
        dt = self.timing.move_time(self.robot.joint_readings(), q)
        self.robot.move_joints(q)
        self.tracker.track(self.reflector(), dt)
        self.clock_s += dt
        self.moves += 1
        return dt

    def robot_device(self, tool: ArrayLike | None = None) -> TwinRobot:
        return TwinRobot(self, tool)

    def tracker_device(self) -> TwinTracker:
        return TwinTracker(self)


class TwinRobot:
    """The twin as a :class:`~plugcell.compensation.protocols.CartesianRobot`.

    ``tool``: the TCP the controller knows (flange frame) for ``move_relative``.
    """

    def __init__(self, cell: TwinCell, tool: ArrayLike | None = None) -> None:
        self.cell = cell
        desc = cell.robot.description
        self._params = desc.nominal_parameters().replace(
            tool=np.eye(4) if tool is None else np.asarray(tool, dtype=float))

    def read_joints(self) -> Array:
        return self.cell.robot.joint_readings()

    def move_joints(self, q: Array) -> float:
        desc = self.cell.robot.description
        q = np.asarray(q, dtype=float)
        if not bool(desc.within_limits(q)):
            raise ValueError("joint target outside the joint limits; the controller refuses it")
        return self.cell.move(q)

    def move_relative(self, dp: Array) -> float:
        """Linear relative TCP move by ``dp`` with the controller's nominal model."""
        desc = self.cell.robot.description
        q = self.read_joints()
        T = forward(desc, self._params, q).tcp
        T[:3, 3] += np.asarray(dp, dtype=float)
        try:
            q_new = inverse(desc, self._params, T, seed=q, target="tcp").q
        except KinematicsError as exc:
            raise ValueError(f"the controller cannot make the relative move: {exc}") from exc
        return self.move_joints(q_new)


class TwinTracker:
    """The tracker model as a raw sensor (tracker frame) for ``RobotFrameSensor``."""

    def __init__(self, cell: TwinCell) -> None:
        self.cell = cell

    def measure(self, duration_s: float, mode: str) -> Reading:
        try:
            m = self.cell.tracker.measure(self.cell.reflector(), duration_s, mode=mode)  # type: ignore[arg-type]
        except BeamNotLockedError as exc:
            raise SensorError(str(exc), reason=exc.reason,
                              details={"offset_m": exc.offset_m}) from exc
        except TargetOutOfRangeError as exc:
            raise SensorError(str(exc), reason="out_of_range") from exc
        self.cell.clock_s += m.elapsed_s
        return Reading(position=np.asarray(m.position), pose=m.pose, duration_s=m.duration_s,
                       elapsed_s=m.elapsed_s)
