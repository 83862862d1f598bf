"""How long ``plugcell`` takes to start: wall time of a whole process, best and median.

    .venv/bin/python benchmarks/cli_startup.py [--repeat 15] [--limit 0.3] [--imports]

Each command is run ``--repeat`` times as its own process (the installed ``plugcell``
script beside this Python, else ``python -m plugcell``), output discarded; the
interpreter alone (``python -c pass``) is the floor.  Wall time (best, median, worst)
and the median CPU time (user + system), which depends less on the machine's load.
The start-up a user feels is what the parser and the chosen sub-command import: only
that sub-command's module is loaded (:mod:`plugcell.apps.cli`), so ``--help`` of any command
does not load Zenoh or the web server.  On a loaded machine run it with ``nice -n 0``
(or not at all under ``nice``): the figures are wall time.

``--imports`` adds what five long-running processes import before they serve, each as
``python -c "import MODULE"`` (the tests start them hundreds of times): the compute
service's functions, the web UI's server, the twin's dynamics (the simulated
controller), the robot service's streaming controller and the robot's link process (the
child that answers the controller's cycles).  Run it on older sources with
``PYTHONPATH=OLD/src`` to compare.
"""

from __future__ import annotations

import argparse
import os
import platform
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

#: (label, arguments after ``plugcell``)
COMMANDS: tuple[tuple[str, list[str]], ...] = (
    ("plugcell --help", ["--help"]),
    ("plugcell kin fk (Smart H4)",
     ["kin", "fk", "--robot", "smart_h4", "--joints", "0,-90,-187,0,90,0"]),
    ("plugcell calibrate --help", ["calibrate", "--help"]),
)
#: (label, module) of ``--imports``: what a service process imports before it serves
IMPORTS: tuple[tuple[str, str], ...] = (
    ("import: compute functions", "plugcell.devices.compute.functions"),
    ("import: web UI server", "plugcell.apps.ui.server"),
    ("import: twin dynamics", "plugcell.sim.twin.dynamics"),
    ("import: robot stream controller", "plugcell.devices.robot.stream_controller"),
    ("import: robot link process", "plugcell.devices.robot.stream.process"),
)


def plugcell_command() -> list[str]:
    """The ``plugcell`` console script of this environment, else ``python -m plugcell``."""
    script = Path(sys.executable).with_name("plugcell")
    return [str(script)] if script.is_file() else [sys.executable, "-m", "plugcell"]


def run_times(cmd: list[str], repeat: int) -> tuple[list[float], list[float]]:
    """Wall and CPU time (user + system, s) of each of ``repeat`` runs of ``cmd``; raises
    if one fails.  CPU time hardly depends on what else the machine runs; wall time does."""
    wall, cpu = [], []
    for _ in range(repeat):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True)
        wall.append(time.perf_counter() - t0)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu.append(after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
    return wall, cpu


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=15, help="runs per command (default 15)")
    ap.add_argument("--limit", type=float, default=0.3,
                    help="target start-up, s (default 0.3); rows above it are marked")
    ap.add_argument("--imports", action="store_true",
                    help="also the imports of five service processes (module docstring)")
    args = ap.parse_args(argv)
    base = plugcell_command()
    print(f"plugcell start-up, {platform.processor() or platform.machine()}, "
          f"{os.cpu_count()} cores, Python {platform.python_version()}, "
          f"nice {os.nice(0)}, load {os.getloadavg()[0]:.2f}; {args.repeat} runs each")
    print(f"{'command':34s} | {'best s':>7s} | {'median s':>8s} | {'worst s':>7s} | "
          f"{'CPU s':>6s} | {'< ' + format(args.limit, 'g') + ' s':>8s}")
    print("-" * 85)
    rows = [("python -c pass (interpreter)", [sys.executable, "-c", "pass"])]
    rows += [(label, base + extra) for label, extra in COMMANDS]
    if args.imports:
        rows += [(label, [sys.executable, "-c", f"import {module}"])
                 for label, module in IMPORTS]
    for label, cmd in rows:
        t, cpu = run_times(cmd, args.repeat)
        med = statistics.median(t)
        ok = med < args.limit
        print(f"{label:34s} | {min(t):7.3f} | {med:8.3f} | {max(t):7.3f} | "
              f"{statistics.median(cpu):6.3f} | {'yes' if ok else 'NO':>8s}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
