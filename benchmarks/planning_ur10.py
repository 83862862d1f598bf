"""Planning on real data: the IPA UR10 (Landgraf et al. 2021, MIT), and its validity region.

    .venv/bin/python benchmarks/planning_ur10.py [--data DIR] [--draws 20] [--quick]
        [--out docs/results/planning-ur10.json] [--figure docs/results/planning-ur10.png]
        [--plot-only docs/results/planning-ur10.json]

1. **Selection.** N = 30, 60, 120 of series A's 11 911 measured poses are chosen by the
   planner (criterion I, and D), as ``plugcell plan --from series_A.csv`` does: the
   candidates are A's configurations, BASE and PROBE come from A's measurements.  Model 1
   (30 parameters) is calibrated on those poses only and validated on series B, C and D
   with BASE + PROBE re-identified on each (as docs/results/ur10.md) — against random
   subsets of A of the same size (median of ``--draws``) and against all of A.
2. **Validity region.** Calibrated on series C, every pose of A is checked against C's
   region; the calibrated error on A is shown against the distance to C's poses.  And
   within one tracker set-up: calibrated on 2000 poses of A with joint 1 < −60°, the
   rest of A by distance to them.

``--quick``: N = 30, 60 and 5 draws.
"""

from __future__ import annotations

import argparse
import itertools
import json
import platform
import time
from pathlib import Path
from typing import Any

import numpy as np

from calibration_ur10 import DEFAULT_DATA, SERIES, read_series, ur10_toml
from plugcell.calibration import CalibrationData, CalibrationError, Calibrator, ErrorModel
from plugcell.calibration.planning import PosePlanner, filter_candidates, planning_keys
from plugcell.io.robots import load_robot
from plugcell.kinematics.rotations import angles_to_matrix

ROOT = Path(__file__).resolve().parents[1]
BINS_MM = (0, 50, 100, 200, 400, 800, 1200, 1600, 2000, 5000)


def _validation_mean(res: Any, sets: dict[str, CalibrationData]) -> dict[str, float]:
    out = {k: float(res.evaluate(sets[k], refit_base=True, refit_probe=True)[1]
                    .position.norm.mean * 1e3) for k in ("B", "C", "D")}
    out["mean"] = float(np.mean([out[k] for k in ("B", "C", "D")]))
    return out


def _bins(distance_m: np.ndarray, before: np.ndarray, after: np.ndarray) -> list[dict[str, Any]]:
    rows = []
    d = distance_m * 1e3
    for lo, hi in itertools.pairwise(BINS_MM):
        s = (d >= lo) & (d < hi)
        if s.sum() >= 20:
            rows.append({"from_mm": lo, "to_mm": hi, "poses": int(s.sum()),
                         "before_mm": float(before[s].mean()), "after_mm": float(after[s].mean())})
    return rows


