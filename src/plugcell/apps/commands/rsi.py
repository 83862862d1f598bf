"""``plugcell rsi`` — KUKA RSI, plugcell as the sensor (docs/kuka-rsi.md).

::

    plugcell rsi files --out DIR --ip PC_IP [--port 49152] [--correction joint|cartesian]
                       [--frame base|tool]
                       [--mode relative|absolute] [--cycle IPO_FAST|IPO] [--timeout 100]
                       [--max-step V,…] [--max-offset V,…] [--max-speed V,…] [--dio OUT]
                       [--dil IN] [--drives pc|robot] [--settle S]
    plugcell rsi run --robot-ip IP [--listen IP] [--port 49152] [same stream options]
                     [--sine AXIS:AMPLITUDE:PERIOD] [--duration S] [--rt-priority N]
                     [--cpu CPUS] [--mlock]

``files`` writes what the user copies to the controller (KRL program, ethernet
configuration, signal flow, the diagram's description) — the KRL program where the PC
drives (``--drives pc``) or where the robot runs its own moves and the PC corrects them
(``--drives robot``, issue 37's mode (b)); ``run`` answers the robot —
holding it, or swinging one axis — and prints the link's counters every second.
Limits are given in the robot's units: degrees (joint) or mm and degrees (X, Y, Z then
A, B, C), per cycle for the step and per second for the speed; one number is for all six
axes.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path

from plugcell.apps.cli import CommandError

from .streaming import (
    add_limit_options,
    add_run_controls,
    add_run_options,
    limits_of,
    named_as_options,
    realtime_of,
    run_link,
    sine_or_hold,
    write_and_list,
)


def _first_index(signals: str) -> Callable[[str], int]:
    """The type of ``--dio``/``--dil``: the first index of a 16-bit word of the
    controller's ``signals`` (``$OUT``, ``$IN``), an integer ≥ 1."""
    def index(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = 0
        if value < 1:
            raise argparse.ArgumentTypeError(f"{text!r}: expected the first {signals} index "
                                             "of the word, an integer >= 1")
        return value

    return index


def _stream_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--port", type=int, default=49152, help="the PC's UDP port (PORT)")
    p.add_argument("--correction", choices=("joint", "cartesian"), default="joint",
                   help="AKorr A1..A6 or RKorr X Y Z A B C (default joint)")
    p.add_argument("--frame", choices=("base", "tool"), default="base",
                   help="RKorr's frame, POSCORR's RefCorrSys: the base or the tool (TCP) "
                   "frame (default base)")
    p.add_argument("--mode", choices=("relative", "absolute"), default="relative",
                   help="RSI_ON(#RELATIVE) or #ABSOLUTE (default relative)")
    p.add_argument("--cycle", choices=("IPO_FAST", "IPO"), default="IPO_FAST",
                   help="4 ms or 12 ms (default IPO_FAST)")
    p.add_argument("--timeout", type=int, default=100,
                   help="the ETHERNET object's Timeout: late packets before RSI stops")
    p.add_argument("--sentype", default="ImFree", help="SENTYPE (default ImFree)")
    add_limit_options(p, "correction", "deg (joint) or mm,…,deg (Cartesian)")
    p.add_argument("--dio", type=_first_index("$OUT"), metavar="OUT",
                   help="route a 16-bit output word DiO to $OUT[OUT…OUT+15]")


def configure(p: argparse.ArgumentParser) -> None:
    """Add the ``rsi`` actions to its parser (declared in :mod:`plugcell.apps.cli`)."""
    p.description = ("KUKA RSI with plugcell as the sensor: write the controller's files, "
                     "or stream to a robot.")
    sub = p.add_subparsers(dest="rsi_command", metavar="ACTION", required=True)
    f = sub.add_parser("files", help="write the KRL program, ethernet configuration and "
                       "signal flow for the controller")
    f.add_argument("--out", type=Path, required=True, help="folder to write into")
    f.add_argument("--ip", required=True, help="the PC's address on the RSI network "
                   "(IP_NUMBER)")
    _stream_args(f)
    f.add_argument("--dil", type=_first_index("$IN"), metavar="IN",
                   help="report a 16-bit input word DiL from $IN[IN…IN+15]")
    f.add_argument("--drives", choices=("pc", "robot"), default="pc",
                   help="pc: the KRL program holds the robot and follows the PC "
                   "(RSI_MOVECORR); robot: your own moves run between RSI_ON and RSI_OFF and "
                   "the PC corrects them (the robot service's CORRECT) (default pc)")
    f.add_argument("--settle", type=float, default=1.0, metavar="S",
                   help="--drives robot: seconds the program waits after your moves for the "
                   "PC to end its correction, before RSI_OFF (default 1)")
    f.set_defaults(func=_files)
    r = sub.add_parser("run", help="answer the robot: hold it, or swing one axis")
    add_run_options(r, "the controller's RSI address")
    _stream_args(r)
    add_run_controls(r)
    r.set_defaults(func=_run)


def _config(args: argparse.Namespace, robot_host: str, listen: str):
    """The RsiConfig the options describe (limits converted to SI)."""
    from plugcell.devices.robot.rsi import (
        OutputSignal,
        RsiConfig,
        RsiConfigError,
    )

    try:
        limits = limits_of(args, args.correction)
        return RsiConfig(robot_host=robot_host, listen_host=listen, listen_port=args.port,
                         correction=args.correction, mode=args.mode, cycle=args.cycle,
                         frame=args.frame,
                         timeout_packets=args.timeout, limits=limits, sentype=args.sentype,
                         outputs=(OutputSignal("DiO", 16),) if args.dio else ())
    except RsiConfigError as exc:
        raise CommandError(named_as_options(exc, {
            "timeout_packets": ("--timeout", args.timeout), "listen_port": ("--port", args.port),
            "sentype": ("--sentype", args.sentype), "robot_host": ("--robot-ip", robot_host),
            "listen_host": ("--listen", listen)})) from None


def _files(args: argparse.Namespace) -> int:
    from plugcell.devices.robot.rsi.controller_files import IoRouting, write_controller_files

    config = _config(args, "0.0.0.0", "0.0.0.0")
    io = IoRouting(outputs={"DiO": args.dio} if args.dio else None,
                   input_tag="DiL" if args.dil else None, input_index=args.dil or 1)
    write_and_list(lambda: write_controller_files(args.out, config, args.ip, io, args.drives,
                                                  args.settle), args.out,
                   {"settle": ("--settle", args.settle)})
    if args.drives == "robot":
        print(f"then on the PC: plugcell serve robot --rsi {args.ip}:{args.port} --rsi-robot "
              f"CONTROLLER_IP --rsi-timeout {args.timeout} --param rsi_correction="
              f"{args.correction}"
              + (f" --param rsi_frame={args.frame}" if args.correction == "cartesian" else "")
              + f" --param rsi_mode={args.mode}, and once RSI is on: "
              f"plugcell call ROBOT CORRECT --data '[\"offset\", \"offset=X,Y,Z,A,B,C\"]'")
        return 0
    print(f"then on the PC: plugcell rsi run --robot-ip CONTROLLER_IP --port {args.port} "
          f"--correction {args.correction} --mode {args.mode} --cycle {args.cycle} "
          f"--timeout {args.timeout}")
    return 0


def _source(args: argparse.Namespace):
    from plugcell.devices.robot.rsi.codec import CARTESIAN_AXES, JOINT_AXES
    from plugcell.io.units import DEG, M_PER_MM

    def unit(i: int) -> float:
        return M_PER_MM if args.correction == "cartesian" and i < 3 else DEG

    return sine_or_hold(args.sine, JOINT_AXES if args.correction == "joint"
                        else CARTESIAN_AXES, unit)


def _run(args: argparse.Namespace) -> int:
    from plugcell.devices.robot.rsi import RsiLink

    config = _config(args, args.robot_ip, args.listen)
    try:
        link = RsiLink(config, _source(args), realtime=realtime_of(args))
    except ValueError as exc:
        raise CommandError(str(exc)) from None
    return run_link(link, args, f"{config.correction}, {config.mode}, {config.cycle}",
                    controller_delay=True)
