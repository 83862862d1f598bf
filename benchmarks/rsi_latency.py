"""KUKA RSI answer latency at 250 Hz: plugcell's link beside a bare UDP echo (issue 37 §7).

    python benchmarks/rsi_latency.py [--seconds 60] [--cycle-ms 4] [--cell N]
        [--rt-priority N] [--no-native] [--json FILE] [--plot PNG]

Four processes: a robot side (this one) that sends a ``<Rob Type="KUKA">`` packet
every cycle (4 ms) to each of three sensors, interleaved a third of a cycle apart —
plugcell's :class:`~plugcell.devices.robot.rsi.RsiLink` (in a process of its own, its
thread answering, a swinging joint offset as the correction, as ``plugcell rsi run`` runs
it), a bare UDP echo (``recvfrom`` → ``sendto`` in a loop, the floor of Python and the
kernel) and the same echo in Rust (rust_echo.py: the floor of any implementation, built
with cargo; left out with ``--no-native`` or where there is no cargo) — and times each
answer from its send to its arrival (the round trip the controller sees).  Each sensor
also times itself, packet in → answer out.  A *missed cycle* is an answer that arrived
more than one cycle after its packet left, or never.  CPU is each sensor process's user
+ system time over the measured seconds (% of one core).  The first two seconds are
warm-up, not counted.

``--cell N`` first starts N plugcell services in a fresh cell (``plugcell serve`` of the
kinds idle_cost.py uses: cameras, drills, benchmark publishers, compute services — Zenoh
on loopback, journals on), waits until each serves, and measures beside them: the
issue's "with the cell's other services running".

Goal (issue 37): p99.9 ≤ 1 ms, ≤ 3× the bare echo, zero missed cycles, ≤ 10 % of one
core.  Nothing is asserted; the table says which goals the run met.  ``--plot PNG`` draws
the histograms of the round trips and of the in→out times, link beside echo.
"""

from __future__ import annotations

import argparse
import array
import contextlib
import gc
import itertools
import json
import os
import resource
import select
import socket
import subprocess
import sys
import tempfile
import time
import uuid
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from plugcell.devices.robot.stream.realtime import RealTime, parse_cpus, pin

WARMUP_S = 2.0
#: The CPUs the benchmark was started on (before the robot side pins itself).
ALL_CPUS = frozenset(os.sched_getaffinity(0))


def rob_packet(ipoc: int, q: float) -> bytes:
    """A robot packet as RSI_EthernetConfig's DEF_ elements make it (~600 bytes)."""
    ax = " ".join(f'A{i}="{q + i:.4f}"' for i in range(1, 7))
    return (f'<Rob Type="KUKA"><RIst X="445.0000" Y="0.0000" Z="900.0000" A="180.0000" '
            f'B="0.0000" C="180.0000"/><RSol X="445.0000" Y="0.0000" Z="900.0000" '
            f'A="180.0000" B="0.0000" C="180.0000"/><AIPos {ax}/><ASPos {ax}/>'
            f'<MACur A1="1.0" A2="2.0" A3="3.0" A4="4.0" A5="5.0" A6="6.0"/><Delay D="0"/>'
            f'<DiL>0</DiL><IPOC>{ipoc}</IPOC></Rob>').encode()


@dataclass(frozen=True)
class EchoPart:
    """What the bare echoes (Python's, :func:`run_echo`, and Rust's, rust_echo.py) send
    back of a datagram: the part that carries its sequence number, so the robot side
    times their answers as it times the link's.

    Attributes
    ----------
    tail : int or None
        Its last ``tail`` bytes (RSI: the tail carries the IPOC); ``None``: the first
        field of a protobuf message, its tag, one length byte and the field,
        ``data[:2 + data[1]]`` (EGM: the header carries the seqno; < 128 bytes).
    """

    tail: int | None = None

    def __call__(self, data: bytes) -> bytes:
        return data[-self.tail:] if self.tail is not None else data[:2 + data[1]]

    def args(self) -> list[str]:
        """The native echo's options for the same part."""
        return ["--tail", str(self.tail)] if self.tail is not None else ["--first-field"]


@dataclass(frozen=True)
class Vendor:
    """What the harness needs of one interface (this file: RSI; egm_latency.py: EGM).

    Attributes
    ----------
    name : str
        The interface ("RSI"); the link's row is "plugcell NAME link".
    script : str
        The file whose ``--role link`` / ``--role echo`` runs the sensors.
    packet : callable
        ``packet(seq, q)``: the robot's datagram of sequence number ``seq``.
    seq_of : callable
        The sequence number an answer (the link's or the echo's) carries.
    seq_step : callable
        ``seq_step(cycle_ms)``: the sequence's advance per cycle.
    echo : EchoPart
        What the bare echoes send back of a datagram (the part carrying the sequence).
    run_link : callable
        ``run_link(cycle_ms, rt)``: the link's process, scheduled as ``rt`` says.
    first_seq : int
        The sequence number before the first datagram's.
    """

    name: str
    script: str
    packet: Callable[[int, float], bytes]
    seq_of: Callable[[bytes], int]
    seq_step: Callable[[float], int]
    echo: EchoPart
    run_link: Callable[[float, RealTime], None]
    first_seq: int = 4_000_000_000

    @property
    def link(self) -> str:
        return f"plugcell {self.name} link"


