"""The EGM link against the simulated controller (sim/controller/egm_robot.py) and a bare
robot socket: targets reach the robot, limits hold, garbage and strangers are dropped
and counted, late and lost cycles are counted, a stream that stops fails within one
CommTimeout and the link recovers when the robot comes back."""

from __future__ import annotations

import time

import numpy as np
import pytest
from egm_testlib import BareRobot, local_config, robot_message, started, wait_until

from plugcell.devices.robot.egm import (
    Correction,
    CorrectionLimits,
    CorrectionRefusedError,
    EgmConfig,
    EgmConfigError,
    SourceFailedError,
    StreamStoppedError,
)
from plugcell.devices.robot.egm.messages import egm_pb2
from plugcell.io.units import DEG
from plugcell.sim.controller.egm_robot import EgmRobotSim


def joints_of(answer: bytes) -> np.ndarray:
    m = egm_pb2.EgmSensor()
    m.ParseFromString(answer)
    return np.array(m.planned.joints.joints)


@pytest.fixture
def pair():
    made = []

    def make(mode="joint", source=None, go=True, **kw):
        """The link and the simulated robot, streaming (``go=False``: the robot not yet
        started, so a test can read where it stands before the first correction)."""
        link = started(local_config(mode=mode, **kw), source)
        robot = EgmRobotSim(link.address, mode=mode)
        if go:
            robot.start()
        made.append((link, robot))
        return link, robot

    yield make
    for link, robot in made:
        robot.stop()
        link.close()


def test_joint_targets_move_the_simulated_robot(pair) -> None:
    target = np.array([0, 0, 0, 0, 0, 2 * DEG])
    link, robot = pair("joint", lambda s: Correction(offset=target), go=False)
    start = robot.state()["joints"]  # before the first packet: nothing moved it yet
    robot.start()
    assert wait_until(lambda: np.allclose(robot.state()["joints"], start + target,
                                          atol=1e-6), 3.0)
    st = link.stats()
    assert st.sessions == 1 and st.refused == 0 and st.answered > 0
    assert st.clamped > 0  # 2° at once is beyond 0.08° a cycle (20°/s): ramped, counted
    assert "A6 speed" in st.last_reason


def test_pose_targets_move_and_turn_the_tcp(pair) -> None:
    offset = np.array([0.002, -0.001, 0.0, 0.0, 0.0, 1 * DEG])
    _link, robot = pair("pose", lambda s: Correction(offset=offset), go=False)
    p0, q0 = robot.state()["position"], robot.state()["quaternion"]  # before it streams
    robot.start()
    from scipy.spatial.transform import Rotation

    want = (Rotation.from_rotvec(offset[3:]) * Rotation.from_quat(q0, scalar_first=True))
    assert wait_until(lambda: np.allclose(robot.state()["position"], p0 + offset[:3],
                                          atol=1e-7), 15.0)
    assert wait_until(lambda: (want.inv() * Rotation.from_quat(
        robot.state()["quaternion"], scalar_first=True)).magnitude() < 1e-4, 15.0)


def test_path_corrections_are_added_to_the_robots_own_path(pair) -> None:
    _link, robot = pair("pathcorr", lambda s: Correction(offset=[0, 0.001, -0.0005, 0, 0, 0]))
    assert wait_until(lambda: np.allclose(robot.state()["correction"], [0, 0.001, -0.0005]),
                      15.0)
    s = robot.state()
    assert wait_until(lambda: np.allclose(robot.state()["position"] - robot.state()[
        "path_start"], [0, 0.001, -0.0005], atol=1e-7), 15.0), s


def test_a_path_correction_with_a_rotation_is_refused(pair) -> None:
    link, robot = pair("pathcorr", lambda s: Correction(offset=[0, 0, 0, 0.001, 0, 0]))
    assert link.wait(lambda lk: lk.failure is not None, 2.0)
    assert isinstance(link.failure, CorrectionRefusedError)
    assert "a path correction has no rotation" in str(link.failure)
    assert np.allclose(robot.state()["correction"], 0)


def test_beyond_the_limits_with_refuse_nothing_moves() -> None:
    lim = CorrectionLimits((0.1 * DEG,) * 6, (1 * DEG,) * 6, (20 * DEG,) * 6, "refuse")
    link = started(local_config(limits=lim), lambda s: Correction(offset=np.full(6, DEG)))
    robot = BareRobot(link.address)
    try:
        first = joints_of(robot.cycle())
        np.testing.assert_allclose(first, [0, 10, 20, 0, 30, 0])  # held where it was
        assert isinstance(link.failure, CorrectionRefusedError)
        assert "A1 speed 250 deg/s > 20 deg/s" in str(link.failure)  # the joint speed
        for _ in range(5):  # the session stays held
            np.testing.assert_allclose(joints_of(robot.cycle()), first)
    finally:
        robot.close()
        link.close()


