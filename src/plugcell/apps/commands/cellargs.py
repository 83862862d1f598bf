"""Options every framework command shares: ``--cell``, ``--connect``, ``--listen``."""

from __future__ import annotations

import argparse
import os

from plugcell.apps.cli import CommandError
from plugcell.framework.keys import DEFAULT_CELL, check_name
from plugcell.framework.transport import TransportConfig


def add_cell_args(parser: argparse.ArgumentParser) -> None:
    """Add ``--cell``, ``--connect`` and ``--listen`` to ``parser``."""
    parser.add_argument(
        "--cell",
        default=os.environ.get("PLUGCELL_CELL", DEFAULT_CELL),
        help="cell name; cells sharing a network do not see each other "
        f"(default: $PLUGCELL_CELL or {DEFAULT_CELL!r})",
    )
    parser.add_argument(
        "--connect",
        action="append",
        metavar="ENDPOINT",
        help="Zenoh endpoint to connect to, e.g. tcp/10.0.0.1:7447 (a plugcell router); "
        "repeatable (default: $PLUGCELL_CONNECT, none)",
    )
    parser.add_argument(
        "--listen",
        action="append",
        metavar="ENDPOINT",
        help="Zenoh endpoint to listen on (default: $PLUGCELL_LISTEN or tcp/127.0.0.1:0)",
    )


def cell_of(args: argparse.Namespace) -> str:
    """The validated cell name (CommandError if invalid)."""
    try:
        return check_name(args.cell, "cell name")
    except ValueError as exc:
        raise CommandError(str(exc)) from None


def transport_of(args: argparse.Namespace, mode: str | None = None) -> TransportConfig:
    """The transport the options and the ``PLUGCELL_*`` environment describe (CommandError
    with the reason if they are invalid: a bad lease, mode, or a client that listens)."""
    try:
        return TransportConfig.from_env(connect=args.connect, listen=args.listen, mode=mode)
    except ValueError as exc:
        raise CommandError(str(exc)) from None
