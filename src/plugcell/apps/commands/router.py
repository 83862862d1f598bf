"""``plugcell router``: a Zenoh router for cells that span machines (same library).

Peers on each machine find each other on loopback; give them ``--connect
tcp/<router-host>:7447`` to reach the others through the router.
"""

from __future__ import annotations

import argparse
import signal
import threading

from plugcell.apps.commands.cellargs import transport_of


def configure(p: argparse.ArgumentParser) -> None:
    """Add the ``router`` options to its parser (declared in :mod:`plugcell.apps.cli`)."""
    p.description = "Run Zenoh in router mode until SIGINT/SIGTERM."
    p.add_argument(
        "--listen",
        action="append",
        metavar="ENDPOINT",
        help="endpoint to listen on (default tcp/0.0.0.0:7447); repeatable",
    )
    p.add_argument(
        "--connect",
        action="append",
        metavar="ENDPOINT",
        help="another router to connect to; repeatable",
    )
    p.add_argument("--cell", help="accepted for symmetry; a router serves every cell")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from plugcell.framework.transport import open_session

    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    session = open_session(transport_of(args, mode="router"))
    try:
        listen = ", ".join(transport_of(args, mode="router").listen)
        print(f"plugcell: router {session.zid()} listening on {listen}", flush=True)
        stop.wait()
    finally:
        session.close()
    return 0
