"""``plugcell path run`` — run a path file with the laser tracker in the loop (issue 38).

::

    plugcell path run (--path path.csv | --program FILE.pdl [--library DIR …])
        [--params PARAMS.json [--physical-only]]
        [--mode 6dof|3dof] [--no-tracking] [--beam-break START:DURATION …]
        [--tracker-lost-at S] [--rate HZ] [--payload KG] [--seed N] [--out result.json]
        [--json] [--learn N] [--learned FILE] [--learned-out FILE]
        [--learn-law p|inverse] [--inverse-reidentify 0|1] [--weighting kalman|none]
        [--weighting-detect K] [--weighting-window-s S] [--weighting-detect-fell 0|1]
        [--learn-gain L] [--learn-cutoff HZ] [--learn-converged PCT] [--learn-diverged PCT]

The path file (:mod:`plugcell.io.path_files`): ``x, y, z`` mm, optionally ``a, b, c``
degrees, ``speed`` mm/s and ``tracking`` 1/0 per segment.  The robot is the twin's KUKA
RSI side running the path by itself; plugcell superimposes the tracker loop's
corrections over RSI (:mod:`plugcell.sim.path_run`), its model-based part from the
calibration ``--params`` (default: the nominal model).  It prints each segment's accuracy
(perpendicular max and 3σ, along max, mm), split by what the loop did on it, the windows
without tracking, and writes the whole result (and the traces) as JSON with ``--out``.
Exit status 0, or 1 with the reason when the run ended early (the tracker silent, RSI
stopped): the result is written all the same.  ``--learn``/``--learned``: the path run
again and again with iterative learning (:mod:`.path_learn`).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np

from plugcell.apps.cli import CommandError
from plugcell.apps.commands import path_learn
from plugcell.apps.commands.progress import ProgressBar
from plugcell.apps.commands.subcommands import add_subcommands
from plugcell.io.path_files import PathFileError, read_path

#: The ``format`` of the result file (``--out``): what the web UI's tracked-path view reads.
RESULT_FORMAT = "plugcell-tracked-path"


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the ``path`` sub-commands to its parser (declared in :mod:`plugcell.apps.cli`)."""
    sub = add_subcommands(
        parser, "Paths with the tracker in the loop (docs/tracked-paths.md).",
        "path_command")
    p = sub.add_parser(
        "run", help="run a path file on the twin with the laser tracker correcting it",
        description="Run the path of a path file (x,y,z[,a,b,c] mm/deg, speed mm/s, "
        "tracking 1/0) on the twin's RSI robot with the tracker in the loop; print the "
        "accuracy of each segment and the windows without tracking.")
    source = p.add_mutually_exclusive_group(required=True)
    source.add_argument("--path", metavar="FILE", help="the path file (CSV)")
    source.add_argument("--program", metavar="FILE.pdl",
                        help="a robot program: its MOVE LINEAR moves are the path, those "
                        "WITH TRACKING tracked (docs/robot-language.md)")
    p.add_argument("--library", action="append", default=[], metavar="DIR",
                   help="a folder of the program's libraries (repeatable)")
    p.add_argument("--params", type=Path, metavar="PARAMS.json",
                   help="the robot's calibration (plugcell calibrate): the model-based part of "
                   "the correction and the identified BASE and PROBE (default: the nominal "
                   "model, the cell's true frames)")
    p.add_argument("--physical-only", action="store_true",
                   help="ignore a learned residual model recorded in PARAMS")
    p.add_argument("--mode", choices=("6dof", "3dof"), default="6dof",
                   help="the tracker measures the T-MAC's pose (6dof, default) or the "
                   "reflector's position (3dof: the orientation from the model)")
    p.add_argument("--no-tracking", action="store_true",
                   help="the tracker only measures: the model alone corrects (comparison)")
    p.add_argument("--beam-break", action="append", default=[], metavar="START:DURATION",
                   help="interrupt the beam at START s after the path's start for DURATION s "
                   "(repeatable)")
    p.add_argument("--tracker-lost-at", type=float, metavar="S",
                   help="the tracker stops sending S s after the path's start")
    p.add_argument("--rate", type=float, default=1000.0, metavar="HZ",
                   help="tracker output rate (default 1000)")
    p.add_argument("--speed", type=float, default=100.0, metavar="MM_S",
                   help="speed of the segments whose row gives none (default 100)")
    p.add_argument("--payload", type=float, default=36.0, metavar="KG",
                   help="payload on the flange (default 36)")
    p.add_argument("--seed", type=int, default=0, help="the twin's and tracker's seed")
    p.add_argument("--out", metavar="FILE", help="write the result and the traces (JSON)")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    path_learn.add_arguments(p)
    p.set_defaults(func=_cmd_run)


def _breaks(texts: list[str]) -> tuple[tuple[float, float], ...]:
    from plugcell.sim.beam_breaks import parse_beam_breaks

    try:
        return parse_beam_breaks(texts)
    except ValueError as exc:
        raise CommandError(f"--beam-break {exc}") from None


def _mm(x: float) -> float:
    return round(x * 1e3, 4)


