"""A robot program's straight moves as a path for ``plugcell path run --program``.

The program runs with the language runtime (:mod:`plugcell.pdl`) against
:class:`PathRecorder`, an arm that moves nothing but records each move as the
controller's nominal model would make it:

* ``MOVE TO`` / ``MOVE JOINT TO`` before the first straight move: where the path starts
  (the robot's home pose otherwise);
* ``MOVE LINEAR TO p``: a segment to ``p`` the tracker does not correct;
* ``MOVE LINEAR TO p WITH TRACKING [T]``: a segment the tracker corrects
  (:class:`~plugcell.pdl.interfaces.TrackedMotion`);
* ``MOVE RELATIVE``: a straight move by the offset (untracked).

A joint move after the path has started, a ``WRITE pc_client`` (there are no services in
a path run) or a pose out of reach fails the program at its line with the reason, and
nothing runs.  Every segment runs at one speed (the language has no speed statement).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from plugcell.devices.robot.arm_model import ControllerArm, matrix_from_position
from plugcell.io.path_files import PathFile
from plugcell.kinematics import RobotDescription, forward, inverse
from plugcell.pdl import Execution, MotionError, Position, Program, ProgramError, SimClock
from plugcell.pdl.errors import Location

Array = NDArray[np.float64]

__all__ = ["PathRecorder", "path_of_program"]

#: Two poses closer than this (m) and turned by less than MIN_TURN (rad) are one point.
MIN_MOVE, MIN_TURN = 1e-5, np.radians(0.01)


class PathRecorder(ControllerArm):
    """The arm of a path run: records the program's moves (module docstring).

    Parameters
    ----------
    description : RobotDescription
        The robot (the controller's nominal model).
    where : callable
        The program's current statement (its line names a segment).
    """

    def __init__(self, description: RobotDescription, where: Callable[[], Location | None]
                 ) -> None:
        super().__init__(description)
        self.where = where
        self.q = np.asarray(description.home, dtype=float)
        self.poses: list[Array] = [forward(description, None, self.q, "nominal").tcp]
        self.tracking: list[bool] = []
        self.trackers: set[str] = set()
        self.lines: list[int] = [self._line()]
        self._relative = False

    def _line(self) -> int:
        loc = self.where()
        return 0 if loc is None else int(loc.line)

    def joint_readings(self) -> Array:
        return self.q.copy()

    def _reach(self, T: Array) -> Array:
        result = inverse(self.description, None, T, seed=self.q, target="tcp",
                         closure="nominal", raise_errors=False)
        if not result.converged:
            raise MotionError("the pose is out of the robot's reach")
        self._check_limits(result.q)
        return np.asarray(result.q, dtype=float)

    def _start(self, q: Array) -> float:
        if self.tracking:
            raise MotionError("a joint move after the path's first MOVE LINEAR: a path is "
                              "straight moves only")
        self._check_limits(q)
        self.q = q
        self.poses[0] = forward(self.description, None, q, "nominal").tcp
        self.lines[0] = self._line()
        return 0.0

    def _segment(self, pose: Position, tracked: bool) -> float:
        T = matrix_from_position(pose)
        last = self.poses[-1]
        cos = (np.trace(last[:3, :3].T @ T[:3, :3]) - 1.0) / 2.0
        if np.linalg.norm(T[:3, 3] - last[:3, 3]) < MIN_MOVE and \
                np.arccos(np.clip(cos, -1.0, 1.0)) < MIN_TURN:
            raise MotionError("the same pose as the move before (a segment needs 0.01 mm or "
                              "0.01° of motion)")
        self.q = self._reach(T)
        self.poses.append(T)
        self.tracking.append(tracked)
        self.lines.append(self._line())
        return 0.0

    def move_joints(self, q_deg: Sequence[float]) -> float:
        return self._start(self._joints_rad(q_deg))

    def move_to(self, pose: Position, linear: bool = False) -> float:
        if linear or self._relative:
            return self._segment(pose, False)
        return self._start(self._reach(matrix_from_position(pose)))

    def move_relative(self, offset_mm: Sequence[float], frame: str) -> float | None:
        """MOVE RELATIVE: the controller's shifted pose, as a straight segment."""
        self._relative = True
        try:
            return super().move_relative(offset_mm, frame)
        finally:
            self._relative = False

    def move_tracked(self, pose: Position, tracker: str) -> float:
        self.trackers.add(tracker)
        return self._segment(pose, True)


class _NoServices:
    def write(self, line: str) -> None:
        raise ConnectionError("a path run has no services to talk to (WRITE pc_client)")


def path_of_program(path: str | Path, description: RobotDescription, speed_mm_s: float,
                    library: Sequence[str | Path] = ()) -> tuple[PathFile, set[str]]:
    """Run the robot program ``path`` on a :class:`PathRecorder`: its path and the tracker
    services its tracked moves name.

    Parameters
    ----------
    path : str or Path
        A ``.pdl`` robot program.
    description : RobotDescription
        The robot.
    speed_mm_s : float
        Every segment's speed (mm/s).
    library : sequence of str or Path
        Folders of the libraries it imports.

    Returns
    -------
    PathFile
        The poses (TCP, F0, m), the segments' speed (m/s) and tracking flags, the
        program's line of each point.
    set of str
        The tracker services named (``WITH TRACKING T``).

    Raises
    ------
    ValueError
        The program is refused or fails (file, line, reason), or makes no straight move.
    """
    try:
        program = Program.load(path, library)
    except ProgramError as exc:
        raise ValueError(str(exc)) from None
    execution: Execution | None = None
    arm = PathRecorder(description, lambda: None if execution is None else execution.location)
    execution = Execution(program, motion=arm, channel=_NoServices(),
                          clock=SimClock(speed=float("inf")))
    result = execution.run()
    if result.error is not None:
        raise ValueError(str(result.error))
    if not result.ok:
        raise ValueError(f"{path}: the program did not finish ({result.state.value})")
    if not arm.tracking:
        raise ValueError(f"{path}: no MOVE LINEAR: a path needs at least one straight move")
    n = len(arm.tracking)
    return PathFile(np.array(arm.poses), np.full(n, speed_mm_s * 1e-3),
                    np.array(arm.tracking, dtype=bool), np.array(arm.lines, dtype=np.int64),
                    True), arm.trackers
