"""The bare UDP echo in Rust, the third row of rsi_latency.py and egm_latency.py.

``benchmarks/native_echo`` must answer the bytes the Python echo answers (so the robot
side times it as it times the others), speak the same lines with the robot side
(``READY``, a line ending the warm-up, a line asking for the JSON report the harness
reads), and run as the harness schedules it.  The harness's accounting of the missed
cycles it adds (near a late send of the robot side, with each other sensor's) is checked
on streams made by hand.  The build and spawn tests are skipped where there is no cargo.
"""

from __future__ import annotations

import json
import os
import shutil
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"
NO_CARGO = pytest.mark.skipif(shutil.which("cargo") is None,
                              reason="needs cargo (a Rust toolchain) to build the native echo")


def _import(name: str) -> ModuleType:
    sys.path.insert(0, str(BENCHMARKS))
    try:
        return __import__(name)
    finally:
        sys.path.remove(str(BENCHMARKS))


@pytest.fixture(scope="module")
def harness() -> ModuleType:
    return _import("rsi_latency")


@pytest.fixture(scope="module")
def rust_echo() -> ModuleType:
    return _import("rust_echo")


@pytest.fixture(scope="module")
def binary(rust_echo: ModuleType) -> Path:
    built = rust_echo.build()
    assert isinstance(built, Path) and built.is_file(), built
    return built


@pytest.fixture(scope="module")
def echoes(rust_echo: ModuleType, binary: Path, harness: ModuleType
           ) -> Iterator[dict[str, tuple[subprocess.Popen, socket.socket]]]:
    """An RSI echo (tail 64) and an EGM echo (first field), each with a socket to it."""
    from plugcell.devices.robot.stream.realtime import RealTime

    out = {}
    for name, part in (("tail", harness.EchoPart(tail=64)), ("field", harness.EchoPart())):
        proc, port, _ = rust_echo.spawn(binary, part.args(), RealTime())
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.bind(("127.0.0.1", 0))
        sock.connect(("127.0.0.1", port))
        sock.settimeout(5)
        out[name] = (proc, sock)
    yield out
    for proc, sock in out.values():
        sock.close()
        proc.kill()
        proc.wait(5)


def _answer(sock: socket.socket, data: bytes) -> bytes:
    sock.send(data)
    return sock.recv(65535)


@NO_CARGO
def test_it_answers_the_python_echos_bytes_of_the_benchmarks_packets(echoes, harness) -> None:
    """The robot side's own packets: the RSI ``<Rob>`` tail with its IPOC, the EGM header
    with its seqno — read back by the robot side's parsers."""
    egm = _import("egm_latency")
    rob = harness.rob_packet(4_000_000_123, 0.5)
    got = _answer(echoes["tail"][1], rob)
    assert got == harness.RSI.echo(rob) == rob[-64:]
    assert harness.RSI.seq_of(got) == 4_000_000_123
    msg = egm.egm_message(77, 0.5)
    got = _answer(echoes["field"][1], msg)
    assert got == egm.EGM.echo(msg) and egm.EGM.seq_of(got) == 77


@NO_CARGO
@settings(max_examples=60, deadline=None)
@given(data=st.binary(min_size=2, max_size=600))
def test_it_answers_what_the_python_echo_answers_of_any_datagram(echoes, harness,
                                                                  data: bytes) -> None:
    assert _answer(echoes["tail"][1], data) == harness.EchoPart(tail=64)(data)
    assert _answer(echoes["field"][1], data) == harness.EchoPart()(data)


@NO_CARGO
def test_it_reports_what_the_harness_reads_after_the_warm_up(rust_echo, binary,
                                                             harness) -> None:
    """The warm-up's packets are forgotten; the report has a time per packet answered
    after it, the CPU and wall seconds and the answering thread's counters."""
    from plugcell.devices.robot.stream.realtime import RealTime

    proc, port, _ = rust_echo.spawn(binary, ["--tail", "64"], RealTime())
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.connect(("127.0.0.1", port))
        sock.settimeout(5)
        for i in range(3):
            _answer(sock, b"warm-up %d" % i)
        proc.stdin.write("go\n")
        proc.stdin.flush()
        time.sleep(0.5)  # it read the line (the robot side does not wait: it keeps sending)
        for i in range(5):
            _answer(sock, harness.rob_packet(i, 0.0))
        proc.stdin.write("stop\n")
        proc.stdin.flush()
        report = json.loads(proc.stdout.readline())
    proc.wait(5)
    assert proc.returncode == 0
    assert len(report["in_out_ns"]) == 5 and all(0 < t < 1e9 for t in report["in_out_ns"])
    assert 0 <= report["cpu_s"] <= report["wall_s"] * os.cpu_count() and report["wall_s"] > 0
    assert set(report["thread"]) == {"minflt", "majflt", "voluntary", "forced", "collections",
                                     "longest_collection_ns"}
    # it waited for the first packet (sent 0.5 s after "go"); a later one may already be
    # there when it calls recv again (the answer woke this thread, which sent the next
    # at once: CI run 18 counted 4 waits for 5 packets)
    assert report["thread"]["voluntary"] >= 1


