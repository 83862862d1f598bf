"""The controller as a separate OS process: world truth, a swapped-in controller, drops.

* The simulated controller publishes its T-MAC's true pose to the sim-only world
  after every move (moving, then at rest) — the truth of an identical twin.
* The robot service started with the issue's flags (``--sim``) and one connected to
  a controller it did not start (``--controller HOST:PORT``, as a real controller
  would be) behave the same.
* A controller that dies gives clear errors, not hangs; one that comes back is
  reconnected.
"""

from __future__ import annotations

import os
import re
import signal
import socket
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from robot_cell import Launcher
from robot_testlib import Proc, until

from plugcell.framework import BlockingClient, ProcessStates, from_data
from plugcell.framework.bus import Bus
from plugcell.framework.keys import KeySpace
from plugcell.framework.transport import open_session
from plugcell.sim.twin.robot import RobotTwin
from plugcell.sim.twin.scenario import TwinScenario
from plugcell.sim.world import WorldView

pytestmark = [pytest.mark.slow, pytest.mark.timeout(120)]


def controller_argv(*args: str) -> list[str]:
    return [sys.executable, "-m", "plugcell.sim.controller", *args]


def listening_port(proc: Proc) -> int:
    line = proc.wait_line(lambda s: "listening on" in s, 30.0)
    return int(re.search(r":(\d+)$", line).group(1))


def ask(sock_file, request: str) -> str:
    sock_file.write(request + "\n")
    sock_file.flush()
    ident = request.split(" ")[1]
    while True:
        line = sock_file.readline().rstrip("\n")
        assert line, "connection closed"
        if line.split(" ")[:2] in (["OK", ident], ["ERR", ident]):
            return line


def values(update) -> list[float]:
    return [float(v) for v in from_data(update.data).reshape(-1)]


def test_moves_publish_the_true_reflector_pose(launcher: Launcher) -> None:
    proc = launcher.start(controller_argv("--port", "0", "--cell", launcher.cell, "--name", "R9",
                                          "--seed", "5", "--speed", "20"))
    port = listening_port(proc)
    session = open_session()
    states: list = []
    world = WorldView(Bus(session, KeySpace(launcher.cell)), on_change=states.append)
    deadline = time.monotonic() + 15.0
    while world.get("R9") is None:  # WorldView asks once: before discovery it finds nothing
        assert time.monotonic() < deadline, "the initial reflector pose not seen"
        world.close()
        world = WorldView(Bus(session, KeySpace(launcher.cell)), on_change=states.append)
    try:
        twin = RobotTwin(TwinScenario(robot="smart_h4", seed=5))  # the same twin, in the test
        assert np.allclose(world.get("R9").matrix(), twin.true_reflector_in_tracker())
        with socket.create_connection(("127.0.0.1", port), timeout=10) as sock:
            f = sock.makefile("rw", newline="\n")
            assert f.readline().startswith("HELLO plugcell-controller 1 robot=smart_h4")
            q = [0.0, -80.0, -170.0, 10.0, 80.0, 5.0]
            reply = ask(f, "MOVE 1 JOINT " + ",".join(map(str, q)))
            assert reply.startswith("OK 1 ")
            until(lambda: world.get("R9").seq >= 3 and not world.get("R9").moving, 10.0,
                  "the arm at rest")
        moved = [s for s in states if s.seq >= 2]
        assert moved[0].moving and not moved[-1].moving  # moving during the move, then at rest
        twin.move_joints(np.radians(q))
        truth = twin.true_reflector_in_tracker()
        assert np.allclose(moved[-1].matrix(), truth, atol=1e-12)
    finally:
        world.close()
        session.close()


def test_a_real_controller_can_take_the_simulated_ones_place(launcher: Launcher) -> None:
    """The service with --controller HOST:PORT: it started nothing, and it cannot tell."""
    ctl = launcher.start(controller_argv("--port", "0", "--no-world", "--speed", "inf",
                                         "--library", str(Path(__file__).parent / "programs")))
    port = listening_port(ctl)
    service = launcher.start([sys.executable, "-m", "plugcell.devices.robot", "--name", "R5",
                              "--controller", f"127.0.0.1:{port}", "--cell", launcher.cell])
    launcher.ready(service)
    with BlockingClient("link-tester", cell=launcher.cell) as client:
        assert client.wait_for("R5")
        home = client.create_process("R5", "ARM_JNTP").result()
        assert values(home) == [0.0, -90.0, -187.0, 0.0, 90.0, 0.0]
        run = client.create_process("R5", "ACTIVATE", "Wait", ["forever"], timeout=5.0)
        time.sleep(0.3)
        ctl.kill9()  # the controller dies under a running program
        final = run.result()
        assert final.state is ProcessStates.Failed
        # a killed process's socket ends with FIN or, with unread bytes, RST: the reason
        # may carry the OS's words after the colon
        assert re.fullmatch(r"ACTIVATE: connection to the controller lost(: .+)?",
                            final.reason), final.reason
        lost = client.create_process("R5", "ARM_POS").result()
        assert lost.state is ProcessStates.Failed
        assert re.fullmatch(r"ARM_POS: controller not connected \(connection to the "
                            r"controller lost(: .+)?\)", lost.reason), lost.reason
        # the controller comes back on the same port: the service reconnects by itself
        again = launcher.start(controller_argv("--port", str(port), "--no-world"))
        listening_port(again)

        def answered() -> bool:
            return client.create_process("R5", "ARM_JNTP").result().state is ProcessStates.Completed

        until(answered, 15.0, "the reconnection")


def test_the_issue_command_line_and_no_leftover_process(launcher: Launcher) -> None:
    """``python -m plugcell.devices.robot --name N --sim [--robot] [--payload-kg] [--speed]``."""
    service = launcher.start([sys.executable, "-m", "plugcell.devices.robot", "--name", "R7",
                              "--sim", "--robot", "smart_h4", "--payload-kg", "36", "--speed",
                              "100", "--cell", launcher.cell])
    launcher.ready(service)
    children = Path(f"/proc/{service.pid}/task/{service.pid}/children").read_text().split()
    assert len(children) == 1  # its simulated controller
    controller = int(children[0])
    assert "plugcell.sim.controller" in Path(f"/proc/{controller}/cmdline").read_text()
    with BlockingClient("cli-tester", cell=launcher.cell) as client:
        assert client.wait_for("R7")
        pos = client.create_process("R7", "POS_TO_JNTP", "", [1500, 0, 1300, 0, 90, 0]).result()
        assert pos.state is ProcessStates.Completed and len(values(pos)) == 6
        inc = client.create_process("R7", "JointIncrement", "",
                                    [1500, 0, 1300, 0, 90, 0, 1499.5, 0, 1300, 0, 90, 0]).result()
        assert inc.state is ProcessStates.Completed
        assert 0 < np.max(np.abs(values(inc))) < 0.1  # half a millimetre: a few hundredths of °
    os.kill(service.pid, signal.SIGKILL)  # the service alone: it cannot clean up ...
    service.popen.wait(10)
    until(lambda: not Path(f"/proc/{controller}").exists()
          or "Z" in Path(f"/proc/{controller}/stat").read_text().split(")")[1][:3],
          10.0, "the end of the orphaned controller")  # ... its controller follows it
