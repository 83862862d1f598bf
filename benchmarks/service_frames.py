"""What one streamed frame costs a service itself, with and without its journal.

    .venv/bin/python benchmarks/service_frames.py [--frames 64000] [--repeat 3]

Drives the publisher of ``plugcell bench transport`` (:class:`BenchService`) the
way its Push does — ``data_feedback.post`` of a frame, 64 per event-loop turn —
through the real DataFeedback receiver, the ProcessUpdate, the journal (in a
temporary folder) and the per-turn flush with its batching and encoding, but
with the Zenoh publisher replaced by one that counts the samples.  The service is
started as any service is, on a Zenoh session of its own that reaches no other
(no scouting, no listening); only its transport adapter's process publishers are
swapped for the counting one.  So the table is the
Python cost of the service's own path per frame, without the transport and
without another process competing for the cores: the part of the transport
benchmark's throughput that plugcell's code, not Zenoh, decides.  Best of
``--repeat`` runs.  The frame is read-only, as Push's is, so it is encoded straight
from its memory (framework/data.py); ``--large`` also shows a writeable frame, which
the service copies first.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import platform
import sys
import tempfile
import time
import uuid
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import numpy as np

from plugcell.apps.bench.device import BURST, bench_service
from plugcell.framework.journal import Journal
from plugcell.framework.messages import Process, Tag
from plugcell.framework.processqueue import Entry
from plugcell.framework.service import GenericDevice
from plugcell.framework.transport import TransportConfig

#: The payloads where per-frame work, not copying bytes, decides the rate (from 64 KiB
#: on, the copy of each frame into its buffer — with the page faults of fresh
#: memory — dominates and varies from run to run by more than the journal costs).
SHAPES = ((4,), (32,), (1024,), (4096,))
#: ``--large``: the camera-sized frames, where the copies decide — with the C allocator
#: as plugcell tunes it (framework/memory.py) and as glibc leaves it, and a writeable
#: frame (copied into its buffer first) beside the read-only one (not copied).
LARGE = ((65536,), (307200,), (921600,))


class _CountingPublisher:
    """Stands in for the Zenoh publisher: counts the samples the flush puts."""

    def __init__(self) -> None:
        self.samples = 0

    def put(self, payload: bytes) -> None:
        self.samples += 1

    def undeclare(self) -> None:
        """Nothing was declared (the service undeclares its publishers when it closes)."""


class _CountingBus:
    """The service's transport adapter (framework/bus.py) with every process publisher
    replaced by the counting one; everything else goes to the real adapter."""

    def __init__(self, bus: Any, publisher: _CountingPublisher) -> None:
        self.bus = bus
        self.publisher = publisher

    def process_publisher(self, name: str, sender: str, *, express: bool) -> _CountingPublisher:
        return self.publisher

    def __getattr__(self, name: str) -> Any:
        return getattr(self.bus, name)


#: A Zenoh session that reaches nobody: no scouting, no listening, no peer to connect to.
ALONE = TransportConfig(listen=(), multicast=False, shared_memory=False)


@contextlib.asynccontextmanager
async def _started_service() -> AsyncIterator[tuple[GenericDevice, _CountingPublisher]]:
    """The benchmark's publisher, started alone in a cell of its own, its process
    publishers counting (the journal is each measurement's own)."""
    service = bench_service("PUBLISHER", cell=f"frames{uuid.uuid4().hex[:8]}",
                            transport=ALONE, journal=False)
    await service.start()
    bus, publisher = service.participant.bus, _CountingPublisher()
    service.participant.bus = _CountingBus(bus, publisher)  # type: ignore[assignment]
    try:
        yield service, publisher
    finally:
        service.participant.bus = bus
        await service.close()


async def _frame_path_us(service: GenericDevice, publisher: _CountingPublisher,
                         shape: tuple[int, ...], frames: int, folder: Path | None,
                         read_only: bool = True) -> float:
    """µs per frame of ``frames`` posted to the started ``service``'s DataFeedback port,
    journaled into a new journal in ``folder`` (None: no journal)."""
    no_journal = service.journal
    if folder is not None:
        service.journal = Journal(folder / f"frames-{time.time_ns()}.sqlite", "PUBLISHER")
    push = service.device.command("Push")
    assert push is not None
    entry = Entry(process=Process(command=push, tag=Tag("CONSUMER", "PUBLISHER"),
                                  identifier=1), command=push)
    service.scheduler.measuring = entry  # the DataFeedback belongs to this Push
    publisher.samples = 0
    frame = np.full(shape, 7, np.uint8)
    frame.flags.writeable = not read_only
    try:
        started = time.perf_counter()
        for i in range(frames):
            service.data_feedback.post(frame)
            if i % BURST == BURST - 1:
                await asyncio.sleep(0)
        await asyncio.sleep(0)
        elapsed = time.perf_counter() - started
    finally:
        service.scheduler.measuring = None
        if folder is not None:
            service.journal.close()
            service.journal = no_journal
    if entry.seq != frames or service.outbox or not publisher.samples:
        raise RuntimeError(f"{entry.seq} of {frames} frames made, {publisher.samples} samples")
    return elapsed / frames * 1e6


async def _per_frame_us(shape: tuple[int, ...], frames: int, folder: Path | None,
                        read_only: bool = True, repeat: int = 1) -> float:
    """The best of ``repeat`` measurements of :func:`_frame_path_us` on a service of its own."""
    async with _started_service() as (service, publisher):
        return min([await _frame_path_us(service, publisher, shape, frames, folder, read_only)
                    for _ in range(repeat)])


async def _table(shapes: tuple[tuple[int, ...], ...], frames: int, repeat: int,
                 folder: Path) -> list[tuple[int, float, float]]:
    """Per shape: (bytes, µs per frame without the journal, with it), each the best of
    ``repeat``, alternated so that both see the same machine."""
    rows = []
    async with _started_service() as (service, publisher):
        for shape in shapes:
            bare, kept = float("inf"), float("inf")
            for _ in range(repeat):
                bare = min(bare, await _frame_path_us(service, publisher, shape, frames, None))
                kept = min(kept, await _frame_path_us(service, publisher, shape, frames, folder))
            rows.append((shape[0], bare, kept))
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=64000)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--large", action="store_true",
                        help="64 KiB – 0.9 MB frames, allocator tuned against glibc's default "
                        "(a child process each, since the tuning is process-wide)")
    args = parser.parse_args(argv)
    if args.large:
        return _large(args.repeat)
    print(f"service path per streamed frame (µs, best of {args.repeat}), "
          f"{platform.processor() or platform.machine()}, Python {platform.python_version()}")
    print(f"{'payload':>9} | {'no journal':>10} | {'journal':>8} | {'journal share':>13}")
    print("-" * 50)
    with tempfile.TemporaryDirectory(prefix="plugcell-frames-") as tmp:
        for n, bare, kept in asyncio.run(_table(SHAPES, args.frames, args.repeat, Path(tmp))):
            print(f"{n:>7} B | {bare:>10.2f} | {kept:>8.2f} | {(kept - bare) / kept:>12.0%}")
    return 0


