"""The cycle loop in a process of its own (LinkProcess, issue 37 §7): a motion goes to the
child over the pipe and moves the robot; the feedback, the stream's state and a failure's
reason come back through shared memory; a stopped stream fails a motion with the link's
reason and a robot coming back starts a new session; closing (or losing) the parent ends
the child.  The robot is the simulated ABB controller's EGM loop (EgmRobotSim, joint
mode) in this process.  A motion in the child fails within one controller timeout of
the stream stopping and at once when the child dies; the parent's wait for its answer
counts the controller's cycles (:func:`await_answer`, with a fake child and clock)."""

from __future__ import annotations

import dataclasses
import os
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from plugcell.devices.robot.egm import EgmConfig
from plugcell.devices.robot.rsi import RsiConfig
from plugcell.devices.robot.stream.drive import drive_refusal
from plugcell.devices.robot.stream.process import (
    ANSWER_GRACE_S,
    FAILED_GRACE_S,
    LinkProcess,
    NoAnswerError,
    Publisher,
    await_answer,
)
from plugcell.devices.robot.stream_controller import streaming_limits
from plugcell.io.robots import load_robot
from plugcell.io.units import DEG
from plugcell.motion import PTP, JointLimits, plan
from plugcell.pdl.interfaces import MotionError
from plugcell.sim.controller.egm_robot import EgmRobotSim
from plugcell.sim.ports import free_port

Q0 = np.radians([0.0, -90.0, -187.0, 0.0, 90.0, 0.0])
V = 20 * DEG
LIMITS = JointLimits.uniform(6, V, 3 * V, 30 * V)


def _config(listen_port: int = 0) -> EgmConfig:
    base = EgmConfig(robot_host="127.0.0.1", listen_host="127.0.0.1", listen_port=listen_port,
                     mode="joint", comm_timeout_s=2.0)
    return dataclasses.replace(base, limits=streaming_limits(LIMITS, base.cycle_s))


def _robot(address, comm_timeout_s: float = 2.0) -> EgmRobotSim:
    return EgmRobotSim(address, "joint", joints=Q0, comm_timeout_s=comm_timeout_s).start()


@pytest.mark.slow
def test_a_motion_in_the_child_moves_the_robot_and_the_feedback_comes_back():
    link = LinkProcess(_config())
    address = link.start()
    robot = _robot(address)
    try:
        assert link.wait(lambda lk: lk.streaming and lk.latest is not None, 20)
        assert link.failure is None
        np.testing.assert_allclose(link.joint_readings(), Q0, atol=1e-9)
        target = Q0 + np.radians([3.0, -2.0, 1.0, 0.0, 2.0, -3.0])
        traj = plan(load_robot("smart_h4"), link.joint_readings(), [PTP(target=target)],
                    LIMITS)
        link.follow(traj)
        assert link.followed == 1
        time.sleep(0.2)  # the follower settles
        np.testing.assert_allclose(robot.state()["joints"], target, atol=1e-4)
        np.testing.assert_allclose(link.joint_readings(), robot.state()["joints"],
                                   atol=2e-3)  # a cycle or two behind
        counters = link.counters()
        assert counters["answered"] >= int(traj.duration / 0.004) and \
            counters["sessions"] == 1

        # a move faster than the link's limits (planned with 4× the speed) is refused by
        # the child's link: the reason reaches the program, the robot holds
        fast = JointLimits.uniform(6, 4 * V, 12 * V, 120 * V)
        rush = plan(load_robot("smart_h4"), target,
                    [PTP(target=target + np.radians([20, 0, 0, 0, 0, 0]))], fast)
        with pytest.raises(MotionError, match=r"correction refused at seqno \d+: A1 (speed|step)"):
            link.follow(rush)
        assert "correction refused" in str(link.failure)
        held = robot.state()["joint_targets"]
        time.sleep(0.1)
        np.testing.assert_array_equal(robot.state()["joint_targets"], held)
    finally:
        robot.stop()
        link.close()
    assert not link.alive


