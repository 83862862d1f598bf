"""``plugcell reproduce``: the thesis's calibration results, recomputed from the code.

``plugcell reproduce 8.1`` — Table 8-1: the errors of the thesis's simulation
added to the nominal Smart H4 (passive joints by the planar four-bar, noise-free)
and identified back with the 34-parameter model; the thesis's table beside ours
(:mod:`plugcell.apps.reproduce.identification_8_1`).

``plugcell reproduce 8.2`` — Tables 8-2, 8-3 and 8-4 on the digital twin: unloaded
(90 poses; nominal and models 1–4), loaded with 18 kg and 36 kg (150 poses;
model 4 against model 5), identified parameters with σ, every figure on
independent validation poses as well as on the calibration poses
(:mod:`plugcell.apps.reproduce.models_8_2`).

``plugcell reproduce 8.3`` — Table 8-5, straightness and tracker iterations of the
two-stage compensation (:mod:`plugcell.apps.reproduce.compensation_8_3`).

Each prints a table (``--json`` for machines) and writes a page with plots to
``--out-dir`` (default ``out/reproduce`` of the current folder, as ``plugcell demo``
writes to ``out/demo``); the repository's own pages are regenerated from its root with
``--out-dir docs/results``.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import numpy as np

from plugcell.apps.cli import CommandError


def configure(p: argparse.ArgumentParser) -> None:
    """Add the ``reproduce`` options to its parser (declared in :mod:`plugcell.apps.cli`)."""
    p.description = (
        "Reproduce thesis 8.1 (simulation) and 8.2 (calibration on "
        "the digital twin) from the code."
    )
    rp = p.add_subparsers(dest="section", metavar="SECTION", required=True)
    a = rp.add_parser("8.1", help="Table 8-1: noise-free simulated identification",
                      description="Table 8-1's errors added to the nominal Smart H4 and "
                                  "identified back (34-parameter model, exact four-bar).")
    a.add_argument("--poses", type=int, default=100, help="configurations (default 100)")
    a.add_argument("--seed", type=int, default=0, help="seed of the configurations (default 0)")
    _common(a)
    a.set_defaults(func=_run_8_1)
    b = rp.add_parser("8.2", help="Tables 8-2..8-4 on the digital twin",
                      description="Models 1-5 on simulated campaigns of the twin: unloaded "
                                  "(90 poses), 18 kg and 36 kg (150 poses), with validation poses.")
    b.add_argument("--seed", type=int, default=0, help="seed of the twin's hidden errors")
    b.add_argument("--quick", action="store_true",
                   help="smaller campaigns (for tests): 40 / 60 poses")
    _common(b)
    b.set_defaults(func=_run_8_2)
    c = rp.add_parser("8.3", help="Table 8-5: two-stage compensation on the twin (36 kg)",
                      description="6 lines x 13 points reached by the nominal model, then "
                                  "model-based compensation (model 5), then tracker-guided "
                                  "correction; Table 8-5, straightness, iterations per point.")
    c.add_argument("--seed", type=int, default=0, help="seed of the twin's hidden errors")
    c.add_argument("--fast", action="store_true", help="fewer points and poses (for tests)")
    _common(c)
    c.set_defaults(func=_run_8_3)


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--json", action="store_true", help="print JSON to stdout")
    p.add_argument("--out-dir", type=Path, default=Path("out/reproduce"),
                   help="where to write the results page and plots (default: out/reproduce; "
                        "the repository's pages: --out-dir docs/results from its root)")
    p.add_argument("--no-write", action="store_true", help="do not write the results page")



def _run_8_1(args: argparse.Namespace) -> int:
    if args.poses < 10:
        raise CommandError(f"--poses must be at least 10, got {args.poses}")
    from plugcell.apps.reproduce import identification_8_1 as r81

    d = r81.reproduce_8_1(args.poses, args.seed)
    return _report(args, d, r81.print_table, r81.write_page)


def _report(args: argparse.Namespace, d: dict[str, Any], print_table: Callable[[Any], Any],
            write: Callable[[Any, Path], Iterable[Any]]) -> int:
    """A section's result ``d`` shown (JSON with ``--json``, else ``print_table(d)``) and,
    unless ``--no-write``, its pages written into ``--out-dir`` (``write``: the paths)."""
    if args.json:
        print(json.dumps(d, indent=2, allow_nan=False, default=_json_default))
    else:
        print_table(d)
    if not args.no_write:
        written = write(d, args.out_dir)
        if not args.json:
            print(f"\nwrote {', '.join(str(w) for w in written)}", file=sys.stderr)
    return 0


def _json_default(x: Any) -> Any:
    if isinstance(x, np.floating | np.integer):
        return x.item()
    raise TypeError(f"not JSON serialisable: {type(x)}")


def _run_8_2(args: argparse.Namespace) -> int:
    def say(msg: str) -> None:
        if not args.json:
            print(msg, file=sys.stderr, flush=True)

    from plugcell.apps.reproduce import models_8_2 as r82

    d = r82.reproduce_8_2(args.seed, args.quick, say)
    return _report(args, d, r82.print_table, r82.write_page)


# ============================================================================ 8.3
def _run_8_3(args: argparse.Namespace) -> int:
    from plugcell.apps.commands.progress import ProgressBar
    from plugcell.apps.reproduce.compensation_8_3 import format_table, run, write_pages

    bar = None if args.json else ProgressBar("8.3 points")
    d = run(fast=args.fast, seed=args.seed, progress=bar)
    return _report(args, d, lambda d: print(format_table(d)),
                   lambda d, out: write_pages(d, str(out)))
