"""``plugcell path run … --learn N`` / ``--learned FILE`` — iterative learning of a
repeated path from the command line (docs/tracked-paths.md "Learning a repeated path").

* ``--learn N``: run the path up to ``N`` times; after each run the learned offset is
  updated from the run's tracker samples (:mod:`plugcell.sim.path_learning`); a table row
  per run; the runs stop early when the learning converged or the measured error grew
  (the offset rolled back to the best run's) — :mod:`plugcell.compensation.tracking.repeat`;
* ``--learned-out FILE`` writes the learned correction with what it was learned for
  (:mod:`plugcell.io.learned_paths`);
* ``--learned FILE`` refuses a correction of another path, speed, robot, tool, payload,
  calibration or loop before anything moves; alone it runs the path once with the
  offset fed forward (no learning), with ``--learn`` the learning goes on from it.

Exit status 0; 1 when the learning diverged, no run could be learned from, or a run
ended early (the reason on stderr; a correction file is written all the same when
something was learned).
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

from plugcell.apps.cli import CommandError
from plugcell.apps.commands.progress import ProgressBar


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The learning's options of ``path run``."""
    g = p.add_argument_group("iterative learning (a repeated path)")
    g.add_argument("--learn", type=int, metavar="N",
                   help="run the path up to N times, learning its repeatable error from each "
                   "run's tracker samples; stop early when converged or diverging")
    g.add_argument("--learned", type=Path, metavar="FILE",
                   help="a learned correction (--learned-out) fed forward: alone, one run "
                   "without learning; with --learn, the learning goes on from it")
    g.add_argument("--learned-out", type=Path, metavar="FILE",
                   help="write the learned correction (JSON) after the runs")
    g.add_argument("--learn-gain", type=float, metavar="L",
                   help="the learning gain L in (0, 2) of a new learning (default 0.8)")
    g.add_argument("--learn-law", choices=("p", "inverse"),
                   help="the law of a new learning: p, the P-type law (default), or inverse: "
                   "an identifying run with a known excitation, then the norm-optimal "
                   "inverse of the identified plant; with --learned, the law to go on with "
                   "(default the file's; an inverse-law file keeps its plant)")
    g.add_argument("--inverse-reidentify", type=int, choices=(0, 1),
                   help="the inverse law of a new learning: 1 (default) identifies the plant "
                   "again after each run, from the excited run against every later run; "
                   "0: once, from the first pair")
    g.add_argument("--weighting", choices=("kalman", "none"),
                   help="the inverse law of a new learning: kalman (default) learns each "
                   "frequency by its Kalman gain against the tracker's noise; none: all of "
                   "the error, the running mean of the runs")
    g.add_argument("--weighting-detect", type=float, metavar="K",
                   help="the Kalman weighting of a new inverse-law learning: raise a "
                   "frequency's gain where a run's error exceeds K times what the weighting "
                   "predicted (covariance matching; default 3; inf: off)")
    g.add_argument("--weighting-window-s", type=float, metavar="S",
                   help="the Kalman weighting of a new inverse-law learning: a gain per S "
                   "seconds of the path (a short-time FFT) rather than one per frequency "
                   "over the whole path (default 1; 0: one per frequency over the path)")
    g.add_argument("--weighting-detect-fell", type=int, choices=(0, 1), metavar="0|1",
                   help="the Kalman weighting of a new inverse-law learning: 1 raises a "
                   "frequency's gain (--weighting-detect) only where the last run's update "
                   "made its error fall (default 1; 0: wherever it exceeds the prediction)")
    g.add_argument("--learn-cutoff", type=float, metavar="HZ",
                   help="the learning filter's cut-off of a new learning (default 6 Hz, below "
                   "the arm's first mode)")
    g.add_argument("--learn-converged", type=float, default=5.0, metavar="PCT",
                   help="converged when a run lowers the best measured error by less than "
                   "PCT %% (default 5)")
    g.add_argument("--learn-diverged", type=float, default=25.0, metavar="PCT",
                   help="stop and roll back when the measured error grows more than PCT %% "
                   "above the best run's (default 25)")


