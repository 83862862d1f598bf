"""``plugcell cell serve``: the cell controller service with its web UI (thesis 7.6).

Starts the cell controller service (it discovers and subscribes to every service
of the cell) and serves its page on ``http://127.0.0.1:PORT/``: services and their
command catalogues, the wiring graph, task forms, robot programs, the live process
monitor with its timeline and queues, the 3-D view and the BASE/PROBE wizards of
appendix D, and the reports.  Local use only; everything is served from plugcell.

``plugcell controller`` is its old name (issue #33: "controller" was also the robot's),
kept working with a deprecation warning (:func:`configure_deprecated`).
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

from plugcell.apps.cli import CommandError
from plugcell.apps.commands.cellargs import add_cell_args, cell_of, transport_of
from plugcell.framework import eventloop


def add_serve_options(p: argparse.ArgumentParser) -> None:
    """Add the ``cell serve`` options to its parser (:mod:`plugcell.apps.commands.cell`)."""
    p.description = (
        "Run the cell controller service (discover, wire, save/load, assign "
        "tasks, run robot programs, monitor) and serve its web UI on localhost."
    )
    p.add_argument("--port", type=int, default=8765, help="TCP port (default 8765; 0: any)")
    p.add_argument("--host", default="127.0.0.1", help="address to serve on (default 127.0.0.1)")
    p.add_argument("--name", help="service name of the controller (default CONTROLLER)")
    p.add_argument("--wiring", type=Path, help="wiring file to load and keep applying")
    p.add_argument("--docs", type=Path,
                   help="docs folder with results/ (default: the source tree's)")
    p.add_argument("--report", type=Path, action="append", default=[],
                   help="a calibration report (HTML) to list; repeatable")
    p.add_argument("--no-journals", action="store_true",
                   help="do not read the services' journals (no queued processes shown)")
    p.add_argument("--log-level", default="WARNING", help="logging level (default WARNING)")
    add_cell_args(p)
    p.set_defaults(func=run)


def configure_deprecated(p: argparse.ArgumentParser) -> None:
    """``plugcell controller``: ``plugcell cell serve`` under its old name, with a warning
    (declared in :mod:`plugcell.apps.cli`)."""
    add_serve_options(p)
    p.description = "Deprecated: use plugcell cell serve. " + (p.description or "")
    p.set_defaults(func=_run_deprecated)


def _run_deprecated(args: argparse.Namespace) -> int:
    from plugcell.apps.commands.deprecated import warn_renamed

    warn_renamed("plugcell controller", "plugcell cell serve")
    return run(args)


def run(args: argparse.Namespace) -> int:
    from plugcell.apps.ui.reports import ReportFiles, default_docs_dir
    from plugcell.apps.ui.server import serve
    from plugcell.devices.cell.service import cell_controller
    from plugcell.framework.participant import PartnerError

    logging.basicConfig(level=args.log_level.upper(), stream=sys.stderr,
                        format="%(asctime)s %(name)s %(levelname)s %(message)s")
    if not 0 <= args.port <= 65535:
        raise CommandError(f"--port {args.port}: not a TCP port")
    if args.docs is not None and not args.docs.is_dir():
        raise CommandError(f"--docs {args.docs}: no such folder")
    try:
        controller = cell_controller(
            args.name, cell=cell_of(args), transport=transport_of(args),
            wiring=args.wiring, journals=not args.no_journals,
        )
    except ValueError as exc:
        raise CommandError(str(exc)) from None
    reports = ReportFiles(args.docs or default_docs_dir(), list(args.report))
    try:
        eventloop.run(serve(controller, host=args.host, port=args.port, reports=reports,
                          log_level=args.log_level.lower()))
    except PartnerError as exc:
        raise CommandError(str(exc)) from None
    except OSError as exc:
        raise CommandError(f"cannot serve on {args.host}:{args.port}: {exc}") from None
    return 0
