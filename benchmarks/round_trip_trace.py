"""Where one CreateProcess → ProcessUpdate round trip spends its time, step by step.

    .venv/bin/python benchmarks/round_trip_trace.py [--cycles 2000] [--no-journal]

The transport benchmark's latency test (``Echo`` of 4 bytes to the
:class:`~plugcell.apps.bench.device.BenchService` in a second OS process), with probes
on both sides: each records ``time.perf_counter_ns()`` — CLOCK_MONOTONIC, one
clock for every process of the machine — at the seams of the path (the Zenoh
callback, the event loop's wake-up, the service's check-and-journal, the commit,
the put, the requester's resumption).  The two traces are merged and the median
of each step over the cycles is printed.

A diagnostic, not a figure of merit: the probes wrap framework methods (about
1 µs each), so the total is a little above ``plugcell bench transport``'s.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

Trace = list[tuple[str, int]]


def _probe(trace: Trace, owner: Any, name: str, before: str, after: str = "") -> None:
    """Wrap ``owner.name`` so that it records ``before`` (and ``after``) around each call."""
    inner: Callable[..., Any] = getattr(owner, name)
    clock = time.perf_counter_ns

    def probed(*args: Any, **kwargs: Any) -> Any:
        trace.append((before, clock()))
        try:
            return inner(*args, **kwargs)
        finally:
            if after:
                trace.append((after, clock()))

    setattr(owner, name, probed)


def _probe_framework(trace: Trace, arrival: bool = False) -> None:
    from plugcell.framework import inbound, journal, outbox, port

    _probe(trace, port.Port, "_drain", "loop wakes")
    if arrival:  # the Zenoh callback's hand-off, on Zenoh's thread
        _probe(trace, port.Port, "post", "Zenoh callback")
    _probe(trace, inbound.Inbound, "create", "check+journal", "checked")
    _probe(trace, outbox.Outbox, "flush", "flush")
    _probe(trace, journal.Journal, "commit", "commit", "committed")
    _probe(trace, outbox.Outbox, "_send", "put", "sent")


#: Steps of the service whose CPU time is compared with their wall time.
CPU_STEPS = (("inbound", "create"), ("journal", "commit"), ("outbox", "_send"))


def _probe_cpu(spent: list[tuple[str, int, int]], owner: Any, name: str) -> None:
    """Wrap ``owner.name`` to record its wall time and its thread's CPU time per call."""
    inner: Callable[..., Any] = getattr(owner, name)

    def probed(*args: Any, **kwargs: Any) -> Any:
        wall, cpu = time.perf_counter_ns(), time.thread_time_ns()
        try:
            return inner(*args, **kwargs)
        finally:
            spent.append((name, time.perf_counter_ns() - wall, time.thread_time_ns() - cpu))

    setattr(owner, name, probed)


def _spy_on_requests(trace: Trace) -> None:
    """Beside the service's own subscriber of requests, a plain Zenoh subscriber of the
    same key on the same session, recording when each request sample reaches it: the
    transfer alone, whatever plugcell's callback does."""
    from zenoh.handlers import Callback

    from plugcell.framework.bus import Bus

    take_requests = Bus.take_requests
    spies: list[Any] = []

    def spied(self: Bus, name: str, handler: Any) -> Any:
        spies.append(self.session.declare_subscriber(
            self.keys.requests(name),
            Callback(lambda _: trace.append(("sample arrives", time.perf_counter_ns())),
                     indirect=False)))
        return take_requests(self, name, handler)

    Bus.take_requests = spied  # type: ignore[method-assign]


def serve(cell: str, journal: bool, out: str, arrival: bool = False) -> None:
    """The publisher, probed; its trace goes to ``out`` when it stops (SIGTERM)."""
    import atexit

    from plugcell.apps.bench import peer
    from plugcell.framework import inbound, outbox
    from plugcell.framework import journal as journal_module

    trace: Trace = []
    spent: list[tuple[str, int, int]] = []
    _probe_framework(trace, arrival)
    if arrival:
        _spy_on_requests(trace)
    # inside the step probes, so they time just what those enclose
    for owner, step in CPU_STEPS:
        _probe_cpu(spent, {"inbound": inbound.Inbound, "outbox": outbox.Outbox,
                           "journal": journal_module.Journal}[owner], step)
    atexit.register(lambda: Path(out).write_text(json.dumps({"trace": trace, "cpu": spent})))
    peer.main(["service", "--cell", cell, *([] if journal else ["--no-journal"])])


class _ProbedDoor:
    """The requester's request publisher, with probes around its put."""

    def __init__(self, door: Any, trace: Trace) -> None:
        self._door, self._trace = door, trace

    def put(self, *args: Any, **kwargs: Any) -> None:
        self._trace.append(("put request", time.perf_counter_ns()))
        self._door.put(*args, **kwargs)
        self._trace.append(("request sent", time.perf_counter_ns()))

    def __getattr__(self, name: str) -> Any:
        return getattr(self._door, name)