def _large(repeat: int) -> int:
    """Per-frame cost of the large frames, journal on, tuned vs default allocator."""
    import os
    import subprocess

    print(f"service path per large frame, journal on (µs, best of {repeat}), "
          f"{platform.machine()}, Python {platform.python_version()}")
    print(f"{'':>9} | {'read-only frame (not copied)':>29} | {'writeable frame (copied)':>29}")
    print(f"{'payload':>9} | {'tuned allocator':>15} {'glibc default':>13} | "
          f"{'tuned allocator':>15} {'glibc default':>13}")
    print("-" * 73)
    code = ("import asyncio, sys, tempfile; from pathlib import Path; sys.path.insert(0, {here!r});"
            "import service_frames as sf; from plugcell.framework.memory import tune_allocator;"
            "tune_allocator(); shape = ({n},);"
            "print(asyncio.run(sf._per_frame_us(shape, 1000, Path(tempfile.mkdtemp()),"
            " {read_only}, {repeat})))")
    here = str(Path(__file__).resolve().parent)
    for (n,) in LARGE:
        row = []
        for read_only in (True, False):
            for malloc in ("", "default"):
                env = {**os.environ, "PLUGCELL_MALLOC": malloc}
                argv = [sys.executable, "-c", code.format(here=here, n=n, read_only=read_only,
                                                          repeat=repeat)]
                out = subprocess.run(argv, env=env, capture_output=True, text=True, check=True)
                row.append(float(out.stdout))
        print(f"{n:>7} B | {row[0]:>15.1f} {row[1]:>13.1f} | {row[2]:>15.1f} {row[3]:>13.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
