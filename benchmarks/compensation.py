"""Benchmark: model-based compensation throughput (issue 4, target ≥ 10 000 targets/s).

    .venv/bin/python benchmarks/compensation.py [N]

Prints a table; ``plugcell bench compensation`` runs the same
:func:`plugcell.apps.bench.compensation.run`.
"""

from __future__ import annotations

import sys

from plugcell.apps.bench.compensation import format_report, run


def main(argv: list[str]) -> int:
    n = int(argv[1]) if len(argv) > 1 else 10_000
    print(format_report(run(n)))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
