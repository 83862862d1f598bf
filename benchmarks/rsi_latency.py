"""KUKA RSI answer latency at 250 Hz: plugcell's link beside a bare UDP echo (issue 37 §7).

    python benchmarks/rsi_latency.py [--seconds 60] [--cycle-ms 4] [--cell N]
        [--rt-priority N] [--json FILE] [--plot PNG]

Three processes: a robot side (this one) that sends a ``<Rob Type="KUKA">`` packet
every cycle (4 ms) to each of two sensors, interleaved half a cycle apart — plugcell's
:class:`~plugcell.devices.robot.rsi.RsiLink` (in a process of its own, its thread
answering, a swinging joint offset as the correction, as ``plugcell rsi run`` runs it)
and a bare UDP echo (``recvfrom`` → ``sendto`` in a loop, the floor of Python and the
kernel) — and times each answer from its send to its arrival (the round trip the
controller sees).  Each sensor also times itself, packet in → answer out.  A *missed
cycle* is an answer that arrived more than one cycle after its packet left, or never.
CPU is each sensor process's user + system time over the measured seconds (% of one
core).  The first two seconds are warm-up, not counted.

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
import contextlib
import gc
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

WARMUP_S = 2.0


def rob_packet(ipoc: int, q: float) -> bytes:
    """A robot packet as RSI_EthernetConfig's DEF_ elements make it (~600 bytes)."""
    ax = " ".join(f'A{i}="{q + i:.4f}"' for i in range(1, 7))
    return (f'<Rob Type="KUKA"><RIst X="445.0000" Y="0.0000" Z="900.0000" A="180.0000" '
            f'B="0.0000" C="180.0000"/><RSol X="445.0000" Y="0.0000" Z="900.0000" '
            f'A="180.0000" B="0.0000" C="180.0000"/><AIPos {ax}/><ASPos {ax}/>'
            f'<MACur A1="1.0" A2="2.0" A3="3.0" A4="4.0" A5="5.0" A6="6.0"/><Delay D="0"/>'
            f'<DiL>0</DiL><IPOC>{ipoc}</IPOC></Rob>').encode()


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
    echo_part : callable
        What the bare echo sends back of a datagram (the part carrying the sequence).
    run_link : callable
        ``run_link(cycle_ms, rt)``: the link's process.
    first_seq : int
        The sequence number before the first datagram's.
    """

    name: str
    script: str
    packet: Callable[[int, float], bytes]
    seq_of: Callable[[bytes], int]
    seq_step: Callable[[float], int]
    echo_part: Callable[[bytes], bytes]
    run_link: Callable[[float, int | None], None]
    first_seq: int = 4_000_000_000

    @property
    def link(self) -> str:
        return f"plugcell {self.name} link"


# ---------------------------------------------------------------- the sensors (children)

def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _report(latencies: list[int], cpu0: float, t0: float) -> None:
    """After a line on stdin: this process's CPU share and its in → out times."""
    sys.stdin.readline()
    cpu, wall = _cpu() - cpu0, time.monotonic() - t0
    print(json.dumps({"cpu_s": cpu, "wall_s": wall, "in_out_ns": latencies}), flush=True)


def run_link(cycle_ms: float, rt: int | None) -> None:
    from plugcell.devices.robot.rsi import RsiConfig, RsiLink
    from plugcell.devices.robot.stream.source import SineOffset
    from plugcell.io.units import DEG

    cfg = RsiConfig(robot_host="127.0.0.1", listen_host="127.0.0.1", listen_port=0,
                    mode="absolute", cycle="IPO_FAST" if cycle_ms == 4 else "IPO")
    serve_link(RsiLink(cfg, SineOffset(axis=5, amplitude=2 * DEG, period=4.0, periods=10**6),
                       record_latency=True, rt_priority=rt))


