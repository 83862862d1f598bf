"""The twin as a robot controller streaming to plugcell, in a process of its own.

What the twin's robot sides of the vendors' real-time interfaces share as processes
(``python -m plugcell.sim.controller.rsi_twin`` — KUKA RSI, ``… .egm_twin`` — ABB EGM):
the command line's common options (:func:`twin_parser`), the run until SIGTERM/SIGINT or
until the robot side stops streaming by itself (:func:`serve`: exit status 3 with the
reason, as the real controller breaks off), and :class:`TwinProcess`, which tests and
demos start, kill (a pulled cable) and start again.
"""

from __future__ import annotations

import argparse
import signal
import subprocess
import sys
import threading
from collections.abc import Callable

__all__ = ["TwinProcess", "run_twin", "serve", "twin_parser"]


class TwinProcess:
    """A twin's robot side in a process of its own: start, kill, start again.

    Parameters
    ----------
    module : str
        The module run with ``python -m``.
    banner : str
        How its first line starts (``"rsi-twin:"``).
    sensor : str
        ``HOST:PORT`` where plugcell listens.
    *options : str
        More options of the command line (``--timeout``, ``--robot`` …).
    """

    def __init__(self, module: str, banner: str, sensor: str, *options: str) -> None:
        self.argv = [sys.executable, "-m", module, "--sensor", sensor, *options]
        self.prefix = banner
        self.proc: subprocess.Popen[str] | None = None
        self.banner = ""

    def start(self, timeout: float = 30.0) -> TwinProcess:
        """Start it and wait for its first line; RuntimeError with its output if it fails."""
        self.proc = subprocess.Popen(self.argv, stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE, text=True)
        got: list[str] = []
        reader = threading.Thread(target=lambda: got.append(self.proc.stdout.readline()),
                                  daemon=True)  # type: ignore[union-attr]
        reader.start()
        reader.join(timeout)
        if not got or not got[0].startswith(self.prefix):
            self.kill()
            err = self.proc.stderr.read() if self.proc.stderr else ""
            raise RuntimeError(f"the twin's robot side did not start: {got} {err}")
        self.banner = got[0].strip()
        return self

    def kill(self) -> None:
        """Kill it at once (a pulled cable, a controller gone)."""
        if self.proc is not None and self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(10)

    def __enter__(self) -> TwinProcess:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.kill()


def twin_parser(prog: str, description: str) -> argparse.ArgumentParser:
    """The options every twin process takes: ``--sensor``, ``--bind``, ``--robot``,
    ``--payload-kg``, ``--seed``."""
    p = argparse.ArgumentParser(prog=prog, description=description)
    p.add_argument("--sensor", required=True, metavar="HOST:PORT",
                   help="where plugcell listens for the robot's packets")
    p.add_argument("--bind", default="127.0.0.1:0", metavar="HOST:PORT",
                   help="the controller's own address (default 127.0.0.1, any port)")
    p.add_argument("--robot", default="smart_h4", help="robot of the twin (name or file)")
    p.add_argument("--payload-kg", type=float, default=0.0)
    p.add_argument("--seed", type=int, default=0, help="twin scenario seed")
    p.add_argument("--stats", metavar="FILE",
                   help="at the end, write the robot side's counts and every answer's round "
                   "trip (ns) to FILE as JSON (benchmarks)")
    return p


def serve(robot: object, banner: Callable[[tuple[str, int]], str], prefix: str,
          stats: Callable[[], dict] | None = None, stats_file: str | None = None) -> int:
    """Run ``robot`` (``start``, ``stop``, ``running``, ``stopped``, ``address``) until a
    signal or until it stops by itself; the exit status (3: it stopped, the reason on
    stderr).  ``stats()`` is written to ``stats_file`` as JSON at the end."""
    done = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: done.set())
    robot.start()  # type: ignore[attr-defined]
    print(f"{prefix} {banner(robot.address)}", flush=True)  # type: ignore[attr-defined]
    while not done.wait(0.1):
        if not robot.running:  # type: ignore[attr-defined]
            break
    robot.stop()  # type: ignore[attr-defined]
    if stats is not None and stats_file:
        import json
        from pathlib import Path

        Path(stats_file).write_text(json.dumps({**stats(), "stopped": robot.stopped}))
    if robot.stopped:  # type: ignore[attr-defined]
        print(f"{prefix} {robot.stopped}", file=sys.stderr, flush=True)  # type: ignore
        return 3
    return 0


def run_twin(args: argparse.Namespace, make: Callable[[tuple[str, int], tuple[str, int]], object],
             what: str, prefix: str, stats: Callable[[object], dict] | None = None) -> int:
    """Make the robot side from the parsed options and :func:`serve` it.

    Parameters
    ----------
    args : argparse.Namespace
        Of :func:`twin_parser` (``sensor``, ``bind``, ``robot`` …).
    make : callable
        ``make(sensor, bind)``: the robot side, given both addresses.
    what : str
        What it streams, for its first line (``"RSI (absolute)"``).
    prefix : str
        Its lines' prefix.
    stats : callable, optional
        ``stats(robot)``: its counts for ``--stats`` (``cycles``, ``late``, ``rtt_ns`` …).

    Returns
    -------
    int
        The exit status: 2 for bad options, else :func:`serve`'s.
    """
    from plugcell.devices.robot.bridge import parse_address

    try:
        sensor = parse_address(args.sensor)
        bind = parse_address(args.bind) if not args.bind.endswith(":0") else \
            (args.bind.rpartition(":")[0], 0)
        robot = make(sensor, bind)
    except Exception as exc:
        print(f"{prefix} error: {exc}", file=sys.stderr)
        return 2
    return serve(robot, lambda a: f"{args.robot} streaming {what} from {a[0]}:{a[1]} to "
                 f"{sensor[0]}:{sensor[1]}", prefix,
                 (lambda: stats(robot)) if stats is not None else None, args.stats)
