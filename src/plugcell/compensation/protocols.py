"""The small device interfaces the sensor-based correction talks to (thesis 6.5.2, 8.3.2).

The correction loop must not know whether it drives the digital twin, a robot
service over Zenoh, or a real controller, nor which metrology system measures —
the thesis makes the same point for its ``SENSOR_COM`` routine (8.3.2: "if another
sensor is used instead of the laser tracker, the technician only has to modify the
relevant commands").  So it sees four :class:`typing.Protocol` interfaces:

* :class:`JointRobot` — read the joint readings, move to joint targets (the
  corrective move of the 6-DOF loop, Fig. 6-11);
* :class:`CartesianRobot` — in addition a relative linear move of the TCP along a
  vector in the robot base frame (the 3-DOF loop, Fig. 6-12: "executes a relative
  movement along this vector", done by the controller with its own model);
* :class:`PoseSensor` / :class:`PositionSensor` — one measurement of a given
  integration time, expressed **in the robot base frame at the tool point**
  (:class:`~plugcell.compensation.frames.RobotFrameSensor` turns a tracker-frame
  device into one with the identified BASE and PROBE).

Every call reports how long it took (seconds of device time — simulated for the
twin, wall-clock for a real device), so the loop can account for the cycle time
per point without a clock of its own.  A device that cannot deliver raises
:class:`~plugcell.compensation.errors.SensorError` (sensor) or any exception
(robot); the loop turns both into a ``CorrectionError`` with the reason.

The correction *while the robot settles* (:mod:`.settling`, issue 38 §3) needs two
more: :class:`MovingRobot` — a joint command that returns at once with the time its
interpolation will end (the robot keeps moving and settling in the background) — and
:class:`PoseStream` — a tracker streaming stamped samples (:class:`StreamReading`) of
the tool pose in the robot base frame, with the clock both share (``now()``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]

__all__ = ["CartesianRobot", "JointRobot", "MovingRobot", "PoseSensor", "PoseStream",
           "PositionSensor", "Reading", "StreamReading"]


@dataclass(frozen=True, eq=False)
class Reading:
    """One measurement, in the frame the device reports (robot base frame for a
    :class:`PoseSensor`/:class:`PositionSensor`).

    Attributes
    ----------
    position : (3,) array, m
        The measured point.
    pose : (4, 4) array, m, or None
        The measured pose, ``None`` for a 3-DOF device.
    duration_s : float, s
        Integration time.
    elapsed_s : float, s
        Time the whole reading took (acquisition, integration, transfer).
    """

    position: Array
    pose: Array | None
    duration_s: float
    elapsed_s: float


@runtime_checkable
class JointRobot(Protocol):
    """A robot that reports its joint readings and moves to joint targets (radians)."""

    def read_joints(self) -> Array:
        """The robot's current joint readings.

        Returns
        -------
        (n_readings,) array, rad (m for prismatic)
            Readings in the description's reading order (its ``actuated`` order without
            a coupling).
        """
        ...

    def move_joints(self, q: Array) -> float:
        """Move to joint readings ``q`` and wait until the move ends.

        Parameters
        ----------
        q : (n_readings,) array, rad (m for prismatic)
            Target readings, description reading order.

        Returns
        -------
        float, s
            Time the move took (device time).
        """
        ...


@runtime_checkable
class CartesianRobot(JointRobot, Protocol):
    """A :class:`JointRobot` that also makes relative linear TCP moves."""

    def move_relative(self, dp: Array) -> float:
        """Move the TCP linearly by ``dp`` along the robot base axes, keeping its
        orientation, ``p_TCP ← p_TCP + dp`` as the controller's own (nominal) kinematics
        sees it — the corrective step of the 3-DOF loop (Fig. 6-12).

        Parameters
        ----------
        dp : (3,) array, m
            Displacement, robot base frame.

        Returns
        -------
        float, s
            Time the move took (device time).
        """
        ...


@runtime_checkable
class PoseSensor(Protocol):
    """A 6-DOF metrology system (a tracker with a T-MAC)."""

    def measure_pose(self, duration_s: float) -> Reading:
        """One reading of the tool pose in the robot base frame.

        Parameters
        ----------
        duration_s : float, s
            Integration time (the device averages over it).

        Returns
        -------
        Reading
            ``pose`` ``(4, 4)`` m and ``position`` ``(3,)`` m of the tool point, robot base
            frame.

        Raises
        ------
        SensorError
            The device cannot deliver (target lost, out of range…).
        """
        ...


@runtime_checkable
class PositionSensor(Protocol):
    """A 3-DOF metrology system (a tracker with an SMR)."""

    def measure_position(self, duration_s: float) -> Reading:
        """One reading of the tool position in the robot base frame.

        Parameters
        ----------
        duration_s : float, s
            Integration time (the device averages over it).

        Returns
        -------
        Reading
            ``position`` ``(3,)`` m of the tool point, robot base frame (``pose`` None).

        Raises
        ------
        SensorError
            The device cannot deliver (target lost, out of range…).
        """
        ...


@dataclass(frozen=True, eq=False)
class StreamReading:
    """One streamed sample of the tool in the robot base frame.

    Attributes
    ----------
    time_s : float, s
        Acquisition time (the middle of the sample's integration) on the loop's clock.
    pose : (4, 4) array, m, or None
        The tool pose; ``None`` when the sample holds no measurement.
    position : (3,) array, m, or None
        Its position.
    status : str
        ``"ok"`` or why the sample is empty (``line_of_sight``, ``tracking_speed``,
        ``out_of_range``, ``reacquiring``…).
    """

    time_s: float
    pose: Array | None
    position: Array | None
    status: str = "ok"


@runtime_checkable
class MovingRobot(Protocol):
    """A robot whose moves run in the background (a controller's interpolator)."""

    def read_joints(self) -> Array:
        """The robot's current joint readings, (n_readings,) rad."""
        ...

    def command_joints(self, q: Array, duration_s: float = 0.0) -> float:
        """Start a move from the last commanded joints to ``q`` and return at once.

        Parameters
        ----------
        q : (n_readings,) array, rad (m for prismatic)
            Target readings.
        duration_s : float, s
            The shortest time the move may take: the controller stretches a shorter
            move (smoothly, rest to rest) to it — a small correction made slowly enough
            not to ring the structure.

        Returns
        -------
        float, s
            The loop clock's time at which the commanded motion (the interpolation)
            ends; the arm still settles after it.
        """
        ...


@runtime_checkable
class PoseStream(Protocol):
    """A metrology system streaming the tool pose (a tracker's real-time output)."""

    def now(self) -> float:
        """The loop's clock (s), shared with the samples' time stamps."""
        ...

    def receive(self, wait_s: float) -> list[StreamReading]:
        """Wait ``wait_s`` seconds; the samples that arrived meanwhile, oldest first.

        Parameters
        ----------
        wait_s : float, s
            How long to wait.

        Returns
        -------
        list of StreamReading
            In order of acquisition; empty ones carry their ``status``.
        """
        ...