# ---------------------------------------------------------------- the sensors (children)

def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _thread_counters(tid: int | None) -> dict[str, int]:
    """A thread's page faults and context switches so far (Linux's /proc; empty elsewhere):
    ``minflt``, ``majflt`` (served from disk), ``voluntary`` (it waited) and ``forced``
    (``nonvoluntary_ctxt_switches``: taken off the CPU while it wanted to run)."""
    out: dict[str, int] = {}
    if tid is None:
        return out
    try:
        with open(f"/proc/self/task/{tid}/stat", encoding="ascii") as f:
            fields = f.read().rsplit(")", 1)[1].split()
        out["minflt"], out["majflt"] = int(fields[7]), int(fields[9])
        with open(f"/proc/self/task/{tid}/status", encoding="ascii") as f:
            for line in f:
                if line.startswith("voluntary_ctxt_switches"):
                    out["voluntary"] = int(line.split()[1])
                elif line.startswith("nonvoluntary_ctxt_switches"):
                    out["forced"] = int(line.split()[1])
    except (OSError, IndexError, ValueError):
        return {}
    return out


class _Collections:
    """The cyclic collector's passes while measuring (``gc.callbacks``): count and the
    longest (ns)."""

    def __init__(self) -> None:
        self.count, self.longest, self._t0 = 0, 0, 0
        gc.callbacks.append(self)

    def __call__(self, phase: str, info: dict) -> None:
        if phase == "start":
            self._t0 = time.perf_counter_ns()
        else:
            self.count += 1
            self.longest = max(self.longest, time.perf_counter_ns() - self._t0)


def _report(latencies: list[int], cpu0: float, t0: float, tid: int | None,
            extra: Callable[[], dict] = dict) -> None:
    """After a line on stdin: this process's CPU share, its in → out times, and what
    happened to the answering thread (page faults, context switches, collections)."""
    counters0, collections = _thread_counters(tid), _Collections()
    sys.stdin.readline()
    cpu, wall = _cpu() - cpu0, time.monotonic() - t0
    counters = _thread_counters(tid)
    thread = {k: counters[k] - counters0.get(k, 0) for k in counters}
    print(json.dumps({"cpu_s": cpu, "wall_s": wall, "in_out_ns": latencies,
                      "thread": thread | {"collections": collections.count,
                                          "longest_collection_ns": collections.longest},
                      **extra()}), flush=True)


def run_link(cycle_ms: float, rt: RealTime) -> None:
    from plugcell.devices.robot.rsi import RsiConfig, RsiLink
    from plugcell.devices.robot.stream.source import SineOffset
    from plugcell.io.units import DEG

    cfg = RsiConfig(robot_host="127.0.0.1", listen_host="127.0.0.1", listen_port=0,
                    mode="absolute", cycle="IPO_FAST" if cycle_ms == 4 else "IPO")
    serve_link(RsiLink(cfg, SineOffset(axis=5, amplitude=2 * DEG, period=4.0, periods=10**6),
                       record_latency=True, realtime=rt))


def serve_link(link) -> None:
    """The link role of a run (RSI's or EGM's link, recording latencies): the process
    prepared as the link process prepares itself (stream/process.py: CPUs, switch
    interval, its other threads' priority), its start-up heap frozen as the link
    process does (a full collection then scans only the cycles' objects), start it, say
    ``READY <port>``, forget the warm-up when told (a line on stdin), report the measured
    seconds, the link's counters and when each packet came in (its ``observer``, the
    link process's shared-memory publisher's place), close it."""
    link.realtime.prepare_process()  # as the link process does (stream/process.py)
    gc.collect()
    gc.freeze()
    # (sequence, packet in, in → out) ns of each answer, in arrays of machine integers:
    # no object per cycle for the collector to count (a list of tuples would trigger a
    # pass every 700 cycles, in the link's thread, and be measured as the link's)
    arrivals = (array.array("q"), array.array("q"), array.array("q"))

    def observe(lk) -> None:
        with contextlib.suppress(IndexError):  # the warm-up's list just emptied
            io = lk.latencies[-1]
            arrivals[0].append(lk._last_seq)
            arrivals[1].append(lk._last_rx)
            arrivals[2].append(io)

    link.observer = observe
    link.start()
    time.sleep(0.05)
    print(f"READY {link.address[1]} {link.rt_note}", flush=True)
    sys.stdin.readline()  # the warm-up is over
    del link.latencies[:]
    for a in arrivals:
        del a[:]
    cpu0, t0 = _cpu(), time.monotonic()
    _report(link.latencies, cpu0, t0, link._thread.native_id,
            lambda: {"arrivals": list(zip(*arrivals, strict=False))})
    print(json.dumps({"stats": dict(link.stats().__dict__)}), flush=True)
    link.close()


