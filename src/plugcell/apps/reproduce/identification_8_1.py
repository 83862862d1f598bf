"""Thesis 8.1, Table 8-1: the errors of the thesis's simulation added to the nominal
Smart H4 (passive joints by the planar four-bar, noise-free) and identified back with
the 34-parameter model; the thesis's table beside ours (``plugcell reproduce 8.1``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

#: Thesis Table 8-1 (labels fixed, see ../shared/data/thesis_table_8_1.csv):
#: (link, field, input, thesis identified, thesis label); units 1e-3 m / 1e-3 rad.
TABLE_8_1: tuple[tuple[str, str, float | None, float | None, str], ...] = (
    ("1", "theta", -1, -0.9999, ""), ("1", "d", -4, -4.0000, ""), ("1", "a", -1, -1.0000, ""),
    ("1", "alpha", 4, 4.0000, ""),
    ("2", "theta", 3, 2.9905, ""), ("2", "a", -1, -1.0000, ""),
    ("2'", "theta", -2, -1.9992, "θ2' + θ3"), ("2'", "d", -3, None, "via d3"),
    ("2'", "a", -2, 2.0089, "a2' − a4'"), ("2'", "alpha", 3, 2.9962, ""),
    ("2'", "beta", 0, -0.0000046, ""),
    ("3'", "d", -2, None, "via d3"), ("3'", "a", -3, -3.0089, ""), ("3'", "alpha", 2, 2.0000, ""),
    ("3'", "beta", 0, -0.0000216, ""),
    ("4'", "d", -1, None, "via d3"), ("4'", "a", -4, None, "via a2'"),
    ("4'", "alpha", 1, None, "via α3 and θ4"), ("4'", "beta", 0, None, "via α3 and θ4"),
    ("3", "theta", 0, None, "via θ2'"), ("3", "d", 4, -2.0024, "d2' + d3' + d4' + d3"),
    ("3", "a", 1, 0.9949, ""), ("3", "alpha", -1, -0.8785, "α3 + α4'·sin 7°"),
    ("4", "theta", 3, 3.9888, "θ4 + α4'·cos 7°"), ("4", "d", 3, 3.0004, ""),
    ("4", "a", 2, 2.0000, ""), ("4", "alpha", -2, -2.0000, ""),
    ("5", "theta", 2, 2.0000, ""), ("5", "d", 2, 2.0000, ""), ("5", "a", 3, 3.0000, ""),
    ("5", "alpha", -3, -3.0000, ""),
    ("6", "theta", 1, 1.0000, ""), ("6", "d", 1, 1.0000, ""), ("6", "a", 4, 4.0000, ""),
    ("6", "alpha", -4, -4.0000, ""),
)
THESIS_8_1 = {"iterations": "4–7", "residual_mean_mm": 3.4e-5, "param_tolerance": 1e-5}


def reproduce_8_1(poses: int = 100, seed: int = 0) -> dict[str, Any]:
    """Run the 8.1 simulation; JSON-ready dict (keys ``iterations``, ``residual_mean_mm``,
    ``max_param_error`` and the table)."""
    from plugcell.calibration.simulation import simulated_identification
    from plugcell.io.robots import load_robot
    from plugcell.sim.twin.campaign import working_volume_joints
    from plugcell.sim.twin.profile import TwinProfile

    desc = load_robot("smart_h4")
    errors = {(lk, f): v * 1e-3 for lk, f, v, _, _ in TABLE_8_1 if v is not None}
    q = working_volume_joints(desc, TwinProfile.load("smart_h4"), poses,
                              np.random.default_rng(seed))
    rep = simulated_identification(desc, errors, q)
    ours = {r["key"]: r for r in rep.rows}
    dep = {r["key"]: r for r in rep.dependent}
    table = []
    for lk, f, inp, thesis, label in TABLE_8_1:
        key = f"{f}{lk}"
        row: dict[str, Any] = {"link": lk, "param": f, "input": inp, "thesis_identified": thesis,
                               "thesis_note": label}
        if key in ours:
            r = ours[key]
            row.update(identified=r["identified"] * 1e3, stands_for=r["stands_for"],
                       expected=r["expected"] * 1e3, error=r["error"] * 1e3)
        elif key in dep:
            row.update(identified=None, stands_for="identified via "
                       + ", ".join(dep[key]["identified_via"]), expected=None, error=None)
        table.append(row)
    extra = [{"key": r["key"], "name": r["name"], "identified": r["identified"] * 1e3,
              "error": r["error"] * 1e3} for r in rep.rows
             if r["key"] not in {f"{f}{lk}" for lk, f, *_ in TABLE_8_1}]
    res = rep.result
    return {
        "section": "8.1",
        "poses": poses,
        "seed": seed,
        "iterations": rep.iterations,
        "converged": rep.converged,
        "residual_mean_mm": rep.residual_mean_mm,
        "max_param_error": rep.max_param_error,
        "max_param_key": rep.max_param_key,
        "parameters_identified": len(rep.rows),
        "condition_number": res.statistics.condition_number if res.statistics else None,
        "history_mean_mm": [h.mean_position_mm for h in res.history]
        + [rep.residual_mean_mm],
        "thesis": THESIS_8_1,
        "units": "table values in 1e-3 m / 1e-3 rad",
        "table": table,
        "frames": extra,
    }


def _fmt(x: float | None, spec: str = "10.4f") -> str:
    return " " * int(spec.split(".")[0]) if x is None else format(x, spec)


def print_table(d: dict[str, Any]) -> None:
    print("Thesis 8.1 — simulated identification of the Smart H4 (noise-free, planar four-bar)")
    print(f"{d['poses']} poses in the working volume; {d['parameters_identified']} parameters; "
          f"κ = {d['condition_number']:.1f}")
    print(f"{'':24s}{'plugcell':>14s}{'thesis':>14s}")
    print(f"{'iterations':24s}{d['iterations']:>14d}{d['thesis']['iterations']:>14s}")
    print(f"{'mean residual (mm)':24s}{d['residual_mean_mm']:>14.2e}"
          f"{d['thesis']['residual_mean_mm']:>14.1e}")
    print(f"{'max parameter error':24s}{d['max_param_error']:>14.2e}{'< 1e-5':>14s}  "
          f"({d['max_param_key']})")
    print()
    print("Table 8-1 (units 1e-3 m, 1e-3 rad)")
    print(f"{'link':>5s} {'Δ':6s}{'input':>8s}{'thesis':>11s}{'plugcell':>11s}{'error':>11s}  "
          "stands for")
    for r in d["table"]:
        err = "" if r.get("error") is None else f"{r['error']:11.2e}"
        print(f"{r['link']:>5s} {r['param']:6s}{_fmt(r['input'], '8.0f')}"
              f"{_fmt(r['thesis_identified'], '11.4f')}{_fmt(r.get('identified'), '11.4f')}"
              f"{err:>11s}  {r.get('stands_for') or ''}")


def write_page(d: dict[str, Any], out: Path) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(5.5, 3.2))
    h = d["history_mean_mm"]
    ax.semilogy(range(len(h)), h, "o-", label="plugcell (exact four-bar)")
    ax.axhline(d["thesis"]["residual_mean_mm"], color="gray", ls="--",
               label="thesis final residual")
    ax.set_xlabel("iteration")
    ax.set_ylabel("mean position residual (mm)")
    ax.set_title("Thesis Fig. 8-1: convergence of the 34-parameter model")
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / "8.1-convergence.png", dpi=110)
    plt.close(fig)
    lines = [
        "# Thesis 8.1 — simulated identification, reproduced",
        "",
        "Generated by `plugcell reproduce 8.1 --out-dir docs/results` (do not edit by hand).",
        "",
        f"The errors of thesis Table 8-1 are added to the nominal Smart H4; {d['poses']} "
        "configurations in the working volume; the passive joints of the *truth* come from the "
        "exact planar four-bar (appendix C), noise-free; BASE and PROBE are identity and known. "
        f"The 34-parameter model identifies {d['parameters_identified']} parameters "
        "(BASE and PROBE frame included).",
        "",
        "| | plugcell | thesis |",
        "|---|---|---|",
        f"| iterations (‖Δg‖ < 1e-6) | {d['iterations']} | {d['thesis']['iterations']} |",
        f"| mean position residual | {d['residual_mean_mm']:.2e} mm | 3.4e-5 mm |",
        f"| largest parameter error | {d['max_param_error']:.2e} ({d['max_param_key']}) "
        "| < 1e-5 m / rad |",
        f"| condition number κ | {d['condition_number']:.1f} | 92.04 |",
        "",
        "![convergence](8.1-convergence.png)",
        "",
        "## Table 8-1 (units 1e-3 m, 1e-3 rad)",
        "",
        "*error* = identified combination − the same combination of the inputs, the "
        "combination linearised at the identified point (see docs/calibration.md).",
        "",
        "| link | Δ | input | thesis | plugcell | error (1e-3 m / rad) | stands for |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in d["table"]:
        ident = "" if r.get("identified") is None else f"{r['identified']:.4f}"
        err = "" if r.get("error") is None else f"{r['error']:.2e}"
        th = "" if r["thesis_identified"] is None else f"{r['thesis_identified']:.4f}"
        inp = "" if r["input"] is None else f"{r['input']:g}"
        lines.append(f"| {r['link']} | {r['param']} | {inp} | {th} | {ident} | {err} | "
                     f"{r.get('stands_for') or ''} |")
    lines += [
        "",
        "Differences from the thesis's table, explained:",
        "",
        "* **Δd3** stands for Δd2' + Δd3' + Δd4' + Δd3 − 0.2481·Δα4' (a3·cos 7°: a turn about "
        "x4' at the cut joint moves frame 3 along the parallel axes); the thesis's −2.0024 "
        "omits the Δα4' term.",
        "* **Δa2', Δa3'** differ from the *nominal* combinations (Δa2' − Δa4', Δa3') by "
        "≈ 1.8e-5 m: with uneven links the four-bar is no longer invariant under equal "
        "changes of crank and follower; linearised at the identified point the combination "
        "is met to < 1e-5. The thesis's own table shows the same effect at half the size "
        "(8.9e-6) — presumably because its loop model is the linearisation 6.20 rather than "
        "the exact closure.",
    ]
    (out / "8.1.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
    return [out / "8.1.md"]


