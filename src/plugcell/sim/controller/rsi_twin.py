"""``python -m plugcell.sim.controller.rsi_twin``: the twin as a KUKA robot streaming RSI.

A process that stands where a KUKA controller running plugcell's KRL program
(``plugcell rsi files``) stands: the dynamic twin (:class:`~plugcell.sim.twin.dynamics.
DynamicTwin`) behind the RSI robot side (:class:`~.rsi_robot.RsiRobot`), which sends its
``<Rob>`` packets to the sensor's address every cycle from ``RSI_ON`` on and applies the
answers.  It prints one line with its own address, then runs until SIGTERM/SIGINT or until
RSI stops (``Timeout`` late answers: exit status 3 with the reason, as the real controller
breaks off).

``python -m plugcell.sim.controller.rsi_twin --sensor 127.0.0.1:49152 [--robot smart_h4]
[--payload-kg M] [--seed S] [--mode absolute] [--timeout 100] [--bind HOST:PORT]
[--cell CELL [--name ROBOT]]`` — with ``--cell`` its moving T-MAC is published on that
cell's simulated world (:mod:`.moving_reflector`), for the simulated tracker.
"""

from __future__ import annotations

import argparse
import signal
import subprocess
import sys
import threading
from collections.abc import Sequence

__all__ = ["RsiTwinProcess", "main"]


class RsiTwinProcess:
    """The twin's RSI side in a process of its own (tests, demos): start, kill, start again.

    Parameters
    ----------
    sensor : str
        ``HOST:PORT`` where plugcell listens.
    *options : str
        More options of the command line (``--timeout``, ``--robot`` …).
    """

    def __init__(self, sensor: str, *options: str) -> None:
        self.argv = [sys.executable, "-m", "plugcell.sim.controller.rsi_twin",
                     "--sensor", sensor, *options]
        self.proc: subprocess.Popen[str] | None = None
        self.banner = ""

    def start(self, timeout: float = 30.0) -> RsiTwinProcess:
        """Start it and wait for its first line; RuntimeError with its output if it fails."""
        self.proc = subprocess.Popen(self.argv, stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE, text=True)
        got: list[str] = []
        reader = threading.Thread(target=lambda: got.append(self.proc.stdout.readline()),
                                  daemon=True)  # type: ignore[union-attr]
        reader.start()
        reader.join(timeout)
        if not got or not got[0].startswith("rsi-twin:"):
            self.kill()
            err = self.proc.stderr.read() if self.proc.stderr else ""
            raise RuntimeError(f"the twin's RSI side did not start: {got} {err}")
        self.banner = got[0].strip()
        return self

    def kill(self) -> None:
        """Kill it at once (a pulled cable, a controller gone)."""
        if self.proc is not None and self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(10)

    def __enter__(self) -> RsiTwinProcess:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.kill()


def main(argv: Sequence[str] | None = None) -> int:
    """Run the twin's RSI robot side (module docstring); the exit status."""
    p = argparse.ArgumentParser(prog="python -m plugcell.sim.controller.rsi_twin",
                                description="The dynamic twin as a KUKA controller streaming "
                                "RSI to plugcell's sensor side.")
    p.add_argument("--sensor", required=True, metavar="HOST:PORT",
                   help="where plugcell listens (the ethernet file's IP_NUMBER:PORT)")
    p.add_argument("--bind", default="127.0.0.1:0", metavar="HOST:PORT",
                   help="the controller's own address (default 127.0.0.1, any port)")
    p.add_argument("--robot", default="smart_h4", help="robot of the twin (name or file)")
    p.add_argument("--payload-kg", type=float, default=0.0)
    p.add_argument("--seed", type=int, default=0, help="twin scenario seed")
    p.add_argument("--mode", choices=("absolute", "relative"), default="absolute",
                   help="RSI_ON(#ABSOLUTE) or #RELATIVE joint corrections (default absolute)")
    p.add_argument("--timeout", type=int, default=100,
                   help="the ETHERNET object's Timeout (late packets)")
    p.add_argument("--cell", default="", help="publish the twin's moving T-MAC in this cell's "
                   "simulated world (for the simulated tracker)")
    p.add_argument("--name", default="ROBOT", help="the T-MAC's name there: the robot "
                   "service's (default ROBOT)")
    args = p.parse_args(argv)
    from plugcell.devices.robot.bridge import parse_address
    from plugcell.devices.robot.rsi.config import CorrectionLimits, RsiConfig
    from plugcell.sim.controller.rsi_robot import RsiRobot
    from plugcell.sim.twin.dynamics import DynamicTwin
    from plugcell.sim.twin.scenario import TwinScenario

    try:
        host, port = parse_address(args.sensor)
        bind = parse_address(args.bind) if not args.bind.endswith(":0") else \
            (args.bind.rpartition(":")[0], 0)
        big = (1e3,) * 6  # the controller's AXISCORR limits are the sensor's business here
        config = RsiConfig(robot_host=bind[0], listen_host=host, listen_port=port,
                           correction="joint", mode=args.mode, timeout_packets=args.timeout,
                           limits=CorrectionLimits(big, big, big))
        arm = DynamicTwin(TwinScenario(robot=args.robot, seed=args.seed,
                                       payload_kg=args.payload_kg))
        robot = RsiRobot(arm, config, bind=bind)
    except Exception as exc:
        print(f"rsi-twin: error: {exc}", file=sys.stderr)
        return 2
    done = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: done.set())
    robot.start()
    reflector = None
    if args.cell:
        from plugcell.sim.controller.moving_reflector import MovingReflector

        reflector = MovingReflector(arm, args.name, args.cell).start()
    h, pt = robot.address
    print(f"rsi-twin: {args.robot} streaming RSI ({args.mode}) from {h}:{pt} to "
          f"{host}:{port}", flush=True)
    while not done.wait(0.1):
        if not robot.running:
            break
    robot.stop()
    if reflector is not None:
        reflector.close()
    if robot.stopped:
        print(f"rsi-twin: {robot.stopped}", file=sys.stderr, flush=True)
        return 3
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