def run_echo(rt: RealTime, echo_part: Callable[[bytes], bytes]) -> None:
    import threading

    pin(rt.cpus)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    latencies: list[int] = []
    note: list[str] = []

    def loop() -> None:
        note.append(rt.apply())  # the same scheduling as the link's thread
        while True:
            data, addr = sock.recvfrom(65535)
            t_in = time.monotonic_ns()
            sock.sendto(echo_part(data), addr)  # the part that carries the sequence
            latencies.append(time.monotonic_ns() - t_in)

    thread = threading.Thread(target=loop, daemon=True)
    thread.start()
    time.sleep(0.05)
    print(f"READY {sock.getsockname()[1]} {note[0] if note else ''}", flush=True)
    sys.stdin.readline()
    del latencies[:]
    _report(latencies, _cpu(), time.monotonic(), thread.native_id)


# ------------------------------------------------------------------ the robot (parent)

def _ipoc_of(answer: bytes) -> int:
    """The IPOC of an answer (the benchmark's robot side, not the code measured)."""
    start = answer.rfind(b"<IPOC>") + 6
    return int(answer[start:answer.index(b"</IPOC>", start)])


@dataclass(frozen=True)
class Setup:
    """How a run is scheduled (the options ``--rt-priority``, ``--cpu``, ``--robot-cpu``,
    ``--mlock``, ``--isolate``).

    Attributes
    ----------
    sensors : RealTime
        The link's thread and the echo's: priority, CPUs, locked memory.
    robot_cpus : frozenset of int or None
        The robot side's CPUs (default: the sensors').
    isolate : bool
        The cell's services on the CPUs the stream does not use.
    """

    sensors: RealTime
    robot_cpus: frozenset[int] | None = None
    isolate: bool = False

    def child_args(self) -> list[str]:
        rt = self.sensors
        return ([*(["--rt-priority", str(rt.priority)] if rt.priority else []),
                 *(["--cpu", ",".join(map(str, sorted(rt.cpus)))] if rt.cpus else []),
                 *(["--mlock"] if rt.lock_memory else [])])

    def cell_cpus(self) -> frozenset[int] | None:
        """Where the cell's services run (None: anywhere): the CPUs this process was
        given at its start that the sensors do not use (the robot side, the controller's
        stand-in, may share theirs: a controller is another machine)."""
        if not self.isolate:
            return None
        return ALL_CPUS - (self.sensors.cpus or frozenset())

    def describe(self) -> str:
        rt = self.sensors
        parts = [f"SCHED_FIFO priority {rt.priority} (robot side, link thread, echo thread)"
                 if rt.priority else "normal (SCHED_OTHER)"]
        if rt.cpus:
            parts.append("link and echo on CPU " + ",".join(map(str, sorted(rt.cpus))))
        if self.robot_cpus or rt.cpus:
            parts.append("robot side on CPU " + ",".join(
                map(str, sorted(self.robot_cpus or rt.cpus))))
        if self.isolate:
            parts.append("cell services on CPU " + ",".join(
                map(str, sorted(self.cell_cpus() or ()))))
        if rt.lock_memory:
            parts.append("memory locked (mlockall)")
        return "; ".join(parts)


def _spawn(vendor: Vendor, role: str, cycle_ms: float,
           setup: Setup) -> tuple[subprocess.Popen, int, str]:
    proc = subprocess.Popen([sys.executable, vendor.script, "--role", role, "--cycle-ms",
                             str(cycle_ms), *setup.child_args()],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            text=True)
    line = proc.stdout.readline()
    if not line.startswith("READY "):
        raise RuntimeError(f"{role} did not start: {line!r}")
    _, port, *note = line.split(maxsplit=2)
    return proc, int(port), " ".join(note).strip()


@dataclass
class _Stream:
    """What the robot side keeps of one sensor's stream."""

    sock: socket.socket
    sent: dict[int, tuple[int, int]]  # sequence → (slot, sent) ns, until answered
    log: list[tuple[int, int, int]]  # (sequence, slot, sent) ns of every packet measured
    answered: dict[int, int]  # sequence → the answer's arrival (ns)


#: The Python echo's row.
ECHO = "bare UDP echo"


