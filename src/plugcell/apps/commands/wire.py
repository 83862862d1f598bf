"""``plugcell wire A B`` / ``plugcell unwire A B``: make service A subscribe to / drop B.

The run-time wiring of the cell controller (thesis 7.6, Figure 7-9): A fetches B's
DeviceInfo with Get and adds it to its Partners — no restart, no reprogramming.
"""

from __future__ import annotations

import argparse
import json
from typing import Any

import msgspec

from plugcell.apps.commands.cellargs import add_cell_args, cell_of, transport_of
from plugcell.framework import eventloop


def configure_wire(p: argparse.ArgumentParser) -> None:
    """Add the ``wire`` options to its parser (declared in :mod:`plugcell.apps.cli`)."""
    p.description = (
        "Service A subscribes to partner B at run time (Get B's DeviceInfo, "
        "add it to A's Partners)."
    )
    _arguments(p, subscribe=True)


def configure_unwire(p: argparse.ArgumentParser) -> None:
    """Add the ``unwire`` options to its parser (declared in :mod:`plugcell.apps.cli`)."""
    p.description = "Service A drops partner B from its Partners at run time."
    _arguments(p, subscribe=False)


def _arguments(p: argparse.ArgumentParser, subscribe: bool) -> None:
    p.add_argument("service", metavar="A")
    p.add_argument("partner", metavar="B")
    add_cell_args(p)
    p.add_argument("--timeout", type=float, default=10.0,
                   help="seconds to wait for A and B to be in the cell, and for the answer "
                        "(default 10)")
    p.add_argument("--json", action="store_true", help="print the response as JSON")
    p.set_defaults(func=run, subscribe=subscribe)


def run(args: argparse.Namespace) -> int:
    from plugcell.apps.cli import CommandError

    response = eventloop.run(_ask(args))
    if args.json:
        print(json.dumps(msgspec.to_builtins(response)))
    elif response.ok:
        verb = "subscribed to" if args.subscribe else "dropped"
        print(f"{args.service} {verb} {args.partner}")
    if not response.ok:
        raise CommandError(response.reason)
    return 0


async def _ask(args: argparse.Namespace) -> Any:
    from plugcell.framework.participant import Participant, default_client_name

    async with Participant(
        default_client_name("wire"), cell=cell_of(args), transport=transport_of(args)
    ) as client:
        # both may still be starting (a robot service starts its controller first): wait
        # for them as `plugcell call` waits for its service (issue 39: `serve … &` then
        # `wire` failed with "no such service"); a partner to drop may have left the cell
        await client.wait_for(args.service, args.timeout)
        if args.subscribe and not await client.wait_for(args.partner, args.timeout):
            from plugcell.apps.cli import CommandError

            raise CommandError(f"unknown device {args.partner!r}: no such service in cell "
                               f"{cell_of(args)!r} (waited {args.timeout:g} s)")
        return await client.ask_subscribe(args.service, args.partner, args.subscribe, args.timeout)
