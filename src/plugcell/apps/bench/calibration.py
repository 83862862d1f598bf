"""``plugcell bench calibration``: identification speed of model 5 (issue 3, section 6).

This module registers nothing by itself: ``plugcell bench`` (owned by
:mod:`plugcell.apps.commands.bench`) wires it as a sub-benchmark::

    c = sub.add_parser("calibration", help=...)
    from plugcell.apps.bench.calibration import add_arguments, run
    add_arguments(c)
    c.set_defaults(func=run)

It times :class:`plugcell.calibration.Calibrator` (model 5, Gauss–Newton, exact
model, BASE/PROBE estimated from the data) on noisy synthetic Smart H4 data
— 150 poses (the thesis: 5 s in Matlab; target: under 50 ms), median of
``--repeat`` runs — and the scaling to ``--max-poses`` (default 100 000), one
run per size.  JSON keys: ``t150_s`` (median seconds, 150 poses, model 5),
``t150_all_s``, ``scaling`` (``[{"poses", "seconds", "seconds_per_pose",
"iterations"}]``), ``parameters``.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from typing import Any

import numpy as np

SIZES = (150, 1_000, 10_000, 100_000)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--json", action="store_true", help="print JSON")
    p.add_argument("--repeat", type=int, default=7, help="runs at 150 poses (default 7)")
    p.add_argument("--max-poses", type=int, default=100_000,
                   help="largest data set of the scaling run (default 100000; 0 = none)")
    p.add_argument("--seed", type=int, default=0)


def synthetic_data(n: int, seed: int = 0) -> Any:
    """``n`` noisy poses (20 µm, 0.001°) of a Smart H4 with model-5 errors, 36 kg."""
    from plugcell.calibration import CalibrationData, ErrorModel
    from plugcell.calibration.identifiability import random_configurations
    from plugcell.io.robots import load_robot
    from plugcell.kinematics.transforms import so3_exp

    desc = load_robot("smart_h4")
    rng = np.random.default_rng(seed)
    base = np.eye(4)
    base[:3, :3] = so3_exp([0.0, 0.0, 3.44])
    base[:3, 3] = (4.6, 1.1, -0.35)
    probe = np.eye(4)
    probe[:3, 3] = (0.045, -0.03, 0.14)
    truth = ErrorModel.create(desc, "loop", gravity=True, payload=True, base=base, probe=probe,
                              payload_ref_kg=36.0)
    truth = truth.with_values(rng.normal(size=len(truth.space)) * 3e-4)
    q = random_configurations(truth, n, seed + 1)
    T = truth.predict(q, 36.0)
    T[:, :3, 3] += rng.normal(0.0, 2e-5, (n, 3))
    T[:, :3, :3] = so3_exp(rng.normal(0.0, 1.7e-5, (n, 3))) @ T[:, :3, :3]
    return desc, CalibrationData.from_poses(q, T, np.full(n, 36.0))


def measure(repeat: int = 7, max_poses: int = 100_000, seed: int = 0) -> dict[str, Any]:
    from plugcell.calibration import Calibrator

    desc, data = synthetic_data(150, seed)
    cal = Calibrator(desc, 5)
    cal.fit(data)  # warm-up (imports, caches)
    times = []
    res = None
    for _ in range(max(repeat, 1)):
        t = time.perf_counter()
        res = cal.fit(data)
        times.append(time.perf_counter() - t)
    assert res is not None
    scaling = []
    for n in SIZES:
        if n > max_poses:
            break
        d, big = synthetic_data(n, seed)
        t = time.perf_counter()
        r = Calibrator(d, 5).fit(big)
        dt = time.perf_counter() - t
        scaling.append({"poses": n, "seconds": dt, "seconds_per_pose": dt / n,
                        "iterations": r.iterations})
    return {
        "benchmark": "calibration",
        "model": 5,
        "parameters": len(res.keys),
        "model_parameters": len(res.model.space),
        "iterations_150": res.iterations,
        "t150_s": statistics.median(times),
        "t150_all_s": times,
        "thesis_t150_s": 5.0,
        "target_t150_s": 0.05,
        "target_met": statistics.median(times) < 0.05,
        "scaling": scaling,
    }


def run(args: argparse.Namespace) -> int:
    d = measure(args.repeat, args.max_poses, args.seed)
    if args.json:
        print(json.dumps(d, indent=2))
        return 0
    met = "met" if d["t150_s"] < d["target_t150_s"] else "NOT met"
    print(f"model 5 ({d['parameters']} identified of its {d['model_parameters']} parameters, "
          f"one payload), 150 poses: median {d['t150_s'] * 1e3:.1f} ms "
          f"over {len(d['t150_all_s'])} runs, {d['iterations_150']} iterations "
          f"(thesis: 5 s in Matlab; target < {d['target_t150_s'] * 1e3:.0f} ms: {met})")
    for s in d["scaling"]:
        print(f"  {s['poses']:>7d} poses: {s['seconds']:8.3f} s  "
              f"({s['seconds_per_pose'] * 1e6:6.1f} µs/pose, {s['iterations']} iterations)")
    return 0


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="plugcell bench calibration", description=__doc__)
    add_arguments(p)
    return run(p.parse_args(argv))


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
