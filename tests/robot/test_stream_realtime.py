"""The cycle loop's scheduling (stream/realtime.py): priority, CPUs, locked memory — the
options of the link, the link process, the robot service and ``plugcell rsi|egm run``,
and their refusals of values that can never work."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest
from hypothesis import given
from hypothesis import strategies as st

from plugcell.apps.cli import main
from plugcell.devices.robot.rsi import RsiConfig, RsiLink
from plugcell.devices.robot.service import RobotService
from plugcell.devices.robot.stream.process import LinkProcess
from plugcell.devices.robot.stream.realtime import RealTime, parse_cpus, pin, stream_realtime
from plugcell.sim.ports import free_port

MINE = frozenset(os.sched_getaffinity(0))
NOT_MINE = max(max(MINE), os.cpu_count() or 1) + 1000


def _format(cpus: set[int]) -> str:
    """``cpus`` as taskset -c writes them: runs as ranges."""
    out, run = [], []
    for c in sorted(cpus):
        if run and c != run[-1] + 1:
            out.append(run)
            run = []
        run.append(c)
    out.append(run)
    return ",".join(f"{r[0]}-{r[-1]}" if len(r) > 1 else str(r[0]) for r in out)


@pytest.mark.parametrize(("text", "cpus"), [
    ("1", {1}), ("0,2", {0, 2}), ("2-3", {2, 3}), ("0,2-4", {0, 2, 3, 4}), (" 1 , 3 ", {1, 3}),
    ("1,1", {1}), ("3-3", {3})])
def test_cpu_lists_read_as_taskset_writes_them(text, cpus) -> None:
    assert parse_cpus(text) == frozenset(cpus)


@pytest.mark.parametrize(("text", "message"), [
    ("", "CPU list '': empty"),
    (" , ", "CPU list ' , ': empty"),
    ("one", "'one' is not a CPU number or a range like 2-3"),
    ("1,,2", "'' is not a CPU number"),
    ("3-1", "'3-1' is not a range of CPU numbers"),
    ("-1", "'-1' is not a CPU number or a range"),
    ("1-", "'1-' is not a CPU number or a range"),
    ("1.5", "'1.5' is not a CPU number"),
])
def test_bad_cpu_lists_are_refused_naming_the_part(text, message) -> None:
    with pytest.raises(ValueError, match="CPU list") as err:
        parse_cpus(text)
    assert message in str(err.value)


@given(st.sets(st.integers(0, 4095), min_size=1, max_size=40))
def test_any_cpu_set_reads_back_from_its_list(cpus) -> None:
    assert parse_cpus(_format(cpus)) == frozenset(cpus)


@given(st.text(max_size=30))
def test_any_text_is_a_cpu_set_or_a_value_error(text) -> None:
    try:
        cpus = parse_cpus(text)
    except ValueError as exc:
        assert str(exc).startswith("CPU list ")
    else:
        assert cpus and all(c >= 0 for c in cpus)


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"priority": 0}, r"rt_priority 0: expected 1\.\.99"),
    ({"priority": 100}, r"rt_priority 100: expected 1\.\.99"),
    ({"priority": True}, r"rt_priority True: expected 1\.\.99"),
    ({"priority": "20"}, r"rt_priority '20': expected 1\.\.99"),
    ({"cpus": frozenset()}, "an empty set"),
    ({"cpus": frozenset({-1})}, r"-1 is not a CPU number"),
    ({"cpus": frozenset({"1"})}, r"'1' is not a CPU number"),
])
def test_bad_scheduling_is_refused_with_the_reason(kwargs, message) -> None:
    with pytest.raises(ValueError, match=message):
        RealTime(**kwargs)


def test_the_defaults_ask_for_nothing_and_say_so() -> None:
    rt = RealTime()
    assert not rt.asked and rt.apply() == "normal priority"
    switch = sys.getswitchinterval()
    assert rt.prepare_process() == "" and sys.getswitchinterval() == switch
    assert RealTime(cpus={0}).cpus == frozenset({0})  # any set is kept frozen


def test_pinning_to_the_cpus_this_process_has_is_granted_and_said() -> None:
    note = pin(MINE)
    assert note == ("CPU " if len(MINE) == 1 else "CPUs ") + ",".join(map(str, sorted(MINE)))
    assert pin(None) == ""
    assert "refused" in pin(frozenset({NOT_MINE}))  # none of them online: the reason
    assert os.sched_getaffinity(0) == MINE  # and nothing changed


def test_locking_memory_is_done_or_refused_with_the_reason() -> None:
    """In a process of its own (mlockall would hold the test runner's memory)."""
    code = ("from plugcell.devices.robot.stream.realtime import RealTime; "
            "print(RealTime(lock_memory=True).apply())")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 0, done.stderr
    note = done.stdout.strip()
    assert note == "normal priority, memory locked" or note.startswith(
        "normal priority, memory not locked (")


def test_a_link_process_prepares_its_threads_or_says_why_not() -> None:
    """In a process of its own: the CPUs, the switch interval, the other threads one
    priority below the link's (granted, or refused with the reason)."""
    cpus = ",".join(map(str, sorted(MINE)))
    code = ("import os, sys; from plugcell.devices.robot.stream.realtime import RealTime; "
            f"print(RealTime(5, frozenset({{{cpus}}})).prepare_process()); "
            "print(sys.getswitchinterval(), sorted(os.sched_getaffinity(0)))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 0, done.stderr
    note, after = done.stdout.strip().splitlines()
    assert note.startswith("CPU")
    assert note.endswith(("other threads SCHED_FIFO priority 4", ")"))
    assert "other threads" in note
    assert after == f"0.0005 {sorted(MINE)}"


def _config() -> RsiConfig:
    return RsiConfig(robot_host="127.0.0.1", listen_host="127.0.0.1", listen_port=0,
                     mode="absolute")


def test_the_link_thread_takes_its_scheduling_before_start_returns() -> None:
    link = RsiLink(_config(), realtime=RealTime(priority=1, cpus=MINE))
    try:
        link.start()
        # granted (root or CAP_SYS_NICE) or refused with the reason, never silent; the
        # note is there as soon as start() returns
        assert link.rt_note.startswith(("SCHED_FIFO priority 1, CPU", "SCHED_FIFO refused ("))
        assert "CPU" in link.rt_note
        assert link.rt_priority == 1
    finally:
        link.close()


def test_a_priority_and_a_scheduling_together_are_refused() -> None:
    with pytest.raises(ValueError, match="give rt_priority or realtime, not both"):
        RsiLink(_config(), rt_priority=5, realtime=RealTime(priority=5))
    with pytest.raises(ValueError, match="give rt_priority or realtime, not both"):
        LinkProcess(_config(), rt_priority=5, realtime=RealTime(priority=5))
    assert LinkProcess(_config(), rt_priority=7).realtime == RealTime(priority=7)


@pytest.mark.parametrize(("options", "message"), [
    ({"stream_rt_priority": 0}, r"stream_rt_priority: rt_priority 0: expected 1\.\.99"),
    ({"stream_cpu": "x"}, r"stream_cpu: CPU list 'x': 'x' is not a CPU number"),
    ({"stream_cpu": "2-1"}, r"stream_cpu: CPU list '2-1': '2-1' is not a range"),
    ({"stream_cpu": str(NOT_MINE)}, rf"stream_cpu '{NOT_MINE}': CPU {NOT_MINE} is not one "
     "of this machine's"),
])
def test_bad_service_scheduling_options_are_refused_naming_the_option(options, message) -> None:
    with pytest.raises(ValueError, match=message):
        RobotService(rsi="127.0.0.1:49152", **options)


def test_the_service_options_give_the_link_process_its_scheduling() -> None:
    cpus = ",".join(map(str, sorted(MINE)))
    service = RobotService(egm="127.0.0.1:6510", stream_rt_priority=20, stream_cpu=cpus,
                           stream_mlock=True)
    assert service.bridge.link.realtime == RealTime(20, MINE, True)
    assert stream_realtime(None, "", False) == RealTime()
    threaded = RobotService(rsi="127.0.0.1:49152", stream_process=False, stream_cpu=cpus)
    assert threaded.bridge.link.realtime == RealTime(None, MINE, False)


@pytest.mark.skipif((os.cpu_count() or 1) < 2, reason="needs two CPUs")
def test_a_service_kept_on_one_cpu_may_put_its_link_on_another() -> None:
    """systemd's CPUAffinity=0 for the service, stream_cpu=1 for its link process: the
    option names this machine's CPUs, not the service's."""
    code = ("import os; os.sched_setaffinity(0, {0}); "
            "from plugcell.devices.robot.stream.realtime import stream_realtime; "
            "print(sorted(stream_realtime(None, '1', False).cpus))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[1]"


@pytest.mark.parametrize(("argv", "message"), [
    (["--cpu", "x"], "--cpu: CPU list 'x': 'x' is not a CPU number"),
    (["--cpu", str(NOT_MINE)], f"--cpu '{NOT_MINE}': CPU {NOT_MINE} is not one of this "
     "machine's"),
    (["--rt-priority", "0"], r"--rt-priority: rt_priority 0: expected 1..99"),
])
@pytest.mark.parametrize("vendor", ["rsi", "egm"])
def test_bad_run_scheduling_options_are_refused_naming_the_option(vendor, argv, message,
                                                                 capsys) -> None:
    port = free_port("udp")
    code = main([vendor, "run", "--robot-ip", "127.0.0.1", "--listen", "127.0.0.1", "--port",
                 str(port), "--duration", "0.1", *argv])
    assert code == 2
    assert message in capsys.readouterr().err


@pytest.mark.slow
def test_the_link_process_applies_its_scheduling_to_every_thread() -> None:
    """The robot service's link process: its note says what the kernel granted, and
    every thread of the child runs on the CPUs asked for (numpy's, started at its import,
    too) — the link's under SCHED_FIFO 5, the others that run Python at 4 (where
    granted)."""
    cpu = min(MINE)
    link = LinkProcess(_config(), realtime=RealTime(5, frozenset({cpu})))
    try:
        link.start()
        note = link.rt_note
        assert note.startswith(("SCHED_FIFO priority 5, CPU", "SCHED_FIFO refused ("))
        assert f"; CPU {cpu}, other threads" in note
        tids = [int(t) for t in os.listdir(f"/proc/{link._proc.pid}/task")]
        assert len(tids) >= 3  # main, the link's, the corrections'
        assert all(os.sched_getaffinity(t) == {cpu} for t in tids)
        if "refused" not in note:  # the threads that run Python; numpy's BLAS pool not
            prios = sorted(os.sched_getparam(t).sched_priority for t in tids
                           if os.sched_getscheduler(t) == os.SCHED_FIFO)
            assert prios[-1] == 5 and set(prios[:-1]) == {4} and len(prios) >= 3
    finally:
        link.close()