@NO_CARGO
def test_the_harness_schedules_it_as_the_other_sensors(rust_echo, binary) -> None:
    """SCHED_FIFO at the sensors' priority on its answering thread, where permitted (else
    the note says why), and every thread of it on the sensors' CPUs."""
    from plugcell.devices.robot.stream.realtime import RealTime

    cpu = min(os.sched_getaffinity(0))
    proc, _, note = rust_echo.spawn(binary, ["--first-field"], RealTime(1, frozenset({cpu})))
    try:
        tasks = os.listdir(f"/proc/{proc.pid}/task")
        assert len(tasks) == 2  # the answering (main) thread and the one reading stdin
        assert all(os.sched_getaffinity(int(t)) == {cpu} for t in tasks)
        if note.startswith("SCHED_FIFO priority 1"):
            assert os.sched_getscheduler(proc.pid) == os.SCHED_FIFO
            assert os.sched_getparam(proc.pid).sched_priority == 1
        else:
            assert "SCHED_FIFO refused" in note, note
        assert f"CPU {cpu}" in note and note.endswith("native echo")
    finally:
        proc.kill()
        proc.wait(5)


@NO_CARGO
def test_it_refuses_bad_options_with_the_reason(binary) -> None:
    for args, says in ((["--tail", "x"], '--tail "x": not a byte count'),
                       ([], "give --tail N or --first-field"),
                       (["--loud"], 'unknown argument "--loud"')):
        done = subprocess.run([str(binary), *args], capture_output=True, text=True, timeout=10)
        assert done.returncode == 2 and says in done.stderr, (args, done.stderr)


def test_without_cargo_the_row_is_left_out_with_the_reason(rust_echo, monkeypatch) -> None:
    monkeypatch.setattr(rust_echo.shutil, "which", lambda name: None)
    reason = rust_echo.build()
    assert isinstance(reason, str) and "no cargo on PATH" in reason


def test_the_missed_cycles_are_placed_against_the_others_and_the_late_sends(harness) -> None:
    """Three streams made by hand, 4 ms cycle: the link misses at 100 ms (with the Python
    echo's miss at 104 ms) and 300 ms (alone); the native echo misses at 500 ms, right
    after the robot side sent a packet 3 ms late at 497 ms."""
    cycle, ms = 4_000_000, 1_000_000

    def stream(missed: set[int], late: set[int] = frozenset()) -> object:
        log, answered = [], {}
        for seq, t in enumerate(range(0, 600 * ms, cycle)):
            slot = t - 3 * ms if t in late else t
            log.append((seq, slot, t))
            if t not in missed:
                answered[seq] = t + 200_000
        return harness._Stream(None, {}, log, answered)

    streams = [stream({100 * ms, 300 * ms}), stream({104 * ms}),
               stream({500 * ms}, late={496 * ms})]
    names = ["link", harness.ECHO, "native"]
    reports = [{"in_out_ns": [1000], "cpu_s": 0.1, "wall_s": 1.0} for _ in names]
    results, _ = harness._figures(names, streams, reports, cycle, 0, [])
    assert [results[n]["missed"] for n in names] == [2, 1, 1]
    assert results["link"]["missed_with"] == {harness.ECHO: 1, "native": 0}
    assert results[harness.ECHO]["missed_with"] == {"link": 1, "native": 0}
    assert results["native"]["missed_with"] == {"link": 0, harness.ECHO: 0}
    assert [results[n]["missed_near_late_send"] for n in names] == [0, 0, 1]
    assert results["native"]["robot_late_sends"] == 1
    assert results["native"]["missed_by_cause"]["robot side"] == 0  # its own packet was on time
    assert results["link"]["missed_by_cause"]["both sensors"] == 1
