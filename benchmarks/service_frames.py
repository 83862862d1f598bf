"""What one streamed frame costs a service itself, with and without its journal.

    .venv/bin/python benchmarks/service_frames.py [--frames 64000] [--repeat 3]

Drives the publisher of ``plugcell bench transport`` (:class:`BenchService`) the
way its Push does — ``data_feedback.post`` of a frame, 64 per event-loop turn —
through the real DataFeedback receiver, the ProcessUpdate, the journal (SQLite in
a temporary folder) and the per-turn flush with its batching and encoding, but
with the Zenoh publisher replaced by one that counts the samples.  So the table is the
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
import platform
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from plugcell.apps.bench.device import BURST, BenchService
from plugcell.framework.journal import Journal
from plugcell.framework.messages import Process, Tag
from plugcell.framework.processqueue import Entry

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


class _CountingBus:
    """Stands in for the service's transport adapter (framework/bus.py): always open,
    every process publisher is the counting one."""

    is_open = True

    def __init__(self, publisher: _CountingPublisher) -> None:
        self.publisher = publisher

    def process_publisher(self, name: str, sender: str, *, express: bool) -> _CountingPublisher:
        return self.publisher


async def _per_frame_us(shape: tuple[int, ...], frames: int, folder: Path | None,
                        read_only: bool = True) -> float:
    service = BenchService("PUBLISHER", journal=False)
    service._loop = asyncio.get_running_loop()
    service._loop_thread = threading.get_ident()
    if folder is not None:
        service.journal = Journal(folder / f"frames-{time.time_ns()}.sqlite", "PUBLISHER")
    publisher = _CountingPublisher()
    service.bus = _CountingBus(publisher)  # type: ignore[assignment]
    service.outbox.loop = service._loop
    push = service.device.command("Push")
    assert push is not None
    entry = Entry(process=Process(command=push, tag=Tag("CONSUMER", "PUBLISHER"),
                                  identifier=1), command=push)
    service._measuring = entry
    frame = np.full(shape, 7, np.uint8)
    frame.flags.writeable = not read_only
    started = time.perf_counter()
    for i in range(frames):
        service.data_feedback.post(frame)
        if i % BURST == BURST - 1:
            await asyncio.sleep(0)
    await asyncio.sleep(0)
    elapsed = time.perf_counter() - started
    if entry.seq != frames or service.outbox or not publisher.samples:
        raise RuntimeError(f"{entry.seq} of {frames} frames made, {publisher.samples} samples")
    service.journal.close()
    return elapsed / frames * 1e6


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
        for shape in SHAPES:
            bare, kept = float("inf"), float("inf")
            for _ in range(args.repeat):  # alternated, so both see the same machine
                bare = min(bare, asyncio.run(_per_frame_us(shape, args.frames, None)))
                kept = min(kept, asyncio.run(_per_frame_us(shape, args.frames, Path(tmp))))
            print(f"{shape[0]:>7} B | {bare:>10.2f} | {kept:>8.2f} | "
                  f"{(kept - bare) / kept:>12.0%}")
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
            "print(min(asyncio.run(sf._per_frame_us(shape, 1000, Path(tempfile.mkdtemp()),"
            " {read_only})) for _ in range({repeat})))")
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
