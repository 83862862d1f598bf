"""The RSI link on a real UDP socket, against a bare robot side written in the test:
answers, corrections in every mode, routed outputs, and every fault the issue lists —
dropped datagrams, gaps, late answers, the controller's Timeout, refused corrections,
a failing source, a controller that goes silent and comes back."""

from __future__ import annotations

import socket
import time
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from rsi_testlib import BareRobot, local_config, rob_packet, started, wait_until

from plugcell.devices.robot.rsi import (
    ControllerStoppedError,
    Correction,
    CorrectionLimits,
    CorrectionRefusedError,
    CycleState,
    OutputSignal,
    SourceFailedError,
    StreamStoppedError,
)
from plugcell.io.units import DEG

JOINTS = ("A1", "A2", "A3", "A4", "A5", "A6")


def values(answer: bytes, tag: str = "AKorr") -> np.ndarray:
    el = ET.fromstring(answer).find(tag)
    keys = JOINTS if tag == "AKorr" else ("X", "Y", "Z", "A", "B", "C")
    return np.array([float(el.get(k)) for k in keys])


def ipoc(answer: bytes) -> int:
    return int(ET.fromstring(answer).find("IPOC").text)


def settled(link, answered: int):
    """The counters once the link has finished its ``answered``-th cycle (the robot may
    read an answer before the link's thread has counted it)."""
    assert link.wait(lambda lk: lk.stats().answered >= answered, timeout=2.0)
    assert link.wait(lambda lk: lk._cycle >= answered or not lk.streaming, timeout=2.0)
    return link.stats()


def failed(link):
    link.wait(lambda lk: lk.failure is not None, timeout=2.0)
    return link.failure


@pytest.fixture
def robot_and(request):
    """``robot_and(config, source)`` → (link, robot); both closed after the test."""
    made = []

    def make(config=None, source=None, **kw):
        link = started(config or local_config(), source, **kw)
        robot = BareRobot(link.address, link.config.ipoc_step)
        made.append((link, robot))
        return link, robot

    yield make
    for link, robot in made:
        robot.close()
        link.close()


def test_each_packet_is_answered_with_its_ipoc_and_the_robot_state_reaches_the_source(
        robot_and) -> None:
    seen: list[CycleState] = []

    def source(state: CycleState):
        seen.append(state)
        return None

    link, robot = robot_and(source=source)
    for _ in range(5):
        answer = robot.cycle(joints_deg=(1, 2, 3, 4, 5, 6), dil=9)
        assert ipoc(answer) == robot.ipoc
        np.testing.assert_array_equal(values(answer), 0.0)  # no source wish: no motion
    assert [s.cycle for s in seen] == [0, 1, 2, 3, 4]
    assert [s.t for s in seen] == pytest.approx([0, 0.004, 0.008, 0.012, 0.016])
    np.testing.assert_allclose(seen[-1].robot.joints, np.deg2rad([1, 2, 3, 4, 5, 6]))
    assert seen[-1].robot.signals["DiL"] == 9
    st = settled(link, 5)
    assert (st.received, st.answered, st.sessions, st.missed) == (5, 5, 1, 0)
    assert st.streaming and link.failure is None


def test_joint_relative_sends_steps_and_absolute_the_offset(robot_and) -> None:
    ramp = lambda s: Correction(offset=np.full(6, 0.01 * DEG) * (s.cycle + 1))  # noqa: E731
    _, rel = robot_and(local_config(mode="relative"), ramp)
    _, ab = robot_and(local_config(mode="absolute"), ramp)
    for k in range(1, 4):
        np.testing.assert_allclose(values(rel.cycle()), 0.01, atol=1e-6)
        np.testing.assert_allclose(values(ab.cycle()), 0.01 * k, atol=1e-6)


def test_a_step_source_in_absolute_mode_accumulates(robot_and) -> None:
    _, robot = robot_and(local_config(mode="absolute"),
                         lambda s: Correction(step=[0, 0.02 * DEG, 0, 0, 0, 0]))
    got = [values(robot.cycle())[1] for _ in range(3)]
    np.testing.assert_allclose(got, [0.02, 0.04, 0.06], atol=1e-6)


