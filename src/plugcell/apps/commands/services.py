"""``plugcell services``: an alias of ``plugcell cell ls`` (:mod:`plugcell.apps.commands.cell`),
with the same options, output (one JSON shape) and exit codes.

The services of the cell, discovered by liveliness and ``Get``: their kind, state,
connection and partners; with ``--commands`` each one's description and command catalogue.
"""

from __future__ import annotations

import argparse

from plugcell.apps.commands.cell import add_ls_options


def configure(p: argparse.ArgumentParser) -> None:
    """``plugcell services``: ``plugcell cell ls`` (declared in :mod:`plugcell.apps.cli`)."""
    add_ls_options(p)
