"""Where the Python of a CreateProcess → ProcessUpdate round trip goes, by function.

    .venv/bin/python benchmarks/round_trip_profile.py [--cycles 5000] [--top 20]

Two :class:`~plugcell.apps.bench.device.BenchService` instances — the requester and
the publisher of ``plugcell bench transport`` — in **one** process and one event loop,
over a real Zenoh session each (peer mode, loopback), journals on; ``--cycles`` Echo
round trips of 4 bytes run under :mod:`cProfile`.  Both sides' Python then runs on one
thread, so the profile holds all of it: the table sums the functions' own time per
round trip by where it is spent (the journal: its log and SQLite, Zenoh's calls, msgspec, the
rest of Python) and lists the largest functions.  The profiler adds its own cost to
every call (compare the plain and profiled times it prints); the shares are what
matter.  The two-process picture with both clocks is ``round_trip_trace.py``.
"""

from __future__ import annotations

import argparse
import cProfile
import os
import platform
import pstats
import sys
import tempfile
import time

import numpy as np


def _kind(func: tuple[str, int, str]) -> str:
    """Where a profiled function's own time is spent."""
    filename, _, name = func
    if ("sqlite3" in name or "sqlite3" in filename or "posix.write" in name
            or filename.endswith(("journal.py", "journal_log.py"))):
        return "journal (its log, SQLite)"
    if "Publisher" in name or "zenoh" in filename or "builtins.Session" in name:
        return "Zenoh calls"
    if "msgspec" in name or "Encoder" in name or "Decoder" in name:
        return "msgspec"
    return "Python"


async def _round_trips(cycles: int, profile: cProfile.Profile | None) -> float:
    from plugcell.apps.bench.device import bench_service
    from plugcell.framework.transport import TransportConfig

    cell = f"profile{os.getpid()}"
    publisher = bench_service("PUBLISHER", cell=cell, transport=TransportConfig.from_env())
    requester = bench_service("CONSUMER", cell=cell, transport=TransportConfig.from_env())
    await publisher.start()
    await requester.start()
    try:
        if not await requester.participant.wait_for("PUBLISHER", 15):
            raise RuntimeError("the publisher did not appear")
        await requester.participant.subscribe("PUBLISHER")
        data = np.full((4,), 7, np.uint8)
        data.flags.writeable = False

        async def once() -> None:
            call = await requester.participant.create_process("PUBLISHER", "Echo", data=data)
            async for update in call:
                if update.data is not None or update.state.final:
                    break

        for _ in range(300):  # warm up
            await once()
        started = time.perf_counter()
        if profile is not None:
            profile.enable()
        for _ in range(cycles):
            await once()
        if profile is not None:
            profile.disable()
        return (time.perf_counter() - started) / cycles * 1e6
    finally:
        await requester.close()
        await publisher.close()


def main(argv: list[str] | None = None) -> int:
    from plugcell.framework import eventloop

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cycles", type=int, default=5000)
    parser.add_argument("--top", type=int, default=20)
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="plugcell-profile-") as home:
        os.environ["PLUGCELL_HOME"] = home
        plain = eventloop.run(_round_trips(args.cycles, None))
        profile = cProfile.Profile()
        profiled = eventloop.run(_round_trips(args.cycles, profile))
    stats = pstats.Stats(profile).stats  # type: ignore[attr-defined]
    own: dict[str, float] = {}
    rows = []
    for func, (_, calls, tottime, _, _) in stats.items():
        own[_kind(func)] = own.get(_kind(func), 0.0) + tottime
        rows.append((tottime, calls, func))
    total = sum(own.values())
    n = args.cycles
    print(f"4-byte Echo round trips, both services in one process, journal on, {n} cycles; "
          f"{platform.machine()}, Python {platform.python_version()}")
    print(f"wall time per round trip: {plain:.1f} µs plain, {profiled:.1f} µs profiled; "
          f"CPU in the profiled functions {total / n * 1e6:.1f} µs")
    print(f"{'own time per round trip':<28} {'µs':>7} {'share':>6}")
    for kind, t in sorted(own.items(), key=lambda kv: -kv[1]):
        print(f"  {kind:<26} {t / n * 1e6:7.1f} {t / total:6.0%}")
    print("largest functions (own time per round trip, calls per round trip):")
    for tottime, calls, (filename, line, name) in sorted(rows, reverse=True)[: args.top]:
        where = f"{os.path.basename(filename)}:{line}" if line else "(built-in)"
        print(f"  {tottime / n * 1e6:6.1f} µs  {calls / n:4.1f}×  {name}  {where}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
