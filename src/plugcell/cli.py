"""The ``plugcell`` command.

Each sub-command lives in its own module under :mod:`plugcell.commands` and
exposes ``register(subparsers)``; the module's ``register`` adds its parser and
sets ``func`` (``func(args) -> int`` exit code).  This file only assembles them.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from plugcell import __version__

#: Sub-command modules, in the order ``plugcell --help`` lists them.
COMMAND_MODULES: tuple[str, ...] = (
    "plugcell.commands.kin",
    "plugcell.commands.twin",
    "plugcell.commands.demo",
    "plugcell.commands.serve",
    "plugcell.commands.services",
    "plugcell.commands.call",
    "plugcell.commands.wire",
    "plugcell.commands.router",
    "plugcell.commands.journal",
    "plugcell.commands.bench",
    "plugcell.commands.compensate",
    "plugcell.commands.calibrate",
    "plugcell.commands.reproduce",
    "plugcell.commands.cell",
    "plugcell.commands.controller",
    "plugcell.commands.certs",
    "plugcell.commands.opcua",
)


class CommandError(Exception):
    """A user-facing error: printed as ``plugcell: error: <message>``, exit code 2."""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="plugcell",
        description="Plug-and-produce robot work-cells made accurate.",
    )
    parser.add_argument("--version", action="version", version=f"plugcell {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    func = getattr(args, "func", None)
    if func is None:
        parser.print_help()
        return 2
    try:
        return int(func(args) or 0)
    except CommandError as exc:
        print(f"plugcell: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("plugcell: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