def robot(vendor: Vendor, seconds: float, cycle_ms: float, setup: Setup,
          native: Path | None = None) -> tuple[dict, dict[str, dict[str, np.ndarray]]]:
    """Run the robot side; the figures per sensor, and its times (µs) for the plot.
    ``native``: the Rust echo's binary (rust_echo.py), a third sensor."""
    cycle_ns = int(cycle_ms * 1e6)
    names = [vendor.link, ECHO]
    sensors = [_spawn(vendor, "link", cycle_ms, setup), _spawn(vendor, "echo", cycle_ms, setup)]
    if native is not None:
        import rust_echo

        names.append(rust_echo.NAME)
        sensors.append(rust_echo.spawn(native, vendor.echo.args(), setup.sensors))
    procs = [proc for proc, _, _ in sensors]
    robot_note = RealTime(setup.sensors.priority, setup.robot_cpus or setup.sensors.cpus,
                          setup.sensors.lock_memory).apply()  # the controller's real-time core
    # and no collector's pass may stall it (it would send the packets it owes at once,
    # and the link answers only the newest of them): its loop frees what it allocates
    gc.collect()
    gc.freeze()
    gc.disable()
    streams = []
    for _, port, _ in sensors:
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        s.bind(("127.0.0.1", 0))
        s.connect(("127.0.0.1", port))
        s.setblocking(False)
        streams.append(_Stream(s, {}, [], {}))
    socks = [st.sock for st in streams]
    ipoc, k = vendor.first_seq, 0
    start = time.monotonic_ns()
    measuring_from = start + int(WARMUP_S * 1e9)
    end = measuring_from + int(seconds * 1e9)
    measuring = False
    cpu0 = _cpu_times()
    steal_log: list[tuple[int, tuple[int, ...]]] = []  # (when, each CPU's steal ticks)
    # slot j: stream j % n sends at start + j · cycle/n; between two, the robot side
    # sleeps in select() (µs resolution: it never spins, so it takes no CPU from the
    # sensors it measures) and takes the answers as they come
    n = len(streams)
    while True:
        slot_t = start + k * cycle_ns // n
        if slot_t >= end:
            break
        if not measuring and slot_t >= measuring_from:
            measuring = True
            for p in procs:
                p.stdin.write("go\n")
                p.stdin.flush()
            for st in streams:
                st.sent.clear()
                st.answered.clear()
            cpu0 = _cpu_times()
        while True:
            now = time.monotonic_ns()
            if now >= slot_t:
                break
            ready, _, _ = select.select(socks, [], [], (slot_t - now) / 1e9)
            for s in ready:
                _take_answers(streams[socks.index(s)], vendor)
        st = streams[k % n]
        if k % n == 0:
            ipoc += vendor.seq_step(cycle_ms)
        packet = vendor.packet(ipoc, (k % 1000) * 1e-3)
        t = time.monotonic_ns()
        st.sent[ipoc] = (slot_t, t)
        if measuring:
            st.log.append((ipoc, slot_t, t))
        st.sock.send(packet)
        if measuring and k % (STEAL_EVERY * n) == 0:  # after a send: it delays none
            steal_log.append((time.monotonic_ns(), _steal_per_cpu()))
        k += 1
    steal = _steal(cpu0, _cpu_times())
    drain_end = time.monotonic_ns() + 2 * cycle_ns  # the last answers, timed as they come
    while any(st.sent for st in streams) and (now := time.monotonic_ns()) < drain_end:
        ready, _, _ = select.select(socks, [], [], (drain_end - now) / 1e9)
        for s in ready:
            _take_answers(streams[socks.index(s)], vendor)
    gc.enable()
    reports = []
    for i, proc in enumerate(procs):
        proc.stdin.write("stop\n")
        proc.stdin.flush()
        reports.append(json.loads(proc.stdout.readline()))
        if i == 0:
            proc.stdin.close()
            reports[0]["stats"] = json.loads(proc.stdout.readline())["stats"]
        proc.wait(timeout=10)
    results, samples = _figures(names, streams, reports, cycle_ns, measuring_from,
                                _stolen(steal_log))
    for name, (_, _, note) in zip(names[1:], sensors[1:], strict=True):
        results[name]["scheduling"] = note
    results[vendor.link] |= {"link_stats": reports[0]["stats"], "scheduling": sensors[0][2],
                             "steal_pct": steal, "robot_scheduling": robot_note,
                             "steal_windows": len(_stolen(steal_log)),
                             "windows": max(0, len(steal_log) - 1)}
    return results, samples


def _take_answers(st: _Stream, vendor: Vendor) -> None:
    """Read the answers queued on a stream's socket; note when each arrived."""
    while True:
        try:
            answer = st.sock.recv(65535)
        except BlockingIOError:
            return
        t = time.monotonic_ns()
        seq = vendor.seq_of(answer)
        if st.sent.pop(seq, None) is not None:
            st.answered[seq] = t


