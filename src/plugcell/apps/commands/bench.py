"""``plugcell bench transport``: the transport benchmark of thesis 5.3 (Table 5-5)."""

from __future__ import annotations

import argparse

from plugcell.apps.cli import CommandError


def configure(p: argparse.ArgumentParser) -> None:
    """Add the ``bench`` options to its parser (declared in :mod:`plugcell.apps.cli`)."""
    sub = p.add_subparsers(dest="bench", metavar="BENCHMARK", required=True)
    t = sub.add_parser(
        "transport",
        help="message throughput and latency between two services (thesis 5.3, Table 5-5)",
        description="Two services in two OS processes: 10 000 ProcessUpdates pushed as fast "
        "as possible (throughput), 2 000 CreateProcess→ProcessUpdate round trips (latency), "
        "payloads 4 B … 0.9 MB, with plain Zenoh measured in the same run as the floor.",
    )
    from plugcell.apps.bench.transport import add_arguments

    add_arguments(t)
    t.set_defaults(func=run)

    c = sub.add_parser(
        "calibration",
        help="identification time of model 5 for 150 poses and its scaling (thesis: 5 s)",
        description="Times the identification of the 52-parameter model on 150 poses "
        "(median of --repeat runs) and its growth to --max-poses.",
    )
    from plugcell.apps.bench import calibration as bench_calibration

    bench_calibration.add_arguments(c)
    c.set_defaults(func=bench_calibration.run)

    m = sub.add_parser(
        "compensation",
        help="model-based compensation throughput for a batch of targets (6.5.1)",
        description="Compensated joint targets per second for --targets targets (model 5).",
    )
    m.add_argument("--targets", type=int, default=10_000, help="batch size (default 10000)")
    m.add_argument("--json", action="store_true", help="print JSON")
    m.set_defaults(func=run_compensation)


def run(args: argparse.Namespace) -> int:
    from plugcell.apps.bench.transport import report_and_exit

    return report_and_exit(args)


def run_compensation(args: argparse.Namespace) -> int:
    import json

    from plugcell.apps.bench.compensation import format_report
    from plugcell.apps.bench.compensation import run as bench

    if args.targets < 1:
        raise CommandError(f"--targets must be positive, got {args.targets}")
    result = bench(args.targets)
    print(json.dumps(result, indent=2, default=float) if args.json else format_report(result))
    return 0
