"""``plugcell services``: list the services of a cell with their command catalogues."""

from __future__ import annotations

import argparse
import asyncio
import json
from typing import Any

import msgspec

from plugcell.apps.commands.cellargs import add_cell_args, cell_of, transport_of
from plugcell.framework import eventloop


def configure(p: argparse.ArgumentParser) -> None:
    """Add the ``services`` options to its parser (declared in :mod:`plugcell.apps.cli`)."""
    p.description = (
        "Discover the services of a cell (liveliness + Get) and print their "
        "DeviceInfo: state, connection, command catalogue, partners."
    )
    add_cell_args(p)
    p.add_argument("--json", action="store_true", help="print JSON")
    p.add_argument(
        "--settle",
        type=float,
        default=0.3,
        help="seconds to let discovery settle before asking (default 0.3)",
    )
    p.add_argument("--timeout", type=float, default=3.0, help="Get timeout, seconds")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    states = eventloop.run(_collect(args))
    if args.json:
        print(json.dumps([msgspec.to_builtins(s) for s in states], indent=2))
        return 0
    if not states:
        print(f"no services in cell {args.cell!r}")
        return 0
    for s in states:
        d = s.device_info
        partners = ", ".join(p.name for p in s.partners) or "-"
        print(
            f"{d.name}  kind={d.kind or '?'}  state={d.state.value}  "
            f"connection={d.connection.value}  partners={partners}"
        )
        if d.info:
            print(f"    {d.info}")
        for c in d.commands:
            from plugcell.framework.data import describe

            print(
                f"    {c.name:<20} {c.type.value:<13} in: "
                f"{describe(c.input_data_type, c.input_data_size):<16} "
                f"out: {describe(c.output_data_type, c.output_data_size)}"
            )
    return 0


async def _collect(args: argparse.Namespace) -> list[Any]:
    from plugcell.framework.participant import Participant, default_client_name

    async with Participant(
        default_client_name("services"), cell=cell_of(args), transport=transport_of(args)
    ) as client:
        await asyncio.sleep(args.settle)
        return await client.list_services(args.timeout)
