"""plugcell's RSI link against a robot side written by others: rsipi 0.3.0's EchoServer
(PyPI ``rsipi``, Apache-2.0), a simulated KUKA controller that owns the IPOC clock,
rejects late or wrong answers, counts them in ``<Delay>``, breaks off past ``Timeout``
and applies AKorr/RKorr relative or absolute.  It reads the ethernet configuration
``plugcell rsi files`` writes for the real controller, and runs in its own process
(rsipi_robot.py says what is adapted there and why)."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("RSIPI", reason="rsipi is a test dependency: pip install -e .[dev]")

from rsi_testlib import local_config

from plugcell.devices.robot.rsi import (
    ControllerStoppedError,
    Correction,
    CycleState,
    RsiLink,
    StreamStoppedError,
)
from plugcell.devices.robot.rsi.controller_files import (
    ETHERNET_FILE,
    write_controller_files,
)
from plugcell.io.units import DEG, M_PER_MM

pytestmark = pytest.mark.slow  # a second process, a few seconds of streaming each

HERE = Path(__file__).resolve().parent


class RsipiRobot:
    """rsipi's EchoServer in a child process, sending to ``link``'s port."""

    def __init__(self, link: RsiLink, mode: str, timeout: int, tmp: Path) -> None:
        port = link.address[1]
        files = write_controller_files(
            tmp / "controller", dataclasses.replace(link.config, listen_port=port),
            "127.0.0.1")
        config = next(p for p in files if p.name == ETHERNET_FILE)
        self.proc = subprocess.Popen(
            [sys.executable, str(HERE / "rsipi_robot.py"), str(config), mode, str(timeout),
             str(tmp)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        for line in self.proc.stdout:
            if line.startswith("READY"):
                break
        else:
            raise RuntimeError(f"rsipi's robot did not start (exit {self.proc.wait()})")

    def stop(self) -> dict:
        """Stop it; its faulty-packet count, whether it still ran, its state."""
        out, _ = self.proc.communicate("stop\n", timeout=30)
        line = next(x for x in out.splitlines() if x.startswith("RESULT "))
        return json.loads(line[len("RESULT "):])


def run_until(link: RsiLink, predicate, timeout: float = 20.0) -> None:
    assert link.wait(lambda lk: predicate(lk) or lk.failure is not None, timeout), \
        f"timed out; {link.stats()}"


@pytest.fixture
def linked(tmp_path):
    made = []

    def make(config, source, timeout: int = 100):
        link = RsiLink(config, source)
        link.start()
        robot = RsipiRobot(link, config.mode, timeout, tmp_path)
        made.append((link, robot))
        return link, robot

    yield make
    for link, robot in made:
        if robot.proc.poll() is None:
            robot.proc.kill()
            robot.proc.wait()
        link.close()


#: The joint path the tests drive: A1 to +2°, A3 to −1.5° in 0.8 s (a cosine ramp), held.
TARGET = np.array([2.0, 0, -1.5, 0, 0, 0]) * DEG


def joint_path(t: float) -> np.ndarray:
    s = min(t / 0.8, 1.0)
    return TARGET * (1 - np.cos(np.pi * s)) / 2


def test_absolute_joint_corrections_move_rsipis_robot(linked) -> None:
    seen: list[tuple[float, np.ndarray]] = []

    def source(state: CycleState) -> Correction:
        seen.append((state.t, state.robot.joints.copy()))
        return Correction(offset=joint_path(state.t))

    link, robot = linked(local_config(mode="absolute", limits=None), source)
    run_until(link, lambda lk: seen and seen[-1][0] > 1.0)
    result = robot.stop()
    assert link.failure is None, link.failure
    q = seen[-1][1]
    # rsipi reports two decimals of a degree
    np.testing.assert_allclose(q / DEG, TARGET / DEG, atol=0.006)
    final = [result["state"]["AIPos"][f"A{i}"] for i in range(1, 7)]
    np.testing.assert_allclose(final, TARGET / DEG, atol=1e-6)  # rsipi's own state
    # on the way, the robot's position followed the path (one cycle behind)
    mid = [(tt, qq) for tt, qq in seen if 0.3 < tt < 0.5]
    assert mid
    for tt, qq in mid:
        assert abs(qq[0] - joint_path(tt)[0]) < 0.1 * DEG
    # what rsipi counted is what it reported in <Delay>, and the link read it
    assert result["faulty_packets"] >= link.stats().controller_late


def test_relative_joint_steps_closed_on_the_reported_position(linked) -> None:
    start: dict[str, np.ndarray] = {}
    last: list[CycleState] = []

    def source(state: CycleState) -> Correction:
        q = state.robot.joints
        start.setdefault("q", q.copy())
        last[:] = [state]
        return Correction(step=joint_path(state.t) - (q - start["q"]))

    link, robot = linked(local_config(mode="relative"), source)
    run_until(link, lambda lk: last and last[0].t > 1.2)
    robot.stop()
    assert link.failure is None, link.failure
    np.testing.assert_allclose((last[0].robot.joints - start["q"]) / DEG, TARGET / DEG,
                               atol=0.006)


def test_relative_cartesian_corrections_move_the_tcp(linked) -> None:
    step = np.array([0.05 * M_PER_MM, 0, -0.02 * M_PER_MM, 0, 0, 0])  # per cycle
    states: list[CycleState] = []

    def source(state: CycleState) -> Correction | None:
        states.append(state)
        return Correction(step=step) if state.cycle < 100 else None

    link, robot = linked(local_config(correction="cartesian", mode="relative"), source)
    run_until(link, lambda lk: len(states) > 120)
    result = robot.stop()
    assert link.failure is None
    tcp = states[-1].robot.tcp - states[0].robot.tcp
    # every accepted step moved the TCP; a step rsipi rejected as late is not applied
    applied = 100 - result["faulty_packets"]
    assert tcp[0] == pytest.approx(applied * 0.05 * M_PER_MM, abs=0.006 * M_PER_MM)
    assert tcp[2] == pytest.approx(-applied * 0.02 * M_PER_MM, abs=0.006 * M_PER_MM)


def test_a_late_answer_is_counted_by_both_sides(linked) -> None:
    states: list[CycleState] = []

    def source(state: CycleState) -> None:
        states.append(state)
        if state.cycle == 50:
            time.sleep(0.03)  # several cycles late

    link, robot = linked(local_config(mode="relative"), source)
    run_until(link, lambda lk: lk.stats().controller_late >= 1 and len(states) > 80)
    result = robot.stop()
    st = link.stats()
    assert st.late >= 1  # the link knows it answered late
    assert result["faulty_packets"] >= 1  # rsipi rejected it and counted the cycles
    assert st.controller_late >= 1  # and reported them in <Delay>, which the link read
    assert link.failure is None  # far below Timeout: the stream goes on


def test_late_answers_up_to_the_timeout_stop_the_stream(linked) -> None:
    def source(state: CycleState) -> None:
        if state.cycle >= 30:
            time.sleep(0.012)  # every answer late from here on

    link, robot = linked(local_config(mode="relative", timeout_packets=25), source,
                         timeout=25)
    assert link.wait(lambda lk: lk.failure is not None, timeout=20.0), link.stats()
    # the link stops at the controller's Timeout (its own count, or rsipi's <Delay>)
    assert isinstance(link.failure, (StreamStoppedError, ControllerStoppedError))
    assert "Timeout is 25" in str(link.failure)
    assert robot.stop()["faulty_packets"] > 0


def test_rsipi_breaks_off_the_link_sees_the_silence_and_recovers(linked, tmp_path) -> None:
    def source(state: CycleState) -> None:
        if state.session == 1 and 30 <= state.cycle < 50:
            time.sleep(0.012)  # twenty late answers: past rsipi's Timeout of 10

    link, robot = linked(local_config(mode="relative", timeout_packets=100), source,
                         timeout=10)
    assert link.wait(lambda lk: lk.failure is not None, timeout=20.0), link.stats()
    silence = link.failure
    assert isinstance(silence, StreamStoppedError)
    assert "no packet from the controller for 0.4" in str(silence)  # one timeout: 100 × 4 ms
    result = robot.stop()
    assert result["running"] is False and result["faulty_packets"] > 10  # rsipi broke off
    # the controller comes back (RSI_ON again): a new session, no failure
    again = RsipiRobot(link, "relative", 10, tmp_path)
    try:
        assert link.wait(lambda lk: lk.stats().sessions == 2 and lk.stats().answered > 0
                         and lk.streaming, timeout=20.0), link.stats()
        assert link.failure is None and link.last_failure is silence
    finally:
        again.stop()


def test_a_motion_followed_to_its_end_on_rsipis_robot(linked) -> None:
    """``RsiLink.follow``, as a robot service runs one motion: to its end, then held."""
    link, robot = linked(local_config(mode="absolute"), None)
    end = link.follow(lambda s: Correction(offset=joint_path(s.t)),
                      done=lambda s: s.t >= 0.8, timeout=30.0)
    time.sleep(0.1)  # held: rsipi's robot stays where the motion ended
    result = robot.stop()
    assert link.failure is None
    final = np.array([result["state"]["AIPos"][f"A{i}"] for i in range(1, 7)])
    np.testing.assert_allclose(final, joint_path(end.t) / DEG, atol=1e-6)
    np.testing.assert_allclose(final, TARGET / DEG, atol=1e-6)
