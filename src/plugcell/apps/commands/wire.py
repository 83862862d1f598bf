"""``plugcell wire A B`` / ``plugcell unwire A B``: aliases of ``plugcell cell wire`` /
``plugcell cell unwire`` (:mod:`plugcell.apps.commands.cell`), with the same options,
output and exit codes.

The run-time wiring of the cell controller (thesis 7.6, Figure 7-9): A fetches B's
DeviceInfo with Get and adds it to its Partners — no restart, no reprogramming.
"""

from __future__ import annotations

import argparse

from plugcell.apps.commands.cell import add_wire_options


def configure_wire(p: argparse.ArgumentParser) -> None:
    """``plugcell wire``: ``plugcell cell wire`` (declared in :mod:`plugcell.apps.cli`)."""
    add_wire_options(p, subscribe=True)


def configure_unwire(p: argparse.ArgumentParser) -> None:
    """``plugcell unwire``: ``plugcell cell unwire`` (declared in :mod:`plugcell.apps.cli`)."""
    add_wire_options(p, subscribe=False)
