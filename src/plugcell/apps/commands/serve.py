"""``plugcell serve KIND --name NAME``: run one service as an OS process until stopped."""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import logging
import signal
import sys
from collections.abc import Awaitable
from pathlib import Path
from typing import Any

from plugcell.apps.cli import CommandError
from plugcell.apps.commands.cellargs import add_cell_args, cell_of, transport_of
from plugcell.apps.commands.deprecated import DeprecatedName
from plugcell.apps.commands.robotargs import add_robot_args
from plugcell.framework import eventloop


def configure(p: argparse.ArgumentParser) -> None:
    """Add the ``serve`` options to its parser (declared in :mod:`plugcell.apps.cli`)."""
    from plugcell.apps.kinds import KINDS

    p.description = (
        "Run one Plug-and-Produce service until SIGINT/SIGTERM, then shut it "
        "down cleanly (Shutdown notification, queued processes end Failed)."
    )
    p.add_argument(
        "kind", help=f"service kind: {', '.join(sorted(KINDS))}, or module:Class of your own"
    )
    p.add_argument("--name", help="service (device) name; default: the kind in capitals")
    add_cell_args(p)
    p.add_argument(
        "--param",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="service-specific parameter, e.g. time_scale=0.01 (repeatable)",
    )
    dev = p.add_argument_group(
        "device options (each passed to the kinds that declare it, like --param)"
    )
    dev.add_argument("--sim", action="store_true",
                     help="drive the simulated device (robot: its simulated controller; "
                     "tracker: the tracker model)")
    dev.add_argument("--line", "--controller", dest="line", action=DeprecatedName,
                     old=("--controller",), metavar="HOST:PORT",
                     help="robot: a real controller over the line protocol "
                     "(docs/controller-protocol.md; --controller is its old name)")
    dev.add_argument("--rsi", metavar="HOST:PORT",
                     help="robot: a KUKA robot over RSI, the program on the PC (the PC drives); "
                     "where plugcell listens for the controller's packets (docs/kuka-rsi.md)")
    dev.add_argument("--rsi-robot", metavar="HOST[:PORT]",
                     help="robot: the controller's address on the RSI network (default: the "
                     "--rsi host)")
    dev.add_argument("--rsi-timeout", type=int, metavar="N",
                     help="robot: the RSI ETHERNET object's Timeout (late packets; default 100)")
    dev.add_argument("--egm", metavar="HOST:PORT",
                     help="robot: an ABB robot over EGM, the program on the PC (the PC drives); "
                     "where plugcell listens for the controller's EgmRobot messages "
                     "(docs/abb-egm.md)")
    dev.add_argument("--egm-robot", metavar="HOST[:PORT]",
                     help="robot: the controller's address (default: the --egm host)")
    dev.add_argument("--egm-timeout", type=float, metavar="S",
                     help="robot: EGMSetupUC's \\CommTimeout (s; default 1)")
    add_robot_args(dev, help="robot: shipped name (default smart_h4), description file "
                   "(.toml) or URDF/xacro file (with --robot-arg, --package-path, --base-link, "
                   "--tip-link)")
    dev.add_argument("--payload-kg", type=float, help="robot: payload carried by the twin")
    dev.add_argument("--speed", type=float, help="robot: simulation speed factor")
    dev.add_argument("--seed", type=int, help="seed of the simulated device")
    dev.add_argument("--endpoint", metavar="opc.tcp://HOST:PORT",
                     help="opcua-device: the OPC UA server of the device")
    dev.add_argument("--map", metavar="FILE",
                     help="opcua-device: the device map (docs/opcua.md)")
    dev.add_argument("--trust", metavar="DIR",
                     help="opcua-device: trusted server certificates and authorities (beside "
                     "the cell's OPC UA CA of --param certs=DIR)")
    dev.add_argument("--insecure-accept-any", action="store_true",
                     help="opcua-device: accept any server, its certificate unchecked "
                     "(a test bench only; logged)")
    p.add_argument("--max-payload", type=int, default=None, help="largest accepted request, bytes")
    p.add_argument("--journal-dir", type=Path, help="where to keep the journal")
    p.add_argument("--no-journal", action="store_true", help="do not journal processes")
    p.add_argument("--log-level", default="WARNING", help="logging level (default WARNING)")
    p.set_defaults(func=run)


def _params(kind: str, pairs: list[str]) -> dict[str, Any]:
    from plugcell.apps.kinds import current_param, kind_params, load_kind

    known = kind_params(kind)
    cls = load_kind(kind)
    out: dict[str, Any] = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        key = current_param(kind, key)
        if not sep or key not in known:
            names = ", ".join(sorted(known)) or "none"
            raise CommandError(f"bad --param {pair!r} for {cls.__name__} (parameters: {names})")
        try:
            out[key] = known[key](value)
        except ValueError as exc:
            raise CommandError(f"bad value for {key}: {exc}") from None
    return out