def test_cartesian_corrections_leave_in_mm_and_degrees(robot_and) -> None:
    _, robot = robot_and(local_config(correction="cartesian"),
                         lambda s: Correction(step=[1e-4, 0, -2e-4, 0.01 * DEG, 0, 0]))
    answer = robot.cycle()
    np.testing.assert_allclose(values(answer, "RKorr"), [0.1, 0, -0.2, 0.01, 0, 0], atol=1e-6)
    assert ET.fromstring(answer).find("AKorr") is None


def test_output_words_are_routed_and_kept(robot_and) -> None:
    outs = (OutputSignal("DiO", 16, initial=3), OutputSignal("Stop", 1))
    wish = {0: {"DiO": 0xBEEF}, 2: {"Stop": True}}
    _, robot = robot_and(local_config(outputs=outs),
                         lambda s: Correction(outputs=wish.get(s.cycle, {})))
    got = [(ET.fromstring(a).find("DiO").text, ET.fromstring(a).find("Stop").text)
           for a in (robot.cycle() for _ in range(3))]
    assert got == [(str(0xBEEF), "0"), (str(0xBEEF), "0"), (str(0xBEEF), "1")]


@pytest.mark.parametrize(("outputs", "reason"), [
    ({"DiO": 1 << 16}, "output DiO = 65536: expected an integer in [0, 65536)"),
    ({"DiO": -1}, "output DiO = -1"),
    ({"DiO": 1.5}, "output DiO = 1.5"),
    ({"Gripper": 1}, "output 'Gripper' is not configured"),
])
def test_a_wrong_output_is_refused_and_fails_the_stream(robot_and, outputs, reason) -> None:
    link, robot = robot_and(local_config(outputs=(OutputSignal("DiO", 16),)),
                            lambda s: Correction(step=np.full(6, 1e-4), outputs=outputs))
    answer = robot.cycle()
    np.testing.assert_array_equal(values(answer), 0.0)  # held
    assert ET.fromstring(answer).find("DiO").text == "0"
    assert isinstance(failed(link), CorrectionRefusedError)
    assert reason in str(link.failure)
    assert link.stats().refused == 1


def test_beyond_the_limits_clamp_cuts_and_counts(robot_and) -> None:
    link, robot = robot_and(local_config(), lambda s: Correction(step=[1.0 * DEG, 0, 0, 0, 0, 0]))
    for _ in range(3):
        np.testing.assert_allclose(values(robot.cycle()), [0.08, 0, 0, 0, 0, 0], atol=1e-6)
    st = settled(link, 3)
    assert st.clamped == 3 and link.failure is None
    assert "A1 speed 250 deg/s > 20 deg/s" in st.last_reason  # the default 20°/s binds


def test_beyond_the_limits_refuse_holds_and_fails(robot_and) -> None:
    lim = CorrectionLimits((0.1 * DEG,) * 6, (1 * DEG,) * 6, (90 * DEG,) * 6, "refuse")
    link, robot = robot_and(local_config(limits=lim, mode="absolute"),
                            lambda s: Correction(offset=np.full(6, 0.05 * DEG) * (s.cycle + 1)
                                                 * (1 if s.cycle < 2 else 10)))
    np.testing.assert_allclose(values(robot.cycle()), 0.05, atol=1e-6)
    np.testing.assert_allclose(values(robot.cycle()), 0.10, atol=1e-6)
    np.testing.assert_allclose(values(robot.cycle()), 0.10, atol=1e-6)  # 1.5°: refused
    np.testing.assert_allclose(values(robot.cycle()), 0.10, atol=1e-6)  # held after
    assert isinstance(failed(link), CorrectionRefusedError)
    assert "A1 step 1.4 deg per cycle > 0.1 deg" in str(link.failure)
    assert link.stats().refused == 1


def test_a_failing_source_holds_the_robot(robot_and) -> None:
    def source(s):
        if s.cycle == 1:
            raise ZeroDivisionError("the trajectory ran out")
        return Correction(step=np.full(6, 0.01 * DEG))

    link, robot = robot_and(local_config(), source)
    np.testing.assert_allclose(values(robot.cycle()), 0.01, atol=1e-6)
    for _ in range(2):
        np.testing.assert_array_equal(values(robot.cycle()), 0.0)
    assert isinstance(failed(link), SourceFailedError)
    assert "ZeroDivisionError: the trajectory ran out" in str(link.failure)


