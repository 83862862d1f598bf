"""The far side of the transport benchmark, run as its own OS process.

``python -m plugcell.apps.bench.peer service --cell C`` serves the publisher
(:class:`~plugcell.apps.bench.device.BenchService`); ``python -m plugcell.apps.bench.peer raw
--cell C`` answers plain Zenoh pub/sub pings and pushes plain samples — the
floor our latency and throughput are compared with.  Both print ``ready`` and run
until SIGTERM.
"""

from __future__ import annotations

import argparse
import asyncio
import queue
import signal
import struct
import sys
import threading

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
    from plugcell.apps.bench.device import BenchService

    service = BenchService(cell=cell, transport=transport, journal=journal)
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
    parser.add_argument("role", choices=("service", "raw"))
    parser.add_argument("--cell", required=True)
    parser.add_argument("--no-journal", action="store_true")
    parser.add_argument("--connect", action="append")
    parser.add_argument("--listen", action="append")
    args = parser.parse_args(argv)
    transport = TransportConfig.from_env(connect=args.connect, listen=args.listen)
    if args.role == "raw":
        serve_raw(args.cell, transport)
    else:
        eventloop.run(serve_service(args.cell, transport, not args.no_journal))
    return 0


if __name__ == "__main__":
    sys.exit(main())
