"""Fuzz the wire decoder with ≥ 100 000 cases: ``python benchmarks/fuzz_wire.py [CASES] [SEED]``.

Random bytes and mutations (flips, insertions, deletions) of valid messages of
every kind; the decoder may only raise ``WireError`` and a decoded buffer may
only fail ``check_data`` with ``DataError``.  Any other exception is a crash and
ends the run with it.
"""

import json
import sys
import time

from plugcell.apps.bench.fuzz import fuzz_decoder


def main() -> int:
    cases = int(sys.argv[1]) if len(sys.argv) > 1 else 100_000
    seed = int(sys.argv[2]) if len(sys.argv) > 2 else 20240611
    started = time.perf_counter()
    counts = fuzz_decoder(cases, seed)
    seconds = time.perf_counter() - started
    print(
        json.dumps(
            {"cases": cases, "seed": seed, "seconds": round(seconds, 2), "crashes": 0, **counts}
        )
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