def test_garbage_is_dropped_counted_and_never_answered(robot_and) -> None:
    link, robot = robot_and(source=lambda s: Correction(step=np.full(6, 1e-4)))
    robot.cycle()
    junk = [b"", b"\x00\xff", b"<Rob", b'<Rob Type="KUKA"><IPOC>x</IPOC></Rob>',
            b'<Sen Type="ImFree"><IPOC>7</IPOC></Sen>', b"<" * 5000,
            rob_packet(robot.ipoc)]  # the same IPOC again: stale
    for d in junk:
        robot.send(d)
    assert robot.no_answer()
    st = link.stats()
    assert st.dropped == {"address": 0, "oversized": 1, "malformed": 4, "foreign": 1,
                          "stale": 1, "inconsistent": 0}
    assert st.answered == 1 and link.failure is None
    assert ipoc(robot.cycle()) == robot.ipoc  # the stream goes on


def test_a_packet_from_another_address_is_dropped(robot_and) -> None:
    link, robot = robot_and()
    other = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        other.bind(("127.0.0.2", 0))  # all of 127/8 is loopback on Linux
    except OSError:
        pytest.skip("no second loopback address here")
    with other:
        other.sendto(rob_packet(5), link.address)
        assert wait_until(lambda: link.stats().dropped["address"] == 1)
    assert link.stats().received == 0 and not link.streaming
    # a fixed robot port: another port of the right host is foreign too
    pinned, robot2 = robot_and(local_config(robot_port=robot.sock.getsockname()[1]))
    robot2.send(rob_packet(5))
    assert wait_until(lambda: pinned.stats().dropped["address"] == 1)
    robot.sock.sendto(rob_packet(5), pinned.address)
    assert robot.sock.recv(1000)


def test_ipoc_gaps_are_missed_cycles(robot_and) -> None:
    link, robot = robot_and()
    robot.cycle()
    robot.ipoc += 3 * 4  # three packets lost on the way
    robot.cycle()
    assert settled(link, 2).missed == 3 and link.failure is None


def test_queued_packets_are_superseded_by_the_newest(robot_and) -> None:
    gate = {"wait": True}

    def slow_once(s):
        if gate.pop("wait", False):
            time.sleep(0.05)  # three packets queue up meanwhile
        return None

    link, robot = robot_and(source=slow_once)
    robot.ipoc += 4
    robot.send(rob_packet(robot.ipoc))
    time.sleep(0.01)
    for _ in range(3):
        robot.ipoc += 4
        robot.send(rob_packet(robot.ipoc))
    answers = [ipoc(robot.sock.recv(1000)), ipoc(robot.sock.recv(1000))]
    assert answers == [robot.ipoc - 12, robot.ipoc]
    st = settled(link, 2)
    assert (st.superseded, st.missed, st.late) == (2, 2, 1)


def test_late_answers_in_a_row_up_to_the_timeout_stop_the_stream(robot_and) -> None:
    # IPO (12 ms): the silence timeout, 5 × 12 ms, leaves the test's own pace room
    link, robot = robot_and(local_config(timeout_packets=5, cycle="IPO"),
                            lambda s: time.sleep(0.013) or Correction(step=np.full(6, 1e-4)))
    for _ in range(4):
        robot.cycle()
    assert settled(link, 4).late == 4 and link.failure is None
    robot.cycle()
    assert isinstance(failed(link), StreamStoppedError)
    assert "5 cycles in a row missed or late (the controller's Timeout is 5)" in str(
        link.failure)
    np.testing.assert_array_equal(values(robot.cycle()), 0.0)  # held from then on


def test_an_answer_in_time_resets_the_run_of_misses(robot_and) -> None:
    link, robot = robot_and(local_config(timeout_packets=4, cycle="IPO"))
    robot.ipoc = 0
    for _ in range(3):
        robot.ipoc += 3 * 12  # two cycles lost before this packet
        robot.send(rob_packet(robot.ipoc))
        robot.sock.recv(1000)
        robot.cycle()
    st = settled(link, 6)
    assert st.missed == 4  # the first packet opens the session: no gap before it
    if st.late:
        pytest.skip("an answer took longer than 12 ms: the machine is too loaded to tell")
    assert link.failure is None  # two in a row at most, never four
    for jump in (4, 2):  # three lost, then one more: four in a row
        robot.ipoc += jump * 12
        robot.send(rob_packet(robot.ipoc))
        robot.sock.recv(1000)
    assert "4 cycles in a row" in str(failed(link))


