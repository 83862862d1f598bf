"""``plugcell demo``: the thesis end to end over services, on the embedded default.

Simulated devices, each its own service process, Zenoh peer mode on loopback, SQLite
journals; the cell controller wires them from the cell file; robot programs of the
shipped library do the work (:mod:`plugcell.apps.demo.services`):

1. calibration of the Smart H4 carrying 36 kg (8.2) by ``calibration.pdl``;
2. the two-stage compensation test (8.3) by ``comp_test.pdl``;
3. the stabiliser demonstration (8.4) with a second robot sharing the tracker.

It prints a table beside the thesis's figures, writes ``demo.json``, ``report.html``
and the journals under ``--out``.
"""

from __future__ import annotations

import argparse
import html
import json
import sys
from pathlib import Path
from typing import Any

from plugcell.apps.cli import CommandError


def configure(p: argparse.ArgumentParser) -> None:
    """Add the ``demo`` options to its parser (declared in :mod:`plugcell.apps.cli`)."""
    p.description = __doc__.split("\n\n")[0]
    p.add_argument("--out", type=Path, default=Path("out/demo"),
                   help="directory for the files it writes (default: out/demo)")
    p.add_argument("--fast", action="store_true",
                   help="fewer poses and targets, faster simulated clock (what CI runs)")
    p.add_argument("--seed", type=int, default=0, help="seed of the twins (default: 0)")
    p.add_argument("--speed", type=float, default=None,
                   help="simulated seconds per real second (default 20; --fast 50)")
    p.add_argument("--link", choices=("serial", "rsi"), default="serial",
                   help="how H4's programs reach the arm: serial (the simulated controller "
                   "runs them, default) or rsi (they run on the PC and every move streams "
                   "over KUKA RSI to the twin, in real time: step 1 only)")
    p.add_argument("--dynamics", action="store_true",
                   help="serial link: the simulated controllers' arms move in time on the "
                   "dynamic twin (slower; default: at the target at once)")
    p.add_argument("--json", action="store_true", help="print the final table as JSON")
    p.set_defaults(func=_demo)