async def _requester(cell: str, journal: bool, cycles: int, trace: Trace,
                     arrival: bool = False) -> None:
    from plugcell.apps.bench.device import bench_service
    from plugcell.framework.transport import TransportConfig

    if arrival:  # before start: the transport adapter keeps the bound hand-off it gets
        from plugcell.framework import port

        _probe(trace, port.Port, "post", "Zenoh callback")
    consumer = bench_service("CONSUMER", cell=cell, transport=TransportConfig.from_env(),
                            journal=journal)
    await consumer.start()
    try:
        if not await consumer.participant.wait_for("PUBLISHER", 15):
            raise RuntimeError("the publisher did not appear")
        await consumer.participant.subscribe("PUBLISHER")
        data = np.full((4,), 7, np.uint8)
        for i in range(200 + cycles):
            if i == 200:  # warmed up: probe from here on
                _probe_framework(trace)
                door = consumer.participant.calls._doors["PUBLISHER"]
                consumer.participant.calls._doors["PUBLISHER"] = _ProbedDoor(door, trace)
            probed = i >= 200
            if probed:
                trace.append(("create_process", time.perf_counter_ns()))
            call = await consumer.participant.create_process("PUBLISHER", "Echo", data=data)
            if probed:
                trace.append(("resumed", time.perf_counter_ns()))
            async for update in call:
                if update.state.final:
                    break
        consumer.participant.calls._doors["PUBLISHER"] = door
    finally:
        await consumer.close()


def _first_of_each(cycle: Trace) -> Trace:
    seen: set[str] = set()
    return [(n, t) for n, t in cycle if not (n in seen or seen.add(n))]


def breakdown(requester: Trace, service: Trace) -> tuple[list[tuple[str, float]], int, int]:
    """Median duration of each step of the most common sequence, per cycle."""
    events = sorted([("requester: " + n, t) for n, t in requester]
                    + [("service: " + n, t) for n, t in service], key=lambda e: e[1])
    cycles: list[Trace] = []
    for name, t in events:
        if name == "requester: create_process":
            cycles.append([])
        if cycles:
            cycles[-1].append((name, t))
    # a round trip ends when the requester resumes; the first time each step is seen
    # is the one on the path (the service may run an empty flush while the answer travels)
    end = "requester: resumed"
    cycles = [_first_of_each(c) for c in cycles if end in (n for n, _ in c)]
    cycles = [c[: [n for n, _ in c].index(end) + 1] for c in cycles]
    shapes = Counter(tuple(n for n, _ in c) for c in cycles)
    shape, count = shapes.most_common(1)[0]
    steps: list[list[int]] = [[] for _ in shape]
    for c in cycles:
        if tuple(n for n, _ in c) == shape:
            for k in range(1, len(c)):
                steps[k].append(c[k][1] - c[k - 1][1])
    rows = [(f"{shape[k - 1]} → {shape[k]}", statistics.median(steps[k]) / 1e3)
            for k in range(1, len(shape))]
    return rows, count, len(cycles)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cycles", type=int, default=2000)
    parser.add_argument("--no-journal", action="store_true")
    parser.add_argument("--arrival", action="store_true",
                        help="also time each sample's arrival: the Zenoh callback's hand-off "
                        "on both sides, and a plain Zenoh subscriber of the requests beside "
                        "the service's (the transfer alone)")
    parser.add_argument("--serve", nargs=2, metavar=("CELL", "OUT"), help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    journal = not args.no_journal
    if args.serve:
        serve(args.serve[0], journal, args.serve[1], args.arrival)
        return 0
    from plugcell.framework import eventloop

    with tempfile.TemporaryDirectory(prefix="plugcell-trace-") as tmp:
        os.environ["PLUGCELL_HOME"] = tmp
        cell, out = f"trace{os.getpid()}", os.path.join(tmp, "service-trace.json")
        child = subprocess.Popen(
            [sys.executable, __file__, "--serve", cell, out,
             *([] if journal else ["--no-journal"]), *(["--arrival"] if args.arrival else [])],
            stdout=subprocess.PIPE, text=True,
        )
        try:
            assert child.stdout is not None
            if child.stdout.readline().strip() != "ready":
                raise RuntimeError("the publisher did not start")
            trace: Trace = []
            eventloop.run(_requester(cell, journal, args.cycles, trace, args.arrival))
        finally:
            child.terminate()
            child.wait(15)
        recorded = json.loads(Path(out).read_text())
        service = [(n, t) for n, t in recorded["trace"]]
    rows, count, total = breakdown(trace, service)
    print(f"4-byte Echo round trip, journal {'on' if journal else 'off'}, "
          f"median of {count} of {total} cycles that took the usual path (µs)")
    width = max(len(name) for name, _ in rows)
    for name, us in rows:
        print(f"  {name:<{width}}  {us:7.1f}")
    print(f"  {'round trip (sum of the medians)':<{width}}  {sum(us for _, us in rows):7.1f}")
    print("the service's steps, wall time against its thread's CPU time (median µs):")
    for _, step in CPU_STEPS:
        calls = [(w, c) for n, w, c in recorded["cpu"][600:] if n == step]  # warmed up
        if calls:
            print(f"  {step:<8} wall {statistics.median(w for w, _ in calls) / 1e3:6.1f}"
                  f"   CPU {statistics.median(c for _, c in calls) / 1e3:6.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