def wants_learning(args: argparse.Namespace) -> bool:
    """Any learning option given (checked, so a lone ``--learned-out`` is refused)."""
    if args.learn is not None and args.learn < 1:
        raise CommandError(f"--learn must be ≥ 1 run, got {args.learn}")
    if args.learned_out is not None and args.learn is None:
        raise CommandError("--learned-out needs --learn N: nothing is learned without it")
    tuned = args.learn_gain is not None or args.learn_cutoff is not None
    if tuned and (args.learn is None or args.learned is not None):
        raise CommandError("--learn-gain/--learn-cutoff set up a new learning (--learn N "
                           "without --learned: a learning continued from a file keeps its "
                           "settings)")
    inverse = args.inverse_reidentify is not None or args.weighting is not None \
        or args.weighting_detect is not None or args.weighting_window_s is not None \
        or args.weighting_detect_fell is not None
    if inverse and (args.learn is None or args.learned is not None
                    or args.learn_law != "inverse"):
        raise CommandError("--inverse-reidentify/--weighting set up the inverse law of a new "
                           "learning (--learn N --learn-law inverse without --learned: a "
                           "learning continued from a file keeps its settings)")
    if args.learn_law is not None and args.learn is None:
        raise CommandError("--learn-law needs --learn N: it is the law of a learning")
    if args.learn_law == "inverse" and args.learned is None and args.learn < 2 \
            and args.learned_out is None:
        raise CommandError(f"--learn-law inverse needs --learn N ≥ 2, got {args.learn}: the "
                           "first run's update adds a known excitation, the second run "
                           "identifies the plant from it (or keep the learning with "
                           "--learned-out FILE and go on with --learned FILE --learn N)")
    return args.learn is not None or args.learned is not None


def _kalman(args: argparse.Namespace) -> Any:
    """The Kalman weighting's settings of ``--weighting-detect``/``--weighting-window-s``/
    ``--weighting-detect-fell`` (None: none given, the defaults)."""
    from plugcell.compensation.tracking import DEFAULT_WEIGHTING

    given = {name: value for name, value in (("detect", args.weighting_detect),
                                             ("window_s", args.weighting_window_s),
                                             ("detect_fell", args.weighting_detect_fell))
             if value is not None}
    if not given:
        return None
    if args.weighting == "none":
        raise CommandError("--weighting-detect/--weighting-window-s/--weighting-detect-fell "
                           "set up the Kalman weighting: not with --weighting none")
    try:
        return dataclasses.replace(DEFAULT_WEIGHTING, **given)
    except ValueError as exc:
        raise CommandError(f"--weighting-detect/--weighting-window-s: {exc}") from None


def _calibration_id(args: argparse.Namespace, calibration: Any) -> tuple[str, bool]:
    if args.params is None:
        return "nominal", False
    digest = hashlib.sha256(Path(args.params).read_bytes()).hexdigest()
    return f"sha256:{digest}", getattr(calibration, "residual_model", None) is not None


