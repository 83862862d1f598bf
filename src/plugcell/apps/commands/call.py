"""``plugcell call SERVICE COMMAND``: create a process and print its updates as JSON lines.

The ``ros2 service call`` of plugcell.  The first line is the acknowledgement,
then one line per ProcessUpdate until the process is Completed or Failed; the
exit code is 0 for Completed, 1 for Failed.  For a MultipleData command,
``--frames N`` (or ``--duration S``, or Ctrl-C) sends the service's StopData
command after N data updates.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import signal
import sys
import time
from typing import Any

from plugcell.apps.cli import CommandError
from plugcell.apps.commands.cellargs import add_cell_args, cell_of, transport_of
from plugcell.framework import eventloop


def configure(p: argparse.ArgumentParser) -> None:
    """Add the ``call`` options to its parser (declared in :mod:`plugcell.apps.cli`)."""
    p.description = (
        "CreateProcess at SERVICE and print the acknowledgement and every "
        "ProcessUpdate as one JSON object per line."
    )
    p.add_argument("service")
    p.add_argument("command")
    p.add_argument("--option", default="", help="the command's Option string")
    p.add_argument("--data", help="input data as JSON, e.g. 500 or [550, 1100]")
    p.add_argument(
        "--timeout",
        type=float,
        default=10.0,
        help="seconds to wait for the service, the ack and each update (default 10)",
    )
    p.add_argument("--frames", type=int, help="MultipleData: stop after N data updates")
    p.add_argument("--duration", type=float, help="MultipleData: stop after S seconds")
    p.add_argument("--stop", help="MultipleData: the StopData command (default: the first)")
    p.add_argument("--full", action="store_true", help="print large data in full")
    p.add_argument("--name", help="sender name (default: call-<host>-<pid>)")
    add_cell_args(p)
    p.set_defaults(func=run)


def _emit(obj: dict[str, Any]) -> None:
    sys.stdout.write(json.dumps(obj) + "\n")
    sys.stdout.flush()


def run(args: argparse.Namespace) -> int:
    data = None
    if args.data is not None:
        try:
            data = json.loads(args.data)
        except json.JSONDecodeError as exc:
            raise CommandError(f"--data is not JSON: {exc}") from None
    return eventloop.run(_call(args, data))


def _update_json(update: Any, full: bool) -> dict[str, Any]:
    from plugcell.framework.data import DataError, to_json_value

    out: dict[str, Any] = {
        "event": "update",
        "sender": update.tag.sender,
        "recipient": update.tag.recipient,
        "identifier": update.identifier,
        "seq": update.seq,
        "state": update.state.value,
        "reason": update.reason,
    }
    try:
        out["data"] = to_json_value(update.data, max_items=sys.maxsize if full else 1000)
    except (DataError, ValueError) as exc:
        out["data"] = {"error": str(exc)}
    return out


async def _call(args: argparse.Namespace, data: Any) -> int:
    from plugcell.framework.messages import CommandTypes
    from plugcell.framework.participant import Participant, default_client_name

    name = args.name or default_client_name("call")
    async with Participant(name, cell=cell_of(args), transport=transport_of(args)) as client:
        if not await client.wait_for(args.service, args.timeout):
            _emit(
                {
                    "event": "ack",
                    "recipient": args.service,
                    "identifier": 0,
                    "state": "Failed",
                    "reason": f"unknown device {args.service!r}: no such service in cell "
                    f"{args.cell!r} (waited {args.timeout:g} s)",
                }
            )
            return 1
        call = await client.create_process(
            args.service, args.command, args.option, data, timeout=args.timeout
        )
        ack = call.ack
        assert ack is not None
        _emit(
            {
                "event": "ack",
                "sender": name,
                "recipient": args.service,
                "identifier": call.identifier,
                "state": ack.state.value,
                "reason": ack.reason,
            }
        )
        partner = client.partners.get(args.service)
        command = partner.device.command(args.command) if partner else None
        multiple = command is not None and command.type is CommandTypes.MultipleData
        interrupted = asyncio.Event()
        if multiple:
            asyncio.get_running_loop().add_signal_handler(signal.SIGINT, interrupted.set)
        started = time.monotonic()
        frames = 0
        stopping = False
        async for update in call:
            _emit(_update_json(update, args.full))
            if update.data is not None:
                frames += 1
            due = (
                (args.frames is not None and frames >= args.frames)
                or (args.duration is not None and time.monotonic() - started >= args.duration)
                or interrupted.is_set()
            )
            if multiple and not stopping and not update.state.final and due:
                stopping = True
                stop = await client.stop_process(call, args.stop)
                final = await stop.result()
                _emit(
                    {
                        "event": "stop",
                        "command": stop.command,
                        "identifier": stop.identifier,
                        "state": final.state.value,
                        "reason": final.reason,
                    }
                )
        final = call.final
        return 0 if final is not None and final.state.value == "Completed" else 1
