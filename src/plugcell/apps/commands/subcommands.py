"""What every ``plugcell`` command with sub-commands of its own shares (``kin``, ``motion``,
``path``): the sub-parsers, and the command's help when none is named."""

from __future__ import annotations

import argparse


def add_subcommands(parser: argparse.ArgumentParser, description: str,
                    dest: str) -> argparse._SubParsersAction:
    """Give ``parser`` its ``description`` and a group of sub-commands.

    Parameters
    ----------
    parser : argparse.ArgumentParser
        The command's parser (declared in :mod:`plugcell.apps.cli`).
    description : str
        What the command does (its ``--help``).
    dest : str
        The attribute of the parsed arguments that holds the chosen sub-command.

    Returns
    -------
    argparse._SubParsersAction
        Where the sub-commands are added (``.add_parser``).  Without one named the command
        prints its help and exits with status 2.
    """
    parser.description = description
    sub = parser.add_subparsers(dest=dest, metavar="SUBCOMMAND")

    def no_sub(args: argparse.Namespace) -> int:
        parser.print_help()
        return 2

    parser.set_defaults(func=no_sub)
    return sub