def serve_link(link) -> None:
    """The link role of a run (RSI's or EGM's link, recording latencies): freeze the
    start-up heap as the link process does (stream/process.py: a full collection then
    scans only the cycles' objects), start it, say ``READY <port>``, forget the warm-up
    when told (a line on stdin), report the measured seconds and the link's counters,
    close it."""
    gc.collect()
    gc.freeze()
    link.start()
    time.sleep(0.05)
    print(f"READY {link.address[1]} {link.rt_note}", flush=True)
    sys.stdin.readline()  # the warm-up is over
    del link.latencies[:]
    cpu0, t0 = _cpu(), time.monotonic()
    _report(link.latencies, cpu0, t0)
    print(json.dumps({"stats": dict(link.stats().__dict__)}), flush=True)
    link.close()


def run_echo(rt: int | None, echo_part: Callable[[bytes], bytes]) -> None:
    import threading

    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    latencies: list[int] = []

    def loop() -> None:
        if rt is not None:  # the same scheduling as the link's thread
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(rt))
        while True:
            data, addr = sock.recvfrom(65535)
            t_in = time.monotonic_ns()
            sock.sendto(echo_part(data), addr)  # the part that carries the sequence
            latencies.append(time.monotonic_ns() - t_in)

    threading.Thread(target=loop, daemon=True).start()
    print(f"READY {sock.getsockname()[1]}", flush=True)
    sys.stdin.readline()
    del latencies[:]
    _report(latencies, _cpu(), time.monotonic())


# ------------------------------------------------------------------ the robot (parent)

def _ipoc_of(answer: bytes) -> int:
    """The IPOC of an answer (the benchmark's robot side, not the code measured)."""
    start = answer.rfind(b"<IPOC>") + 6
    return int(answer[start:answer.index(b"</IPOC>", start)])


def _spawn(vendor: Vendor, role: str, cycle_ms: float,
           rt: int | None) -> tuple[subprocess.Popen, int, str]:
    proc = subprocess.Popen([sys.executable, vendor.script, "--role", role, "--cycle-ms",
                             str(cycle_ms), *(["--rt-priority", str(rt)] if rt else [])],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            text=True)
    line = proc.stdout.readline()
    if not line.startswith("READY "):
        raise RuntimeError(f"{role} did not start: {line!r}")
    _, port, *note = line.split(maxsplit=2)
    return proc, int(port), " ".join(note).strip()