@pytest.mark.parametrize("bad", [np.full(6, np.nan), np.zeros(5)])
def test_a_target_that_is_none_is_refused(bad) -> None:
    link = started(local_config(), lambda s: Correction(offset=bad))
    robot = BareRobot(link.address)
    try:
        np.testing.assert_allclose(joints_of(robot.cycle()), [0, 10, 20, 0, 30, 0])
        assert isinstance(link.failure, CorrectionRefusedError)
    finally:
        robot.close()
        link.close()


def test_a_failing_source_holds_the_robot_and_says_why() -> None:
    def source(state):
        raise KeyError("trajectory")

    link = started(local_config(), source)
    robot = BareRobot(link.address)
    try:
        np.testing.assert_allclose(joints_of(robot.cycle()), [0, 10, 20, 0, 30, 0])
        assert isinstance(link.failure, SourceFailedError)
        assert "KeyError" in str(link.failure)
    finally:
        robot.close()
        link.close()


def test_strangers_and_garbage_are_dropped_and_counted() -> None:
    link = started(EgmConfig(robot_host="127.0.0.2", listen_host="127.0.0.1",
                             listen_port=0))
    robot = BareRobot(link.address)
    try:
        robot.send(robot_message(1))  # from 127.0.0.1: not the configured robot
        assert robot.no_answer()
        assert wait_until(lambda: link.stats().dropped["address"] == 1)
    finally:
        robot.close()
        link.close()
    link = started(local_config())
    robot = BareRobot(link.address)
    try:
        robot.cycle()
        for junk in (b"", b"\xff" * 30, b"x" * 5000, robot_message(2)[:15],
                     robot_message(1)):  # the last: the same seqno again, stale
            robot.send(junk)
        assert robot.no_answer(0.1)
        st = link.stats()
        assert wait_until(lambda: sum(link.stats().dropped.values()) == 5)
        st = link.stats()
        assert st.dropped["oversized"] == 1 and st.dropped["stale"] == 1
        assert st.answered == 1
    finally:
        robot.close()
        link.close()


def test_a_stream_restarted_by_the_controller_is_a_new_session() -> None:
    link = started(local_config(), lambda s: Correction(offset=np.full(6, 0.01 * DEG)))
    robot = BareRobot(link.address)
    try:
        robot.seqno = 1000
        for _ in range(3):
            robot.cycle()
        robot.send(robot_message(999))  # one message late on the way: stale
        assert robot.no_answer()
        robot.seqno = 0  # EGMReset and a new EGMRunJoint: seqno counts from 1 again
        answer = joints_of(robot.cycle(joints_deg=(1, 2, 3, 4, 5, 6)))
        np.testing.assert_allclose(answer, np.arange(1, 7) + 0.01)  # from the new start
        assert link.stats().sessions == 2 and link.stats().dropped["stale"] == 1
        assert link.failure is None
    finally:
        robot.close()
        link.close()


def test_lost_cycles_are_counted_and_too_many_fail_the_stream() -> None:
    link = started(local_config(comm_timeout_s=0.02))  # 5 cycles
    robot = BareRobot(link.address)
    try:
        robot.cycle()
        robot.seqno += 3  # three messages lost on the way
        robot.cycle()
        assert wait_until(lambda: link.stats().missed == 3) and link.failure is None
        robot.seqno += 3
        robot.cycle()
        assert link.wait(lambda lk: lk.failure is not None, 1.0)  # set after the answer
        assert isinstance(link.failure, StreamStoppedError)
        assert "6 cycles in a row missed or late" in str(link.failure)
    finally:
        robot.close()
        link.close()


def test_a_sequence_number_a_timeout_ahead_is_dropped_as_inconsistent() -> None:
    """One message whose seqno jumps a whole controller timeout ahead (a corrupted number:
    the stream would have been silent that long) is dropped; the stream goes on."""
    link = started(local_config(comm_timeout_s=0.02))  # 5 cycles
    robot = BareRobot(link.address)
    try:
        robot.cycle()
        robot.send(robot_message(robot.seqno + 6))  # no answer: dropped
        assert wait_until(lambda: link.stats().dropped["inconsistent"] == 1)
        robot.cycle()  # the next genuine message
        assert wait_until(lambda: link.stats().answered == 2) and link.failure is None
    finally:
        robot.close()
        link.close()


def test_a_late_answer_is_counted() -> None:
    def slow(state):
        time.sleep(0.006)

    link = started(local_config(), slow)
    robot = BareRobot(link.address)
    try:
        robot.cycle()
        assert wait_until(lambda: link.stats().late == 1)
    finally:
        robot.close()
        link.close()


