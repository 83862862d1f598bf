"""How busy the whole machine's CPU was while a command ran (Linux ``/proc/stat``).

Whether more pytest workers could shorten the suite depends on it: a command that keeps
every core busy is CPU-bound, and another worker only shares the same cores.  Usage::

    python benchmarks/cpu_busy.py -- bash .ci/run        # in a fresh clone
    python benchmarks/cpu_busy.py -- make test

runs the command, then prints its exit status, its wall time and the share of the
machine's CPU time (all cores, every process, not only the command's) spent as user,
system, idle, I/O wait and steal between its start and end — the difference of the
``cpu`` line of ``/proc/stat`` (clock ticks) before and after — and *busy*, user + nice +
system + irq + softirq.  Exits with the command's
status.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

#: The first fields of /proc/stat's ``cpu`` line, in order (proc(5)).
FIELDS = ("user", "nice", "system", "idle", "iowait", "irq", "softirq", "steal")
SHOWN = ("user", "system", "idle", "iowait", "steal")


def cpu_ticks(stat: str) -> dict[str, int]:
    """The machine's CPU ticks by kind from the text of ``/proc/stat``.

    Raises
    ------
    ValueError
        No ``cpu`` line with the eight fields of :data:`FIELDS`.
    """
    for line in stat.splitlines():
        parts = line.split()
        if parts and parts[0] == "cpu":
            if len(parts) < 1 + len(FIELDS):
                break
            return dict(zip(FIELDS, (int(v) for v in parts[1:1 + len(FIELDS)]), strict=True))
    raise ValueError("/proc/stat: no 'cpu' line with user … steal")


def shares(before: dict[str, int], after: dict[str, int]) -> dict[str, float]:
    """Each kind's share (%) of the ticks between ``before`` and ``after``."""
    spent = {k: after[k] - before[k] for k in FIELDS}
    total = sum(spent.values())
    if total <= 0:
        raise ValueError("no CPU time passed between the two readings")
    return {k: 100.0 * v / total for k, v in spent.items()}


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("command", nargs=argparse.REMAINDER, help="-- COMMAND [ARG …]")
    args = ap.parse_args(argv)
    command = args.command[1:] if args.command[:1] == ["--"] else args.command
    if not command:
        ap.error("give the command to measure after --")
    stat = Path("/proc/stat")
    if not stat.is_file():
        ap.error("needs Linux's /proc/stat")
    before, t0 = cpu_ticks(stat.read_text()), time.monotonic()
    status = subprocess.call(command)
    wall, after = time.monotonic() - t0, cpu_ticks(stat.read_text())
    share = shares(before, after)
    print(f"command exit {status}, {wall:.1f} s wall")
    print("| " + " | ".join(SHOWN) + " | busy |")
    print("|" + "---:|" * (len(SHOWN) + 1))
    busy = sum(share[k] for k in ("user", "nice", "system", "irq", "softirq"))
    print("| " + " | ".join(f"{share[k]:.1f} %" for k in SHOWN) + f" | {busy:.1f} % |")
    return status


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