def _demo(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from plugcell.apps.commands.progress import ProgressBar
    from plugcell.apps.demo.processes import ServiceStartError
    from plugcell.apps.demo.services import DemoConfig, DemoError, run_demo

    cfg = (DemoConfig.fast if args.fast else DemoConfig.full)(args.seed, args.link)
    if args.dynamics:
        try:
            cfg = replace(cfg, dynamics=True)
        except ValueError as exc:
            raise CommandError(f"--dynamics: {exc}") from None
    if args.speed is not None:
        if not args.speed > 0:
            raise CommandError(f"--speed must be positive, not {args.speed}")
        try:
            cfg = replace(cfg, speed=args.speed)
        except ValueError as exc:
            raise CommandError(f"--speed: {exc}") from None

    def say(text: str) -> None:
        if not args.json:
            print(text, flush=True)
        else:
            print(text, file=sys.stderr, flush=True)

    try:
        stream = sys.stderr if args.json else sys.stdout
        result = run_demo(cfg, args.out.resolve(), say,
                          progress=lambda label: ProgressBar(f"   {label}", stream=stream))
    except (DemoError, ServiceStartError) as exc:
        raise CommandError(f"demo: {exc}") from None
    report = args.out / "report.html"
    report.write_text(_html(result, _plot(result, args.out / "errors.png")))
    if args.json:
        print(json.dumps(result, indent=2, default=float))
        return 0
    print(_table(result))
    print(f"done in {result['wall_time_s']:.0f} s wall; {args.out}/demo.json, {report}, "
          f"journals: {', '.join(result['journal'])}")
    return 0


def _rows(r: dict[str, Any]) -> list[tuple[str, str, str]]:
    c = r["calibration"]
    rows = [
        ("calibration: validation mean (mm), model 5, 36 kg", f"{c['validation']['mean_mm']:.3f}",
         "0.363 (Table 8-3)"),
        ("calibration: validation max (mm)", f"{c['validation']['max_mm']:.3f}", "—"),
        ("identification time (s)", f"{c['identification_s']:.2f}", "minutes (Matlab)"),
    ]
    if "compensation" not in r:  # over RSI: step 1 only
        return [*rows, ("calibration: campaign wall time (s)", f"{c['wall_s']:.1f}", "—")]
    k, d = r["compensation"], r["demonstration"]
    return [
        *rows,
        ("8.3: 3σ position after model (mm)", f"{k['sigma3_position_mm']['model']:.3f}",
         "0.87 (Table 8-5)"),
        ("8.3: 3σ position after sensor (mm)", f"{k['sigma3_position_mm']['sensor']:.3f}",
         "0.12 (Table 8-5)"),
        ("8.3: tracker corrections a point", f"{k['iterations_per_point']:.2f}", "2.14"),
        ("8.3: simulated time a point (s)", f"{k['simulated_s_per_point']:.1f}", "—"),
        ("8.4: mean position, nominal (mm)", f"{d['mean_position_mm']['initial']:.2f}", "—"),
        ("8.4: mean position, model (mm)", f"{d['mean_position_mm']['model']:.3f}", "—"),
        ("8.4: mean position, sensor (mm)", f"{d['mean_position_mm']['sensor']:.3f}", "≤ 0.1"),
        ("8.4: tracker measurements for H4 / KUKA",
         f"{d['tracker_served']['robot1']} / {d['tracker_served']['robot2']}", "—"),
        ("8.4: tracker queue wait H4 / KUKA (s)",
         f"{d['tracker_wait_s']['robot1']:.2f} / {d['tracker_wait_s']['robot2']:.2f}", "—"),
    ]


def _table(result: dict[str, Any]) -> str:
    rows = [("", "plugcell", "thesis"), *_rows(result)]
    w = [max(len(r[i]) for r in rows) for i in range(3)]
    return "\n".join(f"{a:<{w[0]}}  {b:>{w[1]}}  {c}" for a, b, c in rows)


def _plot(result: dict[str, Any], path: Path) -> str | None:
    """Position error per target of 8.3 and 8.4, each stage (PNG); None without
    matplotlib (``pip install plugcell[plots]``)."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return None
    if "compensation" not in result:  # over RSI: no per-target errors
        return None
    fig, axes = plt.subplots(2, 1, figsize=(9, 6.5))
    for ax, (key, title) in zip(axes, (("compensation", "8.3: line test"),
                                       ("demonstration", "8.4: stabiliser holes")),
                                strict=True):
        for stage, errors in result[key]["errors_mm"].items():
            ax.plot(range(1, len(errors) + 1), errors, "o-", ms=3, label=stage,
                    color={"nominal": "C3", "model": "C0", "sensor": "C2"}.get(stage))
        ax.set_yscale("log")
        ax.axhline(0.1, color="grey", ls=":", lw=1, label="0.1 mm")
        ax.set_title(title)
        ax.set_xlabel("target")
        ax.set_ylabel("position error (mm)")
        ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path.name


def _html(result: dict[str, Any], plot: str | None = None) -> str:
    body = "".join(f"<tr><td>{html.escape(a)}</td><td>{html.escape(b)}</td>"
                   f"<td>{html.escape(c)}</td></tr>" for a, b, c in _rows(result))
    return ("<!doctype html><meta charset=utf-8><title>plugcell demo</title>"
            "<style>body{font-family:sans-serif;margin:2em}td,th{padding:.3em 1em;"
            "border-bottom:1px solid #ddd}</style><h1>plugcell demo — thesis chapter 8 "
            "over services</h1><table><tr><th></th><th>plugcell</th><th>thesis</th></tr>"
            f"{body}</table>"
            + (f"<h2>Position error per target</h2><img src='{html.escape(plot)}' "
               "alt='position error per target, each stage'>" if plot else
               "<p>(pip install plugcell[plots] for the plots)</p>" if "compensation" in result
               else "")
            + "<h2>Everything</h2><pre>"
            f"{html.escape(json.dumps(result, indent=2, default=float))}</pre>")
