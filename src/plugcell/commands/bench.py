"""``plugcell bench transport``: the transport benchmark of thesis 5.3 (Table 5-5)."""

from __future__ import annotations

import argparse
from typing import Any


def register(subparsers: Any) -> None:
    p = subparsers.add_parser("bench", help="benchmarks (transport: thesis 5.3)")
    sub = p.add_subparsers(dest="bench", metavar="BENCHMARK", required=True)
    t = sub.add_parser(
        "transport",
        help="message throughput and latency between two services (thesis 5.3, Table 5-5)",
        description="Two services in two OS processes: 10 000 ProcessUpdates pushed as fast "
        "as possible (throughput), 2 000 CreateProcess→ProcessUpdate round trips (latency), "
        "payloads 4 B … 0.9 MB, with plain Zenoh measured in the same run as the floor.",
    )
    from plugcell.bench.transport import add_arguments

    add_arguments(t)
    t.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from plugcell.bench.transport import report_and_exit

    return report_and_exit(args)
