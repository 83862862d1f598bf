"""Table, figures and results page of the 8.3 experiment (ours beside the thesis's).

:func:`format_table` prints Table 8-5 and the other 8.3 figures as text;
:func:`write_pages` writes ``8.3.md``, ``8.3.json`` and the figures of Figs.
8-12 … 8-17 (matplotlib, Agg backend) into a directory (``plugcell reproduce 8.3 --out-dir``).  The
thesis's figures did not survive the text extraction, so each of ours is shown
with the numbers the thesis gives for it.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["FIGURES", "format_table", "write_pages"]

STAGE_NAMES = {"initial": "(0) initial", "model": "(1) model-based", "sensor": "(2) sensor-based"}

#: Figure files and what the thesis says about the figure they mirror.
FIGURES: dict[str, tuple[str, str]] = {
    "8.3-fig-8-12.png": ("Fig. 8-12 Initial position errors (36 kg)",
                         "X biased positive, Z negative; 3σ = 6.50 mm"),
    "8.3-fig-8-13.png": ("Fig. 8-13 Residual position errors after the two stages",
                         "model: within ±0.7 mm; tracker: within ±0.1 mm; 3σ 0.87 / 0.12 mm"),
    "8.3-fig-8-14.png": ("Fig. 8-14 Correcting the position to ±0.08 mm with the tracker",
                         "1 s readings at t = −2, −1, 6 s; 50 ms readings t = 0…5 s; "
                         "the 5 s and 6 s readings differ by 0.02 mm"),
    "8.3-fig-8-15.png": ("Fig. 8-15 Correcting the orientation to ±0.05° with the tracker",
                         "the 5 s and 6 s readings differ by 0.015°"),
    "8.3-fig-8-16.png": ("Fig. 8-16 Straightness in Z along the Y lines",
                         "bands 1.32 → 0.43 → 0.16 mm"),
    "8.3-fig-8-17.png": ("Fig. 8-17 Straightness in X along the Y lines",
                         "bands 0.67 → 0.44 → 0.13 mm"),
    "8.3-iterations.png": ("Tracker iterations per point, with and without the model stage",
                           "~6 iterations, ~6 s with the model; > 11 s without"),
}


def _f(x: Any, fmt: str = "{:.3f}") -> str:
    if x is None:
        return "—"
    if isinstance(x, str):
        return x
    if isinstance(x, float) and math.isnan(x):
        return "—"
    return fmt.format(x)


def _triple(v: Any, fmt: str = "{:.3f}") -> str:
    return "/".join(_f(x, fmt) for x in v) if v is not None else "—"


def _rows(result: dict[str, Any]) -> list[tuple[str, str, str]]:
    """(quantity, ours, thesis) rows of the summary table."""
    th = result["thesis"]
    rows: list[tuple[str, str, str]] = []
    for s in ("initial", "model", "sensor"):
        ours, ref = result["table_8_5"][s], th["table_8_5"][s]
        name = STAGE_NAMES[s]
        rows += [
            (f"{name}: mean ‖Δp‖ / σ (mm)",
             f"{_f(ours['mean_dp_mm'])} / {_f(ours['std_dp_mm'])}",
             f"{_f(ref['mean_dp_mm'], '{:.2f}')} / {_f(ref['std_dp_mm'], '{:.2f}')}"),
            (f"{name}: mean Δφx/Δφy/Δφz (°)", _triple(ours["mean_dphi_deg"], "{:.4f}"),
             _triple(ref["mean_dphi_deg"])),
            (f"{name}: σ Δφx/Δφy/Δφz (°)", _triple(ours["std_dphi_deg"], "{:.4f}"),
             _triple(ref["std_dphi_deg"])),
        ]
    for s in ("initial", "model", "sensor"):
        rows.append((f"3σ position, {STAGE_NAMES[s]} (mm)",
                     _f(result["sigma3_position_mm"][s]),
                     _f(th["sigma3_position_mm"][s], "{:.2f}")))
    for s in ("initial", "model", "sensor"):
        rows.append((f"3σ orientation, {STAGE_NAMES[s]} (°)",
                     _f(result["sigma3_orientation_deg"][s], "{:.4f}"),
                     _f(th["sigma3_orientation_deg"][s], "{:.2f}")))
    for s in ("initial", "model", "sensor"):
        b, ref = result["straightness"][s]["band_mm"], th["straightness_band_mm"][s]
        rows.append((f"straightness band Z / X, {STAGE_NAMES[s]} (mm)",
                     f"{_f(b['z'])} / {_f(b['x'])}", f"{ref['z']:.2f} / {ref['x']:.2f}"))
    rows.append(("3σ position after the tracker, without the model stage (mm)",
                 _f(result["sensor_without_model"]["sigma3_position_mm"]), "—"))
    it, tp = result["iterations_mean"], result["time_per_point_s"]
    rows += [
        ("tracker iterations per point, with model", _f(it["with_model"], "{:.2f}"),
         _f(th["iterations_mean"]["with_model"], "{}")),
        ("tracker iterations per point, without model", _f(it["without_model"], "{:.2f}"), "—"),
        ("simulated time per point, with model (s)", _f(tp["with_model"], "{:.2f}"),
         _f(th["time_per_point_s"]["with_model"], "{:.0f}")),
        ("simulated time per point, without model (s)", _f(tp["without_model"], "{:.2f}"),
         str(th["time_per_point_s"]["without_model"])),
    ]
    return rows


def format_table(result: dict[str, Any]) -> str:
    """Table 8-5 and the other 8.3 figures as aligned text, ours beside the thesis's."""
    rows = _rows(result)
    w0 = max(len(r[0]) for r in rows)
    w1 = max(12, *(len(r[1]) for r in rows))
    cal = result["calibration"]
    lines = [
        f"Thesis 8.3 on the twin (seed {result['seed']}{', fast' if result['fast'] else ''}): "
        f"{result['lines']} lines × {result['points_per_line']} points, 36 kg, model "
        f"{cal['model']} from {cal['poses']} poses "
        f"(calibration mean {_f(cal['mean_position_mm'])} mm, validation "
        f"{_f(cal['validation_mean_position_mm'])} mm)",
        f"{'':{w0}s}  {'twin':>{w1}s}  thesis",
    ]
    lines += [f"{a:{w0}s}  {b:>{w1}s}  {c}" for a, b, c in rows]
    met = result["targets_met"]
    lines.append("targets: " + ", ".join(f"{k} {'yes' if v else 'NO'}" for k, v in met.items()))
    fails = (result["correction"]["with_model"]["failures"]
             + result["correction"]["without_model"]["failures"])
    if fails:
        lines.append(f"correction failures: {len(fails)} (first: {fails[0]['message']})")
    return "\n".join(lines)