@pytest.mark.slow
def test_an_adjusted_motion_adds_what_the_service_computes_each_cycle():
    """A tracked move's hook with the link in its child: the hook runs here, in the
    service's process, on each cycle the child published (its index, the robot's time and
    joints); the child adds the newest result — the robot ends on target + Δq; a hook that
    raises fails the motion with its reason after the motion, which kept the last Δq."""
    link = LinkProcess(_config())
    address = link.start()
    robot = _robot(address)
    dq = np.radians([0.2, -0.1, 0.05, 0.0, 0.1, -0.2])
    seen: list[tuple[int, float, np.ndarray]] = []

    def adjust(state, k, q_k):
        seen.append((k, state.t, np.array(state.robot.joints)))
        return dq * min(1.0, k / 75)  # ramped in over 0.3 s: the link's limits hold

    try:
        assert link.wait(lambda lk: lk.streaming and lk.latest is not None, 20)
        target = Q0 + np.radians([3.0, -2.0, 1.0, 0.0, 2.0, -3.0])
        traj = plan(load_robot("smart_h4"), link.joint_readings(), [PTP(target=target)],
                    LIMITS)
        assert traj.duration > 0.5  # longer than the ramp
        link.follow(traj, adjust=adjust)
        time.sleep(0.2)  # the follower settles
        np.testing.assert_allclose(robot.state()["joints"], target + dq, atol=1e-4)
        ks = np.array([k for k, _, _ in seen])
        ts = np.array([t for _, t, _ in seen])
        assert len(seen) > 0.5 * traj.duration / 0.004  # most cycles (a loaded PC skips)
        # the robot's time is EgmHeader.tm, whole milliseconds: two packets sent within a
        # millisecond (the robot catching up after a stall, CI run 21) share it
        assert np.all(np.diff(ks) > 0) and np.all(np.diff(ts) >= 0)
        assert ks[-1] >= round(traj.duration / 0.004) - 5  # … up to the motion's end
        assert all(np.all(np.isfinite(q)) for _, _, q in seen)  # the actual joints

        def broken(state, k, q_k):
            if k > 20:
                raise ZeroDivisionError("the loop's bug")
            return np.zeros(6)

        back = plan(load_robot("smart_h4"), link.joint_readings(), [PTP(target=Q0)], LIMITS)
        with pytest.raises(MotionError, match="ZeroDivisionError: the loop's bug"):
            link.follow(back, adjust=broken)
        assert link.failure is None  # the stream itself is fine
        link.follow(back)  # and the next motion runs unadjusted (Δq of another motion)
        time.sleep(0.2)
        np.testing.assert_allclose(robot.state()["joints"], Q0, atol=1e-4)
    finally:
        robot.stop()
        link.close()


def test_the_seqvector_reads_what_was_written_whole():
    import multiprocessing

    from plugcell.devices.robot.stream.adjusting import SeqVector

    raw = multiprocessing.get_context("spawn").RawArray("d", 4)
    vec = SeqVector(raw)
    vec.write(np.array([1.0, 2.0, 3.0]))
    vec.write(np.array([4.0, 5.0]))  # a shorter write leaves the rest
    assert vec.snapshot()[0] == 4  # two writes: even
    np.testing.assert_array_equal(vec.read(), [4.0, 5.0, 3.0])


@pytest.mark.slow
def test_a_stopped_stream_fails_with_its_reason_and_a_new_session_recovers():
    link = LinkProcess(_config())
    address = link.start()
    try:
        robot = _robot(address)
        assert link.wait(lambda lk: lk.streaming, 20)
        robot.stop()  # the controller gone
        t0 = time.monotonic()
        assert link.wait(lambda lk: not lk.streaming, 10)
        assert time.monotonic() - t0 < 2.0 + 1.0  # one \CommTimeout, and the poll
        assert str(link.failure).startswith("EGM stream stopped: no packet from the "
                                            "controller for 2.0")
        with pytest.raises(MotionError, match="EGM stream stopped: no packet"):
            link.joint_readings()
        robot = _robot(address)  # back: a new session, the failure gone
        try:
            assert link.wait(lambda lk: lk.streaming and lk.failure is None, 20)
            assert link.counters()["sessions"] == 2
        finally:
            robot.stop()
    finally:
        link.close()