def run(data_dir: Path, n_values: tuple[int, ...], draws: int) -> dict[str, Any]:
    t0 = time.perf_counter()
    work = Path("/tmp/plugcell-planning-ur10")
    work.mkdir(parents=True, exist_ok=True)
    (work / "ur10.toml").write_text(ur10_toml(), encoding="utf-8")
    desc = load_robot(work / "ur10.toml")
    sets = {}
    for key, (rel, _) in SERIES.items():
        q, p, a = read_series(data_dir / rel)
        sets[key] = CalibrationData(q, p, angles_to_matrix(a, "xyz"))
    A = sets["A"]
    full = Calibrator(desc, "serial").fit(A)
    out: dict[str, Any] = {"machine": f"{platform.machine()}, Python {platform.python_version()}",
                           "poses": {k: len(v) for k, v in sets.items()},
                           "all_A": _validation_mean(full, sets), "rows": []}
    print(f"all {len(A)} poses of A: validation mean {out['all_A']['mean']:.4f} mm", flush=True)

    # the planner's model: BASE and PROBE from A's measurements (as plugcell plan --from)
    base, probe, _ = Calibrator(desc, 1).initial_frames(A)
    model = ErrorModel.create(desc, "serial", base=base, probe=probe)
    cands = filter_candidates(model, A.q)
    keys = planning_keys(model)
    H = PosePlanner(model, keys).blocks(cands, keys)
    rng = np.random.default_rng(2026)

    def fit_on(index: np.ndarray) -> dict[str, float] | None:
        try:
            return _validation_mean(Calibrator(desc, "serial").fit(A.subset(index)), sets)
        except CalibrationError:
            return None

    for n in n_values:
        row: dict[str, Any] = {"n": n}
        for crit in ("I", "D"):
            t = time.perf_counter()
            plan = PosePlanner(model, keys, criterion=crit).plan(cands, n, blocks=H)
            row[f"plan_{crit}_s"] = time.perf_counter() - t
            row[f"planned_{crit}"] = fit_on(cands.source[plan.index])
            row[f"planned_{crit}_kappa"] = plan.condition_number
        rand = [fit_on(rng.choice(len(A), n, replace=False)) for _ in range(draws)]
        means = np.array([np.nan if r is None else r["mean"] for r in rand])
        row["random_means_mm"] = means.tolist()
        row["random_median_mm"] = float(np.nanmedian(means))
        row["random_p10_mm"], row["random_p90_mm"] = (float(v) for v in
                                                      np.nanpercentile(means, [10, 90]))
        out["rows"].append(row)
        print(f"N = {n:3d}: planned I {row['planned_I']['mean']:.4f}, D "
              f"{row['planned_D']['mean']:.4f} mm; random median {row['random_median_mm']:.4f} "
              f"mm [{row['random_p10_mm']:.4f}, {row['random_p90_mm']:.4f}]", flush=True)

    # ---- validity region: C -> A
    resC = Calibrator(desc, "serial").fit(sets["C"])
    r = resC.evaluate_poses(A, refit_base=True, refit_probe=True)
    check = resC.check_region(A.q)
    assert check is not None
    inside_c = resC.check_region(sets["C"].q)
    assert inside_c is not None
    out["C_to_A"] = {
        "threshold_mm": check.threshold_m * 1e3, "outside": check.count, "poses": len(A),
        "calibration_C_outside": inside_c.count,
        "before_mm": float(r.norms("before").mean() * 1e3),
        "after_mm": float(r.norms("after").mean() * 1e3),
        "bins": _bins(check.distance_m, r.norms("before") * 1e3, r.norms("after") * 1e3),
        "distance_mm": (check.distance_m * 1e3).tolist(),
        "after_each_mm": (r.norms("after") * 1e3).tolist(),
        "before_each_mm": (r.norms("before") * 1e3).tolist(),
    }
    # ---- within one set-up: A with joint 1 < -60 deg -> the rest of A
    region = np.flatnonzero(np.degrees(A.q[:, 0]) < -60.0)
    idx = np.sort(np.random.default_rng(0).choice(region, 2000, replace=False))
    resS = Calibrator(desc, "serial").fit(A.subset(idx))
    rest = np.setdiff1d(np.arange(len(A)), idx)
    rs = resS.evaluate_poses(A.subset(rest))
    cs = resS.check_region(A.q[rest])
    assert cs is not None
    o = cs.outside
    out["A_split"] = {
        "threshold_mm": cs.threshold_m * 1e3, "poses": len(rest), "outside": cs.count,
        "inside_after_mm": float(rs.norms("after")[~o].mean() * 1e3),
        "outside_after_mm": float(rs.norms("after")[o].mean() * 1e3),
        "inside_before_mm": float(rs.norms("before")[~o].mean() * 1e3),
        "outside_before_mm": float(rs.norms("before")[o].mean() * 1e3),
        "bins": _bins(cs.distance_m, rs.norms("before") * 1e3, rs.norms("after") * 1e3),
    }
    out["elapsed_s"] = time.perf_counter() - t0
    return out


