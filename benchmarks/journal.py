"""What the journal costs a service, schema 1 against schema 2, and how long recovery takes.

    .venv/bin/python benchmarks/journal.py [--processes 20000] [--updates 50]

* per request: one process row, its Running and Completed updates and one commit
  — what a short process (the transport benchmark's ``Echo``) adds to the
  service's path before it may answer (a commit is an append to the journal's log);
* moved, per request: what moving those rows from the log into SQLite costs the
  journal's background thread afterwards (the schema matters here);
* per streamed frame: update rows written 64 to a commit, as a burst of
  MultipleData frames is;
* recovery: a journal of ``--processes`` × ``--updates`` rows, 1 % of them left
  unfinished, recovered at a first start-up (a pass over everything) and at the
  next one (from the ``recovered_through`` mark: only what came since).

Schema 1 is the journal as written before version 2 (``updates`` keyed by
recipient, sender, identifier and seq); both are the real :class:`Journal` on a
file in a temporary folder.  Best of ``--repeat`` runs.
"""

from __future__ import annotations

import argparse
import platform
import sqlite3
import sys
import tempfile
import time
import timeit
from pathlib import Path

from plugcell.framework import journal as journal_module
from plugcell.framework.journal import Journal

#: ``updates`` as schema 1 declared it (a journal written before version 2).
SCHEMA_1_UPDATES = """CREATE TABLE updates (
    recipient TEXT NOT NULL, sender TEXT NOT NULL, identifier INTEGER NOT NULL,
    seq INTEGER NOT NULL, t_ns INTEGER NOT NULL, state TEXT NOT NULL,
    reason TEXT NOT NULL DEFAULT '', data TEXT NOT NULL DEFAULT '',
    PRIMARY KEY (recipient, sender, identifier, seq))"""


def _journal(folder: Path, schema: int) -> Journal:
    path = folder / f"schema{schema}-{time.time_ns()}.sqlite"
    if schema == 1:
        with sqlite3.connect(path) as db:
            db.execute(SCHEMA_1_UPDATES)
    return Journal(path, "PUBLISHER")


def _process(journal: Journal, identifier: int, command: str = "Echo") -> None:
    journal.record_process(
        sender="CONSUMER", identifier=identifier, sender_instance="c" * 16,
        recipient_instance="p" * 16, command=command, option="", command_type="SingleData",
        input_summary="Byte[4] [7, 7, 7, 7]", received_ns=time.time_ns(), state="Queued",
    )


def per_request_us(
    folder: Path, schema: int, repeat: int, number: int = 2000
) -> tuple[float, float]:
    """µs per request on the service's path, and µs per request to move it into SQLite
    (best of ``repeat`` each; the background mover held off while timing)."""
    period, journal_module.MOVE_PERIOD_S = journal_module.MOVE_PERIOD_S, 3600.0
    journal = _journal(folder, schema)
    identifier = iter(range(1, 10**9))

    def request() -> None:
        i = next(identifier)
        _process(journal, i)
        journal.record_update("CONSUMER", i, 1, "Running", "", "")
        journal.record_update("CONSUMER", i, 2, "Completed", "OK", "Byte[4] [7, 7, 7, 7]")
        journal.commit()

    try:
        path, moves = [], []
        for _ in range(repeat):
            path.append(timeit.timeit(request, number=number))
            started = time.perf_counter()
            journal.settle()
            moves.append(time.perf_counter() - started)
        return min(path) / number * 1e6, min(moves) / number * 1e6
    finally:
        journal.close()
        journal_module.MOVE_PERIOD_S = period


def per_frame_us(folder: Path, schema: int, repeat: int, bursts: int = 300) -> float:
    journal = _journal(folder, schema)
    _process(journal, 1, "Push")
    seq = iter(range(1, 10**9))

    def burst() -> None:
        for _ in range(64):
            journal.record_update("CONSUMER", 1, next(seq), "Running", "", "Byte[4] [7, 7, 7, 7]")
        journal.commit()

    try:
        return min(timeit.repeat(burst, number=bursts, repeat=repeat)) / bursts / 64 * 1e6
    finally:
        journal.close()


def recovery_s(folder: Path, schema: int, processes: int, updates: int) -> tuple[float, float]:
    """Seconds of the first recovery of a long journal, and of the next start's."""
    journal = _journal(folder, schema)
    path = journal.path
    for i in range(1, processes + 1):
        _process(journal, i, "Push")
        unfinished = i % 100 == 0
        for k in range(1, updates + 1):
            state = "Completed" if k == updates and not unfinished else "Running"
            journal.record_update("CONSUMER", i, k, state, "", "Byte[4] [7, 7, 7, 7]")
        if i % 1000 == 0:
            journal.commit()
    journal.close()
    times = []
    for start in range(2):
        journal = Journal(path, "PUBLISHER")
        t0 = time.perf_counter()
        recovered = journal.recover("interrupted")
        times.append(time.perf_counter() - t0)
        expected = processes // 100 if start == 0 else 100
        if recovered != expected:
            raise RuntimeError(f"recovered {recovered} processes, expected {expected}")
        first_new = processes + 100 * start + 1
        for i in range(first_new, first_new + 100):  # the next run, interrupted too
            _process(journal, i, "Push")
            journal.record_update("CONSUMER", i, 1, "Running", "", "")
        journal.commit()
        journal.close()
    return times[0], times[1]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--processes", type=int, default=20000)
    parser.add_argument("--updates", type=int, default=50)
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args(argv)
    if args.processes < 100 or args.updates < 1 or args.repeat < 1:
        parser.error("need --processes ≥ 100, --updates ≥ 1, --repeat ≥ 1")
    print(f"journal (SQLite {sqlite3.sqlite_version}, WAL, synchronous=NORMAL), "
          f"{platform.processor() or platform.machine()}, Python {platform.python_version()}")
    rows = args.processes * args.updates
    print(f"{'schema':>6} | {'per request µs':>14} | {'moved, per request µs':>21} | "
          f"{'per frame µs':>12} | {'1st recovery s':>14} | {'next recovery s':>15}"
          f"   ({rows:,} update rows)")
    print("-" * 100)
    with tempfile.TemporaryDirectory(prefix="plugcell-journal-") as tmp:
        folder = Path(tmp)
        for schema in (1, 2):
            request, moved = per_request_us(folder, schema, args.repeat)
            frame = per_frame_us(folder, schema, args.repeat)
            first, following = recovery_s(folder, schema, args.processes, args.updates)
            print(f"{schema:>6} | {request:>14.1f} | {moved:>21.1f} | {frame:>12.2f} | "
                  f"{first:>14.2f} | {following:>15.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
