"""``plugcell egm`` — ABB EGM, plugcell as the sensor (docs/abb-egm.md).

::

    plugcell egm files --out DIR --ip PC_IP [--port 6510] [--mode joint|pose|pathcorr]
                       [--sample-ms 4] [--timeout S] [--max-step V,…] [--max-offset V,…]
                       [--max-speed V,…] [--device NAME]
    plugcell egm run --robot-ip IP [--listen IP] [--port 6510] [same stream options]
                     [--sine AXIS:AMPLITUDE:PERIOD] [--duration S] [--rt-priority N]
                     [--cpu CPUS] [--mlock]

``files`` writes what the user loads into the controller (RAPID module, the UDP unit
device's configuration); ``run`` answers the robot — holding it where EGM started, or
swinging one axis — and prints the link's counters every second.  Limits are given in
the robot's units: degrees (joint) or mm and degrees (X, Y, Z then the rotation vector),
per cycle for the step and per second for the speed; one number is for all six axes.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from .streaming import (
    add_limit_options,
    add_run_controls,
    add_run_options,
    limits_of,
    realtime_of,
    run_link,
    sine_or_hold,
    write_and_list,
)

AXES = {"joint": ("A1", "A2", "A3", "A4", "A5", "A6"),
        "cartesian": ("X", "Y", "Z", "RX", "RY", "RZ")}


def _stream_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--port", type=int, default=6510,
                   help="the PC's UDP port (the UDP unit device's remote port)")
    p.add_argument("--mode", choices=("joint", "pose", "pathcorr"), default="joint",
                   help="EGMRunJoint, EGMRunPose or EGMMoveL path corrections (joint)")
    p.add_argument("--sample-ms", type=int, default=4, help="\\SampleRate in ms (4)")
    p.add_argument("--timeout", type=float, default=1.0,
                   help="EGMSetupUC's \\CommTimeout in seconds (1)")
    add_limit_options(p, "offset change", "deg (joint) or mm,…,deg (pose)")


def configure(p: argparse.ArgumentParser) -> None:
    """Add the ``egm`` actions to its parser (declared in :mod:`plugcell.apps.cli`)."""
    p.description = ("ABB EGM with plugcell as the sensor: write the controller's files, "
                     "or stream to a robot.")
    sub = p.add_subparsers(dest="egm_command", metavar="ACTION", required=True)
    f = sub.add_parser("files", help="write the RAPID module and the UDP unit device's "
                       "configuration for the controller")
    f.add_argument("--out", type=Path, required=True, help="folder to write into")
    f.add_argument("--ip", required=True, help="the PC's address on the controller's "
                   "network (RemoteAdress)")
    f.add_argument("--device", default="plugcellUC", help="the UDP unit device's name")
    _stream_args(f)
    f.set_defaults(func=_files)
    r = sub.add_parser("run", help="answer the robot: hold it, or swing one axis")
    add_run_options(r, "the controller's address")
    _stream_args(r)
    add_run_controls(r)
    r.set_defaults(func=_run)


def _config(args: argparse.Namespace, robot_host: str, listen: str):
    """The EgmConfig the options describe (limits converted to SI)."""
    from plugcell.apps.cli import CommandError
    from plugcell.devices.robot.egm import (
        EgmConfig,
        EgmConfigError,
    )

    try:
        limits = limits_of(args, "joint" if args.mode == "joint" else "cartesian")
        return EgmConfig(robot_host=robot_host, listen_host=listen, listen_port=args.port,
                         mode=args.mode, sample_rate_ms=args.sample_ms,
                         comm_timeout_s=args.timeout, limits=limits)
    except EgmConfigError as exc:
        raise CommandError(str(exc)) from None


def _files(args: argparse.Namespace) -> int:
    from plugcell.devices.robot.egm.controller_files import write_controller_files

    config = _config(args, "0.0.0.0", "0.0.0.0")
    write_and_list(lambda: write_controller_files(args.out, config, args.ip, args.device),
                   args.out)
    print(f"then on the PC: plugcell egm run --robot-ip CONTROLLER_IP --port {args.port} "
          f"--mode {args.mode} --sample-ms {args.sample_ms} --timeout {args.timeout:g}")
    return 0


def _source(args: argparse.Namespace):
    from plugcell.io.units import DEG, M_PER_MM

    def unit(i: int) -> float:
        return M_PER_MM if args.mode != "joint" and i < 3 else DEG

    def allowed(i: int) -> str:
        return ("a path correction has no rotation (X, Y or Z)"
                if args.mode == "pathcorr" and i >= 3 else "")

    return sine_or_hold(args.sine, AXES["joint" if args.mode == "joint" else "cartesian"],
                        unit, allowed)


def _run(args: argparse.Namespace) -> int:
    from plugcell.apps.cli import CommandError
    from plugcell.devices.robot.egm import EgmLink

    config = _config(args, args.robot_ip, args.listen)
    try:
        link = EgmLink(config, _source(args), realtime=realtime_of(args))
    except ValueError as exc:
        raise CommandError(str(exc)) from None
    return run_link(link, args, f"{config.mode}, {config.sample_rate_ms} ms")