def plot(d: dict[str, Any], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(14, 4))
    ax = axes[0]
    rows = d["rows"]
    n = [r["n"] for r in rows]
    ax.fill_between(n, [r["random_p10_mm"] for r in rows], [r["random_p90_mm"] for r in rows],
                    color="0.85", label="random subsets of A, 10–90 %")
    ax.plot(n, [r["random_median_mm"] for r in rows], "o-", color="0.35",
            label="random subsets of A, median")
    ax.plot(n, [r["planned_I"]["mean"] for r in rows], "s-", color="tab:blue",
            label="planned, I-optimal")
    ax.plot(n, [r["planned_D"]["mean"] for r in rows], "^--", color="tab:orange",
            label="planned, D-optimal")
    ax.axhline(d["all_A"]["mean"], color="k", lw=1, label=f"all {d['poses']['A']} poses of A")
    ax.axhline(1.1 * d["all_A"]["mean"], color="tab:red", lw=0.8, ls=":", label="+10 %")
    ax.set_xlabel("poses of series A calibrated on (N)")
    ax.set_ylabel("mean position error on B, C, D (mm)")
    ax.set_title("IPA UR10, model 1: selecting poses")
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    for ax, key, title in ((axes[1], "C_to_A", "calibrated on C, checked on A"),
                           (axes[2], "A_split", "calibrated on A (joint 1 < −60°), rest of A")):
        b = d[key]["bins"]
        mid = [0.5 * (x["from_mm"] + x["to_mm"]) for x in b]
        ax.plot(mid, [x["before_mm"] for x in b], "o-", color="tab:red", label="nominal")
        ax.plot(mid, [x["after_mm"] for x in b], "s-", color="tab:blue", label="calibrated")
        ax.axvline(d[key]["threshold_mm"], color="k", ls=":",
                   label=f"region threshold {d[key]['threshold_mm']:.0f} mm")
        ax.set_xscale("log")
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.set_xlabel("distance to the nearest calibration pose (mm)")
        ax.set_ylabel("mean position error (mm)")
        ax.set_title(title, fontsize=10)
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA)
    ap.add_argument("--draws", type=int, default=20)
    ap.add_argument("--quick", action="store_true", help="N = 30, 60 and 5 draws")
    ap.add_argument("--out", type=Path, help="write the results (JSON)")
    ap.add_argument("--figure", type=Path, help="write the figure (PNG, needs matplotlib)")
    ap.add_argument("--plot-only", type=Path, metavar="JSON",
                    help="only draw --figure from the results of an earlier --out")
    args = ap.parse_args()
    if args.plot_only is not None:
        plot(json.loads(args.plot_only.read_text(encoding="utf-8")), args.figure)
        return 0
    d = run(args.data, (30, 60) if args.quick else (30, 60, 120),
            5 if args.quick else args.draws)
    print(f"{'N':>4s} {'planned I':>10s} {'planned D':>10s} {'random median':>14s} "
          f"{'all of A':>9s}  (mm, mean of B, C, D; {d['elapsed_s']:.0f} s)")
    for r in d["rows"]:
        print(f"{r['n']:4d} {r['planned_I']['mean']:10.4f} {r['planned_D']['mean']:10.4f} "
              f"{r['random_median_mm']:14.4f} {d['all_A']['mean']:9.4f}")
    c = d["C_to_A"]
    print(f"C → A: {c['outside']} of {c['poses']} poses of A outside C's region; nominal "
          f"{c['before_mm']:.3f} → calibrated {c['after_mm']:.3f} mm")
    s = d["A_split"]
    print(f"A split: {s['outside']} of {s['poses']} outside; calibrated {s['inside_after_mm']:.3f} "
          f"mm inside, {s['outside_after_mm']:.3f} mm outside")
    if args.out is not None:
        slim = {**d, "C_to_A": {k: v for k, v in d["C_to_A"].items()
                                if not k.endswith(("_each_mm", "distance_mm"))}}
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(slim, indent=1) + "\n", encoding="utf-8")
    if args.figure is not None:
        plot(d, args.figure)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
