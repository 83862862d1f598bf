"""``plugcell journal``: show or export the journal of a cell (every process and update)."""

from __future__ import annotations

import argparse
import json
from datetime import datetime
from pathlib import Path

from plugcell.apps.cli import CommandError


def configure(p: argparse.ArgumentParser) -> None:
    """Add the ``journal`` options to its parser (declared in :mod:`plugcell.apps.cli`)."""
    p.description = (
        "Every process the services of this machine received: who asked whom, "
        "which command, when, every update, the final state and its reason."
    )
    p.add_argument("--cell", default=None, help="cell name (default: $PLUGCELL_CELL or 'default')")
    p.add_argument("--service", help="only this recipient")
    p.add_argument("--json", action="store_true", help="export as JSON (with the updates)")
    p.add_argument("--limit", type=int, default=0, help="only the last N processes")
    p.add_argument("--journal-dir", type=Path, help="read journals from this folder")
    p.set_defaults(func=run)


def _time(ns: int | None) -> str:
    if not ns:
        return "-"
    return datetime.fromtimestamp(ns / 1e9).strftime("%Y-%m-%d %H:%M:%S.%f")[:-3]


def run(args: argparse.Namespace) -> int:
    import os

    from plugcell.framework.journal import journal_files, read_journal
    from plugcell.framework.keys import DEFAULT_CELL, check_name

    cell = args.cell or os.environ.get("PLUGCELL_CELL", DEFAULT_CELL)
    try:
        check_name(cell, "cell name")
    except ValueError as exc:
        raise CommandError(str(exc)) from None
    files = sorted(args.journal_dir.glob("*.sqlite")) if args.journal_dir else journal_files(cell)
    if args.service:
        files = [f for f in files if f.stem == args.service]
    rows = read_journal(files)
    if args.limit:
        rows = rows[-args.limit :]
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0
    if not rows:
        print(f"journal of cell {cell!r} is empty")
        return 0
    for r in rows:
        what = f"{r.get('command') or '?'}"
        if r.get("option"):
            what += f"#{r['option']}"
        line = (
            f"{_time(r.get('received_ns'))}  {r.get('sender') or '?'} -> {r['recipient']}  "
            f"{what}  #{r.get('identifier') or 0}  {r['state']}"
        )
        if r.get("updates"):
            line += f"  ({len(r['updates'])} updates)"
        if r.get("reason"):
            line += f"  {r['reason']}"
        print(line)
    return 0
