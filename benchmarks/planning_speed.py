"""Benchmark: choosing a calibration campaign (issue 17, target: 40 of 10 000 candidates
for the Smart H4's model 5 in ≤ 2 s).

    .venv/bin/python benchmarks/planning_speed.py [--candidates 10000] [--poses 40] [--repeat 3]

Candidates: the Smart H4 in its working volume, visible from the twin's tracker (45°),
each configuration with payloads 0, 18 and 36 kg; model 5 (51 parameters identifiable
with several payloads — the thesis counts 52).  Prints one row per criterion: the time
to draw the candidates, to compute their identification Jacobian, and to select
(greedy start + exchanges: the time the target is about), the best of ``--repeat``.
"""

from __future__ import annotations

import argparse
import platform
import time

import numpy as np

from plugcell.calibration import ErrorModel
from plugcell.calibration.planning import (
    CRITERIA,
    PosePlanner,
    Visibility,
    planning_keys,
    sample_candidates,
)
from plugcell.io.robots import load_robot

TRACKER = (4.6, 1.1, 0.35)
PAYLOADS = (0.0, 18.0, 36.0)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--candidates", type=int, default=10_000)
    ap.add_argument("--poses", type=int, default=40)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    desc = load_robot("smart_h4")
    model = ErrorModel.create(desc, "loop", gravity=True, payload=True, payload_ref_kg=36.0)
    t = time.perf_counter()
    cands = sample_candidates(model, args.candidates, payloads=PAYLOADS,
                              volume=desc.working_volume,
                              visibility=Visibility(TRACKER, np.radians(45.0)), seed=1)
    t_sample = time.perf_counter() - t
    keys = planning_keys(model, PAYLOADS)
    print(f"Smart H4, model 5: {len(keys)} parameters, {len(cands)} candidates "
          f"(drawn in {t_sample:.2f} s), {args.poses} poses; Python "
          f"{platform.python_version()}, {platform.machine()}")
    print(f"{'criterion':>9s} {'Jacobian s':>11s} {'select s':>9s} {'exchanges':>9s} "
          f"{'value':>12s} {'κ':>7s} {'median σ/σ_noise':>17s}")
    for crit in CRITERIA:
        planner = PosePlanner(model, keys, criterion=crit)
        tj, ts = [], []
        for _ in range(args.repeat):
            t = time.perf_counter()
            H = planner.blocks(cands, keys)
            tj.append(time.perf_counter() - t)
            t = time.perf_counter()
            plan = planner.plan(cands, args.poses, blocks=H)
            ts.append(time.perf_counter() - t)
        rel = np.median(plan.sigma / plan.noise_m)
        print(f"{crit:>9s} {min(tj):11.3f} {min(ts):9.3f} {plan.exchanges:9d} "
              f"{plan.value:12.5g} {plan.condition_number:7.1f} {rel:17.3g}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