def test_an_ipoc_beyond_the_timeout_within_a_session_is_inconsistent(robot_and) -> None:
    """No controller sends an IPOC a Timeout ahead while it streams (it would have been
    silent that long): such a packet is dropped, and the stream goes on."""
    link, robot = robot_and(local_config(timeout_packets=50))
    robot.cycle()
    robot.send(rob_packet(robot.ipoc + 51 * 4))  # fifty cycles lost: Timeout
    assert robot.no_answer()
    assert link.stats().dropped["inconsistent"] == 1
    assert ipoc(robot.cycle()) == robot.ipoc and link.failure is None


def test_the_controllers_own_count_stops_the_stream(robot_and) -> None:
    link, robot = robot_and(local_config(timeout_packets=10, cycle="IPO"))
    robot.cycle(delay=7)  # a session starting with Delay 7: the count is from here
    robot.cycle(delay=12)
    assert settled(link, 2).controller_late == 5 and link.failure is None
    robot.cycle(delay=17)
    assert isinstance(failed(link), ControllerStoppedError)
    assert "the controller counted 10 late packets (<Delay>), its Timeout is 10" in str(
        link.failure)


def test_silence_stops_the_stream_within_one_timeout_and_packets_resume_it(robot_and) -> None:
    link, robot = robot_and(local_config(timeout_packets=25, cycle="IPO", mode="absolute"),
                            lambda s: Correction(offset=np.full(6, 0.01 * DEG) * (s.cycle + 1)))
    for _ in range(3):
        robot.cycle()
    silent_from = time.monotonic()
    assert link.wait(lambda lk: not lk.streaming, timeout=5.0)
    stopped_after = time.monotonic() - silent_from
    assert stopped_after >= 0.3 * 0.99  # not before one timeout: 25 × 12 ms
    assert isinstance(link.failure, StreamStoppedError)
    assert "no packet from the controller for 0.3" in str(link.failure)
    assert "(one controller timeout: 25 × 12 ms)" in str(link.failure)
    # the controller comes back (a new RSI_ON): a new session from a zero offset
    answer = robot.cycle()
    np.testing.assert_allclose(values(answer), 0.01, atol=1e-6)
    assert link.streaming and link.failure is None and link.stats().sessions == 2
    assert isinstance(link.last_failure, StreamStoppedError)


def test_every_datagram_is_accounted_for(robot_and) -> None:
    link, robot = robot_and()
    for k in range(20):
        robot.cycle()
        if k % 3 == 0:
            robot.send(b"<junk/>")
    assert wait_until(lambda: sum(link.stats().dropped.values()) == 7)
    st = settled(link, 20)
    assert st.received == st.answered + st.superseded + st.dropped["stale"] == 20


def test_the_link_refuses_a_source_that_is_none() -> None:
    from plugcell.devices.robot.rsi import RsiLink

    with pytest.raises(TypeError, match="correction source"):
        RsiLink(local_config(), source=42)  # type: ignore[arg-type]


def test_a_busy_port_is_an_error_naming_it() -> None:
    holder = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    holder.bind(("127.0.0.1", 0))
    port = holder.getsockname()[1]
    from plugcell.devices.robot.rsi import RsiConfig, RsiLink

    with holder, pytest.raises(OSError, match=f"cannot listen on 127.0.0.1:{port}"):
        RsiLink(RsiConfig(robot_host="127.0.0.1", listen_host="127.0.0.1",
                          listen_port=port)).start()


def test_an_internal_error_is_reported_not_swallowed(robot_and, monkeypatch) -> None:
    from plugcell.devices.robot.rsi import RsiLinkError
    from plugcell.devices.robot.rsi import link as link_module

    link, robot = robot_and()
    robot.cycle()

    def broken(*args, **kwargs):
        raise RuntimeError("encoder broke")

    monkeypatch.setattr(link_module, "encode_sen", broken)
    robot.ipoc += 4
    robot.send(rob_packet(robot.ipoc))
    err = failed(link)
    assert type(err) is RsiLinkError
    assert "internal error at IPOC" in str(err) and "RuntimeError: encoder broke" in str(err)
    assert link._thread.is_alive()  # the link goes on listening


