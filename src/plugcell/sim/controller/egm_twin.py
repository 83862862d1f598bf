"""The twin's EGM side: an ABB controller's EGM loop whose axes are the dynamic twin.

:class:`TwinEgmRobot` stands where an ABB controller running plugcell's RAPID module
(``plugcell egm files --mode joint``: ``EGMRunJoint`` where the robot stands) stands: the
controller's EGM loop (:class:`~.egm_robot.EgmRobotSim`: an ``EgmRobot`` to the sensor's
address every sample, the newest ``EgmSensor`` followed, ``\\CommTimeout``) with the
dynamic twin (:class:`~plugcell.sim.twin.dynamics.DynamicTwin`) as its axes: each sample
the joint target goes to the twin's servo loops (:class:`~.egm_robot.DynamicFollower`),
the feedback joints are its encoder readings, and the feedback pose is the controller's
*nominal* forward kinematics of them (a real controller reports its model, not the true
TCP).  ``plugcell twin egm`` (:mod:`plugcell.apps.commands.twin_robot`) runs it;
:class:`EgmTwinProcess` runs that command for tests and benchmarks.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from plugcell.sim.controller.egm_robot import DynamicFollower, EgmRobotSim
from plugcell.sim.controller.twin_process import TwinProcess

__all__ = ["BANNER", "EgmTwinProcess", "TwinEgmRobot"]

Array = NDArray[np.float64]

#: The first line the command prints when it streams.
BANNER = "twin egm:"


class TwinEgmRobot(EgmRobotSim):
    """EgmRobotSim in joint mode on the dynamic twin, its feedback pose the nominal model's
    forward kinematics ``T(q)`` of its joints.

    Parameters
    ----------
    arm : DynamicTwin
        The arm; its cycle is the EGM sample, its joints now the start.
    sensor : tuple of (str, int)
        Where plugcell listens.
    **kwargs
        More of :class:`~.egm_robot.EgmRobotSim` (``comm_timeout_s``, ``bind``).
    """

    def __init__(self, arm: Any, sensor: tuple[str, int], **kwargs: Any) -> None:
        self.description = arm.twin.description
        q = np.array(arm.measured, dtype=float)
        p, quat = self._pose(q)
        super().__init__(sensor, "joint", joints=q, position=p, quaternion=quat,
                         sample_s=arm.params.cycle, follower=DynamicFollower(arm), **kwargs)

    def _pose(self, q: Array) -> tuple[Array, Array]:
        """The nominal TCP of ``q`` (rad): position (m), shape (3,); quaternion
        ``(w, x, y, z)``, shape (4,)."""
        from plugcell.kinematics import forward
        from plugcell.kinematics.rotations import matrix_to_quat

        T = forward(self.description, None, q, "nominal").tcp
        return T[:3, 3].copy(), matrix_to_quat(T[:3, :3])

    def advance(self, dt: float) -> None:
        super().advance(dt)
        self.p, self.quat = self._pose(self.q)


class EgmTwinProcess(TwinProcess):
    """``plugcell twin egm`` in a process of its own: ``EgmTwinProcess(sensor, *options)``.

    Parameters
    ----------
    sensor : str
        ``HOST:PORT`` where plugcell listens.
    *options : str
        More options of the command line (``--timeout``, ``--robot``, ``--stats`` …).
    """

    def __init__(self, sensor: str, *options: str) -> None:
        super().__init__("egm", sensor, *options)
