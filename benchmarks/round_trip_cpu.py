"""What one small round trip costs in CPU, by process and thread: plugcell beside its floors.

    .venv/bin/python benchmarks/round_trip_cpu.py [--cycles 4000] [--rounds 3] [--no-journal]
        [--switches]

``plugcell bench transport``'s 4-byte latency test and two of its floors, run one after
the other ``--rounds`` times between a requester and an answering process (peer mode,
loopback, journals on unless ``--no-journal``):

* *raw*: plain Zenoh ping-pong, each callback handing the sample to a thread (both
  ends processes of their own, as in ``bench transport``);
* *event loops*: the same, each side's callback handing it to an event loop
  (``call_soon_threadsafe``) — the hops of any asyncio service, nothing more;
* *plugcell*: ``create_process("PUBLISHER", "Echo", 4 bytes)`` until its update, as
  the benchmark's requester does (in this process), against the benchmark's service.

Around each run it reads every thread's time on the CPU from
``/proc/PID/task/TID/schedstat`` (nanoseconds) in both processes and prints, per round
trip, its time (twice the run's average one-way latency, as ``bench transport`` reports
it) and the CPU time of both processes together (warm-up and hand-shake included, when
the threads are all but idle), split by process — the requester and the answering
peer — into its Python threads (plugcell's event loop, the journal's mover;
the floors' waiting threads) and Zenoh's own runtime threads (``rx-*``, ``tx-*``,
``net-*``, ``acc-*``, ``app-*``); with ``--switches`` also their context switches
(``/proc/PID/task/TID/status``), voluntary and forced.  On a machine with
few cores the CPU a round trip needs is what its latency follows: what a faster request
path has to remove is read here.  Linux only (reads /proc).
"""

from __future__ import annotations

import argparse
import asyncio
import os
import platform
import sys
import tempfile
import uuid
from collections.abc import Awaitable, Callable
from pathlib import Path

#: Name prefixes of Zenoh's runtime threads (zenoh-runtime's pools).
ZENOH_THREADS = ("rx-", "tx-", "net-", "acc-", "app-")
#: The columns: (process, kind of thread), the requester's process first.
PARTS = ("requester: Python", "requester: Zenoh", "answerer: Python", "answerer: Zenoh")


#: What :func:`thread_readings` reads of each thread, in this order.
READINGS = ("CPU ns", "voluntary switches", "forced switches")


def thread_readings(pid: int) -> dict[tuple[int, str], tuple[int, ...]]:
    """Of each live thread of ``pid``, keyed by (thread id, name): its time on the CPU
    (ns, ``schedstat``) and its voluntary and forced context switches (``status``)."""
    out: dict[tuple[int, str], tuple[int, ...]] = {}
    for task in Path(f"/proc/{pid}/task").iterdir():
        try:
            name = (task / "comm").read_text().strip()
            ns = int((task / "schedstat").read_text().split()[0])
            status = dict(line.split(":", 1) for line in
                          (task / "status").read_text().splitlines() if ":" in line)
            switches = (int(status["voluntary_ctxt_switches"]),
                        int(status["nonvoluntary_ctxt_switches"]))
        except (OSError, ValueError, IndexError, KeyError):  # the thread ended meanwhile
            continue
        out[(int(task.name), name)] = (ns, *switches)
    return out


def part_of(process: int, name: str) -> str:
    """Which of :data:`PARTS` a thread named ``name`` of process ``process`` (0: the
    requester, 1: the answerer) is."""
    return PARTS[2 * process + name.startswith(ZENOH_THREADS)]


def by_part(before: list[dict[tuple[int, str], tuple[int, ...]]],
            after: list[dict[tuple[int, str], tuple[int, ...]]], reading: int) -> dict[str, int]:
    """How much of reading ``reading`` (an index of :data:`READINGS`) the requester's and the
    answerer's threads added between two readings, by :data:`PARTS` (a thread started in
    between counts from 0)."""
    total = dict.fromkeys(PARTS, 0)
    for process, (b, a) in enumerate(zip(before, after, strict=True)):
        for key, values in a.items():
            total[part_of(process, key[1])] += values[reading] - b.get(key, (0,) * 3)[reading]
    return total