def robot(vendor: Vendor, seconds: float, cycle_ms: float,
          rt: int | None) -> tuple[dict, dict[str, dict[str, np.ndarray]]]:
    """Run the robot side; the figures per sensor, and its times (µs) for the plot."""
    cycle_ns = int(cycle_ms * 1e6)
    link_proc, link_port, link_note = _spawn(vendor, "link", cycle_ms, rt)
    echo_proc, echo_port, _ = _spawn(vendor, "echo", cycle_ms, rt)
    if rt is not None:  # the robot side too: it stands for the controller's real-time core
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(rt))
    # and no collector's pass may stall it (it would send the packets it owes at once,
    # and the link answers only the newest of them): its loop frees what it allocates
    gc.collect()
    gc.freeze()
    gc.disable()
    names = (vendor.link, "bare UDP echo")
    socks, sent, rtts, late = [], [{}, {}], [[], []], [0, 0]
    for port in (link_port, echo_port):
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        s.bind(("127.0.0.1", 0))
        s.connect(("127.0.0.1", port))
        s.setblocking(False)
        socks.append(s)
    poller = select.poll()
    for s in socks:
        poller.register(s, select.POLLIN)
    fd_index = {s.fileno(): i for i, s in enumerate(socks)}
    ipoc, k = vendor.first_seq, 0
    start = time.monotonic_ns()
    measuring_from = start + int(WARMUP_S * 1e9)
    end = measuring_from + int(seconds * 1e9)
    measuring = False
    worst = [(0, 0.0), (0, 0.0)]  # the longest round trip and when its packet left (s)
    late_at: list[list[float]] = [[], []]  # when the late answers' packets left (s)
    cpu0 = _cpu_times()
    # slot j: stream j % 2 sends at start + j · cycle/2
    while True:
        slot_t = start + k * cycle_ns // 2
        if slot_t >= end:
            break
        if not measuring and slot_t >= measuring_from:
            measuring = True
            for p in (link_proc, echo_proc):
                p.stdin.write("go\n")
                p.stdin.flush()
            sent, rtts, late = [{}, {}], [[], []], [0, 0]
            worst = [(0, 0.0), (0, 0.0)]
            late_at = [[], []]
            cpu0 = _cpu_times()
        # wait for the slot, taking answers as they come
        while True:
            now = time.monotonic_ns()
            if now >= slot_t:
                break
            for fd, _ in poller.poll(max(0, (slot_t - now) // 1_000_000)):
                i = fd_index[fd]
                while True:
                    try:
                        answer = socks[i].recv(65535)
                    except BlockingIOError:
                        break
                    t = time.monotonic_ns()
                    sent_at = sent[i].pop(vendor.seq_of(answer), None)
                    if sent_at is not None:
                        rtt = t - sent_at
                        rtts[i].append(rtt)
                        late[i] += rtt > cycle_ns
                        if rtt > cycle_ns:
                            late_at[i].append((sent_at - measuring_from) / 1e9)
                        if measuring and rtt > worst[i][0]:
                            worst[i] = (rtt, (sent_at - measuring_from) / 1e9)
        i = k % 2
        if i == 0:
            ipoc += vendor.seq_step(cycle_ms)
        packet = vendor.packet(ipoc, (k % 1000) * 1e-3)
        sent[i][ipoc] = time.monotonic_ns()
        socks[i].send(packet)
        k += 1
    steal = _steal(cpu0, _cpu_times())
    gc.enable()
    time.sleep(0.05)  # the last answers
    for i, s in enumerate(socks):
        while True:
            try:
                answer = s.recv(65535)
            except BlockingIOError:
                break
            sent_at = sent[i].pop(vendor.seq_of(answer), None)
            if sent_at is not None:
                rtts[i].append(time.monotonic_ns() - sent_at)
                late[i] += rtts[i][-1] > cycle_ns
                if rtts[i][-1] > cycle_ns:
                    late_at[i].append((sent_at - measuring_from) / 1e9)
    results, samples = {}, {}
    link_stats = None
    for i, (name, proc) in enumerate(zip(names, (link_proc, echo_proc), strict=True)):
        proc.stdin.write("stop\n")
        proc.stdin.flush()
        report = json.loads(proc.stdout.readline())
        if i == 0:
            proc.stdin.close()
            link_stats = json.loads(proc.stdout.readline())["stats"]
        proc.wait(timeout=10)
        r = np.array(rtts[i], dtype=float) / 1e3
        io = np.array(report["in_out_ns"], dtype=float) / 1e3
        never = len(sent[i])  # sent, never answered
        results[name] = {
            "cycles": len(r) + never,
            "rtt_us": {q: float(np.percentile(r, p)) for q, p in
                       (("p50", 50), ("p99", 99), ("p99.9", 99.9))} | {"max": float(r.max())},
            "in_out_us": {q: float(np.percentile(io, p)) for q, p in
                          (("p50", 50), ("p99", 99), ("p99.9", 99.9))} | {"max": float(io.max())},
            "missed": late[i] + never,
            "cpu_pct": 100 * report["cpu_s"] / report["wall_s"],
            "max_at_s": worst[i][1],
            "missed_at_s": sorted(late_at[i] + [(t - measuring_from) / 1e9
                                                for t in sent[i].values()]),
        }
        samples[name] = {"round trip": r, "in→out": io}
    results[vendor.link]["link_stats"] = link_stats
    results[vendor.link]["scheduling"] = link_note
    results[vendor.link]["steal_pct"] = steal
    return results, samples


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
    link, echo = results[vendor.link], results["bare UDP echo"]
    lines = [f"{vendor.name} answer latency, {1000 / cycle_ms:.0f} Hz, {seconds:.0f} s measured "
             f"(+{WARMUP_S:.0f} s warm-up), two streams interleaved half a cycle apart",
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
              f"{link.get('scheduling')}"]
    return "\n".join(lines)


@contextlib.contextmanager
def cell_services(n: int) -> Iterator[None]:
    """``n`` plugcell services serving in a fresh cell while the block runs."""
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
                stderr=subprocess.STDOUT, text=True))
        for p in procs:
            _wait_for(p, "serving in cell")
        print(f"{n} plugcell services serving in cell {cell}", flush=True)
        yield
    finally:
        for p in procs:
            p.terminate()
        for p in procs:
            try:
                p.wait(10)
            except subprocess.TimeoutExpired:
                p.kill()


