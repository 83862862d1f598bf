"""The far side of the transport benchmark, run as its own OS process.

``python -m plugcell.apps.bench.peer service --cell C`` serves the publisher
(:class:`~plugcell.apps.bench.device.BenchService`); ``python -m plugcell.apps.bench.peer raw
--cell C`` answers plain Zenoh pub/sub pings and pushes plain samples — the
floor our latency and throughput are compared with.  Both print ``ready`` and run
until SIGTERM.  ``raw-requester`` is the other end of that floor (:class:`RawFloor`),
measuring on the commands it reads from standard input until it ends.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import queue
import signal
import statistics
import struct
import sys
import threading
import time
from collections.abc import Callable
from typing import Any

# Zenoh itself, not plugcell's transport adapter (framework/bus.py): the raw peer is
# the far side of the raw-Zenoh floor of ``plugcell bench transport``.
import zenoh
from zenoh.handlers import Callback

from plugcell.framework import eventloop
from plugcell.framework.transport import TransportConfig, open_session


def raw_keys(cell: str) -> dict[str, str]:
    """Keys of the raw Zenoh floor (outside the plugcell key space, isolated by cell)."""
    root = f"plugcell-bench/{cell}"
    return {k: f"{root}/{k}" for k in ("ping", "pong", "push", "data", "echo", "echoed",
                                       "aping", "apong")}


def stats_ms(half_trips_ns: list[int]) -> dict[str, float]:
    """avg/max/min/std (population, "jitter") and p99 of one-way latencies, in ms."""
    ms = [t / 1e6 for t in half_trips_ns]
    ordered = sorted(ms)
    return {
        "avg": statistics.fmean(ms),
        "max": ordered[-1],
        "min": ordered[0],
        "std": statistics.pstdev(ms),
        "p99": ordered[min(len(ordered) - 1, int(0.99 * len(ordered)))],
    }


class RawFloor:
    """Plain Zenoh pub/sub from this process to the raw peer (:func:`serve_raw`).

    Zenoh itself, not plugcell's transport adapter (framework/bus.py): the raw-Zenoh
    floor plugcell is compared with.  ``plugcell bench transport`` runs it in a process
    of its own (:func:`serve_raw_requester`), so that it is plain Zenoh as a Python
    program using Zenoh alone gets it, not sharing the benchmark's Zenoh threads whose
    Python thread states plugcell keeps (framework/threadstate.py).  Its event loop
    (:meth:`latency_in_loop`) runs in a thread of its own for the floor's lifetime.
    """

    def __init__(self, cell: str, transport: TransportConfig) -> None:
        self.keys = raw_keys(cell)
        self.session = open_session(transport)
        self._pongs: queue.SimpleQueue[bytes] = queue.SimpleQueue()
        self._count = 0
        self._target = 0
        self._done = threading.Event()
        self._subs = [
            self.session.declare_subscriber(
                self.keys["pong"],
                Callback(lambda s: self._pongs.put(s.payload.to_bytes()), indirect=False),
            ),
            self.session.declare_subscriber(
                self.keys["data"], Callback(self._on_data, indirect=False)
            ),
        ]
        self._ping = self.session.declare_publisher(
            self.keys["ping"], express=True, congestion_control=zenoh.CongestionControl.BLOCK
        )
        self._echo = self.session.declare_publisher(self.keys["echo"], express=True)
        self._on_echoed: Callable[[], None] = lambda: None
        self._subs.append(self.session.declare_subscriber(
            self.keys["echoed"], Callback(lambda _: self._on_echoed(), indirect=False)
        ))
        self._push = self.session.declare_publisher(self.keys["push"])
        self._aping = self.session.declare_publisher(
            self.keys["aping"], express=True, congestion_control=zenoh.CongestionControl.BLOCK
        )
        self._on_apong: Callable[[bytes], None] = lambda _: None
        self._loop = eventloop.new_event_loop()
        self._looper = threading.Thread(target=self._loop.run_forever, name="asyncio floor",
                                        daemon=True)
        self._looper.start()
        self._subs.append(self.session.declare_subscriber(
            self.keys["apong"],
            Callback(lambda s: self._on_apong(s.payload.to_bytes()), indirect=False),
        ))
        # handshake: declarations propagate asynchronously, so ping until a pong comes
        for _ in range(100):
            self._ping.put(b"hello")
            with contextlib.suppress(queue.Empty):
                self._pongs.get(timeout=0.1)
                break
        else:
            raise RuntimeError("raw peer not reachable")
        with contextlib.suppress(queue.Empty):
            while True:
                self._pongs.get(timeout=0.2)  # late duplicates of the handshake

    def _on_data(self, sample: zenoh.Sample) -> None:
        sample.payload.to_bytes()  # receive it as a consumer would
        self._count += 1
        if self._count >= self._target:
            self._done.set()

    def latency(self, nbytes: int, cycles: int, warmup: int) -> dict[str, float]:
        payload = bytes(nbytes)
        trips = []
        for i in range(warmup + cycles):
            t0 = time.perf_counter_ns()
            self._ping.put(payload)
            self._pongs.get(timeout=10)
            if i >= warmup:
                trips.append((time.perf_counter_ns() - t0) // 2)
        return stats_ms(trips)

    def latency_in_callback(self, nbytes: int, cycles: int, warmup: int) -> dict[str, float]:
        """Ping-pong with both sides answering inside Zenoh's callbacks (no thread hop).

        Each echo's callback sends the next one, so the cycles chain by themselves;
        this thread only waits for the last.
        """
        payload, total = bytes(nbytes), warmup + cycles
        trips: list[int] = []
        done = threading.Event()
        for _ in range(100):  # the peer's echo subscriber may not be matched yet
            self._on_echoed = done.set
            self._echo.put(payload)
            if done.wait(0.1):
                break
        else:
            raise RuntimeError("raw peer does not echo inside its callback")
        time.sleep(0.2)  # late duplicates of the handshake
        done.clear()
        cycle = {"number": 1, "sent_ns": 0}

        def on_echoed() -> None:
            now = time.perf_counter_ns()
            if cycle["number"] > warmup:
                trips.append((now - cycle["sent_ns"]) // 2)
            if cycle["number"] == total:
                done.set()
                return
            cycle["number"] += 1
            cycle["sent_ns"] = time.perf_counter_ns()
            self._echo.put(payload)

        self._on_echoed = on_echoed
        cycle["sent_ns"] = time.perf_counter_ns()
        self._echo.put(payload)
        finished = done.wait(max(30.0, total * 0.01))
        self._on_echoed = lambda: None
        if not finished:
            raise RuntimeError(f"in-callback ping-pong: {len(trips)}/{cycles} echoes arrived")
        return stats_ms(trips)

    def latency_in_loop(self, nbytes: int, cycles: int, warmup: int) -> dict[str, float]:
        """Ping-pong where each side's callback hands the sample to an event loop.

        Both ends run plugcell's event loop (uvloop; here in the floor's own thread) and
        reach it by ``call_soon_threadsafe``; this side awaits a future per cycle (under
        a 10 s timeout, as plugcell's calls wait under theirs), the peer puts the answer
        from its loop — the hops of any asyncio service and
        nothing of plugcell's own work: the floor of the event-loop design.
        """
        payload = bytes(nbytes)

        async def ping_pong() -> list[int]:
            loop = asyncio.get_running_loop()
            waiting: list[asyncio.Future[bytes]] = []

            def arrived(answer: bytes) -> None:
                if waiting and not waiting[0].done():
                    waiting[0].set_result(answer)

            self._on_apong = lambda b: loop.call_soon_threadsafe(arrived, b)
            for _ in range(100):  # the peer's subscriber may not be matched yet
                waiting[:] = [loop.create_future()]
                self._aping.put(payload)
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(waiting[0], 0.1)
                    break
            else:
                raise RuntimeError("raw peer does not answer from its event loop")
            await asyncio.sleep(0.2)  # late duplicates of the handshake
            trips = []
            for i in range(warmup + cycles):
                waiting[:] = [loop.create_future()]
                t0 = time.perf_counter_ns()
                self._aping.put(payload)
                await asyncio.wait_for(waiting[0], 10)
                if i >= warmup:
                    trips.append((time.perf_counter_ns() - t0) // 2)
            return trips

        try:
            trips = asyncio.run_coroutine_threadsafe(ping_pong(), self._loop).result()
        finally:
            self._on_apong = lambda _: None
        return stats_ms(trips)

    def throughput(self, nbytes: int, messages: int) -> float:
        self._count, self._target = 0, messages
        self._done.clear()
        t0 = time.perf_counter()
        self._push.put(struct.pack("<QQ", messages, nbytes))
        if not self._done.wait(300):
            raise RuntimeError(f"raw throughput: {self._count}/{messages} samples arrived")
        return messages / (time.perf_counter() - t0)

    def close(self) -> None:
        for s in self._subs:
            s.undeclare()
        self._ping.undeclare()
        self._echo.undeclare()
        self._push.undeclare()
        self._aping.undeclare()
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._looper.join(5)
        if not self._looper.is_alive():
            self._loop.close()
        self.session.close()


#: What :func:`serve_raw_requester` runs on command: :class:`RawFloor`'s measurements.
REQUESTER_OPERATIONS = ("latency", "latency_in_callback", "latency_in_loop", "throughput")


def requester_answer(floor: Any, line: str) -> str:
    """The answer line (JSON, no newline) of :func:`serve_raw_requester` to one command.

    ``line`` must be ``[operation, *counts]``: an operation of
    :data:`REQUESTER_OPERATIONS` and non-negative integers.  The answer is
    ``{"result": ...}`` with what ``floor``'s method returned, or ``{"error": reason}``
    for anything else — bad JSON, another shape, an unknown operation, a wrong count
    or the measurement's own failure; it never raises.
    """
    try:
        command = json.loads(line)
        if not isinstance(command, list) or not command or not isinstance(command[0], str):
            raise ValueError(f"a command is [operation, *counts], got {line.strip()[:80]!r}")
        op, *args = command
        if op not in REQUESTER_OPERATIONS:
            raise ValueError(f"unknown operation {op!r} (known: {', '.join(REQUESTER_OPERATIONS)})")
        if not all(type(a) is int and a >= 0 for a in args):
            raise ValueError(f"arguments must be counts, got {args!r}")
        result = getattr(floor, op)(*args)
    except Exception as exc:  # answer every line: the caller waits for it
        return json.dumps({"error": f"{type(exc).__name__}: {exc}"})
    return json.dumps({"result": result})


def serve_raw_requester(cell: str, transport: TransportConfig) -> None:
    """Run the floor's requester (:class:`RawFloor`) and its measurements on command.

    Prints ``ready`` once the raw peer answers, then answers each line of standard input
    with one line (:func:`requester_answer`); ends when standard input does.
    """
    floor = RawFloor(cell, transport)
    print("ready", flush=True)
    try:
        for line in sys.stdin:
            print(requester_answer(floor, line), flush=True)
    finally:
        floor.close()


def serve_raw(cell: str, transport: TransportConfig) -> None:
    """Echo every ping as a pong; on ``push`` (count, size) put ``count`` samples on ``data``.

    Also echo ``echo`` as ``echoed`` inside Zenoh's callback itself — what Zenoh
    alone costs, without the hop to a thread that plugcell's callbacks must make
    (and the ping/pong floor makes too): a reference, never a way to serve.  And
    echo ``aping`` as ``apong`` from an event loop (plugcell's, in a thread of its
    own) that each sample reaches by ``call_soon_threadsafe`` — the hop every
    asyncio service makes, plugcell's included, with nothing else on the path.
    """
    keys = raw_keys(cell)
    session = open_session(transport)
    inbox: queue.SimpleQueue[tuple[str, bytes]] = queue.SimpleQueue()
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: (stop.set(), inbox.put(("stop", b""))))
    subs = [
        session.declare_subscriber(
            keys["ping"],
            Callback(lambda s: inbox.put(("ping", s.payload.to_bytes())), indirect=False),
        ),
        session.declare_subscriber(
            keys["push"],
            Callback(lambda s: inbox.put(("push", s.payload.to_bytes())), indirect=False),
        ),
    ]
    pong = session.declare_publisher(
        keys["pong"], express=True, congestion_control=zenoh.CongestionControl.BLOCK
    )
    echoed = session.declare_publisher(keys["echoed"], express=True)
    subs.append(session.declare_subscriber(
        keys["echo"], Callback(lambda s: echoed.put(s.payload.to_bytes()), indirect=False)
    ))
    data = session.declare_publisher(keys["data"], congestion_control=zenoh.CongestionControl.BLOCK)
    apong = session.declare_publisher(
        keys["apong"], express=True, congestion_control=zenoh.CongestionControl.BLOCK
    )
    loop = eventloop.new_event_loop()
    looper = threading.Thread(target=loop.run_forever, name="asyncio floor", daemon=True)
    looper.start()
    subs.append(session.declare_subscriber(
        keys["aping"],
        Callback(lambda s: loop.call_soon_threadsafe(apong.put, s.payload.to_bytes()),
                 indirect=False),
    ))
    print("ready", flush=True)
    try:
        while not stop.is_set():
            kind, payload = inbox.get()
            if kind == "ping":
                pong.put(payload)
            elif kind == "push":
                count, size = struct.unpack("<QQ", payload)
                blob = bytes(size)
                for _ in range(count):
                    data.put(blob)
    finally:
        for s in subs:
            s.undeclare()
        loop.call_soon_threadsafe(loop.stop)
        looper.join(5)
        pong.undeclare()
        echoed.undeclare()
        apong.undeclare()
        data.undeclare()
        session.close()


async def serve_service(cell: str, transport: TransportConfig, journal: bool) -> None:
    from plugcell.apps.bench.device import bench_service

    service = bench_service(cell=cell, transport=transport, journal=journal)
    stop = asyncio.Event()
    asyncio.get_running_loop().add_signal_handler(signal.SIGTERM, stop.set)
    await service.start()
    print("ready", flush=True)
    try:
        await stop.wait()
    finally:
        await service.close()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m plugcell.apps.bench.peer")
    parser.add_argument("role", choices=("service", "raw", "raw-requester"))
    parser.add_argument("--cell", required=True)
    parser.add_argument("--no-journal", action="store_true")
    parser.add_argument("--connect", action="append")
    parser.add_argument("--listen", action="append")
    args = parser.parse_args(argv)
    transport = TransportConfig.from_env(connect=args.connect, listen=args.listen)
    if args.role == "raw":
        serve_raw(args.cell, transport)
    elif args.role == "raw-requester":
        serve_raw_requester(args.cell, transport)
    else:
        eventloop.run(serve_service(args.cell, transport, not args.no_journal))
    return 0


if __name__ == "__main__":
    sys.exit(main())