def test_a_robot_that_goes_fails_the_stream_within_one_timeout_and_comes_back() -> None:
    link = started(local_config(comm_timeout_s=0.2),
                   lambda s: Correction(offset=[0, 0, 0, 0, 0, 0.1 * DEG]))
    robot = EgmRobotSim(link.address, comm_timeout_s=0.2).start()
    try:
        assert link.wait(lambda lk: lk.stats().answered > 20, 3.0)
        robot.stop()  # the controller's program stops: silence
        gone = time.monotonic()
        assert link.wait(lambda lk: not lk.streaming, 2.0)
        assert time.monotonic() - gone < 0.2 + 0.15  # one CommTimeout (+ the test's slack)
        assert isinstance(link.failure, StreamStoppedError)
        assert "no packet from the controller" in str(link.failure)
        robot = EgmRobotSim(link.address, comm_timeout_s=0.2).start()  # back
        assert link.wait(lambda lk: lk.streaming and lk.stats().sessions == 2, 3.0)
        assert link.wait(lambda lk: lk.failure is None, 1.0)
        assert wait_until(lambda: abs(robot.state()["joints"][5] - 0.1 * DEG) < 1e-6, 3.0)
    finally:
        robot.stop()
        link.close()


def test_the_simulated_controller_stops_after_its_timeout() -> None:
    import socket

    sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)  # a sensor that never answers
    sink.bind(("127.0.0.1", 0))
    robot = EgmRobotSim(sink.getsockname(), comm_timeout_s=0.1).start()
    try:
        assert robot.wait_stopped(2.0)
        assert "EGM communication timeout" in robot.stopped
        assert robot.unanswered >= 20
    finally:
        robot.stop()
        sink.close()


@pytest.mark.parametrize(("kw", "says"), [
    ({"mode": "cartesian"}, "mode 'cartesian'"),
    ({"sample_rate_ms": 6}, "multiple of 4"),
    ({"comm_timeout_s": 0.001}, "CommTimeout"),
    ({"robot_host": "irb.local"}, "robot_host 'irb.local': expected an IP address"),
    ({"listen_port": 70000}, "listen_port 70000"),
])
def test_a_wrong_configuration_names_the_field(kw, says) -> None:
    args = {"robot_host": "127.0.0.1"} | kw
    with pytest.raises(EgmConfigError, match=says):
        EgmConfig(**args)


def test_a_correction_ramped_out_faster_than_the_limits_ends_only_at_zero() -> None:
    """The controller's clock jumps past a correction's ramp out (its samples came late on
    a loaded machine, as the simulated controller's do): the ramp asks zero at once, the
    limits let the offset down 0.2 mm a cycle, and the correction ends when what the link
    sends is zero again — ending at the first cycle the ramp asked zero left the rest on
    the robot's path (0.16–0.39 mm in two CI runs under load)."""
    from plugcell.devices.robot.stream.correcting import CorrectionSpec, Corrector

    link = started(local_config(mode="pathcorr"))
    robot = BareRobot(link.address)

    def correction_mm(answer: bytes) -> float:
        m = egm_pb2.EgmSensorPathCorr()
        m.ParseFromString(answer)
        return m.pathCorr.pos.y

    try:
        robot.cycle()
        assert link.wait(lambda lk: lk.streaming, 2.0)
        corrector = Corrector(link)
        corrector.start(CorrectionSpec("offset", (0, 0.5e-3, 0, 0, 0, 0), frame="path",
                                       ramp_s=0.02, duration_s=0.2))
        sent = [correction_mm(robot.cycle()) for _ in range(20)]  # in, held (80 ms)
        assert sent[-1] == pytest.approx(0.5), sent
        tm = robot.seqno * 4 + 200  # the clock 200 ms on: the ramp out starts …
        assert correction_mm(robot.cycle(tm=tm)) == pytest.approx(0.5)
        tm += 100  # … and the next sample comes after its end
        sent.append(correction_mm(robot.cycle(tm=tm)))
        assert sent[-1] == pytest.approx(0.3)  # down the limits' 0.2 mm, not to zero
        for _ in range(10):
            tm += 4
            sent.append(correction_mm(robot.cycle(tm=tm)))
        assert wait_until(lambda: corrector.poll() is not None)
        assert corrector.poll() == ""
        np.testing.assert_allclose(sent[-11:-7], [0.3, 0.1, 0.0, 0.0], atol=1e-12)
        tm += 4  # after the end the link holds what it sent last: zero
        assert correction_mm(robot.cycle(tm=tm)) == 0.0
    finally:
        robot.close()
        link.close()
