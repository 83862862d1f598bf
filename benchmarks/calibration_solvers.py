"""The thesis's Gauss–Newton against SciPy's least_squares, on the same problems.

    .venv/bin/python benchmarks/calibration_solvers.py [--data DIR] [--quick]

Fits each case with ``Calibrator(method="gauss-newton")`` (the default, thesis Fig. 6-9)
and ``method="least-squares"`` (:func:`scipy.optimize.least_squares`, trust-region
reflective, ``x_scale="jac"``, the analytic Jacobian) and prints, per case and solver,
the validation mean and maximum position error, the iterations (Jacobian evaluations)
and the wall time of the fit:

* the digital twin of the thesis (8.2): 150 calibration and 150 validation poses at
  36 kg, models 1–5 (``--quick``: 60 poses);
* the IPA UR10 (series A calibrates, B validates with BASE re-identified, model 1),
  when the data set is found (``--data``, default ``../shared/data/ipa-robot-accuracy``).
"""

from __future__ import annotations

import argparse
import platform
import time
from pathlib import Path
from typing import Any

import numpy as np

from plugcell.calibration import CalibrationData, Calibrator
from plugcell.sim.twin.campaign import measure_poses, working_volume_joints
from plugcell.sim.twin.robot import RobotTwin
from plugcell.sim.twin.scenario import TwinScenario
from plugcell.sim.twin.tracker import LaserTracker

ROOT = Path(__file__).resolve().parents[1]
SOLVERS = ("gauss-newton", "least-squares")


def campaign(robot: RobotTwin, tracker: LaserTracker, n: int, seed: int) -> CalibrationData:
    q = working_volume_joints(robot.description, robot.reveal_truth().profile, n,
                              np.random.default_rng(seed))
    data, _ = measure_poses(robot, tracker, q)
    return CalibrationData.from_measurements(data)


def fit_row(case: str, desc: Any, model: Any, cal: CalibrationData, val: CalibrationData,
            solver: str, refit_base: bool = False) -> dict[str, Any]:
    t = time.perf_counter()
    result = Calibrator(desc, model, method=solver).fit(cal)
    elapsed = time.perf_counter() - t
    _, after = result.evaluate(val, refit_base=refit_base)
    return {"case": case, "solver": solver, "mean_mm": after.position.norm.mean * 1e3,
            "max_mm": after.position.norm.max * 1e3, "iterations": result.iterations,
            "time_s": elapsed}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=ROOT.parent / "shared" / "data" /
                    "ipa-robot-accuracy")
    ap.add_argument("--quick", action="store_true", help="60 twin poses instead of 150")
    args = ap.parse_args()
    n = 60 if args.quick else 150
    robot = RobotTwin(TwinScenario(seed=0))
    tracker = LaserTracker(seed=0)
    robot.set_payload(36.0)
    cal, val = campaign(robot, tracker, n, 201), campaign(robot, tracker, n, 202)
    rows = [fit_row(f"twin 36 kg, model {m}", robot.description, m, cal, val, solver)
            for m in (1, 2, 3, 4, 5) for solver in SOLVERS]
    series_a = args.data / "Series_A" / "measurements_grid.csv"
    if series_a.is_file():
        import sys

        sys.path.insert(0, str(ROOT / "benchmarks"))
        from calibration_ur10 import SERIES, read_series, ur10_toml
        from plugcell.io.robots import load_robot
        from plugcell.kinematics.rotations import angles_to_matrix

        work = Path("/tmp") / "plugcell-solvers"
        work.mkdir(exist_ok=True)
        (work / "ur10.toml").write_text(ur10_toml(), encoding="utf-8")
        desc = load_robot(work / "ur10.toml")
        sets = {}
        for key in ("A", "B"):
            q, p, a = read_series(args.data / SERIES[key][0])
            sets[key] = CalibrationData(q, p, angles_to_matrix(a, "xyz"))
        rows += [fit_row("IPA UR10 A → B, model 1", desc, "serial", sets["A"], sets["B"],
                         solver, refit_base=True) for solver in SOLVERS]
    print(f"calibration solvers — {platform.machine()}, Python {platform.python_version()}, "
          f"twin {n} + {n} poses")
    print(f"{'case':28s} {'solver':14s} {'val. mean mm':>12s} {'val. max mm':>12s} "
          f"{'iterations':>10s} {'time s':>8s}")
    for r in rows:
        print(f"{r['case']:28s} {r['solver']:14s} {r['mean_mm']:12.4f} {r['max_mm']:12.4f} "
              f"{r['iterations']:10d} {r['time_s']:8.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