@pytest.mark.slow
def test_a_crashed_link_process_says_so_and_starts_again():
    link = LinkProcess(_config(listen_port=free_port("udp")))
    address = link.start()
    robot = _robot(address, 30.0)  # waits for the new child's answers
    try:
        assert link.wait(lambda lk: lk.streaming, 20)
        os.kill(link._proc.pid, signal.SIGKILL)  # the child dies (a bug, the OOM killer)
        assert link.wait(lambda lk: not lk.streaming, 5)
        assert "the EGM link process has exited (exit code -9)" in str(link.failure)
        with pytest.raises(MotionError, match="link process has exited"):
            link.joint_readings()
        assert link.start() == address  # the controller's connect starts it again
        assert link.wait(lambda lk: lk.streaming and lk.failure is None, 20)
    finally:
        robot.stop()
        link.close()


def _long_motion(link) -> object:
    """A PTP of some seconds from where the robot stands."""
    target = link.joint_readings() + np.radians([60.0, 0, 0, 0, 0, 0])
    traj = plan(load_robot("smart_h4"), link.joint_readings(), [PTP(target=target)], LIMITS)
    assert traj.duration > 3.0
    return traj


@pytest.mark.slow
def test_a_motion_fails_within_one_controller_timeout_of_the_stream_stopping():
    """The controller gone during a motion in the child: the motion fails with the
    stream's reason one \\CommTimeout (2 s) after the last packet, not at the motion's
    own timeout."""
    link = LinkProcess(_config())
    address = link.start()
    robot = _robot(address)
    try:
        assert link.wait(lambda lk: lk.streaming and lk.latest is not None, 20)
        traj = _long_motion(link)
        threading.Timer(0.5, robot.stop).start()  # the controller gone mid-motion
        t0 = time.monotonic()
        with pytest.raises(MotionError, match=r"EGM stream stopped: no packet from the "
                                              r"controller for 2\.0"):
            link.follow(traj)
        assert time.monotonic() - t0 < 0.5 + 2.0 + 1.5  # the stop, one timeout, the pipe
    finally:
        robot.stop()
        link.close()


@pytest.mark.slow
def test_a_motion_fails_at_once_when_the_child_dies():
    link = LinkProcess(_config())
    address = link.start()
    robot = _robot(address)
    try:
        assert link.wait(lambda lk: lk.streaming and lk.latest is not None, 20)
        traj = _long_motion(link)
        pid = link._proc.pid
        threading.Timer(0.5, os.kill, (pid, signal.SIGKILL)).start()
        t0 = time.monotonic()
        with pytest.raises(MotionError, match="the EGM link process has exited"):
            link.follow(traj)
        assert time.monotonic() - t0 < 0.5 + 1.5
    finally:
        robot.stop()
        link.close()


class _Child:
    """A fake child for :func:`await_answer`: a clock, its cycles, its answer."""

    def __init__(self, rate: float = 250.0, answer_at: float | None = None) -> None:
        self.t, self.rate, self.answer_at = 0.0, rate, answer_at
        self.alive, self.failed_at, self.cycles_until = True, None, float("inf")

    def receive(self, wait: float):
        self.t += wait
        return "" if self.answer_at is not None and self.t >= self.answer_at else None

    def cycles(self) -> int:
        return int(self.rate * min(self.t, self.cycles_until))

    def failed(self) -> bool:
        return self.failed_at is not None and self.t >= self.failed_at

    def wait(self, timeout: float = 3.0, cycle_s: float = 0.004) -> str:
        return await_answer(self.receive, lambda: self.alive, self.cycles, self.failed,
                            timeout, cycle_s, clock=lambda: self.t)


def test_the_parent_waits_in_controller_cycles_not_on_the_wall_clock():
    """A controller whose cycles come at half speed (a loaded machine): the motion takes
    twice its time on the wall clock, and the parent still gets the child's answer."""
    child = _Child(rate=125.0, answer_at=2 * (3.0 + ANSWER_GRACE_S) - 1.0)
    assert child.wait() == ""
    # … but not forever: past the motion's timeout counted in cycles, it gives up
    child = _Child(rate=125.0)
    with pytest.raises(NoAnswerError, match=r"within 1500 controller cycles"):
        child.wait()
    assert child.t == pytest.approx(2 * (3.0 + ANSWER_GRACE_S), abs=0.1)