# ----------------------------------------------------------------------------- figures
def _plt() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _fig_errors(result: dict[str, Any], stages: list[str], path: Path, title: str) -> None:
    plt = _plt()
    fig, axes = plt.subplots(len(stages), 1, figsize=(8, 2.8 * len(stages)), squeeze=False)
    P = result["points_per_line"]
    for ax, s in zip(axes[:, 0], stages, strict=True):
        e = np.asarray(result["errors"][s]["dp_mm"])
        idx = np.arange(1, len(e) + 1)
        for c, lab in enumerate("XYZ"):
            ax.plot(idx, e[:, c], marker=".", lw=0.8, label=f"Δ{lab}")
        for k in range(1, result["lines"]):
            ax.axvline(k * P + 0.5, color="0.85", lw=0.8)
        ax.axhline(0.0, color="0.5", lw=0.5)
        ax.set_ylabel("mm")
        ax.set_title(f"{STAGE_NAMES[s]}: 3σ = {result['sigma3_position_mm'][s]:.3f} mm",
                     fontsize=9)
        ax.legend(fontsize=7, ncol=3, loc="upper right")
    axes[-1, 0].set_xlabel("target point (lines separated by grey bars)")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _fig_history(result: dict[str, Any], key: str, unit: str, tol: float, path: Path,
                 title: str) -> None:
    """Figs. 8-14/8-15: verification (1 s) and loop (50 ms) readings of the example point.

    As in the thesis's figures, the 1 s verification readings sit at t = −2 s (nominal)
    and −1 s (model-based) and one second after the loop's last reading; the loop's
    readings are at their simulated times from the start of the correction.
    """
    plt = _plt()
    ex = result["example"]
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8), sharey=True)
    for ax, which in zip(axes, ("with_model", "without_model"), strict=True):
        h = ex[which]
        pts: list[tuple[float, list[float], bool]] = []
        if "initial" in h["verify"]:
            pts.append((-2.0, h["verify"]["initial"][key], True))
        if "model" in h["verify"]:
            pts.append((-1.0, h["verify"]["model"][key], True))
        t = 0.0
        for step in h["loop"]:
            pts.append((t, step[key], False))
            t = step["clock_s"]
        last = pts[-1][0] if h["loop"] else 0.0
        if "sensor" in h["verify"]:
            pts.append((last + 1.0, h["verify"]["sensor"][key], True))
        x = np.array([p[0] for p in pts])
        y = np.array([p[1] for p in pts])
        one = np.array([p[2] for p in pts])
        for c, lab in enumerate("xyz"):
            line, = ax.plot(x, y[:, c], lw=0.8, label=f"Δ{lab}")
            ax.plot(x[~one], y[~one, c], "o", ms=3, color=line.get_color())
            ax.plot(x[one], y[one, c], "s", ms=6, mfc="none", color=line.get_color())
        ax.axhspan(-tol, tol, color="0.9", label=f"±{tol:g} {unit}")
        ax.set_yscale("symlog", linthresh=tol / 4)
        ax.set_title(f"{'with' if which == 'with_model' else 'without'} the model stage: "
                     f"{h['iterations']} iteration(s), {_f(h['time_s'], '{:.2f}')} s",
                     fontsize=9)
        ax.set_xlabel("t (s): □ 1 s readings, ● 50 ms loop readings")
    axes[0].set_ylabel(unit)
    axes[0].legend(fontsize=7, loc="upper right")
    fig.suptitle(f"{title} — point {ex['point']} (the most iterations with the model)",
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _fig_straightness(result: dict[str, Any], axis: str, path: Path, title: str) -> None:
    plt = _plt()
    fig, axes = plt.subplots(3, 1, figsize=(7, 8), sharex=True)
    P, spacing = result["points_per_line"], result["config"]["spacing_m"] * 1e3
    y = (np.arange(P) - (P - 1) / 2.0) * spacing
    for ax, s in zip(axes, ("initial", "model", "sensor"), strict=True):
        st = result["straightness"][s]
        D = np.asarray(st["deviations_mm"][axis])
        for k, d in enumerate(D):
            ax.plot(y, d, marker=".", lw=0.8, label=f"line {k + 1}")
        th = result["thesis"]["straightness_band_mm"][s][axis]
        ax.set_title(f"{STAGE_NAMES[s]}: band {st['band_mm'][axis]:.3f} mm "
                     f"(thesis {th:.2f} mm)", fontsize=9)
        ax.set_ylabel(f"Δ{axis.upper()} (mm)")
    axes[-1].set_xlabel("Y (mm)")
    axes[0].legend(fontsize=7, ncol=3)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _fig_iterations(result: dict[str, Any], path: Path, title: str) -> None:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7, 3.2))
    data = result["correction"]
    its = [[i for i in data[w]["iterations"] if i is not None]
           for w in ("with_model", "without_model")]
    top = max([*its[0], *its[1], 1])
    bins = np.arange(-0.5, top + 1.5)
    ax.hist(its, bins=bins, label=[
        f"with model (mean {result['iterations_mean']['with_model']:.2f})",
        f"without model (mean {result['iterations_mean']['without_model']:.2f})"])
    ax.set_xlabel("corrective moves per point")
    ax.set_ylabel("points")
    ax.legend(fontsize=8)
    ax.set_title(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# ----------------------------------------------------------------------------- page
def _page(result: dict[str, Any]) -> str:
    rows = _rows(result)
    cal, cfg = result["calibration"], result["config"]
    corr = cfg["correction"]
    out = [
        "# Thesis 8.3 on the digital twin — two-stage error compensation",
        "",
        "Generated by `plugcell reproduce 8.3 --out-dir docs/results` "
        "(`plugcell.apps.reproduce.compensation_8_3.run` + `write_pages`); "
        f"seed {result['seed']}{', fast layout' if result['fast'] else ''}. "
        "Method, assumptions and the algorithms: [docs/compensation.md](../compensation.md).",
        "",
        "## Setup",
        "",
        f"* Smart H4 twin carrying {cfg['payload_kg']:g} kg off the flange centre; "
        f"model {cal['model']} identified from a simulated {cal['poses']}-pose campaign "
        f"({cal['parameters']} parameters; mean position residual "
        f"{_f(cal['mean_position_mm'])} mm on the calibration poses, "
        f"{_f(cal['validation_mean_position_mm'])} mm on {cal['validation_poses']} "
        f"independent poses, nominal {_f(cal['validation_nominal_mean_position_mm'])} mm).",
        f"* {result['lines']} lines parallel to Y, {result['points_per_line']} points "
        f"{cfg['spacing_m'] * 1e3:g} mm apart, x ∈ {list(cfg['line_x_m'])} m, "
        f"z ∈ {list(cfg['line_z_m'])} m (the thesis's Fig. 8-9 is lost; this is our "
        "layout inside the calibration volume).",
        "* Every stage verified by a 1 s tracker reading; the loop uses "
        f"{corr['duration_s'] * 1e3:g} ms readings and stops at ‖Δp‖ < "
        f"{corr['position_tol_m'] * 1e3:g} mm and ‖Δφ‖ < {corr['orientation_tol_deg']:g}°.",
        "* Simulated time per corrective iteration: tracker reading + move (joint travel at "
        f"40°/s + {cfg['timing']['correction_settle_s']:g} s settling) + "
        f"{corr['overhead_s']:g} s controller-side overhead — both constants are "
        "assumptions sized from the thesis's own ~1 iteration/s on the C3G (8.3.3); the "
        "iteration counts are the twin's.",
        "",
        "## Results beside the thesis",
        "",
        "| quantity | twin | thesis |",
        "|---|---|---|",
    ]
    out += [f"| {a} | {b} | {c} |" for a, b, c in rows]
    met = result["targets_met"]
    out += [
        "",
        "Issue-4 targets on the twin: " + ", ".join(
            f"{k}: **{'met' if v else 'not met'}**" for k, v in met.items()) + ".",
        "",
        "3σ position = mean + 3σ of ‖Δp‖ (reproduces all of the thesis's position figures); "
        "3σ orientation = 3·√(σx² + σy² + σz²) (reproduces its 0.44°); the other variant of "
        "each is in `8.3.json`.  Orientation components are the rotation vector about the "
        "robot base axes.",
        "",
        "Simulator-only check (`truth_check` in the JSON): the true T-MAC pose, not the "
        "tracker's reading, against the target — 3σ position "
        + " → ".join(_f(result["truth_check"][s]["sigma3_position_mm"])
                     for s in ("initial", "model", "sensor")) + " mm.",
        "",
        "## Reading the numbers",
        "",
        *_reading(result),
        "",
        "## Figures",
        "",
    ]
    for name, (caption, thesis) in FIGURES.items():
        out += [f"### {caption}", "", f"Thesis: {thesis}.", "", f"![{caption}]({name})", ""]
    return "\n".join(out)


def _reading(result: dict[str, Any]) -> list[str]:
    """Data-driven notes on where the twin and the thesis differ (honest, not tuned)."""
    cal, t85 = result["calibration"], result["table_8_5"]
    cw, cwo = result["correction"]["with_model"], result["correction"]["without_model"]
    moved = sum(1 for i in cw["iterations"] if i)
    return [
        f"* **Model stage.** Model 5 predicts this twin to {_f(cal['validation_mean_position_mm'])}"
        " mm (mean, independent poses); the thesis's real robot to 0.57 mm (Table 8-3).  The "
        f"model stage therefore leaves {_f(t85['model']['mean_dp_mm'])} mm on average here "
        "against the thesis's 0.39 mm: the twin's effects outside model 5 (link bending, "
        "encoder resolution, repeatability) are small or, at one fixed payload, absorbed by "
        "the identified parameters.  A real robot has effects the twin does not model "
        "(e.g. backlash, thermal drift, gear eccentricity; see docs/twin.md for what it "
        "does model).",
        f"* **Tracker stage with the model.** {moved} of {result['points']} points needed a "
        "corrective move at all: the model stage already put the others inside 0.08 mm / "
        "0.05° (measured with 50 ms readings).  The residual after the loop is set by the "
        "thresholds, the robot's repeatability and the 50 ms reading's noise, as in the "
        "thesis (its 0.06 mm mean; here "
        f"{_f(t85['sensor']['mean_dp_mm'])} mm).",
        f"* **Tracker stage without the model.** {_f(cwo['iterations_mean'], '{:.2f}')} "
        "corrective moves per point on average: one step δθ = J⁻¹Δx with the identified "
        "Jacobian takes the ~4–5 mm nominal error down to the repeatability, because the "
        "twin executes a small joint increment exactly up to encoder counts and a random "
        "repeatability error.  The twin has no backlash, stick-slip or oscillation after the "
        "stop; the thesis names the latter and the robot's resolution (8.3.2–8.3.3) — "
        "plausibly why its C3G loop needed ~6 iterations with the model and > 11 s without "
        "it.  The ordering (fewer iterations with the model stage) holds; the magnitudes "
        "are the twin's.",
        "* **Time per point** is iterations × the per-iteration time model (setup above); the "
        "time with the model stage is mostly the single 50 ms reading that confirms the point.",
    ]


def write_pages(result: dict[str, Any], out_dir: str | Path) -> list[str]:
    """Write ``8.3.md``, ``8.3.json`` and the figures into ``out_dir``; returns the paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    _fig_errors(result, ["initial"], out / "8.3-fig-8-12.png", FIGURES["8.3-fig-8-12.png"][0])
    _fig_errors(result, ["model", "sensor"], out / "8.3-fig-8-13.png",
                FIGURES["8.3-fig-8-13.png"][0])
    corr = result["config"]["correction"]
    _fig_history(result, "dp_mm", "mm", corr["position_tol_m"] * 1e3, out / "8.3-fig-8-14.png",
                 FIGURES["8.3-fig-8-14.png"][0])
    _fig_history(result, "dphi_deg", "°", corr["orientation_tol_deg"], out / "8.3-fig-8-15.png",
                 FIGURES["8.3-fig-8-15.png"][0])
    _fig_straightness(result, "z", out / "8.3-fig-8-16.png", FIGURES["8.3-fig-8-16.png"][0])
    _fig_straightness(result, "x", out / "8.3-fig-8-17.png", FIGURES["8.3-fig-8-17.png"][0])
    _fig_iterations(result, out / "8.3-iterations.png", FIGURES["8.3-iterations.png"][0])
    paths += [str(out / n) for n in FIGURES]
    (out / "8.3.md").write_text(_page(result) + "\n")
    (out / "8.3.json").write_text(json.dumps(result, indent=1, allow_nan=False) + "\n")
    paths += [str(out / "8.3.md"), str(out / "8.3.json")]
    return paths
