"""plugcell against FIGAROH on the same twin data (issue 3, section 5).

FIGAROH (pip ``figaroh``, Apache-2.0) is the best open-source geometric calibrator;
it models serial chains from a URDF, so it gets the Smart H4 as the serial robot of
eq. 6.3 (thesis model 1) — it cannot model the parallelogram loop or the payload.
Both calibrate on the same simulated campaign of the digital twin and are scored
on the same independent validation poses (positions, mm).

FIGAROH stays out of plugcell's dependencies: it runs in a separate interpreter
(``--figaroh-python``, e.g. a venv made with ``python -m venv /tmp/figvenv &&
/tmp/figvenv/bin/pip install figaroh``), fed with files this script writes: a URDF
of the serial-equivalent Smart H4 (generated from plugcell's description), a
FIGAROH configuration and the measurement CSVs.

    .venv/bin/python benchmarks/calibration_figaroh.py --figaroh-python /tmp/figvenv/bin/python
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import textwrap
import time
from pathlib import Path
from typing import Any

import numpy as np

from plugcell.calibration import Calibrator, kinematic_structure
from plugcell.kinematics.rotations import matrix_to_rpy
from plugcell.kinematics.transforms import dh_hayati, rot_z

ROOT = Path(__file__).resolve().parents[1]


def urdf_of(structure: Any) -> str:
    """URDF of a serial structure: joint i turns about z of F_{i-1}·Rz(θ_i) (DH, B.1)."""
    desc = structure.desc
    chain = [desc.links[i] for i in desc.chain]
    parts = ['<?xml version="1.0"?>', f'<robot name="{desc.name.split()[0]}_serial">',
             '  <link name="base_link"/>']
    prev_T = np.eye(4)  # fixed part between the previous joint frame and this joint
    parent = "base_link"
    for k, lk in enumerate(chain):
        T = prev_T @ rot_z(lk.theta)
        xyz = T[:3, 3]
        rpy = matrix_to_rpy(T[:3, :3])
        name = f"j{k + 1}"
        parts += [f'  <link name="l{k + 1}"/>',
                  f'  <joint name="{name}" type="revolute">',
                  f'    <parent link="{parent}"/><child link="l{k + 1}"/>',
                  f'    <origin xyz="{xyz[0]:.9f} {xyz[1]:.9f} {xyz[2]:.9f}" '
                  f'rpy="{rpy[0]:.12f} {rpy[1]:.12f} {rpy[2]:.12f}"/>',
                  '    <axis xyz="0 0 1"/>',
                  '    <limit lower="-12.6" upper="12.6" effort="1000" velocity="3"/>',
                  '  </joint>']
        prev_T = dh_hayati(0.0, lk.d, lk.a, lk.alpha, lk.beta)
        parent = f"l{k + 1}"
    xyz = prev_T[:3, 3]
    rpy = matrix_to_rpy(prev_T[:3, :3])
    parts += ['  <link name="flange"/>',
              '  <joint name="flange_joint" type="fixed">',
              f'    <parent link="{parent}"/><child link="flange"/>',
              f'    <origin xyz="{xyz[0]:.9f} {xyz[1]:.9f} {xyz[2]:.9f}" '
              f'rpy="{rpy[0]:.12f} {rpy[1]:.12f} {rpy[2]:.12f}"/>',
              '  </joint>', '</robot>']
    return "\n".join(parts) + "\n"


CONFIG = """\
robot:
  name: "smart_h4_serial"
  properties:
    joints:
      active_joints: [j1, j2, j3, j4, j5, j6]
