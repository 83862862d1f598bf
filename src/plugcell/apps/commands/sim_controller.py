"""The simulated robot controller's program: ``python -m plugcell.sim.controller``.

::

    python -m plugcell.sim.controller --robot smart_h4 --port P --cell C --name N
        [--payload-kg M] [--speed X] [--seed S] [--dynamics] [--link-baud B]
        [--library DIR] [--no-world] [--parent-watch]

A separate OS process, as a real controller is: it listens on ``--port`` (0: a free one,
printed on its first line, ``… listening on HOST:PORT``) for the robot service and serves
it with :class:`~plugcell.sim.controller.line_controller.SimController` until SIGTERM or
SIGINT, or, with ``--parent-watch``, until its parent is gone.  Exit code 0, or 2 for bad
options (the reason on stderr, ``plugcell-controller: error: …``).  ``plugcell serve robot
--param sim=true`` starts it (:mod:`plugcell.sim.controller.launcher`); the old
``python -m plugcell.sim.controller.controller`` runs it too.
"""

from __future__ import annotations

import argparse
import logging
import os
import signal
import socket
import sys
import threading
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from plugcell.devices.robot.protocol import PROTOCOL, VERSION
from plugcell.pdl import SimClock
from plugcell.sim.controller.arm import DynamicArm, TwinArm
from plugcell.sim.controller.line_controller import SimController

if TYPE_CHECKING:
    from plugcell.sim.twin.robot import RobotTwin

__all__ = ["build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    """The options of the simulated controller's program."""
    p = argparse.ArgumentParser(
        prog="python -m plugcell.sim.controller",
        description="Simulated robot controller: drives the digital twin, runs robot "
        f"programs, speaks the {PROTOCOL} line protocol v{VERSION} on TCP.",
    )
    p.add_argument("--robot", default="smart_h4", help="robot description (name or .toml path)")
    p.add_argument("--host", default="127.0.0.1", help="address to listen on")
    p.add_argument("--port", type=int, default=0, help="TCP port (0: the OS picks one)")
    p.add_argument("--cell", default="default", help="cell of the simulated world")
    p.add_argument("--name", default="ROBOT", help="robot service name (the reflector's name)")
    p.add_argument("--payload-kg", type=float, default=0.0, help="dead weight on the flange")
    p.add_argument("--speed", type=float, default=1.0,
                   help="simulated seconds per real second (inf: never sleep)")
    p.add_argument("--seed", type=int, default=0, help="twin scenario seed (hidden errors)")
    p.add_argument("--library", action="append", default=[], type=Path,
                   help="folder of robot programs (repeatable; the shipped ones come last)")
    p.add_argument("--link-baud", type=float, default=0.0,
                   help="simulate the serial line to the PC at this bit rate (thesis: "
                   "19200; 0: a network link that costs no simulated time)")
    p.add_argument("--dynamics", action="store_true",
                   help="the arm moves in time: every move planned and followed by the "
                   "dynamic twin cycle by cycle (4 ms), paced by --speed, its T-MAC published "
                   "as it moves (default: it is at the target at once, the move's time passes "
                   "on the clock only)")
    p.add_argument("--no-world", action="store_true",
                   help="do not publish the reflector truth to the sim world")
    p.add_argument("--parent-watch", action="store_true",
                   help="exit when the parent process (the robot service) is gone")
    p.add_argument("--log-level", default="WARNING")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Run the simulated controller until SIGTERM/SIGINT (or its parent is gone): 0, or 2
    for bad options (the reason on stderr)."""
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=args.log_level.upper(), stream=sys.stderr,
                        format="%(asctime)s %(name)s %(levelname)s %(message)s")
    from plugcell.framework.keys import check_name
    from plugcell.sim.twin.robot import RobotTwin
    from plugcell.sim.twin.scenario import TwinScenario

    try:
        check_name(args.cell, "cell name")
        check_name(args.name, "robot service name")
        if not (args.speed > 0):
            raise ValueError(f"--speed must be positive, not {args.speed}")
        if not (args.link_baud >= 0):
            raise ValueError(f"--link-baud must be 0 or positive, not {args.link_baud}")
        twin = RobotTwin(TwinScenario(robot=args.robot, seed=args.seed,
                                      payload_kg=args.payload_kg))
    except Exception as exc:
        print(f"plugcell-controller: error: {exc}", file=sys.stderr)
        return 2
    arm, clock, world, feed = _arm(args, twin)
    controller = SimController(arm, speed=args.speed, clock=clock, name=args.name,
                               library=args.library, link_baud=args.link_baud)
    listener = socket.create_server((args.host, args.port))
    host, port = listener.getsockname()[:2]
    parent = os.getppid()

    def stop(*_: object) -> None:
        controller.shutdown()

    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    if args.parent_watch:
        def watch() -> None:
            while not controller._shutdown.wait(0.5):
                if os.getppid() != parent:
                    controller.shutdown()

        threading.Thread(target=watch, name="parent-watch", daemon=True).start()
    print(f"plugcell-controller: {args.name} ({twin.description.name}, speed {args.speed:g}) "
          f"listening on {host}:{port}", flush=True)
    try:
        controller.serve(listener)
    finally:
        controller.shutdown()
        listener.close()
        if feed is not None:
            feed.stop()
        if world is not None:
            world.close()
    return 0


def _arm(args: argparse.Namespace, twin: RobotTwin) -> tuple[TwinArm | DynamicArm,
                                                            SimClock | None, Any, Any]:
    """The arm the options ask for, its clock (None: the controller's own), and the
    reflector truth and feed (None with ``--no-world``; the feed only ``--dynamics``)."""
    from plugcell.sim.controller.reflector import ReflectorFeed, ReflectorTruth
    from plugcell.sim.twin.dynamics import DynamicTwin

    if not args.dynamics:
        world = None if args.no_world else ReflectorTruth(args.name, args.cell, args.speed)
        if world is not None:
            world.publish(twin.true_reflector_in_tracker(), moving=False)
        return TwinArm(twin, on_move=world.on_move if world else None), None, world, None
    dynamic = DynamicTwin(twin)
    clock = SimClock(speed=args.speed)
    world = feed = None
    if not args.no_world:
        world = ReflectorTruth(args.name, args.cell, args.speed,
                               current=twin.true_reflector_in_tracker)
        feed = ReflectorFeed(world, dynamic).start()
    return DynamicArm(dynamic, clock), clock, world, feed