def _session(args: argparse.Namespace, path: Any, name: str, options: Any,
             calibration: Any) -> tuple[Any, Any, list[dict[str, Any]]]:
    """The context of this run, the learning (fresh or from ``--learned``; a continued
    one's stop rule judges the new runs against the file's best run, as an uninterrupted
    learning would) and the runs the file recorded."""
    from plugcell.compensation.tracking.learning import IterativeLearning
    from plugcell.compensation.tracking.repeat import RepeatedLearning, StopRule
    from plugcell.io.learned_paths import LearnedFileError, load_learned
    from plugcell.sim.path_learning import learned_context, learning_settings

    cal, residual = _calibration_id(args, calibration)
    try:
        context = learned_context(path, name, options, cal, residual)
        rule = StopRule(converged_rel=args.learn_converged / 100,
                        diverged_rel=args.learn_diverged / 100)
    except ValueError as exc:
        raise CommandError(f"{args.path or args.program}: {exc}" if "StopRule" not in str(exc)
                           else f"--learn-converged/--learn-diverged: {exc}") from None
    before: list[dict[str, Any]] = []
    best = None
    if args.learned is not None:
        try:
            file = load_learned(args.learned)
        except LearnedFileError as exc:
            raise CommandError(str(exc)) from None
        why = file.context.mismatch(context)
        if why is not None:
            raise CommandError(f"{args.learned}: cannot be used for this run: {why}")
        learning, before = file.learning, file.runs
        if args.learn is not None:
            best = file.best
            try:
                learning = file.continued(args.learn_law)
            except ValueError as exc:
                by = "" if args.learn_law is None else f" by the law {args.learn_law}"
                raise CommandError(f"{args.learned}: cannot be continued{by}: {exc}") from None
    else:
        kalman = _kalman(args)
        try:
            settings = learning_settings(options, args.learn_gain, args.learn_cutoff,
                                         args.learn_law or "p", args.inverse_reidentify,
                                         args.weighting, kalman)
        except ValueError as exc:
            raise CommandError(f"--learn-gain/--learn-cutoff: {exc}") from None
        learning = IterativeLearning(context.duration_s, settings)
    repeated = RepeatedLearning(learning, rule)
    repeated.resume(best)
    return context, repeated, before


HEADER = ("run  perp 3σ mm  perp max mm  along 3σ mm  along max mm  tracker rms mm"
          "  change mm  without tracking")


def _row(k: int, run: Any, record: Any) -> dict[str, Any]:
    acc = run.accuracy.of(-1)
    mm = 1e3
    return {"run": k, "perpendicular_3sigma_mm": acc.perpendicular_3sigma * mm,
            "perpendicular_max_mm": acc.perpendicular_max * mm,
            "along_3sigma_mm": acc.along_3sigma * mm, "along_max_mm": acc.along_max * mm,
            "tracker_rms_mm": math.nan if record is None else record.rms_m * mm,
            "tracker_max_mm": math.nan if record is None else record.max_m * mm,
            "measured_share": math.nan if record is None else record.measured,
            "change_max_mm": math.nan if record is None else record.change_m * mm,
            "verdict": "ended early" if record is None else record.verdict,
            "law": None if record is None else record.law or None,
            "reason": run.ended if record is None else record.reason,
            "windows_without_tracking": [
                [round(w.start_s, 3), None if w.end_s is None else round(w.end_s, 3),
                 w.reason] for w in run.windows]}


def _print_row(r: dict[str, Any]) -> None:
    wins = ", ".join(f"{a:.2f}–{'end' if b is None else f'{b:.2f}'} s"
                     for a, b, _ in r["windows_without_tracking"]) or "–"
    change = "–" if math.isnan(r["change_max_mm"]) else f"{r['change_max_mm']:.4f}"
    print(f"{r['run']:>3}  {r['perpendicular_3sigma_mm']:>10.4f}  "
          f"{r['perpendicular_max_mm']:>11.4f}  {r['along_3sigma_mm']:>11.4f}  "
          f"{r['along_max_mm']:>12.4f}  {r['tracker_rms_mm']:>14.4f}  {change:>9}  {wins}",
          flush=True)


def _ending(rows: list[dict[str, Any]], runs: int) -> tuple[str, int]:
    """The closing message and the exit status."""
    last = rows[-1]
    learned = [r for r in rows if r["verdict"] in ("learned", "converged")]
    if last["verdict"] == "ended early":
        return f"run {last['run']} ended early: {last['reason']}; not learned from", 1
    if not learned:
        return (f"no run could be learned from (beam broken in every run?): "
                f"{last['reason']}", 1)
    if last["verdict"] == "diverged":
        return f"diverged at run {last['run']}: {last['reason']}", 1
    if last["verdict"] == "converged":
        return f"converged at run {last['run']}: {last['reason']}", 0
    return f"{runs} runs learned; not converged yet (more runs: --learned FILE --learn N)", 0