def test_a_cycle_leaves_nothing_for_the_garbage_collector(robot_and) -> None:
    """A cycle frees what it allocates, so the cyclic collector (whose full passes stall a
    process for milliseconds) never runs in a stream (docs/kuka-rsi.md, Performance)."""
    import gc

    link, robot = robot_and(local_config(mode="absolute"),
                            lambda s: Correction(offset=np.full(6, 1e-4 * s.cycle)))
    robot.cycle()
    collections: list[int] = []

    def count(phase, info) -> None:
        if phase == "start":
            collections.append(info["generation"])

    gc.collect()
    gc.callbacks.append(count)
    try:
        for _ in range(3000):
            robot.cycle()
    finally:
        gc.callbacks.remove(count)
    assert settled(link, 3001).answered == 3001
    assert collections == []


def test_real_time_priority_is_asked_for_and_reported(robot_and) -> None:
    from plugcell.devices.robot.rsi import RsiLink

    with pytest.raises(ValueError, match=r"rt_priority 0: expected 1\.\.99"):
        RsiLink(local_config(), rt_priority=0)
    link, robot = robot_and(rt_priority=1)
    robot.cycle()  # the thread has run: its scheduling is settled
    # granted (root or CAP_SYS_NICE) or refused with the reason, never silent
    assert link.rt_note == "SCHED_FIFO priority 1" or link.rt_note.startswith(
        "SCHED_FIFO refused (")


def test_follow_runs_a_motion_to_its_end_then_holds(robot_and) -> None:
    import threading

    link, robot = robot_and(local_config(mode="absolute"))
    robot.cycle()
    result: dict = {}
    motion = threading.Thread(target=lambda: result.setdefault("end", link.follow(
        lambda s: Correction(offset=np.full(6, 0.01 * DEG) * min(s.cycle, 3)),
        done=lambda s: s.cycle >= 3, timeout=10.0)))
    motion.start()
    time.sleep(0.05)  # the motion's source is set
    got = [values(robot.cycle())[0] for _ in range(6)]
    motion.join(10)
    assert result["end"].cycle == 3
    # offsets until the last cycle of the motion, then held
    assert got[-1] == pytest.approx(0.03, abs=1e-6) and got[-2] == pytest.approx(0.03, abs=1e-6)


def test_follow_raises_the_streams_failure(robot_and) -> None:
    import threading

    link, robot = robot_and(local_config(timeout_packets=25, cycle="IPO"))
    robot.cycle()
    outcome: dict = {}

    def run() -> None:
        try:
            link.follow(lambda s: Correction(step=np.full(6, 1e-5)), lambda s: False, 10.0)
        except Exception as exc:  # the test looks at what it is
            outcome["error"] = exc

    motion = threading.Thread(target=run)
    motion.start()
    robot.cycle()
    t0 = time.monotonic()  # the controller goes silent
    motion.join(10)
    assert isinstance(outcome["error"], StreamStoppedError)
    assert "no packet from the controller" in str(outcome["error"])
    assert time.monotonic() - t0 >= 0.3 * 0.99  # one controller timeout, 25 × 12 ms
    with pytest.raises(StreamStoppedError):  # the held session is over
        link.follow(lambda s: None, lambda s: True, 1.0)


def _follow_in_thread(link, done, timeout: float) -> tuple[object, dict]:
    import threading

    outcome: dict = {}

    def run() -> None:
        try:
            outcome["end"] = link.follow(lambda s: Correction(offset=np.zeros(6)), done,
                                         timeout)
        except Exception as exc:  # the test looks at what it is
            outcome["error"] = exc

    motion = threading.Thread(target=run)
    motion.start()
    time.sleep(0.05)  # the motion's source is set
    return motion, outcome


