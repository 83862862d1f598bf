"""Where a test suite's CPU goes, read from a py-spy recording of every process it starts.

    py-spy record --subprocesses -r 25 -f raw -o suite.raw -- \\
        .venv/bin/python -m pytest -q -n 2 --dist loadfile --no-loadscope-reorder
    .venv/bin/python benchmarks/suite_profile.py suite.raw [--top 20]

The suite is CPU-bound on a 2-core machine (``benchmarks/cpu_busy.py``), so its time is
the CPU of the pytest workers and of the hundreds of processes they start (services, the
command line, the docs' examples).  py-spy's raw format is one line per distinct stack:
``process PID:"CMDLINE";…;function (file.py:LINE);… COUNT`` (a command line may span
lines).  Samples without a Python frame are idle threads and are left out; a sample is
``1 / rate`` seconds of CPU.  Four tables:

* **processes** — CPU by kind of process (``plugcell serve robot``, a pytest worker, a
  benchmark script, …: the innermost process of the sample's chain);
* **imports** — the share of all CPU spent importing (under ``_find_and_load``), and by
  the package whose module body runs;
* **import edges** — the first plugcell module in an import chain that imports another
  package, with that package (what to make lazy);
* **functions** — the functions with the most CPU including what they call, beside
  pytest's, xdist's and the interpreter's own frames.

py-spy is not a dependency of plugcell (``pip install py-spy`` where you run it).
"""

from __future__ import annotations

import argparse
import re
import sys
from collections import Counter
from collections.abc import Iterator
from itertools import pairwise
from pathlib import Path

FRAME = re.compile(r"\(.*:\d+\)$")
PROCESS = re.compile(r'process \d+:"([^"]*)"')
MODULE_FILE = re.compile(r"\((.*?)(?:/__init__)?\.py:")
COMMAND = re.compile(r"-m (plugcell[\w.]*(?: [\w-]+)?(?: [\w-]+)?)")
#: Frames of the test runner and the interpreter, left out of the functions table.
PLUMBING = ("pluggy/", "_pytest/", "xdist/", "execnet/", "<frozen", "runpy", "<string>",
            "threading.py", "hypothesis/", "plugcell/__main__", "plugcell/apps/cli.py")


def samples(text: str) -> Iterator[tuple[str, int]]:
    """``(stack, count)`` of each record of py-spy's raw output ``text``."""
    record: list[str] = []
    for line in text.splitlines():
        if line.startswith("process ") and record and re.search(r" \d+$", record[-1]):
            yield _split(record)
            record = []
        record.append(line)
    if record:
        yield _split(record)


def _split(record: list[str]) -> tuple[str, int]:
    stack, _, count = "\n".join(record).rpartition(" ")
    if not count.isdigit():
        raise ValueError(f"not py-spy's raw format (a record ends {count[-40:]!r})")
    return stack, int(count)


def kind(process: str) -> str:
    """A short name for a process's command line."""
    cmd = re.sub(r"\s+", " ", process)
    if "exec(eval(sys.stdin.readline()))" in cmd:
        return "pytest worker (the tests' own code)"
    if found := COMMAND.search(cmd):
        return found.group(1)
    if found := re.search(r"benchmarks/(\S+)", cmd):
        return f"benchmark {found.group(1)}"
    if "multiprocessing.spawn" in cmd:
        return "multiprocessing child (spawn)"
    return cmd[:60]


def tables(text: str, rate: float, top: int) -> str:
    """The four tables (module docstring) of a recording at ``rate`` samples/s."""
    busy = imports = 0
    by_kind, by_package, edges, functions = Counter(), Counter(), Counter(), Counter()
    for stack, count in samples(text):
        frames = [f for f in stack.split(";") if FRAME.search(f)]
        if not frames:
            continue  # idle
        busy += count
        chain = PROCESS.findall(stack)
        by_kind[kind(chain[-1]) if chain else "?"] += count
        for f in set(frames):
            if not any(p in f for p in PLUMBING):
                functions[f] += count
        if not any(f.startswith("_find_and_load ") for f in frames):
            continue
        imports += count
        modules = [m.group(1) for f in frames if f.startswith("<module> (")
                   and (m := MODULE_FILE.search(f)) and m.group(1) != "<string>"]
        if modules:
            by_package[modules[-1].split("/")[0]] += count
        for a, b in pairwise(modules):
            if a.startswith("plugcell") and not b.startswith("plugcell"):
                edges[f"{a.replace('/', '.')} → {b.split('/')[0]}"] += count
                break
    if busy == 0:
        raise ValueError("no busy sample in the recording")

    def rows(counter: Counter, title: str) -> list[str]:
        out = [f"| {title} | CPU s | share |", "|---|---:|---:|"]
        out += [f"| {k} | {v / rate:.1f} | {v / busy:.1%} |" for k, v in counter.most_common(top)]
        return [*out, ""]

    return "\n".join([
        f"busy samples: {busy} ({busy / rate:.0f} s of CPU at {rate:g} samples/s); "
        f"importing: {imports / rate:.0f} s ({imports / busy:.1%})", "",
        *rows(by_kind, "process"), *rows(by_package, "package whose module body runs"),
        *rows(edges, "plugcell module → the package it imports"),
        *rows(functions, "function (with what it calls)")])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("recording", type=Path, help="py-spy record -f raw output")
    ap.add_argument("--rate", type=float, default=25.0,
                    help="the recording's samples per second (py-spy -r; default 25)")
    ap.add_argument("--top", type=int, default=20, help="rows per table (default 20)")
    args = ap.parse_args()
    if args.rate <= 0 or args.top < 1:
        ap.error("--rate must be positive and --top at least 1")
    try:
        print(tables(args.recording.read_text(encoding="utf-8", errors="replace"),
                     args.rate, args.top))
    except (OSError, ValueError) as e:
        print(f"suite_profile: {args.recording}: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