async def measure(pids: list[int], run: Callable[[], Awaitable[dict[str, float]]],
                  trips: int) -> dict[str, float]:
    """µs per round trip of ``run`` (``trips`` round trips, warm-up included): its time
    (from the one-way latency in ms it returns), and the CPU and context switches of
    the threads of ``pids`` (the requester's process, then the answerer's)."""
    before = [thread_readings(p) for p in pids]
    latency_ms = await run()
    after = [thread_readings(p) for p in pids]
    parts = by_part(before, after, 0)
    row = {"round trip": 2e3 * latency_ms["avg"], "cpu": sum(parts.values()) / trips / 1e3}
    row.update({k: v / trips / 1e3 for k, v in parts.items()})
    for reading in (1, 2):  # context switches per round trip
        row.update({f"{k}, {READINGS[reading]}": v / trips
                    for k, v in by_part(before, after, reading).items()})
    return row


async def _main(args: argparse.Namespace) -> dict[str, list[dict[str, float]]]:
    from plugcell.apps.bench import transport as bench
    from plugcell.framework.transport import TransportConfig

    home = tempfile.mkdtemp(prefix="plugcell-rtcpu-")
    os.environ["PLUGCELL_HOME"] = home
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    cell = f"rtcpu{uuid.uuid4().hex[:8]}"
    four = bench.PAYLOADS[0]
    warmup, cycles = 50, args.cycles
    results: dict[str, list[dict[str, float]]] = {"raw": [], "event loops": [], "plugcell": []}
    async with bench.parties(cell, env, TransportConfig.from_env(), not args.no_journal) as who:
        floor = [who.raw.popen.pid, who.raw_peer.popen.pid]
        ours = [os.getpid(), who.publisher.popen.pid]
        await bench.our_latency(who.consumer.participant, four, warmup, 0)  # warm both paths once
        await asyncio.to_thread(who.raw.latency, four.nbytes, warmup, 0)
        for _ in range(args.rounds):
            results["raw"].append(await measure(
                floor, lambda: asyncio.to_thread(who.raw.latency, four.nbytes, cycles, warmup),
                cycles + warmup))
            results["event loops"].append(await measure(
                floor,
                lambda: asyncio.to_thread(who.raw.latency_in_loop, four.nbytes, cycles, warmup),
                cycles + warmup))
            results["plugcell"].append(await measure(
                ours, lambda: bench.our_latency(who.consumer.participant, four, cycles, warmup),
                cycles + warmup))
    return results


def _median(values: list[float]) -> float:
    ordered = sorted(values)
    mid = len(ordered) // 2
    return ordered[mid] if len(ordered) % 2 else (ordered[mid - 1] + ordered[mid]) / 2


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cycles", type=int, default=4000)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--no-journal", action="store_true")
    ap.add_argument("--switches", action="store_true",
                    help="also print the context switches per round trip, by part")
    args = ap.parse_args()
    if args.cycles < 1 or args.rounds < 1:
        ap.error("--cycles and --rounds must be at least 1")
    if not Path("/proc/self/task").is_dir():
        print("round_trip_cpu.py reads /proc: Linux only", file=sys.stderr)
        return 2
    from plugcell.framework import eventloop

    results = eventloop.run(_main(args))
    print(f"4-byte round trips, {args.cycles} cycles (+50 warm-up) × {args.rounds} rounds, "
          f"journal {'off' if args.no_journal else 'on'}; {platform.machine()}, Python "
          f"{platform.python_version()}, {os.cpu_count()} cores, "
          f"load {os.getloadavg()[0]:.1f}")
    print("µs per round trip, both processes, median of the rounds (range)")
    header = ["round trip", "CPU", *PARTS]
    print(f"{'path':12s}" + "".join(f"{h:>24s}" for h in header) + f"{'CPU ÷ raw':>11s}")
    raw_cpu = _median([r["cpu"] for r in results["raw"]])
    for path, rows in results.items():
        cells = []
        for key in ("round trip", "cpu", *PARTS):
            values = [r[key] for r in rows]
            cells.append(f"{_median(values):6.1f} ({min(values):6.1f}–{max(values):6.1f})")
        ratio = _median([r["cpu"] for r in rows]) / raw_cpu
        print(f"{path:12s}" + "".join(f"{c:>24s}" for c in cells) + f"{ratio:10.2f}×")
    if args.switches:
        print("context switches per round trip, voluntary / forced, median of the rounds")
        print(f"{'path':12s}" + "".join(f"{h:>24s}" for h in PARTS))
        for path, rows in results.items():
            cells = [f"{_median([r[f'{k}, voluntary switches'] for r in rows]):6.2f} / "
                     f"{_median([r[f'{k}, forced switches'] for r in rows]):4.2f}"
                     for k in PARTS]
            print(f"{path:12s}" + "".join(f"{c:>24s}" for c in cells))
    return 0


if __name__ == "__main__":
    sys.exit(main())
