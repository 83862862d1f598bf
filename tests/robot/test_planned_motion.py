"""Programs on the PC: PlannedMotion plans every move (plugcell.motion), checks it before
motion and hands it to a Drive — the same program runs on the twin through TwinArm and
through PlannedMotion + TwinDrive (#37)."""

from __future__ import annotations

import math
import threading
from pathlib import Path

import numpy as np
import pytest

from plugcell.devices.robot.planned_motion import Drive, PlannedMotion
from plugcell.devices.robot.runner import ProgramRunner
from plugcell.kinematics import forward
from plugcell.motion import CartesianLimits, JointLimits, Trajectory
from plugcell.pdl import Execution, ExecutionState, Motion, Program, SimClock
from plugcell.sim.controller.arm import TwinArm, TwinDrive
from plugcell.sim.twin.robot import RobotTwin
from plugcell.sim.twin.scenario import TwinScenario

JOINTS = JointLimits(np.radians([120, 115, 120, 190, 180, 260]),
                     np.radians([400, 350, 400, 600, 600, 800]),
                     np.radians([3000, 2500, 3000, 5000, 5000, 7000]))
CART = CartesianLimits(1.0, 4.0, 40.0, 2.0, 8.0, 80.0)

PROGRAM = """\
PROGRAM MOVES
VAR j : JOINTPOS
VAR p : POSITION
BEGIN
  j := JNTP(10, -80, -190, 30, 60, -20)
  MOVE TO j
  p := ARM_POS
  p := POS(p.x + 200, p.y, p.z - 100, p.a, p.b, p.c)
  MOVE LINEAR TO p
  MOVE RELATIVE VEC(0, 50, 0) IN BASE
  MOVE TO POS(4000, 0, 1000, 0, 90, 0)
END MOVES
"""


class _Silent:
    def write(self, line: str) -> None:  # the programs here write nothing
        raise AssertionError(line)


class _Recording(TwinDrive):
    """The twin's drive, keeping every trajectory it followed."""

    def __init__(self, twin: RobotTwin) -> None:
        super().__init__(twin)
        self.trajectories: list[Trajectory] = []

    def follow(self, trajectory: Trajectory) -> None:
        self.trajectories.append(trajectory)
        super().follow(trajectory)


def _twin() -> RobotTwin:
    return RobotTwin(TwinScenario(robot="smart_h4", seed=1))


def _run(motion: Motion, source: str) -> tuple[object, Execution]:
    ex = Execution(Program.from_source(source, "moves.pdl"), motion=motion, channel=_Silent(),
                   clock=SimClock(speed=math.inf))
    return ex.run(), ex


def test_the_same_program_runs_on_twin_arm_and_on_planned_motion() -> None:
    body = PROGRAM.replace("  MOVE TO POS(4000, 0, 1000, 0, 90, 0)\n", "")
    on_twin = TwinArm(_twin())
    drive = _Recording(_twin())
    planned = PlannedMotion(on_twin.description, drive, JOINTS, CART)
    assert isinstance(drive, Drive) and isinstance(planned, Motion)
    r1, _ = _run(on_twin, body)
    r2, _ = _run(planned, body)
    assert r1.state is ExecutionState.FINISHED and r2.state is ExecutionState.FINISHED
    # both end at the same joints (up to the twins' encoder noise)
    assert np.allclose(on_twin.joint_readings(), drive.joint_readings(), atol=1e-4)
    assert drive.followed == 3
    # the program's time is the planned trajectories' (not the twin's 40°/s rule)
    assert r2.sim_time != pytest.approx(r1.sim_time)
    # MOVE LINEAR TO was a straight line: its TCP stays on it
    traj = drive.trajectories[1]
    assert planned.last is drive.trajectories[2]
    desc = on_twin.description
    T = forward(desc, None, traj.sample(np.linspace(0, traj.duration, 50), 0).q,
                "nominal").tcp[:, :3, 3]
    d = T[-1] - T[0]
    off = (T - T[0]) - np.outer((T - T[0]) @ d / (d @ d), d)
    assert np.max(np.linalg.norm(off, axis=1)) < 1e-9


def test_a_move_the_checks_refuse_fails_the_program_at_its_line() -> None:
    drive = TwinDrive(_twin())
    planned = PlannedMotion(drive.twin.description, drive, JOINTS, CART)
    result, _ = _run(planned, PROGRAM)
    assert result.state is ExecutionState.FAILED
    assert result.location is not None and result.location.line == 11
    assert "out of reach" in str(result.error)
    assert drive.followed == 3  # the refused move never reached the drive


def test_a_joint_speed_the_robot_cannot_give_is_refused_before_motion() -> None:
    drive = TwinDrive(_twin())
    slow = JointLimits.uniform(6, 0.05, 1.0, 10.0)
    planned = PlannedMotion(drive.twin.description, drive, slow, CART)
    result, _ = _run(planned, PROGRAM)
    assert result.state is ExecutionState.FAILED and result.location.line == 9
    assert "LIN at" in str(result.error) and "speed" in str(result.error)
    assert drive.followed == 1


def test_the_program_runner_runs_on_planned_motion(tmp_path: Path) -> None:
    (tmp_path / "moves.pdl").write_text(PROGRAM.replace(
        "  MOVE TO POS(4000, 0, 1000, 0, 90, 0)\n", ""), encoding="utf-8")
    drive = TwinDrive(_twin())
    events: list[object] = []
    runner = ProgramRunner(PlannedMotion(drive.twin.description, drive, JOINTS, CART),
                           SimClock(speed=math.inf), _Silent(), events.append,
                           library=[tmp_path])
    info = runner.start(1, "MOVES")
    assert info.ended.wait(30)
    assert info.state == "FINISHED" and drive.followed == 3
    assert [type(e).__name__ for e in events] == ["ProgramStarted", "ProgramEnded"]
    assert threading.active_count() >= 1
