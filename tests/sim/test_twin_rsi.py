"""The twin's robot side of RSI (plugcell.sim.controller.rsi_robot) driven by plugcell's
sensor side (RsiLink) over UDP on loopback: a joint PTP from plugcell.motion streamed as
absolute or relative corrections moves the dynamic twin, whose joints follow within
the following error its dynamics predict; a late sensor is counted in <Delay>; past
Timeout the twin stops RSI and the link sees the silence."""

from __future__ import annotations

import dataclasses
import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from plugcell.devices.robot.rsi import (
    ControllerStoppedError,
    Correction,
    CorrectionLimits,
    CycleState,
    RsiConfig,
    RsiLink,
    StreamStoppedError,
)
from plugcell.devices.robot.rsi.codec import PacketError, encode_rob, parse_rob, parse_sen
from plugcell.io.units import DEG
from plugcell.motion import PTP, JointLimits, plan
from plugcell.sim.controller.rsi_robot import RsiRobot
from plugcell.sim.twin.dynamics import DynamicTwin
from plugcell.sim.twin.scenario import TwinScenario

CYCLE = 0.004
SCENARIO = TwinScenario(robot="smart_h4", payload_kg=36.0)
LIMITS = CorrectionLimits((0.5 * DEG,) * 6, (20 * DEG,) * 6, (60 * DEG,) * 6)


def _config(**kw) -> RsiConfig:
    return RsiConfig(robot_host="127.0.0.1", listen_host="127.0.0.1", listen_port=0,
                     limits=LIMITS, **kw)


def _robot(link: RsiLink, **kw) -> RsiRobot:
    cfg = dataclasses.replace(link.config, listen_port=link.address[1], **kw)
    return RsiRobot(DynamicTwin(SCENARIO), cfg, record=True).start()


def _ptp() -> tuple[np.ndarray, np.ndarray]:
    """The PTP's offsets from the start, one row per cycle (rad), and the start."""
    arm = DynamicTwin(SCENARIO)
    q0 = arm.measured.copy()
    target = q0 + np.array([6.0, 0.0, -4.0, 0.0, 3.0, 0.0]) * DEG
    traj = plan(arm.twin.description, q0, [PTP(target=target)],
                JointLimits.uniform(6, 20 * DEG, 60 * DEG, 600 * DEG))
    return traj.sample(traj.cycle_times(CYCLE), 0).q - q0, q0


def _predicted_following_error(offsets: np.ndarray, q0: np.ndarray) -> float:
    """The dynamics' own prediction: the arm offline on the ideal command (one cycle of
    the RSI round later), the largest |link − path|."""
    arm = DynamicTwin(SCENARIO)
    cmd = q0 + np.vstack([offsets[:1], offsets, np.repeat(offsets[-1:], 100, 0)])
    out = arm.run(cmd)
    path = q0 + np.vstack([offsets, np.repeat(offsets[-1:], 101, 0)])
    return float(np.max(np.abs(out["link"] - path)))


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["absolute", "relative"])
def test_rsilink_drives_the_twin_through_a_ptp(mode: str) -> None:
    offsets, q0 = _ptp()
    n = len(offsets)
    start: dict[str, object] = {}

    def source(state: CycleState) -> Correction:
        first = start.setdefault("cycle", state.cycle)  # the motion starts now
        k = min(state.cycle - first, n - 1)
        if mode == "absolute":
            return Correction(offset=offsets[k])
        q = state.robot.joints_setpoint  # ASPos: the commanded joints, closed on them
        start.setdefault("q", q.copy())
        return Correction(step=offsets[k] - (q - start["q"]))

    with RsiLink(_config(mode=mode, timeout_packets=1000)) as link:
        robot = _robot(link)
        try:
            link.follow(source, done=lambda s: s.cycle - start["cycle"] >= n + 150,
                        timeout=60.0)
        finally:
            robot.stop()
    st = robot.stats()
    assert link.failure is None and robot.stopped is None
    log = st.log
    links = np.array([x[2] for x in log])
    commands = np.array([x[1] for x in log])
    target = q0 + offsets[-1]
    np.testing.assert_allclose(commands[-1], target, atol=1e-6)  # the stream arrived
    lost = DynamicTwin(SCENARIO).twin.reveal_truth().profile.lost_motion
    # the twin is the dynamics: the same commands offline give the same arm, bit for bit
    again = DynamicTwin(SCENARIO)
    replay = again.run(commands)
    np.testing.assert_array_equal(replay["link"], links)
    # and once the mode has rung out the arm is at the target, up to half the lost motion
    settled = again.run(np.repeat(commands[-1:], 500, 0))["link"][-1]
    np.testing.assert_allclose(settled, target, atol=0.5 * lost + 2e-5)
    # its joints followed the path within the following error the dynamics predict
    # (a cycle the sensor answered late holds the command: one more cycle of lag each)
    first = int(np.argmax(np.any(np.abs(commands - q0) > 1e-9, axis=1)))
    path = q0 + np.vstack([offsets, np.repeat(offsets[-1:], len(log), 0)])[:len(log) - first]
    error = np.max(np.abs(links[first:] - path))
    step = np.max(np.abs(np.diff(offsets, axis=0)))
    assert error <= _predicted_following_error(offsets, q0) + 2 * (st.delay + 1) * step + 1e-5