tasks:
  calibration:
    enabled: true
    type: kinematic_calibration
    parameters:
      calibration_level: "full_params"
      include_non_geometric: false
      regularization_coefficient: 0.0
      outlier_threshold: 0.05
    kinematics:
      base_frame: "universe"
      tool_frame: "flange"
    measurements:
      markers:
        - name: "tmac"
          reference_joint: "j6"
          measurable_dof: [true, true, true, false, false, false]
          sensor_type: "tracker"
      poses:
        base_pose: [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
        tool_pose: [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    data:
      source_file: "{cal}"
      number_of_samples: {n}
"""

RUNNER = textwrap.dedent('''
    import json, sys, time, warnings
    import numpy as np
    import pandas as pd
    warnings.filterwarnings("ignore")
    from figaroh.tools.robot import load_robot
    from figaroh.calibration.base_calibration import BaseCalibration
    from figaroh.calibration.calibration_tools import calc_updated_fkm

    work = sys.argv[1]

    class Calib(BaseCalibration):
        def cost_function(self, var):
            PEEe = calc_updated_fkm(self.model, self.data, var, self.q_measured,
                                    self.calib_config)
            return self.PEE_measured - PEEe

    robot = load_robot(work + "/robot.urdf", load_by_urdf=True)
    cal = Calib(robot, work + "/config.yaml")
    # the tracker-to-base and flange-to-T-MAC frames are unknown: FIGAROH identifies them
    cal.calib_config["known_baseframe"] = False
    cal.calib_config["known_tipframe"] = False
    t = time.perf_counter()
    cal.initialize()
    cal.solve(max_iterations=1, enable_logging=False)
    dt = time.perf_counter() - t
    cc = cal.calib_config
    out = {"seconds": dt, "parameters": len(cc["param_name"]),
           "param_name": list(cc["param_name"]), "status": cal.STATUS}
    for name in ("cal", "val"):
        df = pd.read_csv(work + "/" + name + ".csv")
        q = np.tile(robot.q0, (len(df), 1))
        for k in range(6):
            q[:, cc["config_idx"][k]] = df["j%d" % (k + 1)].to_numpy()
        cfg = dict(cc)
        cfg["NbSample"] = len(df)
        p = calc_updated_fkm(robot.model, robot.data, cal.var_, q, cfg)
        out[name] = np.asarray(p).reshape(3, len(df)).T.tolist()
    json.dump(out, open(work + "/figaroh_out.json", "w"))
''')


def write_csv(path: Path, q_serial: np.ndarray, positions: np.ndarray) -> None:
    cols = [f"j{k + 1}" for k in range(q_serial.shape[1])] + ["x1", "y1", "z1"]
    rows = [",".join(cols)]
    for qq, p in zip(q_serial, positions, strict=True):
        rows.append(",".join(f"{v:.12g}" for v in (*qq, *p)))
    path.write_text("\n".join(rows) + "\n", encoding="utf-8")


def run(figaroh_python: str, work: Path, seed: int = 0, n_cal: int = 90, n_val: int = 90
        ) -> dict[str, Any]:
    from plugcell.apps.reproduce.models_8_2 import campaign as _campaign
    from plugcell.sim.twin.robot import RobotTwin
    from plugcell.sim.twin.scenario import TwinScenario
    from plugcell.sim.twin.tracker import LaserTracker

    robot = RobotTwin(TwinScenario(seed=seed))
    tracker = LaserTracker(seed=seed)
    cal = _campaign(robot, tracker, n_cal, 101, 0.0)
    val = _campaign(robot, tracker, n_val, 102, 0.0)
    desc = robot.description
    out: dict[str, Any] = {"seed": seed, "poses": {"calibration": n_cal, "validation": n_val},
                           "plugcell": {}}
    from plugcell.calibration import CalibrationData

    cal3 = CalibrationData(cal.q, cal.positions, None, cal.payload_kg)
    val3 = CalibrationData(val.q, val.positions, None, val.payload_kg)
    runs = [(n, "6dof", cal, val) for n in (1, 2, 4)] + [(n, "positions", cal3, val3)
                                                        for n in (1, 2, 4)]
    for number, kind, c, v in runs:
        t = time.perf_counter()
        r = Calibrator(desc, number).fit(c, validation=v)
        dt = time.perf_counter() - t
        out["plugcell"][f"model{number}/{kind}"] = {
            "name": r.config.name, "data": kind, "parameters": len(r.keys), "seconds": dt,
            "calibration_mean_mm": r.calibration.position.norm.mean * 1e3,
            "validation_mean_mm": r.validation.position.norm.mean * 1e3,
            "validation_before_mm": r.validation_before.position.norm.mean * 1e3,
        }
    # FIGAROH: the serial robot of eq. 6.3, positions only, tracker frame
    work.mkdir(parents=True, exist_ok=True)
    s = kinematic_structure(desc, "serial")
    (work / "robot.urdf").write_text(urdf_of(s), encoding="utf-8")
    write_csv(work / "cal.csv", s.joints(cal.q), cal.positions)
    write_csv(work / "val.csv", s.joints(val.q), val.positions)
    (work / "config.yaml").write_text(CONFIG.format(cal=work / "cal.csv", n=n_cal),
                                      encoding="utf-8")
    (work / "runner.py").write_text(RUNNER, encoding="utf-8")
    proc = subprocess.run([figaroh_python, str(work / "runner.py"), str(work)],
                          capture_output=True, text=True, timeout=1800)
    if proc.returncode != 0:
        out["figaroh"] = {"error": proc.stderr.strip().splitlines()[-1:] or ["failed"]}
        return out
    f = json.loads((work / "figaroh_out.json").read_text())
    e_cal = np.linalg.norm(np.array(f["cal"]) - cal.positions, axis=1)
    e_val = np.linalg.norm(np.array(f["val"]) - val.positions, axis=1)
    out["figaroh"] = {"parameters": f["parameters"], "seconds": f["seconds"],
                      "status": f["status"],
                      "calibration_mean_mm": float(e_cal.mean() * 1e3),
                      "validation_mean_mm": float(e_val.mean() * 1e3)}
    return out


def write_page(d: dict[str, Any], path: Path) -> None:
    f = d["figaroh"]
    lines = [
        "# plugcell beside FIGAROH on the same twin data",
        "",
        "Generated by `benchmarks/calibration_figaroh.py` (do not edit by hand). FIGAROH "
        "(pip `figaroh`) runs in its own interpreter on files this script writes: a URDF of "
        "the Smart H4's serial equivalent (eq. 6.3, generated from plugcell's description), "
        "its configuration (`full_params`, unknown base and tool frames) and the measured "
        "positions. It models serial chains only: no parallelogram, no deflection. Same "
        f"twin campaign (seed {d['seed']}, unloaded), {d['poses']['calibration']} calibration "
        f"and {d['poses']['validation']} independent validation poses; FIGAROH fits positions, "
        "so the plugcell rows marked *positions* are the like-for-like comparison.",
        "",
        "| calibrator | model | data | parameters | validation mean (mm) | calibration mean "
        "(mm) | time (s) |",
        "|---|---|---|---|---|---|---|",
    ]
    for k, v in d["plugcell"].items():
        lines.append(f"| plugcell | {k.split('/')[0]} ({v['name']}) | {v['data']} | "
                     f"{v['parameters']} | {v['validation_mean_mm']:.3f} | "
                     f"{v['calibration_mean_mm']:.3f} | {v['seconds']:.3f} |")
    if "error" in f:
        lines.append(f"| FIGAROH | serial | positions | | failed: {f['error']} | | |")
    else:
        lines.append(f"| FIGAROH | serial (URDF) | positions | {f['parameters']} | "
                     f"{f['validation_mean_mm']:.3f} | {f['calibration_mean_mm']:.3f} | "
                     f"{f['seconds']:.3f} |")
    lines += ["", "Same serial model, same data: the two calibrators agree; the loop and "
              "gravity models, which FIGAROH cannot express, are what make the difference. "
              "Times include BASE/PROBE estimation and identifiability analysis (plugcell) "
              "and `initialize` + `solve` (FIGAROH).", ""]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines), encoding="utf-8")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--figaroh-python", default=sys.executable,
                    help="an interpreter with figaroh installed (default: this one)")
    ap.add_argument("--work-dir", type=Path, default=Path("/tmp/plugcell-figaroh"))
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "results" / "figaroh.md")
    args = ap.parse_args()
    d = run(args.figaroh_python, args.work_dir, args.seed)
    write_page(d, args.out)
    if args.json:
        print(json.dumps(d, indent=2))
        return 0
    print(f"twin seed {d['seed']}, {d['poses']['calibration']} calibration / "
          f"{d['poses']['validation']} validation poses, validation mean position error:")
    for k, v in d["plugcell"].items():
        print(f"  plugcell {k:18s} ({v['name']}, {v['parameters']} params): "
              f"{v['validation_mean_mm']:.3f} mm (calibration {v['calibration_mean_mm']:.3f}; "
              f"nominal {v['validation_before_mm']:.3f}) in {v['seconds']:.3f} s")
    f = d["figaroh"]
    print("  (FIGAROH fits positions only: compare with the plugcell rows marked 'positions')")
    if "error" in f:
        print(f"  FIGAROH failed: {f['error']}")
    else:
        print(f"  FIGAROH (serial robot, {f['parameters']} params): {f['validation_mean_mm']:.3f}"
              f" mm (calibration {f['calibration_mean_mm']:.3f}) in {f['seconds']:.3f} s "
              f"[{f['status']}]")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