def run_learning(args: argparse.Namespace, path: Any, name: str, options: Any,
                 calibration: Any, results: Any) -> int:
    """``path run`` with ``--learn`` and/or ``--learned`` (module docstring); ``results``
    has ``path run``'s ``result_document(run, name)`` and ``print_result(args, run,
    name)`` (:mod:`.path`, which imports this module)."""
    from plugcell.io.learned_paths import LearnedFile, run_entries, save_learned
    from plugcell.sim.path_learning import repeat_path

    context, repeated, before = _session(args, path, name, options, calibration)
    runs = args.learn if args.learn is not None else 1
    if args.learn is None:
        return _feed_forward(args, path, name, options, calibration, repeated, results)
    rows: list[dict[str, Any]] = []
    bars: dict[int, ProgressBar] = {}

    def progress(k: int, fraction: float) -> None:
        if not args.json:
            bars.setdefault(k, ProgressBar(f"run {k}/{runs} {name}"))(round(100 * fraction),
                                                                        100)

    def on_run(k: int, done: Any) -> None:
        rows.append(_row(k, done.run, done.record))
        if not args.json:
            if k == 1:
                print(HEADER)
            _print_row(rows[-1])

    try:
        done = repeat_path(path, options, repeated, runs, first_seed_run=len(before) + 1,
                           calibration=calibration, on_run=on_run, progress=progress)
    except ValueError as exc:
        raise CommandError(f"{args.path or args.program}: {exc}") from None
    message, status = _ending(rows, runs)
    holes = repeated.never_measured()
    learned = any(r["verdict"] in ("learned", "converged", "diverged") for r in rows)
    document = {"path": name, "runs": rows, "ending": message,
                "never_measured_s": [[round(a, 3), round(b, 3)] for a, b in holes]}
    if args.learned_out is not None and learned:
        save_learned(args.learned_out, LearnedFile(
            context, repeated.learning, run_entries(repeated.records, before),
            best=repeated.best))
    if args.out:
        out = results.result_document(done[-1].run, name)
        Path(args.out).write_text(json.dumps({**out, "learning": _strict(document)}) + "\n")
    if args.json:
        print(json.dumps(_strict(document)))
    else:
        _report(message, holes, args, repeated, learned)
    if status:
        print(message, file=sys.stderr)
    return status


def _strict(x: Any) -> Any:
    """NaN → None (strict JSON)."""
    from plugcell.io.json_fields import strict

    return strict(x)


def _report(message: str, holes: list[tuple[float, float]], args: argparse.Namespace,
            repeated: Any, learned: bool) -> None:
    print(message)
    for a, b in holes:
        print(f"never measured in any learned run: {a:.3f}–{b:.3f} s of the path (the "
              "learned offset there is only what the filter spreads into it)")
    if args.learned_out is not None:
        if learned:
            u = float(np.abs(repeated.learning.u).max()) * 1e3
            print(f"learned correction: {args.learned_out} ({repeated.learning.steps} "
                  f"updates, largest offset {u:.3f} mm)")
        else:
            print(f"nothing learned: {args.learned_out} not written")


def _feed_forward(args: argparse.Namespace, path: Any, name: str, options: Any,
                  calibration: Any, repeated: Any, results: Any) -> int:
    """One run with the file's offset fed forward (no learning): ``path run``'s table."""
    from plugcell.sim.path_run import run_path

    bar = ProgressBar(f"running {name} (learned correction)")
    try:
        run = run_path(path, options, None if args.json else
                       (lambda f: bar(round(100 * f), 100)), calibration,
                       learned=repeated.feedforward(options.settle_s))
    except ValueError as exc:
        raise CommandError(f"{args.path or args.program}: {exc}") from None
    lr = repeated.learning
    if not args.json:
        print(f"learned correction: {args.learned} ({lr.steps} updates, largest offset "
              f"{float(np.abs(lr.u).max()) * 1e3:.3f} mm), fed forward, not learning")
    return results.print_result(args, run, name)
