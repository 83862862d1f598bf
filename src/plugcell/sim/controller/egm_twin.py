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
:class:`TwinEgmPathRobot` is the controller running its own program with ``EGMMoveL``
and path corrections (``plugcell twin egm --mode pathcorr --lin …``).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from plugcell.kinematics.path_frame import applied_displacement, path_frame, path_tangents
from plugcell.sim.controller.egm_robot import DynamicFollower, EgmRobotSim
from plugcell.sim.controller.twin_process import TwinProcess

__all__ = ["BANNER", "EgmTwinProcess", "TwinEgmPathRobot", "TwinEgmRobot"]

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


class TwinEgmPathRobot(TwinEgmRobot):
    """``EGMMoveL`` on the dynamic twin (issue 37's mode (b)): the controller runs its own
    program and adds the PC's path corrections (``EgmSensorPathCorr``) in ABB's path
    coordinate system (:mod:`plugcell.kinematics.path_frame`).

    Each sample ``k`` the program's joints ``q_p(k)`` (``path``, sampled at the sample),
    its nominal TCP ``T_p(k)``, its path frame ``R(k) = [x y z]`` (``x`` the program's
    tangent, :func:`~plugcell.kinematics.path_frame.path_tangents`: where it stands
    still, the direction it last moved in or, before it moves, the first; ``y = x ×
    z_tool``, ``z_tool`` the TCP's z; ``z = x × y``) and the correction ``c`` (m, path
    coordinates) give the displacement ``d = R(k) · (0, c_y, c_z)`` — the controller
    corrects y and z, never x, the path direction — and the joint command
    ``q_p + J(q_p)⁺ · [d; 0]`` (the nominal model's Jacobian at the program's joints,
    computed for the whole path at once): the TCP moves by ``d`` to first order, its
    orientation kept; the dynamic twin follows the command.

    Parameters
    ----------
    arm : DynamicTwin
        The arm; it stands where ``path`` starts.
    sensor : tuple of (str, int)
        Where plugcell listens.
    path : Trajectory
        The program (:func:`~.own_program.linear_program`).
    path_delay_s : float
        The program waits this long after ``EGMActMove`` before it moves (s).
    **kwargs
        More of :class:`TwinEgmRobot`.
    """

    def __init__(self, arm: Any, sensor: tuple[str, int], path: Any,
                 path_delay_s: float = 0.0, **kwargs: Any) -> None:
        from plugcell.kinematics import forward
        from plugcell.kinematics.jacobian import manipulator_jacobian

        super().__init__(arm, sensor, **kwargs)
        self.mode = "pathcorr"
        q = np.asarray(path.setpoints(self.T)[1], dtype=float)
        if not (np.isfinite(path_delay_s) and path_delay_s >= 0):
            raise ValueError(f"path_delay_s must be ≥ 0 seconds, got {path_delay_s!r}")
        self._path = np.vstack([np.repeat(q[:1], round(path_delay_s / self.T), 0), q])
        self._J = manipulator_jacobian(self.description, None, self._path, "tcp", "nominal")
        T = forward(self.description, None, self._path, "nominal").tcp
        #: the program's path frame at each sample, (n, 3, 3)
        self.frames = path_frame(path_tangents(T[:, :3, 3]), T[:, :3, 2])
        self.path_index = 0

    @property
    def path_done(self) -> bool:
        """The program has reached its end."""
        return self.path_index >= len(self._path) - 1

    def advance(self, dt: float) -> None:
        k = self.path_index = min(self.path_index + 1, len(self._path) - 1)
        o = np.concatenate([applied_displacement(self.correction, self.frames[k]), np.zeros(3)])
        self.q_target = self._path[k] + np.linalg.lstsq(self._J[k], o, rcond=None)[0]
        self.q = self.follower.step(self.q, self.q_target, dt)
        self.p, self.quat = self._pose(self.q)

    def shift(self) -> Array:
        """The corrections' shift of the commanded TCP now: the nominal TCP of the joint
        command minus the program's (m, (3,))."""
        from plugcell.sim.controller.own_program import path_shift

        with self._lock:
            k, q = self.path_index, self.q_target.copy()
        T_p = self._pose_matrix(self._path[k])
        return path_shift(self.description, q, T_p)

    def path_pose(self) -> Array:
        """The program's own nominal TCP pose now, without the corrections (F0, 4×4)."""
        return self._pose_matrix(self._path[self.path_index])

    def _pose_matrix(self, q: Array) -> Array:
        from plugcell.kinematics import forward

        return forward(self.description, None, q, "nominal").tcp


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
