"""The simulated controller with ``--dynamics``: moves take their time on the dynamic twin
(planned with plugcell.motion, stepped every 4 ms, paced by the clock's speed, ending in an
exact stop), ARM_JNTP reports the moving arm, a dropped connection halts a move."""

from __future__ import annotations

import math
import socket
import threading
import time
from collections.abc import Iterator

import numpy as np
import pytest
from test_sim_controller import Line, numbers

from plugcell.pdl import Execution, ExecutionState, Program, SimClock
from plugcell.sim.controller.arm import IN_POSITION_RAD, SETTLE_MAX_S, DynamicArm, TwinArm
from plugcell.sim.controller.line_controller import SimController
from plugcell.sim.twin.dynamics import DynamicTwin
from plugcell.sim.twin.robot import RobotTwin
from plugcell.sim.twin.scenario import TwinScenario

pytestmark = pytest.mark.timeout(60)

SCENARIO = TwinScenario(robot="smart_h4", seed=1, payload_kg=36.0)
TARGET = [20.0, -80.0, -180.0, 10.0, 80.0, 10.0]


def _serve(speed: float) -> tuple[SimController, socket.socket, threading.Thread]:
    clock = SimClock(speed=speed)
    sim = SimController(DynamicArm(DynamicTwin(SCENARIO), clock), clock=clock, name="R1")
    listener = socket.create_server(("127.0.0.1", 0))
    thread = threading.Thread(target=sim.serve, args=(listener,), daemon=True)
    thread.start()
    return sim, listener, thread


@pytest.fixture(params=[math.inf, 4.0], ids=["speed-inf", "speed-4"])
def served(request) -> Iterator[tuple[SimController, Line]]:
    sim, listener, thread = _serve(request.param)
    line = Line(listener.getsockname()[1])
    assert line.recv().startswith("HELLO plugcell-controller 1 robot=smart_h4")
    try:
        yield sim, line
    finally:
        line.close()
        sim.shutdown()
        thread.join(5)
        listener.close()


def test_a_move_takes_its_time_and_ends_in_position(served) -> None:
    sim, link = served
    t0 = time.monotonic()
    duration = float(link.ask(f"MOVE 1 JOINT {','.join(map(str, TARGET))}").split(" ")[2])
    wall = time.monotonic() - t0
    planned = sim.arm.last.duration
    # the trajectory, then the exact stop (dead time and servo lag), on the clock
    assert planned < duration < planned + SETTLE_MAX_S
    assert sim.clock.now() == pytest.approx(duration)
    if math.isfinite(sim.clock.speed):  # paced: others see it move at the simulation's pace
        assert wall >= duration / sim.clock.speed - 0.01
    reading = numbers(link.ask("ARM_JNTP 2"))
    assert np.max(np.abs(np.radians(reading - TARGET))) <= IN_POSITION_RAD
    # the link side is where the static twin says the gears leave it, within the mode's
    # ringing (the true pose follows the moving arm)
    arm = sim.arm.arm
    assert np.max(np.abs(arm.link - arm.motor)) < np.radians(0.05)
    assert sim.arm.moves == 1


def test_the_moving_arm_is_reported_while_it_moves() -> None:
    sim, listener, thread = _serve(2.0)
    link = Line(listener.getsockname()[1])
    try:
        link.recv()
        start = numbers(link.ask("ARM_JNTP 1"))
        link.send(f"MOVE 2 JOINT {','.join(map(str, TARGET))}")
        seen = []
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline:
            time.sleep(0.1)
            reply = link.ask(f"ARM_JNTP {3 + len(seen)}")
            seen.append(numbers(reply)[0])
            if abs(seen[-1] - TARGET[0]) < 1e-3:
                break
        line, _ = link.reply("2", timeout=20)
        assert line.startswith("OK 2 ")
        between = [a for a in seen if start[0] + 0.5 < a < TARGET[0] - 0.5]
        assert len(between) >= 3  # A1 seen on its way
        assert np.all(np.diff(seen) >= -1e-6)  # forward, a jerk-limited PTP
    finally:
        link.close()
        sim.shutdown()
        thread.join(5)
        listener.close()


def test_a_dropped_connection_halts_the_move() -> None:
    sim, listener, thread = _serve(1.0)
    link = Line(listener.getsockname()[1])
    try:
        link.recv()
        link.send(f"MOVE 1 JOINT {','.join(map(str, TARGET))}")
        time.sleep(0.5)
        link.close()  # the service is gone
        deadline = time.monotonic() + 5
        while sim._moving and time.monotonic() < deadline:
            time.sleep(0.02)
        assert not sim._moving
        q = np.degrees(sim.arm.joint_readings())
        assert abs(q[0] - TARGET[0]) > 1.0  # stopped on the way
        time.sleep(0.3)
        assert np.allclose(np.degrees(sim.arm.joint_readings()), q, atol=0.5)
    finally:
        sim.shutdown()
        thread.join(5)
        listener.close()


