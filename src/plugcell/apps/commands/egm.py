"""``plugcell egm`` — ABB EGM, plugcell as the sensor (docs/abb-egm.md).

::

    plugcell egm files --out DIR --ip PC_IP [--port 6510] [--mode joint|pose|pathcorr]
                       [--sample-ms 4] [--timeout S] [--max-step V,…] [--max-offset V,…]
                       [--max-speed V,…] [--device NAME]
                       [--ext-config pathCorr] [--ext-kp 5] [--ext-bandwidth 20]
                       [--ext-ramp 0.5] [--ext-speed-factor F]     (--mode pathcorr)
    plugcell egm run --robot-ip IP [--listen IP] [--port 6510] [same stream options]
                     [--sine AXIS:AMPLITUDE:PERIOD] [--duration S] [--rt-priority N]
                     [--cpu CPUS] [--mlock]

``files`` writes what the user loads into the controller (RAPID module, the UDP unit
device's configuration, and for path corrections the External Motion Interface Data
entry, MOC_plugcell.cfg); ``run`` answers the robot — holding it where EGM started, or
swinging one axis — and prints the link's counters every second.  Limits are given in
the robot's units: degrees (joint) or mm and degrees (X, Y, Z then the rotation vector),
per cycle for the step and per second for the speed; one number is for all six axes.
"""

from __future__ import annotations

import argparse
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
    x = f.add_argument_group(
        "path corrections (--mode pathcorr): Motion > External Motion Interface Data, "
        "written to MOC_plugcell.cfg (its largest position adjustment: --max-offset)")
    x.add_argument("--ext-config", default="pathCorr", metavar="NAME",
                   help="the entry's name, EGMSetupUC's ExtConfigName (pathCorr)")
    x.add_argument("--ext-kp", type=float, default=5.0, metavar="KP",
                   help="ext_motion_Kp, the correction's proportional gain, 1/s (5)")
    x.add_argument("--ext-bandwidth", type=float, default=20.0, metavar="HZ",
                   help="ext_motion_filter_bandwidth, the correction's filter, Hz (20)")
    x.add_argument("--ext-ramp", type=float, default=0.5, metavar="S",
                   help="ramp_time, the correction's ramp in and out, s (0.5)")
    x.add_argument("--ext-speed-factor", type=float, metavar="F",
                   help="max_allowed_speed_factor (default: the controller's own)")
    f.set_defaults(func=_files)
    r = sub.add_parser("run", help="answer the robot: hold it, or swing one axis")
    add_run_options(r, "the controller's address")
    _stream_args(r)
    add_run_controls(r)
    r.set_defaults(func=_run)


def _config(args: argparse.Namespace, robot_host: str, listen: str):
    """The EgmConfig the options describe (limits converted to SI)."""
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
        raise CommandError(named_as_options(exc, {
            "sample_rate_ms": ("--sample-ms", args.sample_ms),
            "comm_timeout_s": ("--timeout", args.timeout), "listen_port": ("--port", args.port),
            "robot_host": ("--robot-ip", robot_host), "listen_host": ("--listen", listen)})) \
            from None


def _files(args: argparse.Namespace) -> int:
    from plugcell.devices.robot.egm.controller_files import write_controller_files

    config = _config(args, "0.0.0.0", "0.0.0.0")
    ext = _ext_motion(args)
    write_and_list(lambda: write_controller_files(args.out, config, args.ip, args.device,
                                                  ext_motion=ext), args.out)
    print(f"then on the PC: plugcell egm run --robot-ip CONTROLLER_IP --port {args.port} "
          f"--mode {args.mode} --sample-ms {args.sample_ms} --timeout {args.timeout:g}")
    return 0


def _ext_motion(args: argparse.Namespace):
    """The External Motion Interface Data entry of ``--mode pathcorr`` (``None`` for the
    other modes; CommandError when one of its options is given there, or is bad)."""
    from plugcell.devices.robot.egm.controller_files import ExtMotion

    given = {"--ext-config": args.ext_config != "pathCorr", "--ext-kp": args.ext_kp != 5.0,
             "--ext-bandwidth": args.ext_bandwidth != 20.0, "--ext-ramp": args.ext_ramp != 0.5,
             "--ext-speed-factor": args.ext_speed_factor is not None}
    if args.mode != "pathcorr":
        if any(given.values()):
            option = next(k for k, v in given.items() if v)
            raise CommandError(f"{option}: External Motion Interface Data goes with "
                               "--mode pathcorr (joint and pose targets use \"default\")")
        return None
    try:
        return ExtMotion(args.ext_config, args.ext_kp, args.ext_bandwidth, args.ext_ramp,
                         args.ext_speed_factor)
    except ValueError as exc:
        raise CommandError(str(exc)) from None


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
    from plugcell.devices.robot.egm import EgmLink

    config = _config(args, args.robot_ip, args.listen)
    try:
        link = EgmLink(config, _source(args), realtime=realtime_of(args))
    except ValueError as exc:
        raise CommandError(str(exc)) from None
    return run_link(link, args, f"{config.mode}, {config.sample_rate_ms} ms")