@pytest.mark.slow
def test_a_late_sensor_is_counted_by_the_twin() -> None:
    def source(state: CycleState) -> None:
        if state.cycle == 40:
            time.sleep(0.03)  # several cycles late

    with RsiLink(_config(mode="relative", timeout_packets=1000), source) as link:
        robot = _robot(link)
        try:
            assert link.wait(lambda lk: lk.stats().controller_late >= 1
                             and robot.stats().cycles > 80, timeout=20.0), robot.stats()
        finally:
            robot.stop()
    assert robot.stats().delay >= 1  # the twin counted it and reported it in <Delay>
    assert link.stats().late >= 1
    assert robot.stopped is None  # far below Timeout


@pytest.mark.slow
def test_past_timeout_the_twin_stops_rsi() -> None:
    def source(state: CycleState) -> None:
        if state.cycle >= 20:
            time.sleep(0.012)  # every answer late from here on

    with RsiLink(_config(mode="relative", timeout_packets=100), source) as link:
        robot = _robot(link, timeout_packets=10)
        try:
            deadline = time.monotonic() + 20
            while robot.running and time.monotonic() < deadline:
                time.sleep(0.01)
            assert not robot.running
            assert robot.stopped is not None and "Timeout of 10" in robot.stopped
            assert robot.stats().delay >= 10
            assert link.wait(lambda lk: lk.failure is not None, timeout=5.0), link.stats()
            assert isinstance(link.failure, (StreamStoppedError, ControllerStoppedError))
        finally:
            robot.stop()


def test_the_robot_packet_reads_back_and_answers_are_checked() -> None:
    q = np.array([0.1, -1.2, 0.3, 0.0, 0.5, -0.2])
    x = np.array([1.2, -0.1, 0.9, 0.3, -0.2, 0.1])
    st = parse_rob(encode_rob(1234, q, x, delay=3, signals={"DiL": 5}))
    assert st.ipoc == 1234 and st.delay == 3 and st.signals == {"DiL": 5.0}
    np.testing.assert_allclose(st.joints, q, atol=1e-6)
    np.testing.assert_allclose(st.tcp, x, atol=1e-6)
    ans = parse_sen(b'<Sen Type="ImFree"><AKorr A1="1" A2="0" A3="0" A4="0" A5="0" A6="-2"/>'
                    b"<DiO>5</DiO><IPOC>77</IPOC></Sen>", "joint")
    assert ans.ipoc == 77 and ans.signals == {"DiO": 5.0}
    np.testing.assert_allclose(ans.correction, np.array([1, 0, 0, 0, 0, -2]) * DEG)
    for bad, why in [(b"<Sen><IPOC>1</IPOC></Sen>", "no <AKorr>"),
                     (b'<Sen><RKorr X="0" Y="0" Z="0" A="0" B="0" C="0"/><IPOC>1</IPOC></Sen>',
                      "the controller expects <AKorr>"),
                     (b'<Sen><AKorr A1="nan" A2="0" A3="0" A4="0" A5="0" A6="0"/>'
                      b"<IPOC>1</IPOC></Sen>", "not finite"),
                     (b'<Rob Type="KUKA"><IPOC>1</IPOC></Rob>', "expected <Sen"),
                     (b"<Sen", "not well-formed")]:
        with pytest.raises(PacketError, match=why):
            parse_sen(bad, "joint")


@settings(max_examples=300, deadline=None)
@given(st.one_of(st.binary(max_size=300),
                 st.builds(lambda a, i: (f'<Sen Type="ImFree"><AKorr A1="{a}" A2="0" A3="0" '
                                         f'A4="0" A5="0" A6="0"/><IPOC>{i}</IPOC></Sen>'
                                         ).encode(), st.text(max_size=6), st.text(max_size=6))),
       st.sampled_from(["joint", "cartesian"]))
def test_parse_sen_reads_or_refuses_anything(data: bytes, kind: str) -> None:
    """Whatever arrives at the controller's port: an answer or a PacketError, nothing else."""
    try:
        ans = parse_sen(data, kind)
    except PacketError as exc:
        assert exc.kind in ("malformed", "oversized", "foreign")
        return
    assert ans.correction.shape == (6,) and np.all(np.isfinite(ans.correction))