def test_a_motion_takes_its_time_on_the_controllers_clock(robot_and) -> None:
    """A controller whose cycles come slower than real time (a loaded machine: the twin's
    process starved, or its lockstep) runs the motion to its end: the motion's timeout is
    the controller's time (its cycles), not the wall clock's, which such a controller
    cannot keep up with."""
    link, robot = robot_and(local_config(mode="absolute"))
    robot.cycle()
    motion, outcome = _follow_in_thread(link, lambda s: s.cycle >= 8, 0.2)
    for _ in range(10):  # 10 cycles of 4 ms, one every 60 ms: 0.6 s of wall time
        time.sleep(0.06)
        robot.cycle()
    motion.join(10)
    assert "error" not in outcome, outcome
    assert outcome["end"].cycle == 8


def test_a_motion_that_outlasts_its_timeout_on_the_controllers_clock_fails(robot_and) -> None:
    link, robot = robot_and(local_config(mode="absolute"))
    robot.cycle()
    motion, outcome = _follow_in_thread(link, lambda s: False, 0.1)  # 25 cycles of 4 ms
    for _ in range(40):
        robot.cycle()
        if not motion.is_alive():
            break
    motion.join(10)
    assert isinstance(outcome.get("error"), TimeoutError), outcome
    assert "the motion did not end within 0.1 s (streaming)" in str(outcome["error"])


@pytest.mark.parametrize("frame", ["joints", "base"])  # base: g computed in a thread too
def test_closing_ends_and_joins_a_correction_still_running(robot_and, frame) -> None:
    """A correction (mode (b), the link in the service's thread) still running when the
    service closes: closing the link ends its motion (the link is gone: it fails with that
    reason) and closing the corrector joins its thread — none lingers."""
    import threading

    from plugcell.devices.robot.stream.correcting import CorrectionSpec, Corrector

    q = (-15.0, -75.0, -190.0, 0.0, 75.0, 0.0)  # H4's (the spec's robot) parallelogram open
    link, robot = robot_and(local_config(mode="absolute"))
    robot.cycle(joints_deg=q)
    corrector = Corrector(link)
    corrector.start(CorrectionSpec("offset", (1e-4,) * 6, frame=frame, ramp_s=0.01))
    for _ in range(5):
        robot.cycle(joints_deg=q)
    assert corrector.poll() is None  # runs (until CORRECT_END, or 24 h)
    link.close()
    corrector.close()
    assert not [t for t in threading.enumerate() if t.name.startswith("correction")]
    assert "the correction failed: RSI link closed" in corrector.poll()


def test_the_services_close_ends_a_correction_still_running() -> None:
    """The robot service's stream controller with its link in a thread
    (``stream_process=false``): its close ends and joins a CORRECT still running."""
    import asyncio
    import threading
    import types

    from plugcell.devices.robot.stream.correcting import CorrectionSpec
    from plugcell.devices.robot.streamed import streamed_link
    from plugcell.sim.ports import free_port

    q = (-15.0, -75.0, -190.0, 0.0, 75.0, 0.0)
    controller = streamed_link(types.SimpleNamespace(), robot="smart_h4", library=(),
                               name="R", rsi=f"127.0.0.1:{free_port('udp')}",
                               stream_process=False)
    robot = BareRobot(controller.link.start(), controller.config.ipoc_step)
    try:
        robot.cycle(joints_deg=q)
        controller.corrector.start(CorrectionSpec("offset", (1e-4,) * 6, frame="joints",
                                                  ramp_s=0.01))
        for _ in range(5):
            robot.cycle(joints_deg=q)
        assert controller.corrector.poll() is None
        asyncio.run(controller.close())
    finally:
        robot.close()
    assert not [t for t in threading.enumerate() if t.name.startswith("correction")]


def test_follow_times_out_without_a_controller() -> None:
    from plugcell.devices.robot.rsi import RsiLink

    with RsiLink(local_config()) as link, pytest.raises(
            TimeoutError, match="no stream from the controller"):
        link.follow(lambda s: None, lambda s: True, 0.2)


def test_a_flood_of_garbage_does_not_keep_the_link_from_answering(robot_and) -> None:
    from plugcell.devices.robot.stream.link import DRAIN

    link, robot = robot_and()
    robot.cycle()
    for _ in range(3 * DRAIN):
        robot.send(b"<Rob Type='KUKA'><junk")
    robot.ipoc += 4
    robot.send(rob_packet(robot.ipoc))
    assert ipoc(robot.sock.recv(1000)) == robot.ipoc
    assert settled(link, 2).dropped["malformed"] == 3 * DRAIN