def result_dict(run: Any, path_name: str) -> dict[str, Any]:
    """The run as JSON-ready data (lengths mm, times s)."""
    rows = [{"segment": r.segment, "state": r.state, "cycles": r.n,
             "duration_s": round(r.duration_s, 3),
             "perpendicular_max_mm": _mm(r.perpendicular_max),
             "perpendicular_3sigma_mm": _mm(r.perpendicular_3sigma),
             "along_max_mm": _mm(r.along_max)} for r in run.accuracy.rows]
    windows = [{"start_s": round(w.start_s, 3),
                "end_s": None if w.end_s is None else round(w.end_s, 3), "reason": w.reason}
               for w in run.windows]
    return {"path": path_name, "ended": run.ended, "cycles": run.cycles,
            "duration_s": round(run.duration_s, 3), "late": run.late, "clamped": run.clamped,
            "samples_used": run.samples_ok, "samples_bad": run.samples_lost,
            "accuracy": rows, "windows_without_tracking": windows}


def _traces(run: Any) -> dict[str, Any]:
    tr = run.traces
    return {"t_s": np.round(tr["t"], 4).tolist(),
            **{f"{k}_mm": np.round(tr[k] * 1e3, 4).tolist()
               for k in ("commanded", "corrected", "actual")},
            "measured_mm": [[round(r[0], 4), *np.round(r[1:] * 1e3, 4).tolist()]
                            for r in tr["measured"]],
            "segment": tr["segment"].tolist(), "state": tr["state"].tolist()}


def result_document(run: Any, path_name: str) -> dict[str, Any]:
    """The result file of ``--out``: :func:`result_dict` with its format and the traces."""
    return {"format": RESULT_FORMAT, "format_version": 1, **result_dict(run, path_name),
            "traces": _traces(run)}


def _print_table(result: dict[str, Any]) -> None:
    print("segment  state      cycles  perp max mm  perp 3σ mm  along max mm")
    for r in result["accuracy"]:
        seg = "path" if r["segment"] < 0 else str(r["segment"] + 1)
        print(f"{seg:>7}  {r['state']:<9} {r['cycles']:>7}  {r['perpendicular_max_mm']:>11.3f}"
              f"  {r['perpendicular_3sigma_mm']:>10.3f}  {r['along_max_mm']:>12.3f}")
    for w in result["windows_without_tracking"]:
        end = "end" if w["end_s"] is None else f"{w['end_s']:.3f} s"
        print(f"without tracking: {w['start_s']:.3f} s – {end} ({w['reason']})")


def _read(args: argparse.Namespace) -> Any:
    """The path of ``--path`` or of ``--program`` (its straight moves)."""
    if args.path is not None:
        if args.library:
            raise CommandError("--library goes with --program")
        try:
            return read_path(args.path, speed_mm_s=args.speed)
        except PathFileError as exc:
            raise CommandError(str(exc)) from None
    from plugcell.io.robots import load_robot
    from plugcell.sim.path_program import path_of_program

    try:
        path, trackers = path_of_program(args.program, load_robot("smart_h4"), args.speed,
                                         args.library)
    except (OSError, ValueError) as exc:
        raise CommandError(str(exc)) from None
    if len(trackers) > 1:
        raise CommandError(f"{args.program}: its moves name {len(trackers)} trackers "
                     f"({', '.join(sorted(trackers))}); the twin has one")
    return path


def _cmd_run(args: argparse.Namespace) -> int:
    from plugcell.sim.path_run import PathRunOptions, run_path  # late: the twin is heavy

    if not (np.isfinite(args.speed) and args.speed > 0):
        raise CommandError(f"--speed must be > 0 mm/s, got {args.speed}")
    learning = path_learn.wants_learning(args)
    path = _read(args)
    calibration = None
    if args.params is not None:
        from plugcell.apps.commands.files import read_compensation_model

        args.robot = None  # the robot the file records
        calibration = read_compensation_model(args.params, args, not args.physical_only)
    try:
        options = PathRunOptions(payload_kg=args.payload, seed=args.seed,
                                 tracking=not args.no_tracking, rate_hz=args.rate,
                                 six_dof=args.mode == "6dof",
                                 beam_breaks=_breaks(args.beam_break),
                                 tracker_lost_at=args.tracker_lost_at)
    except ValueError as exc:
        raise CommandError(str(exc)) from None

    name = Path(args.path or args.program).name
    if learning:
        results = SimpleNamespace(result_document=result_document, print_result=print_result)
        return path_learn.run_learning(args, path, name, options, calibration, results)
    bar = ProgressBar(f"running {name}")

    def progress(fraction: float) -> None:
        if not args.json:
            bar(round(100 * fraction), 100)

    try:
        run = run_path(path, options, progress, calibration)
    except ValueError as exc:
        where = args.params if "calibration" in str(exc) else args.path or args.program
        raise CommandError(f"{where}: {exc}") from None
    return print_result(args, run, name)


def print_result(args: argparse.Namespace, run: Any, name: str) -> int:
    """Write ``--out``, print the table (or ``--json``); the exit status (1: ended early)."""
    result = result_dict(run, name)
    if args.out:
        Path(args.out).write_text(json.dumps(result_document(run, name)) + "\n")
    if args.json:
        print(json.dumps(result))
    else:
        _print_table(result)
    if run.ended:
        print(f"ended early: {run.ended}", file=sys.stderr)
        return 1
    return 0
