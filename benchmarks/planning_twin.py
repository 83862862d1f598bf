"""Planned against random campaigns on the twin: Smart H4, model 5, payloads 0/18/36 kg.

    .venv/bin/python benchmarks/planning_twin.py [--quick] [--draws 20]
        [--out docs/results/planning-twin.json] [--figure docs/results/planning-twin.png]

The pool: 1500 configurations drawn as ``plugcell twin measure`` draws them (flange in the
working volume, T-MAC towards the tracker, nominal IK), each measured by the twin at 0, 18
and 36 kg — 4500 candidate poses.  For every N a *random* campaign is N poses drawn from
the pool (the median of ``--draws`` draws is shown, with the 10–90 % band); a *planned*
campaign is N poses chosen from the same pool by :class:`PosePlanner` (criteria I and D),
as ``plugcell plan --from pool.csv`` does; a third curve plans from 5000 candidates drawn
as ``plugcell plan`` draws them by default (uniform in joint space, 45° line of sight) —
poses the twin then measures.  Each campaign is validated twice: on 300 poses drawn as
``twin measure`` draws them (the pool's distribution) and on 300 poses drawn as
``plugcell plan`` draws its candidates (wider: any wrist orientation within 45° of the
tracker).  Every campaign is calibrated with model 5
(51 parameters) and validated on 300 independent poses (100 at each payload, another
seed).  ``--quick``: N = 20, 40, 150 and 5 draws.
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path
from typing import Any

import numpy as np

from plugcell.calibration import CalibrationData, CalibrationError, Calibrator, ErrorModel
from plugcell.calibration.planning import (
    Candidates,
    PosePlanner,
    Visibility,
    planning_keys,
    sample_candidates,
)
from plugcell.kinematics.rotations import rpy_to_matrix
from plugcell.sim.twin.campaign import measure_poses, working_volume_joints
from plugcell.sim.twin.robot import RobotTwin
from plugcell.sim.twin.scenario import TwinProfile, TwinScenario
from plugcell.sim.twin.tracker import LaserTracker

ROOT = Path(__file__).resolve().parents[1]
PAYLOADS = (0.0, 18.0, 36.0)
FULL_N = (20, 30, 40, 60, 90, 120, 150)
QUICK_N = (20, 40, 150)


def _measure(scenario: TwinScenario, q: np.ndarray, m: float, seed: int) -> CalibrationData:
    data, _ = measure_poses(RobotTwin(scenario.with_payload(m)), LaserTracker(seed=seed), q)
    return CalibrationData.from_measurements(data)


def _concat(parts: list[CalibrationData]) -> CalibrationData:
    return CalibrationData(np.concatenate([p.q for p in parts]),
                           np.concatenate([p.positions for p in parts]),
                           np.concatenate([p.rotations for p in parts]),  # type: ignore[misc]
                           np.concatenate([p.payload_kg for p in parts]))


def run(n_values: tuple[int, ...], draws: int, pool_size: int = 1500) -> dict[str, Any]:
    scenario = TwinScenario(robot="smart_h4", seed=0)
    desc = RobotTwin(scenario).description
    prof = TwinProfile.load("smart_h4")
    t0 = time.perf_counter()
    q = working_volume_joints(desc, prof, pool_size, np.random.default_rng(11))
    measured = {m: _measure(scenario, q, m, 5 + int(m)) for m in PAYLOADS}
    qv = working_volume_joints(desc, prof, 100, np.random.default_rng(99))
    validation = _concat([_measure(scenario, qv, m, 77 + int(m)) for m in PAYLOADS])
    t_measure = time.perf_counter() - t0
    # candidate i: configuration i // 3 at payload PAYLOADS[i % 3]
    cq = np.repeat(q, len(PAYLOADS), axis=0)
    cm = np.tile(PAYLOADS, len(q))
    pool = _concat([measured[cm[i]].subset([i // len(PAYLOADS)]) for i in range(len(cq))])

    # the planner's model: the tracker where the twin's cell puts it, its T-MAC
    probe = np.eye(4)
    probe[:3, :3] = rpy_to_matrix(*prof.probe_rpy)
    probe[:3, 3] = prof.probe_position
    base = np.eye(4)
    base[:3, 3] = -np.asarray(prof.tracker_position)
    model = ErrorModel.create(desc, "loop", gravity=True, payload=True, base=base, probe=probe,
                              payload_ref_kg=max(PAYLOADS))
    cands = Candidates(cq, cm, np.zeros((len(cq), 3)), np.arange(len(cq), dtype=np.int64))
    keys = planning_keys(model, PAYLOADS)
    H = PosePlanner(model, keys).blocks(cands, keys)

    # candidates drawn as plugcell plan draws them by default (joint space, 45° line of sight)
    def draw(count: int, seed: int) -> Candidates:
        return sample_candidates(model.with_references(base=np.eye(4)), count,
                                 payloads=PAYLOADS, volume=desc.working_volume,
                                 visibility=Visibility(prof.tracker_position, np.radians(45.0)),
                                 seed=seed)

    drawn = draw(5000, 0)
    H_drawn = PosePlanner(model, keys).blocks(drawn, keys)
    # a second, wider validation set: 100 other drawn configurations at each payload
    qw = draw(300, 5).q[:: len(PAYLOADS)][:100]
    wide = _concat([_measure(scenario, qw, m, 88 + int(m)) for m in PAYLOADS])

    def validate(index: np.ndarray) -> tuple[float, float]:
        return _validate(pool.subset(index))

    def _validate(data: CalibrationData) -> tuple[float, float]:
        try:
            res = Calibrator(desc, 5).fit(data)
        except CalibrationError:
            return float("nan"), float("nan")
        return (float(res.evaluate(validation)[1].position.norm.mean * 1e3),
                float(res.evaluate(wide)[1].position.norm.mean * 1e3))

    rng = np.random.default_rng(2026)
    rows = []
    for n in n_values:
        row: dict[str, Any] = {"n": n}
        for crit in ("I", "D"):
            t = time.perf_counter()
            plan = PosePlanner(model, keys, criterion=crit).plan(cands, n, blocks=H)
            row[f"plan_{crit}_s"] = time.perf_counter() - t
            row[f"planned_{crit}_mm"], row[f"planned_{crit}_wide_mm"] = validate(plan.index)
            row[f"planned_{crit}_kappa"] = plan.condition_number
            row[f"planned_{crit}_payloads"] = {f"{m:g}": int(np.sum(plan.payload_kg == m))
                                               for m in PAYLOADS}
        plan = PosePlanner(model, keys, criterion="I").plan(drawn, n, blocks=H_drawn)
        row["planned_drawn_mm"], row["planned_drawn_wide_mm"] = _validate(_concat([
            _measure(scenario, plan.q[plan.payload_kg == m], m, 5 + int(m))
            for m in PAYLOADS if np.any(plan.payload_kg == m)]))
        both = np.array([validate(rng.choice(len(cands), n, replace=False))
                         for _ in range(draws)])
        for key, r in (("random", both[:, 0]), ("random_wide", both[:, 1])):
            row[f"{key}_mm"] = r.tolist()
            row[f"{key}_median_mm"] = float(np.nanmedian(r))
            row[f"{key}_p10_mm"], row[f"{key}_p90_mm"] = (float(v) for v in
                                                          np.nanpercentile(r, [10, 90]))
        rows.append(row)
        print(f"N = {n:3d}: planned I {row['planned_I_mm']:.4f}, D {row['planned_D_mm']:.4f}, "
              f"I from drawn candidates {row['planned_drawn_mm']:.4f} mm; "
              f"random median {row['random_median_mm']:.4f} mm "
              f"[{row['random_p10_mm']:.4f}, {row['random_p90_mm']:.4f}]; wide validation: "
              f"planned I {row['planned_I_wide_mm']:.4f}, I drawn "
              f"{row['planned_drawn_wide_mm']:.4f}, random {row['random_wide_median_mm']:.4f}",
              flush=True)
    before = Calibrator(desc, 5).fit(pool.subset(np.arange(0, len(cq), 7))).evaluate(
        validation)[0].position.norm.mean * 1e3
    return {"machine": f"{platform.machine()}, Python {platform.python_version()}",
            "pool_configurations": pool_size, "candidates": len(cands), "parameters": len(keys),
            "validation_poses": len(validation), "wide_validation_poses": len(wide),
            "draws": draws, "nominal_mm": before,
            "measure_s": t_measure, "rows": rows,
            "elapsed_s": time.perf_counter() - t0}


def plot(d: dict[str, Any], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = d["rows"]
    n = [r["n"] for r in rows]
    wide = "random_wide_median_mm" in rows[0]
    fig, axes = plt.subplots(1, 2 if wide else 1, figsize=(13 if wide else 7, 4.4),
                             squeeze=False)
    panels = [("", "validated on poses as twin measure draws them")]
    if wide:
        panels.append(("_wide", "validated on poses as plugcell plan draws them"))
    for ax, (sfx, title) in zip(axes[0], panels, strict=True):
        ax.fill_between(n, [r[f"random{sfx}_p10_mm"] for r in rows],
                        [r[f"random{sfx}_p90_mm"] for r in rows], color="0.85",
                        label=f"random from the pool, 10–90 % of {d['draws']} draws")
        ax.plot(n, [r[f"random{sfx}_median_mm"] for r in rows], "o-", color="0.35",
                label="random from the pool, median")
        ax.plot(n, [r[f"planned_I{sfx}_mm"] for r in rows], "s-", color="tab:blue",
                label="planned from the pool, I-optimal")
        ax.plot(n, [r[f"planned_D{sfx}_mm"] for r in rows], "^--", color="tab:orange",
                label="planned from the pool, D-optimal")
        if f"planned_drawn{sfx}_mm" in rows[0]:
            ax.plot(n, [r[f"planned_drawn{sfx}_mm"] for r in rows], "v-.", color="tab:purple",
                    label="planned, I, from candidates drawn as plugcell plan does (45°)")
        last = rows[-1][f"random{sfx}_median_mm"]
        ax.axhline(1.1 * last, color="tab:red", lw=0.8, ls=":",
                   label=f"+10 % of {rows[-1]['n']} random poses")
        ax.set_xlabel("poses in the calibration campaign (N)")
        ax.set_ylabel("validation mean position error (mm)")
        ax.set_title(f"Smart H4 twin, model 5, 0/18/36 kg: {title}", fontsize=8.5)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="N = 20, 40, 150 and 5 draws")
    ap.add_argument("--draws", type=int, default=20)
    ap.add_argument("--out", type=Path, help="write the results (JSON)")
    ap.add_argument("--figure", type=Path, help="write the figure (PNG, needs matplotlib)")
    ap.add_argument("--plot-only", type=Path, metavar="JSON",
                    help="only draw --figure from the results of an earlier --out")
    args = ap.parse_args()
    if args.plot_only is not None:
        plot(json.loads(args.plot_only.read_text(encoding="utf-8")), args.figure)
        return 0
    d = run(QUICK_N if args.quick else FULL_N, 5 if args.quick else args.draws)
    print(f"{'N':>4s} {'planned I':>10s} {'planned D':>10s} {'I, drawn':>9s} "
          f"{'random median':>14s}  (mm, validation mean; nominal {d['nominal_mm']:.3f} mm; "
          f"{d['elapsed_s']:.0f} s)")
    for r in d["rows"]:
        print(f"{r['n']:4d} {r['planned_I_mm']:10.4f} {r['planned_D_mm']:10.4f} "
              f"{r['planned_drawn_mm']:9.4f} {r['random_median_mm']:14.4f}")
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(d, indent=1) + "\n", encoding="utf-8")
    if args.figure is not None:
        plot(d, args.figure)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