def _figures(names: list[str], streams: list[_Stream], reports: list[dict], cycle_ns: int,
             t0: int, stolen: list[tuple[int, int]]
             ) -> tuple[dict, dict[str, dict[str, np.ndarray]]]:
    """Each sensor's round trips, in → out times, missed cycles (when, and why: see
    :func:`_causes`; how many near a time the hypervisor took a CPU, ``stolen``'s
    windows; near a late send of the robot side, :func:`_late_windows`; within two
    cycles of each other sensor's), CPU share and thread counters.  The first sensor is
    the link (its report says when each packet came in)."""
    results, samples = {}, {}
    missed_at: list[list[int]] = []
    for st in streams:
        missed_at.append([sent for seq, _, sent in st.log
                          if st.answered.get(seq, sent + cycle_ns + 1) - sent > cycle_ns])
    link_in = {seq: (t_in, io) for seq, t_in, io in reports[0].get("arrivals", ())}
    late = _late_windows(streams, cycle_ns)
    for i, (name, st, report) in enumerate(zip(names, streams, reports, strict=True)):
        others = [t for j, at in enumerate(missed_at) if j != i for t in at]
        r = np.array([st.answered[seq] - sent for seq, _, sent in st.log
                      if seq in st.answered], dtype=float) / 1e3
        io = np.array(report["in_out_ns"], dtype=float) / 1e3
        worst = max(((st.answered[seq] - sent, sent) for seq, _, sent in st.log
                     if seq in st.answered), default=(0, t0))
        robot_late = [sent - slot for _, slot, sent in st.log if sent - slot > cycle_ns // 4]
        results[name] = {
            "cycles": len(st.log),
            "rtt_us": _quantiles(r),
            "in_out_us": _quantiles(io),
            "missed": len(missed_at[i]),
            "cpu_pct": 100 * report["cpu_s"] / report["wall_s"],
            "max_at_s": (worst[1] - t0) / 1e9,
            "missed_at_s": [(t - t0) / 1e9 for t in missed_at[i]],
            "missed_by_cause": _causes(st, missed_at[i], others, cycle_ns,
                                       link_in if i == 0 else None),
            "missed_near_steal": sum(_near(t, stolen) for t in missed_at[i]),
            "missed_near_late_send": sum(_near(t, late, 0) for t in missed_at[i]),
            "missed_with": {other: _within(missed_at[i], missed_at[j], 2 * cycle_ns)
                            for j, other in enumerate(names) if j != i},
            "robot_late_sends": len(robot_late),
            "robot_late_near_steal": sum(_near(sent, stolen) for _, slot, sent in st.log
                                         if sent - slot > cycle_ns // 4),
            "robot_longest_late_us": max(robot_late, default=0) / 1e3,
            "thread": report.get("thread", {}),
        }
        samples[name] = {"round trip": r, "in→out": io}
    return results, samples


def _late_windows(streams: list[_Stream], cycle_ns: int) -> list[tuple[int, int]]:
    """When the robot side stalled: for each packet of any stream it sent more than a
    quarter cycle after its slot, (slot − 2 cycles, sent + 2 cycles) ns — a sensor's
    missed cycle in one of these came with the machine's stall, not the sensor's."""
    return [(slot - 2 * cycle_ns, sent + 2 * cycle_ns) for st in streams
            for _, slot, sent in st.log if sent - slot > cycle_ns // 4]


def _within(times: list[int], others: list[int], margin: int) -> int:
    """How many of ``times`` (ns) lie within ``margin`` ns of one of ``others``."""
    ref = np.sort(np.asarray(others, dtype=np.int64))
    if not len(ref):
        return 0
    t = np.asarray(times, dtype=np.int64)
    i = np.clip(np.searchsorted(ref, t), 1, len(ref)) - 1
    nearest = np.minimum(np.abs(ref[i] - t), np.abs(ref[np.minimum(i + 1, len(ref) - 1)] - t))
    return int(np.count_nonzero(nearest <= margin))


#: The robot side reads each CPU's steal every this many cycles (100 ms at 4 ms).
STEAL_EVERY = 25


def _steal_per_cpu() -> tuple[int, ...]:
    """Each CPU's ``steal`` so far (/proc/stat, clock ticks; empty where there is none)."""
    try:
        with open("/proc/stat", encoding="ascii") as f:
            return tuple(int(line.split()[8]) for line in f
                         if line.startswith("cpu") and line[3].isdigit())
    except (OSError, IndexError, ValueError):
        return ()


def _stolen(log: list[tuple[int, tuple[int, ...]]]) -> list[tuple[int, int]]:
    """The windows (from, to) ns between two readings in which the hypervisor took time
    from any CPU (its steal grew)."""
    return [(t0, t1) for (t0, a), (t1, b) in itertools.pairwise(log)
            if any(y > x for x, y in zip(a, b, strict=False))]


def _near(t: int, windows: list[tuple[int, int]], margin: int = 100_000_000) -> bool:
    """``t`` falls within ``margin`` ns of one of the ``windows`` (steal is counted in
    10 ms ticks, read every 100 ms)."""
    return any(a - margin <= t <= b + margin for a, b in windows)


def _quantiles(v: np.ndarray) -> dict[str, float]:
    if not len(v):
        return dict.fromkeys(("p50", "p99", "p99.9", "max"), float("nan"))
    return {q: float(np.percentile(v, p)) for q, p in
            (("p50", 50), ("p99", 99), ("p99.9", 99.9))} | {"max": float(v.max())}


#: The causes of a missed cycle (:func:`_causes`), in the order they are tried.
CAUSES = ("robot side", "both sensors", "woke late", "own cycle", "answer's way back")


def _causes(st: _Stream, missed: list[int], other: list[int], cycle_ns: int,
            arrivals: dict[int, tuple[int, int]] | None) -> dict[str, int]:
    """Why each missed cycle of a stream was missed, the first that applies of:

    * *robot side*: the robot side (the controller's stand-in, a Python process) sent
      the packet more than a quarter cycle after its slot, or the next one less than half
      a cycle after it (a stall, then the packets it owed at once; a sensor answering the
      newest of queued packets, as the link does, misses the older);
    * *both sensors*: another sensor (``other``: their missed cycles) missed a cycle
      within two cycles of it (the machine stalled both);
    * where the sensor's own times are known (the link's: when each packet came in and
      its in → out): *woke late* (it read the packet more than half a cycle after it was
      sent, or never: a newer one was read with it — the kernel ran it late), *own cycle*
      (its in → out took more than half a cycle), else *answer's way back*; for the echo,
      which does not say, *woke late*.
    """
    log = {sent: (j, slot) for j, (_, slot, sent) in enumerate(st.log)}
    seqs = [seq for seq, _, _ in st.log]
    other_sorted = np.array(sorted(other), dtype=np.int64)
    out = dict.fromkeys(CAUSES, 0)
    for sent in missed:
        j, slot = log[sent]
        burst = j + 1 < len(st.log) and st.log[j + 1][2] - sent < cycle_ns // 2
        if sent - slot > cycle_ns // 4 or burst:
            out["robot side"] += 1
            continue
        near = np.searchsorted(other_sorted, sent - 2 * cycle_ns)
        if near < len(other_sorted) and other_sorted[near] <= sent + 2 * cycle_ns:
            out["both sensors"] += 1
            continue
        got = None if arrivals is None else arrivals.get(seqs[j])
        if got is None or got[0] - sent > cycle_ns // 2:
            out["woke late"] += 1
        elif got[1] > cycle_ns // 2:
            out["own cycle"] += 1
        else:
            out["answer's way back"] += 1
    return out


def _cpu_times() -> list[int]:
    """The machine's CPU time by kind (/proc/stat's first line; empty where there is none)."""
    try:
        with open("/proc/stat", encoding="ascii") as f:
            return [int(x) for x in f.readline().split()[1:]]
    except OSError:
        return []


def _steal(before: list[int], after: list[int]) -> float | None:
    """The share (%) of the CPUs' time the hypervisor gave other machines (``steal``)."""
    if len(before) < 8 or len(after) < 8:
        return None
    total = sum(after[:8]) - sum(before[:8])
    return 100 * (after[7] - before[7]) / total if total else None


def plot(samples: dict[str, dict[str, np.ndarray]], cycle_ms: float, title: str,
         path: Path) -> bool:
    """Histograms of the round trips and the in→out times, link beside echo (log axes)."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return False
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.0), sharey=True)
    top = max(float(v.max()) for per in samples.values() for v in per.values())
    bins = np.geomspace(5.0, max(top, 2e3 * cycle_ms) * 1.05, 120)
    for ax, what in zip(axes, ("round trip", "in→out"), strict=True):
        for name, per in samples.items():
            v = per[what]
            ax.hist(v, bins=bins, histtype="step", lw=1.0,
                    label=f"{name}: p99.9 {np.percentile(v, 99.9):.0f} µs, max {v.max():.0f}")
        ax.axvline(1000, color="k", ls="--", lw=0.8)
        ax.axvline(1000 * cycle_ms, color="r", ls=":", lw=0.8)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel(f"{what} (µs); dashed: the goal's 1 ms, dotted: one cycle")
        ax.legend(fontsize=7, loc="upper right")
    axes[0].set_ylabel("packets")
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return True


def table(vendor: Vendor, results: dict, seconds: float, cycle_ms: float) -> str:
    link, echo = results[vendor.link], results[ECHO]
    apart = "half a cycle" if len(results) == 2 else f"1/{len(results)} of a cycle"
    lines = [f"{vendor.name} answer latency, {1000 / cycle_ms:.0f} Hz, {seconds:.0f} s measured "
             f"(+{WARMUP_S:.0f} s warm-up), {len(results)} streams interleaved {apart} apart",
             "",
             "| sensor | cycles | round trip p50 / p99 / p99.9 / max (µs) | in→out p50 / p99 / "
             "p99.9 / max (µs) | missed | CPU % of a core |",
             "|---|---:|---|---|---:|---:|"]
    for name, r in results.items():
        rt, io = r["rtt_us"], r["in_out_us"]
        lines.append(f"| {name} | {r['cycles']} | {rt['p50']:.0f} / {rt['p99']:.0f} / "
                     f"{rt['p99.9']:.0f} / {rt['max']:.0f} | {io['p50']:.0f} / {io['p99']:.0f} / "
                     f"{io['p99.9']:.0f} / {io['max']:.0f} | {r['missed']} | {r['cpu_pct']:.1f} |")
    lines.append("")
    lines.append("longest round trips at " + ", ".join(
        f"{name}: {r['max_at_s']:.1f} s" for name, r in results.items()) + " into the run")
    for name, r in results.items():
        at = r.get("missed_at_s") or []
        if at:
            lines.append(f"missed cycles of the {name} at (s): " + ", ".join(
                f"{t:.3f}" for t in at[:30]) + (" …" if len(at) > 30 else ""))
    if link.get("steal_pct") is not None:
        lines.append(f"CPU time taken by the hypervisor (steal) during the run: "
                     f"{link['steal_pct']:.2f} %")
    ratio = link["rtt_us"]["p99.9"] / echo["rtt_us"]["p99.9"]
    goals = [("p99.9 round trip ≤ 1 ms", link["rtt_us"]["p99.9"] <= 1000,
              f"{link['rtt_us']['p99.9']:.0f} µs"),
             ("p99.9 ≤ 3× the bare echo's", ratio <= 3, f"{ratio:.2f}×"),
             ("zero missed cycles", link["missed"] == 0, str(link["missed"])),
             ("≤ 10 % of one core", link["cpu_pct"] <= 10, f"{link['cpu_pct']:.1f} %")]
    lines += ["", "| goal (issue 37) | this run | met |", "|---|---|---|"]
    lines += [f"| {g} | {v} | {'yes' if ok else 'NO'} |" for g, ok, v in goals]
    st = link.get("link_stats") or {}
    lines += ["", f"link's own counters: answered {st.get('answered')}, late "
              f"{st.get('late')}, missed {st.get('missed')}, dropped "
              f"{sum((st.get('dropped') or {}).values())}, max in→out "
              f"{(st.get('max_latency_ns') or 0) / 1e3:.0f} µs; link thread: "
              f"{link.get('scheduling')}; robot side: {link.get('robot_scheduling')}"]
    lines += ["", "| sensor | missed: " + " / ".join(CAUSES) + " | missed near steal | missed "
              "near a late send | missed with another's | robot side's late sends (longest "
              "µs; near steal) | answering thread: page faults (from disk) / forced off the "
              "CPU / collector's passes (longest µs) |",
              "|---|---|---:|---:|---|---|---|"]
    for name, r in results.items():
        by, th = r["missed_by_cause"], r.get("thread") or {}
        lines.append(f"| {name} | " + " / ".join(str(by[c]) for c in CAUSES)
                     + f" | {r['missed_near_steal']} | {r.get('missed_near_late_send', '?')} | "
                     + (", ".join(f"{o}: {c}" for o, c in (r.get("missed_with") or {}).items())
                        or "–")
                     + f" | {r['robot_late_sends']} "
                     f"({r['robot_longest_late_us']:.0f}; {r['robot_late_near_steal']}) | "
                     f"{th.get('minflt', '?')} ({th.get('majflt', '?')}) / "
                     f"{th.get('forced', '?')} / {th.get('collections', '?')} "
                     f"({th.get('longest_collection_ns', 0) / 1e3:.0f}) |")
    for name, r in results.items():
        if name not in (vendor.link, ECHO):
            lines.append(f"{vendor.link}'s p99.9 ÷ the {name}'s: "
                         f"{link['rtt_us']['p99.9'] / r['rtt_us']['p99.9']:.2f}×")
    if link.get("windows"):
        lines.append(f"the hypervisor took time from a CPU in {link['steal_windows']} of the "
                     f"run's {link['windows']} windows of 0.1 s (near steal: within 0.1 s of "
                     "one)")
    lines.append("near a late send: within two cycles of a packet the robot side sent over a "
                 "quarter cycle after its slot (any stream's); missed with another's: within "
                 "two cycles of that sensor's missed cycle")
    return "\n".join(lines)


@contextlib.contextmanager
def cell_services(n: int, cpus: frozenset[int] | None = None) -> Iterator[None]:
    """``n`` plugcell services serving in a fresh cell while the block runs (on
    ``cpus``, every thread of theirs, when given)."""
    from idle_cost import KINDS, _wait_for  # the idle cell's kinds and start-up wait

    home = Path(tempfile.mkdtemp(prefix="plugcell-stream-cell-"))
    env = {**os.environ, "PLUGCELL_HOME": str(home), "PYTHONUNBUFFERED": "1"}
    cell = f"rsi{uuid.uuid4().hex[:8]}"
    procs = []
    try:
        for i in range(n):
            kind = KINDS[i % len(KINDS)]
            procs.append(subprocess.Popen(
                [sys.executable, "-m", "plugcell", "serve", kind, "--cell", cell, "--name",
                 f"{kind.upper()}{i}"], env=env, stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT, text=True,
                preexec_fn=None if cpus is None else lambda: os.sched_setaffinity(0, cpus)))
        for p in procs:
            _wait_for(p, "serving in cell")
        where = "" if cpus is None else " on CPU " + ",".join(map(str, sorted(cpus)))
        print(f"{n} plugcell services serving in cell {cell}{where}", flush=True)
        yield
    finally:
        for p in procs:
            p.terminate()
        for p in procs:
            try:
                p.wait(10)
            except subprocess.TimeoutExpired:
                p.kill()


def _service_params(rt: RealTime) -> tuple[str, ...]:
    """The robot service's parameters of the link's scheduling ``rt`` (``--in-service``)."""
    return ((*([f"stream_rt_priority={rt.priority}"] if rt.priority else []),
             *([f"stream_cpu={','.join(map(str, sorted(rt.cpus)))}"] if rt.cpus else []),
             *(["stream_mlock=true"] if rt.lock_memory else [])))


def _priority(text: str) -> int:
    """``--rt-priority``'s value: 1..99."""
    try:
        return RealTime(int(text)).priority  # type: ignore[return-value]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected a SCHED_FIFO priority 1..99") \
            from None


def _cpus(text: str) -> frozenset[int]:
    """``--cpu``'s value: CPUs this machine has."""
    try:
        cpus = parse_cpus(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    have = ALL_CPUS
    if not cpus <= have:
        raise argparse.ArgumentTypeError(
            f"{text!r}: CPU {min(cpus - have)} is not one this process may use "
            f"({','.join(map(str, sorted(have)))})")
    return cpus


def main(argv: list[str], vendor: Vendor | None = None, doc: str | None = None) -> int:
    vendor = vendor or RSI
    ap = argparse.ArgumentParser(description=(doc or __doc__).split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=60.0, help="measured seconds (60)")
    ap.add_argument("--cycle-ms", type=float, default=4.0, choices=(4.0, 12.0))
    ap.add_argument("--json", type=Path, help="also write the figures as JSON")
    ap.add_argument("--plot", type=Path, metavar="PNG",
                    help="also draw the histograms of the times (matplotlib)")
    ap.add_argument("--rt-priority", type=_priority, metavar="N",
                    help="run the robot side, the link's thread and the echo's under "
                    "SCHED_FIFO priority N (1-99; Linux, root or CAP_SYS_NICE)")
    ap.add_argument("--cpu", type=_cpus, metavar="CPUS",
                    help="pin the link's and the echo's processes (and the robot side, "
                    "unless --robot-cpu) to these CPUs, e.g. 1 (taskset -c syntax)")
    ap.add_argument("--robot-cpu", type=_cpus, metavar="CPUS",
                    help="pin the robot side to these CPUs")
    ap.add_argument("--isolate", action="store_true",
                    help="run the cell's services (--cell) on the CPUs the link and the echo "
                    "do not use (needs --cpu)")
    ap.add_argument("--mlock", action="store_true",
                    help="lock the memory of the robot side, the link and the echo "
                    "(mlockall)")
    ap.add_argument("--cell", type=int, default=0, metavar="N",
                    help="measure beside N plugcell services serving in a cell")
    ap.add_argument("--in-service", action="store_true",
                    help=f"measure plugcell serve robot --{vendor.name.lower()} running a "
                    "program against the twin's robot side instead (stream_in_service.py)")
    ap.add_argument("--link-thread", action="store_true",
                    help="with --in-service: the link in a thread of the service's process, "
                    "not its own")
    ap.add_argument("--no-native", action="store_true",
                    help="leave out the bare UDP echo in Rust (benchmarks/native_echo, built "
                    "with cargo; left out anyway where there is no cargo)")
    ap.add_argument("--role", choices=("link", "echo"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.isolate and not args.cpu:
        ap.error("--isolate keeps the cell's services off the stream's CPUs: give --cpu")
    rt = RealTime(args.rt_priority, args.cpu, args.mlock)
    if args.role == "link":
        vendor.run_link(args.cycle_ms, rt)
        return 0
    if args.role == "echo":
        run_echo(rt, vendor.echo)
        return 0
    setup = Setup(rt, args.robot_cpu, args.isolate)
    if args.isolate and not setup.cell_cpus():
        ap.error(f"--isolate: no CPU is left for the cell's services (the sensors use "
                 f"{sorted(args.cpu)}, this process may run on "
                 f"{sorted(ALL_CPUS)})")
    if args.in_service:
        import stream_in_service

        with cell_services(args.cell, setup.cell_cpus()) if args.cell else \
                contextlib.nullcontext():
            return stream_in_service.main(vendor.name, args.seconds, args.json,
                                          args.link_thread, _service_params(rt))
    native = None
    if not args.no_native:
        import rust_echo

        native = rust_echo.build()
        if isinstance(native, str):
            print(native, flush=True)
            native = None
    load0 = os.getloadavg()[0]
    print(f"machine: {os.cpu_count()} CPUs, load average {load0:.2f} at start", flush=True)
    with cell_services(args.cell, setup.cell_cpus()) if args.cell else \
            contextlib.nullcontext():
        results, samples = robot(vendor, args.seconds, args.cycle_ms, setup, native)
    print(table(vendor, results, args.seconds, args.cycle_ms))
    if args.cell:
        print(f"beside {args.cell} plugcell services serving in a cell")
    print("scheduling: " + setup.describe())
    print(f"load average {os.getloadavg()[0]:.2f} at the end")
    if args.json:
        args.json.write_text(json.dumps(results, indent=1), encoding="utf-8")
    if args.plot:
        title = (f"{vendor.name} at {1000 / args.cycle_ms:.0f} Hz, {args.seconds:.0f} s, "
                 f"{args.cell} services in the cell, "
                 f"{'SCHED_FIFO ' + str(args.rt_priority) if args.rt_priority else 'normal'}"
                 f" priority{', CPU ' + ','.join(map(str, sorted(args.cpu))) if args.cpu else ''}"
                 f", load average {load0:.1f} → {os.getloadavg()[0]:.1f} "
                 f"({os.cpu_count()} CPUs)")
        drawn = plot(samples, args.cycle_ms, title, args.plot)
        print(f"plot: {args.plot}" if drawn else "plot: no matplotlib")
    return 0


RSI = Vendor("RSI", __file__, rob_packet, _ipoc_of, lambda cycle_ms: int(cycle_ms),
             EchoPart(tail=64), run_link)  # the tail carries the IPOC


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