def test_the_parent_gives_up_without_cycles_a_dead_child_or_a_failed_session():
    child = _Child()
    child.cycles_until = 1.0  # the stream stopped after a second, the child silent
    with pytest.raises(NoAnswerError, match=r"no controller cycle for 6\.\d s"):
        child.wait()
    assert child.t == pytest.approx(1.0 + 3.0 + ANSWER_GRACE_S, abs=0.1)
    child = _Child()
    child.alive = False
    with pytest.raises(NoAnswerError, match="has exited"):
        child.wait()
    assert child.t == pytest.approx(0.05)
    child = _Child()
    child.failed_at = 0.5  # the session failed; the child does not answer
    with pytest.raises(NoAnswerError, match="did not answer after its stream failed"):
        child.wait()
    assert child.t == pytest.approx(0.5 + FAILED_GRACE_S, abs=0.1)


def test_the_publisher_writes_a_consistent_state():
    """The seqlock: even after a write, the values of the link, the failure's text once per
    failure."""
    import multiprocessing

    from plugcell.devices.robot.stream.errors import StreamStoppedError
    from plugcell.devices.robot.stream.process import FAILURES, JOINTS, SEQ, SLOTS, TEXT_BYTES

    ctx = multiprocessing.get_context("spawn")
    values, text = ctx.RawArray("d", SLOTS), ctx.RawArray("c", TEXT_BYTES)
    publish = Publisher(values, text)

    class _Link:
        failure = None
        streaming = True
        latest = type("S", (), {"joints": Q0})()
        _sessions, _received, _answered, _late, _missed = 1, 5, 5, 0, 0

    link = _Link()
    publish(link)
    v = np.frombuffer(values)
    assert v[SEQ] == 2 and v[FAILURES] == 0
    np.testing.assert_array_equal(v[JOINTS], Q0)
    link.failure = StreamStoppedError("x" * 5000)  # longer than the text: cut, not broken
    publish(link)
    publish(link)
    assert v[SEQ] == 6 and v[FAILURES] == 1
    assert text.value == b"x" * (TEXT_BYTES - 1)


def test_only_whole_joint_commands_are_streamed_from_the_pc():
    assert "EGM link is configured for pose" in drive_refusal(
        EgmConfig(robot_host="127.0.0.1", mode="pose"))
    assert "RSI link is configured for relative joint" in drive_refusal(
        RsiConfig(robot_host="127.0.0.1", mode="relative"))
    assert drive_refusal(RsiConfig(robot_host="127.0.0.1", mode="absolute")) == ""


@pytest.mark.slow
def test_the_child_ends_when_its_parent_is_killed(tmp_path):
    """A parent killed outright (no close) leaves no link process behind: the pipe's end of
    file ends the child."""
    script = tmp_path / "parent.py"
    script.write_text(
        "from plugcell.devices.robot.egm import EgmConfig\n"
        "from plugcell.devices.robot.stream.process import LinkProcess\n"
        "import time\n"
        "if __name__ == '__main__':\n"
        "    link = LinkProcess(EgmConfig(robot_host='127.0.0.1', listen_host='127.0.0.1',\n"
        "                                 listen_port=0))\n"
        "    link.start()\n"
        "    print(link._proc.pid, flush=True)\n"
        "    time.sleep(60)\n")
    parent = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, text=True)
    try:
        child = int(parent.stdout.readline())  # type: ignore[union-attr]
        parent.send_signal(signal.SIGKILL)
        parent.wait(10)
        end = time.monotonic() + 10
        while time.monotonic() < end and _alive(child):
            time.sleep(0.05)
        assert not _alive(child)
    finally:
        if parent.poll() is None:
            parent.kill()


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    from pathlib import Path

    stat = Path(f"/proc/{pid}/stat").read_text()  # a zombie (not yet reaped) is gone
    return stat.rsplit(")", 1)[1].split()[0] != "Z"
