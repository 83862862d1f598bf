"""What the journal's durability rule costs *any* implementation of the request path.

    .venv/bin/python benchmarks/durability_floor.py [--cycles 4000] [--repeat 3]

The event-loop floor of ``plugcell bench transport`` (raw Zenoh between two OS
processes, each sample handed to an event loop by ``call_soon_threadsafe``, the answer
put from that loop, the requester awaiting a future) with the answering side doing,
before each answer, what the journal's rule asks of every request ("a process row is
committed before its acknowledgement is sent; every update before it is published",
``framework/journal.py``) and nothing else:

* ``nothing`` — the floor itself;
* ``log append`` — the same three rows (a process and its Running and Completed
  updates) encoded with msgspec and appended to a file with one ``os.write``: the
  cheapest write that, like SQLite's WAL with ``synchronous=NORMAL``, survives the
  death of the process (the kernel has the bytes);
* ``SQLite commit`` — the same rows inserted into the journal's tables and committed
  in one SQLite transaction (WAL, ``synchronous=NORMAL``): how plugcell's journal kept
  the rule until 2026-11-26;
* ``Journal`` — the real :class:`~plugcell.framework.journal.Journal`:
  ``record_process``, two ``record_update`` and one ``commit``, as an ``Echo`` costs
  the service (a log append; its rows move into SQLite in the background).

No decoding, admission, scheduling or outbox: whatever a native or Python framework
adds comes on top, so the table bounds from below what the request path can reach with
each way of keeping the rule.  The variants run interleaved, ``--repeat`` rounds; the
table gives each one's median over the rounds of the average one-way latency
(round trip ÷ 2) and what it adds to the floor.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import platform
import sqlite3
import statistics
import subprocess
import sys
import tempfile
import time
from importlib import metadata
from pathlib import Path

import msgspec
import zenoh

VARIANTS = ("nothing", "log append", "SQLite commit", "Journal")


def _serve(variant: str, key: str, folder: str) -> None:
    """Answer every ``key/ping`` on ``key/pong`` from an event loop, after ``variant``."""
    from plugcell.framework import eventloop
    from plugcell.framework.journal import TABLES, Journal
    from plugcell.framework.transport import TransportConfig, open_session

    session = open_session(TransportConfig.from_env())
    pong = session.declare_publisher(
        f"{key}/pong", express=True, congestion_control=zenoh.CongestionControl.BLOCK
    )
    loop = eventloop.new_event_loop()
    journal = (
        Journal(Path(folder) / "SERVICE.sqlite", "SERVICE") if variant == "Journal" else None
    )
    log = (
        os.open(Path(folder) / "SERVICE.log", os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
        if variant == "log append"
        else None
    )
    db = None
    if variant == "SQLite commit":
        db = sqlite3.connect(Path(folder) / "SERVICE.sqlite")
        db.execute("PRAGMA journal_mode=WAL")
        db.execute("PRAGMA synchronous=NORMAL")
        db.executescript(TABLES)
    encoder = msgspec.msgpack.Encoder()
    count = 0

    def answer(payload: bytes) -> None:
        nonlocal count
        count += 1
        if journal is not None:
            journal.record_process(
                sender="REQUESTER", identifier=count, sender_instance="requester-instance",
                recipient_instance="service-instance", command="Echo", option="",
                command_type="Get", input_summary="Integer[1] [7]",
                received_ns=time.time_ns(), state="Queued",
            )
            journal.record_update("REQUESTER", count, 1, "Running", "", "")
            journal.record_update("REQUESTER", count, 2, "Completed", "", "Integer[1] [7]")
            journal.commit()
        elif db is not None:
            now = time.time_ns()
            db.execute(
                "INSERT INTO processes VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?)",
                ("SERVICE", "REQUESTER", count, "service-instance", "requester-instance",
                 "Echo", "", "Get", "Integer[1] [7]", now, now, "Queued", ""),
            )
            db.executemany("INSERT INTO updates VALUES (?,?,?,?,?,?,?,?)", (
                ("SERVICE", "REQUESTER", count, 1, now, "Running", "", ""),
                ("SERVICE", "REQUESTER", count, 2, now, "Completed", "", "Integer[1] [7]"),
            ))
            db.commit()
        elif log is not None:
            now = time.time_ns()
            os.write(log, encoder.encode((
                ("SERVICE", "REQUESTER", count, "service-instance", "requester-instance",
                 "Echo", "", "Get", "Integer[1] [7]", now, now, "Queued", ""),
                ("SERVICE", "REQUESTER", count, 1, now, "Running", "", ""),
                ("SERVICE", "REQUESTER", count, 2, now, "Completed", "", "Integer[1] [7]"),
            )))
        pong.put(payload)

    session.declare_subscriber(
        f"{key}/ping",
        lambda sample: loop.call_soon_threadsafe(answer, sample.payload.to_bytes()),
    )
    print("ready", flush=True)
    loop.run_forever()


async def _ping(key: str, cycles: int, warmup: int) -> float:
    """Average one-way latency in ms of ``cycles`` 4-byte round trips to ``key``."""
    from plugcell.framework.transport import TransportConfig, open_session

    session = open_session(TransportConfig.from_env())
    loop = asyncio.get_running_loop()
    waiting: list[asyncio.Future[bytes]] = []

    def arrived(answer: bytes) -> None:
        if waiting and not waiting[0].done():
            waiting[0].set_result(answer)

    session.declare_subscriber(
        f"{key}/pong", lambda sample: loop.call_soon_threadsafe(arrived, sample.payload.to_bytes())
    )
    ping = session.declare_publisher(
        f"{key}/ping", express=True, congestion_control=zenoh.CongestionControl.BLOCK
    )
    try:
        for _ in range(200):  # until the answering side's subscriber is matched
            waiting[:] = [loop.create_future()]
            ping.put(b"ping")
            try:
                await asyncio.wait_for(waiting[0], 0.05)
                break
            except TimeoutError:
                continue
        else:
            raise RuntimeError("the answering process never answered")
        half_trips = []
        for i in range(warmup + cycles):
            waiting[:] = [loop.create_future()]
            started = time.perf_counter_ns()
            ping.put(b"ping")
            await asyncio.wait_for(waiting[0], 5.0)
            if i >= warmup:
                half_trips.append((time.perf_counter_ns() - started) / 2)
        return statistics.fmean(half_trips) / 1e6
    finally:
        session.close()


def _round(variant: str, cycles: int, warmup: int) -> float:
    from plugcell.framework import eventloop

    key = f"plugcell-bench/durability{os.getpid()}/{time.monotonic_ns()}"
    with tempfile.TemporaryDirectory(prefix="plugcell-durability-") as folder:
        server = subprocess.Popen(
            [sys.executable, __file__, "--serve", variant, key, folder],
            stdout=subprocess.PIPE, text=True,
        )
        try:
            assert server.stdout is not None
            if server.stdout.readline().strip() != "ready":
                raise RuntimeError(f"the answering process for {variant!r} did not start")
            return eventloop.run(_ping(key, cycles, warmup))
        finally:
            server.kill()
            server.wait()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cycles", type=int, default=4000)
    parser.add_argument("--warmup", type=int, default=500)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--serve", nargs=3, metavar=("VARIANT", "KEY", "FOLDER"),
                        help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.serve:
        _serve(*args.serve)
        return 0
    if args.cycles < 1 or args.repeat < 1 or args.warmup < 0:
        parser.error("--cycles and --repeat must be at least 1, --warmup at least 0")
    results: dict[str, list[float]] = {v: [] for v in VARIANTS}
    for r in range(args.repeat):
        for variant in VARIANTS:
            results[variant].append(_round(variant, args.cycles, args.warmup))
            print(f"  … round {r + 1}/{args.repeat}: {variant}: "
                  f"{results[variant][-1]:.4f} ms", file=sys.stderr, flush=True)
    print(f"4-byte round trips between two processes through an event loop on each side, "
          f"{args.cycles} cycles × {args.repeat} rounds; {platform.machine()}, "
          f"Python {platform.python_version()}, eclipse-zenoh {metadata.version('eclipse-zenoh')}")
    floor = statistics.median(results[VARIANTS[0]])
    print(f"{'before each answer':<20} {'one-way ms':>11} {'added µs':>9} {'× floor':>8}  rounds")
    for variant in VARIANTS:
        med = statistics.median(results[variant])
        rounds = " ".join(f"{x:.4f}" for x in results[variant])
        print(f"{variant:<20} {med:11.4f} {(med - floor) * 1e3:9.1f} {med / floor:8.2f}  {rounds}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