def _device_options(kind: str, args: argparse.Namespace) -> list[str]:
    """The device flags that were given, as ``KEY=VALUE`` pairs for :func:`_params`."""
    from plugcell.apps.commands.robotargs import robot_file_of
    from plugcell.apps.kinds import kind_params, load_kind

    known = kind_params(kind)
    cls = load_kind(kind)
    pairs = []
    urdf_options = [getattr(args, k, None) for k in ("robot_arg", "package_path", "base_link",
                                                     "tip_link")]
    if args.robot is None and any(urdf_options):
        raise CommandError("--robot-arg, --package-path, --base-link and --tip-link describe "
                           "a URDF robot: give it with --robot FILE")
    if getattr(args, "insecure_accept_any", False):
        if "insecure_accept_any" not in known:
            raise CommandError(f"--insecure-accept-any: not an option of {cls.__name__}")
        pairs.append("insecure_accept_any=true")
    if args.sim:
        if "sim" in known:
            pairs.append("sim=true")
        elif "driver" in known:
            pairs.append("driver=sim")
        else:
            raise CommandError(f"--sim: {cls.__name__} has no simulated mode")
    for flag, key in (("line", "line"), ("rsi", "rsi"), ("rsi_robot", "rsi_robot"),
                      ("rsi_timeout", "rsi_timeout"), ("egm", "egm"), ("egm_robot", "egm_robot"),
                      ("egm_timeout", "egm_timeout"), ("robot", "robot"),
                      ("payload_kg", "payload_kg"), ("speed", "speed"), ("seed", "seed"),
                      ("endpoint", "endpoint"), ("map", "map"), ("trust", "trust")):
        value = getattr(args, flag, None)
        if flag == "robot" and value is not None and key in known:
            value = robot_file_of(args)  # a URDF robot: imported, as a description file
        if value is not None:
            if key not in known:
                option = "--" + flag.replace("_", "-")
                raise CommandError(f"{option}: not an option of {cls.__name__}")
            pairs.append(f"{key}={value}")
    return pairs


def run(args: argparse.Namespace) -> int:
    from plugcell.apps.kinds import build, current_kind, load_kind
    from plugcell.framework.participant import PartnerError
    from plugcell.framework.service import DeviceError

    logging.basicConfig(
        level=args.log_level.upper(),
        stream=sys.stderr,
        format="%(asctime)s %(name)s %(levelname)s %(message)s",
    )
    args.kind = current_kind(args.kind)  # an old name: its new one, with a warning
    try:
        load_kind(args.kind)  # an unknown kind: one error line
    except KeyError as exc:
        raise CommandError(str(exc.args[0])) from None
    params = _params(args.kind, [*_device_options(args.kind, args), *args.param])
    options: dict[str, Any] = {"max_payload": args.max_payload} if args.max_payload else {}
    journal: bool | Path = args.journal_dir or not args.no_journal
    try:
        service = build(args.kind, args.name, params, cell=cell_of(args),
                        transport=transport_of(args), journal=journal, **options)
    except (ValueError, TypeError) as exc:
        raise CommandError(str(exc)) from None
    try:
        eventloop.run(_serve(service))
    except (PartnerError, DeviceError) as exc:  # a name conflict; a device it cannot reach
        raise CommandError(str(exc)) from None
    return 0


def stop_on_signals() -> asyncio.Event:
    """An event set by SIGINT or SIGTERM (handlers on the running loop)."""
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    return stop


async def start_unless_stopped(start: Awaitable[None], stop: asyncio.Event) -> bool:
    """Await ``start`` unless ``stop`` is set first: then cancel it (its own clean-up runs,
    e.g. ``Service.start`` closes what it opened) and return False.

    A service connecting to a device that does not answer would otherwise ignore
    SIGTERM until the connection's timeout (60 s for an OPC UA device with
    ``watch_s=30``).  ``start``'s own error propagates.
    """
    starting = asyncio.ensure_future(start)
    stopping = asyncio.ensure_future(stop.wait())
    try:
        await asyncio.wait({starting, stopping}, return_when=asyncio.FIRST_COMPLETED)
    finally:
        stopping.cancel()
    if starting.done():
        starting.result()
        return True
    starting.cancel()
    with contextlib.suppress(asyncio.CancelledError):
        await starting
    return False


async def _say_when_listening(service: Any) -> None:
    """A robot service streaming to its controller (``--rsi``, ``--egm``) starts only once
    the controller streams: say when its link listens — the moment to start the
    controller's program, whose own timeout runs from its first packet."""
    bridge = getattr(service.interface, "bridge", None)
    listening = getattr(bridge, "listening", None)
    if not isinstance(listening, asyncio.Event):
        return
    await listening.wait()
    print(f"plugcell: {service.name} ({service.declaration.kind}) listening on "
          f"{bridge.address} for the {bridge.vendor} stream of the controller at "
          f"{bridge.config.robot_host}", flush=True)


async def _serve(service: Any) -> None:
    from plugcell.framework.participant import PartnerError

    stop = stop_on_signals()
    listening = asyncio.create_task(_say_when_listening(service))
    try:
        if not await start_unless_stopped(service.start(), stop):
            return
    finally:
        listening.cancel()
    print(
        f"plugcell: {service.name} ({service.declaration.kind}) serving in cell "
        f"{service.cell!r} "
        f"as instance {service.participant.instance}",
        flush=True,
    )
    stopping = asyncio.create_task(stop.wait())
    withdrawn = asyncio.create_task(service.stopped.wait())
    try:
        await asyncio.wait({stopping, withdrawn}, return_when=asyncio.FIRST_COMPLETED)
    finally:
        stopping.cancel()
        withdrawn.cancel()
        with contextlib.suppress(Exception):
            await service.close()
    if service.conflict:
        raise PartnerError(service.conflict)