PROGRAM = """\
PROGRAM MOVES
VAR p : POSITION
BEGIN
  MOVE TO JNTP(10, -80, -190, 30, 60, -20)
  p := ARM_POS
  p := POS(p.x + 200, p.y, p.z - 100, p.a, p.b, p.c)
  MOVE LINEAR TO p
  MOVE RELATIVE VEC(0, 50, 0) IN BASE
END MOVES
"""


class _Silent:
    def write(self, line: str) -> None:
        raise AssertionError(line)


def test_a_program_runs_as_on_the_teleporting_arm_and_its_time_is_the_moves() -> None:
    clock = SimClock(speed=math.inf)
    dynamic = DynamicArm(DynamicTwin(SCENARIO), clock)
    teleport = TwinArm(RobotTwin(SCENARIO))
    runs = []
    for arm, c in ((dynamic, clock), (teleport, SimClock(speed=math.inf))):
        ex = Execution(Program.from_source(PROGRAM, "moves.pdl"), motion=arm,
                       channel=_Silent(), clock=c)
        runs.append(ex.run())
    assert all(r.state is ExecutionState.FINISHED for r in runs)
    assert dynamic.moves == 3 and dynamic.drive.followed == 3
    # the same place (the two twins' encoder readings, the static one's noise aside)
    assert np.allclose(dynamic.joint_readings(), teleport.joint_readings(), atol=2e-4)
    # the clock advanced once per move, by the move and its exact stop
    assert runs[0].sim_time == pytest.approx(clock.now())
    assert clock.now() > dynamic.last.duration


class _Truth:
    """A ReflectorTruth that keeps what it was given."""

    def __init__(self) -> None:
        self.published: list[tuple[np.ndarray, bool]] = []

    def publish(self, pose: np.ndarray, moving: bool = False) -> None:
        self.published.append((pose, moving))


def test_the_reflector_feed_publishes_the_arm_as_it_moves_then_once_at_rest() -> None:
    from plugcell.sim.controller.reflector import ReflectorFeed

    arm = DynamicTwin(SCENARIO)
    truth = _Truth()
    feed = ReflectorFeed(truth, arm, rate_hz=200.0).start()  # type: ignore[arg-type]
    try:
        deadline = time.monotonic() + 5
        while not truth.published and time.monotonic() < deadline:
            time.sleep(0.01)
        assert truth.published[0][1] is False  # where it stands, at rest
        q = arm.measured
        for k in range(150):  # A1 turns 3° in 0.6 s, 2 ms of wall time a cycle
            arm.step(q + np.radians([min(k, 100) * 0.03, 0, 0, 0, 0, 0]))
            time.sleep(0.002)
        moving = [p for p, m in truth.published if m]
        assert len(moving) >= 5
        start = truth.published[0][0][:3, 3]
        went = max(float(np.linalg.norm(p[:3, 3] - start)) for p in moving)
        assert went > 0.05  # the T-MAC went round with A1 (metres)
        n = len(truth.published)
        # the arm stands (its command held): at most one sample of a look taken before it
        # stood (the feed reads the angles, then spends milliseconds on the static physics:
        # a loaded machine can count n in between — CI of 2026-11-28), one of the final
        # angles if the feed lagged, then one at rest … (waited for, not slept on: a
        # loaded machine delays the feed's thread, it cannot add samples)
        deadline = time.monotonic() + 10
        while truth.published[-1][1] is not False and time.monotonic() < deadline:
            time.sleep(0.01)
        assert truth.published[-1][1] is False
        assert len(truth.published) <= n + 3
        m = len(truth.published)
        time.sleep(0.2)
        assert len(truth.published) == m  # … then none
    finally:
        feed.stop()
    np.testing.assert_allclose(truth.published[-1][0], arm.twin.true_reflector_in_tracker())


def test_dynamics_is_the_simulated_controllers_option() -> None:
    from plugcell.devices.robot.service import RobotService
    from plugcell.sim.controller.launcher import SimControllerProcess

    with pytest.raises(ValueError, match="dynamics moves the simulated controller's twin in "
                                         "time: give sim=true too"):
        RobotService(line="127.0.0.1:7000", dynamics=True)
    assert RobotService(sim=True, launcher=SimControllerProcess, dynamics=True).dynamics

    assert "--dynamics" in SimControllerProcess(name="R1", cell="c", dynamics=True).argv
    assert "--dynamics" not in SimControllerProcess(name="R1", cell="c").argv