def main(argv: list[str], vendor: Vendor | None = None, doc: str | None = None) -> int:
    vendor = vendor or RSI
    ap = argparse.ArgumentParser(description=(doc or __doc__).split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=60.0, help="measured seconds (60)")
    ap.add_argument("--cycle-ms", type=float, default=4.0, choices=(4.0, 12.0))
    ap.add_argument("--json", type=Path, help="also write the figures as JSON")
    ap.add_argument("--plot", type=Path, metavar="PNG",
                    help="also draw the histograms of the times (matplotlib)")
    ap.add_argument("--rt-priority", type=int, metavar="N",
                    help="run the robot side, the link's thread and the echo's under "
                    "SCHED_FIFO priority N (Linux, root or CAP_SYS_NICE)")
    ap.add_argument("--cell", type=int, default=0, metavar="N",
                    help="measure beside N plugcell services serving in a cell")
    ap.add_argument("--in-service", action="store_true",
                    help=f"measure plugcell serve robot --{vendor.name.lower()} running a "
                    "program against the twin's robot side instead (stream_in_service.py)")
    ap.add_argument("--link-thread", action="store_true",
                    help="with --in-service: the link in a thread of the service's process, "
                    "not its own")
    ap.add_argument("--role", choices=("link", "echo"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.role == "link":
        vendor.run_link(args.cycle_ms, args.rt_priority)
        return 0
    if args.role == "echo":
        run_echo(args.rt_priority, vendor.echo_part)
        return 0
    if args.in_service:
        import stream_in_service

        with cell_services(args.cell) if args.cell else contextlib.nullcontext():
            return stream_in_service.main(vendor.name, args.seconds, args.json,
                                          args.link_thread)
    load0 = os.getloadavg()[0]
    print(f"machine: {os.cpu_count()} CPUs, load average {load0:.2f} at start", flush=True)
    with cell_services(args.cell) if args.cell else contextlib.nullcontext():
        results, samples = robot(vendor, args.seconds, args.cycle_ms, args.rt_priority)
    print(table(vendor, results, args.seconds, args.cycle_ms))
    if args.cell:
        print(f"beside {args.cell} plugcell services serving in a cell")
    print("scheduling: " + (f"SCHED_FIFO priority {args.rt_priority} (robot side, link "
                            "thread, echo thread)" if args.rt_priority else
                            "normal (SCHED_OTHER)"))
    print(f"load average {os.getloadavg()[0]:.2f} at the end")
    if args.json:
        args.json.write_text(json.dumps(results, indent=1), encoding="utf-8")
    if args.plot:
        title = (f"{vendor.name} at {1000 / args.cycle_ms:.0f} Hz, {args.seconds:.0f} s, "
                 f"{args.cell} services in the cell, "
                 f"{'SCHED_FIFO ' + str(args.rt_priority) if args.rt_priority else 'normal'}"
                 f" priority, load average {load0:.1f} → {os.getloadavg()[0]:.1f} "
                 f"({os.cpu_count()} CPUs)")
        drawn = plot(samples, args.cycle_ms, title, args.plot)
        print(f"plot: {args.plot}" if drawn else "plot: no matplotlib")
    return 0


RSI = Vendor("RSI", __file__, rob_packet, _ipoc_of, lambda cycle_ms: int(cycle_ms),
             lambda data: data[-64:],  # the tail carries the IPOC
             run_link)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
