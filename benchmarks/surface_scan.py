"""A surface scan at constant tool orientation on the twin: the frames before and after
issue 36 (docs/calibration.md, *Identifiability*).

The Fanuc M-20iA twin (seed 3, T-MAC 50 mm out on the flange's z axis) scans a
horizontal patch of its working volume with the tool orientation held constant
(``plugcell twin measure --scan N``); ``Calibrator(model="serial")`` identifies it from
the 6-DoF (T-MAC) and the 3-DoF (SMR) measurements.  *before* is the old code path
(``null_tol=0``: no null-space test, plain least squares), *after* the default.  For
each: the identified PROBE offset, how far BASE lies from the twin's true one, the
mean position residual, the validity region's largest lever arm and threshold, what
``plugcell export --format toml`` does and how far the exported robot's TCP lies from
its base at the first scan pose (``kin fk`` of the exported description), and the
warnings.

    PYTHONPATH=src python benchmarks/surface_scan.py [--poses 1300] [--seed 3]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from plugcell.calibration import CalibrationData, Calibrator, ErrorModel
from plugcell.io.export import ExportError, export_calibration
from plugcell.io.robots import load_robot_file
from plugcell.sim.twin.campaign import measure_poses, surface_scan_joints
from plugcell.sim.twin.robot import RobotTwin
from plugcell.sim.twin.scenario import TwinScenario
from plugcell.sim.twin.tracker import LaserTracker


def _tcp_distance(text: str, q0: np.ndarray, tmp: str) -> float:
    """Distance (m) of the exported robot's TCP from its base at readings ``q0`` (what
    ``plugcell kin fk`` of the exported description and its tool give)."""
    import pathlib

    path = pathlib.Path(tmp) / "exported.toml"
    path.write_text(text)
    exported = load_robot_file(path)
    tcp = ErrorModel.create(exported, "serial", base=np.eye(4)).predict(q0)[0]
    return float(np.linalg.norm(tcp[:3, 3]))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--poses", type=int, default=1300)
    ap.add_argument("--seed", type=int, default=3)
    args = ap.parse_args()
    import tempfile

    robot = RobotTwin(TwinScenario(robot="fanuc_m20ia", seed=args.seed))
    desc = robot.description
    truth_base = robot.true_base()
    q = surface_scan_joints(desc, robot.reveal_truth().profile, args.poses,
                            np.random.default_rng(args.seed + 2))
    six, _ = measure_poses(robot, LaserTracker(seed=args.seed), q)
    three, _ = measure_poses(robot, LaserTracker(seed=args.seed + 1), q, mode="3dof")
    print(f"Fanuc M-20iA twin (seed {args.seed}), surface scan of {args.poses} poses: joint "
          f"ranges {', '.join(f'{v:.0f}' for v in np.degrees(np.ptp(q, axis=0)))}°; "
          "true T-MAC offset (0, 0, 50) mm")
    print()
    print("| data | code | PROBE offset (mm) | BASE error (mm) | mean residual (mm) | "
          "lever arm max (m/rad) | region threshold (mm) | export --format toml | "
          "exported TCP from base (m) | fit (s) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    warnings = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, ms in (("6-DoF", six), ("3-DoF", three)):
            data = CalibrationData.from_measurements(ms)
            for code, tol in (("before", 0.0), ("after", None)):
                t0 = time.perf_counter()
                cal = (Calibrator(desc, "serial", null_tol=tol) if tol is not None
                       else Calibrator(desc, "serial"))
                res = cal.fit(data)
                dt = time.perf_counter() - t0
                t = res.model.probe()[:3, 3] * 1e3
                berr = np.linalg.norm(res.model.base()[:3, 3] - truth_base[:3, 3]) * 1e3
                try:
                    out = export_calibration(res, desc, "toml")
                    exported, dist = "written", _tcp_distance(out.text, data.q[0], tmp)
                except ExportError:
                    exported, dist = "refused", float("nan")
                print(f"| {name} | {code} | {t[0]:.1f}, {t[1]:.1f}, {t[2]:.1f} | {berr:.1f} | "
                      f"{res.calibration.position.norm.mean * 1e3:.3f} | "
                      f"{res.validity.lever_m.max():.2f} | {res.validity.threshold_m * 1e3:.0f}"
                      f" | {exported} | {'—' if np.isnan(dist) else f'{dist:.2f}'} | {dt:.1f} |")
                warnings[(name, code)] = res.warnings
                if code == "after":
                    P = np.eye(4)
                    P[:3, 3] = [0.0, 0.0, 0.05]
                    out = export_calibration(res, desc, "toml", probe=P)
                    dist = _tcp_distance(out.text, data.q[0], tmp)
                    print(f"| {name} | after, export --probe 0,0,50,0,0,0 | | | | | | written | "
                          f"{dist:.2f} | |")
    print()
    for (name, code), ws in warnings.items():
        print(f"{name}, {code}: {len(ws)} warning(s)")
        for w in ws:
            print(f"  - {w}")


if __name__ == "__main__":
    main()
