"""UR10 end to end from its vendor description: xacro in, calibration, UR kinematics file out.

ur_description's ``ur.urdf.xacro`` (``ur_type:=ur10``, ../shared/data/urdf) is imported
(plugcell.io.urdf), its nominal FK compared with pinocchio's FK of the same URDF, the
IPA series A (../shared/data/ipa-robot-accuracy) calibrated with it (model 1) and
validated on B, C, D exactly as ``benchmarks/calibration_ur10.py`` does with the
hand-written DH — side by side — then the calibration exported as
``default_kinematics.yaml``, the official xacro expanded again with it, and pinocchio's
FK of that URDF compared with plugcell's calibrated model; the same for the exported
URDF with BASE and PROBE.  Writes ``docs/results/urdf_ur10.md``.

    .venv/bin/python benchmarks/urdf_roundtrip_ur10.py [--shared DIR] [--work-dir DIR]
                                                      [--out docs/results/urdf_ur10.md]
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import time
from pathlib import Path
from typing import Any

import numpy as np

from plugcell.calibration import CalibrationData, Calibrator
from plugcell.io.export import export_calibration
from plugcell.io.robots import RobotSource, load_robot
from plugcell.io.urdf import import_urdf
from plugcell.kinematics import forward
from plugcell.kinematics.rotations import angles_to_matrix

try:
    from calibration_ur10 import SERIES, read_series, ur10_toml
except ImportError:  # run from elsewhere
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from calibration_ur10 import SERIES, read_series, ur10_toml

ROOT = Path(__file__).resolve().parents[1]
ARGS = {"ur_type": "ur10", "name": "ur10"}


def pinocchio_poses(urdf: str, joints: tuple[str, ...], frame: str, q: np.ndarray) -> np.ndarray:
    """``(N, 4, 4)`` poses of ``frame`` by pinocchio for joint values ``q`` (N, 6)."""
    import pinocchio as pin

    model = pin.buildModelFromXML(urdf)
    data = model.createData()
    fid = model.getFrameId(frame)
    idx = [model.joints[model.getJointId(j)].idx_q for j in joints]
    out = np.empty((len(q), 4, 4))
    for k, row in enumerate(q):
        qp = pin.neutral(model)
        qp[idx] = row
        pin.framesForwardKinematics(model, data, qp)
        out[k] = data.oMf[fid].homogeneous
    return out


def pose_diff(A: np.ndarray, B: np.ndarray) -> tuple[float, float]:
    """Largest position (m) and rotation (rad) difference."""
    R = np.einsum("nji,njk->nik", A[:, :3, :3], B[:, :3, :3])
    s = np.linalg.norm(R - np.eye(3), axis=(1, 2)) / (2 * math.sqrt(2))
    return (float(np.abs(A[:, :3, 3] - B[:, :3, 3]).max()),
            float((2 * np.arcsin(np.clip(s, 0, 1))).max()))


def summary(stats: Any) -> dict[str, float]:
    return {"mean": stats.position.norm.mean * 1e3, "max": stats.position.norm.max * 1e3}


def calibrate(desc: Any, sets: dict[str, CalibrationData]) -> tuple[Any, list[tuple]]:
    res = Calibrator(desc, "serial").fit(sets["A"])
    rows = [("calibration A", summary(res.calibration_before), summary(res.calibration))]
    for v in "BCD":
        b, a = res.evaluate(sets[v], refit_base=True)
        rows.append((f"validation {v}, BASE refit", summary(b), summary(a)))
    for v in "BCD":
        b, a = res.evaluate(sets[v], refit_base=True, refit_probe=True)
        rows.append((f"validation {v}, BASE + PROBE refit", summary(b), summary(a)))
    return res, rows


def run(shared: Path, work: Path) -> dict[str, Any]:
    work.mkdir(parents=True, exist_ok=True)
    xacro = shared / "data" / "urdf" / "ur_description" / "urdf" / "ur.urdf.xacro"
    t = time.perf_counter()
    imp = import_urdf(xacro, ARGS)
    t_import = time.perf_counter() - t
    desc = imp.description
    rng = np.random.default_rng(0)
    q1000 = rng.uniform(desc.joint_limits[:, 0], desc.joint_limits[:, 1], size=(1000, 6))
    nominal = pose_diff(forward(desc, None, q1000).world_tcp,
                        pinocchio_poses(imp.urdf, desc.actuated, "tool0", q1000))
    (work / "ur10_dh.toml").write_text(ur10_toml(), encoding="utf-8")
    hand = load_robot(work / "ur10_dh.toml")
    sets = {}
    for key, (rel, _) in SERIES.items():
        q, p, a = read_series(shared / "data" / "ipa-robot-accuracy" / rel)
        sets[key] = CalibrationData(q, p, angles_to_matrix(a, "xyz"))
    t = time.perf_counter()
    res, rows = calibrate(desc, sets)
    t_cal = time.perf_counter() - t
    _, rows_hand = calibrate(hand, sets)
    src = RobotSource(str(xacro), ARGS)
    # UR kinematics file → the official xacro again → pinocchio
    ur = export_calibration(res, desc, "ur-kinematics", source=src, params_path="(benchmark)")
    yaml_path = work / "default_kinematics.yaml"
    yaml_path.write_text(ur.text, encoding="utf-8")
    again = import_urdf(xacro, {**ARGS, "kinematics_params": str(yaml_path)})
    assert ur.side is not None
    base = np.array(ur.side["base"]["matrix"])
    tcp = np.array(ur.side["tcp_in_tip"]["matrix"])
    model_1000 = res.model.predict(q1000)
    yaml_1000 = pose_diff(base @ pinocchio_poses(again.urdf, desc.actuated, "tool0", q1000) @ tcp,
                          model_1000)
    qa = sets["A"].q
    yaml_a = pose_diff(base @ pinocchio_poses(again.urdf, desc.actuated, "tool0", qa) @ tcp,
                       res.model.predict(qa))
    # URDF with BASE and PROBE → pinocchio
    urdf = export_calibration(res, desc, "urdf", source=src, include_base=True,
                              include_probe=True, params_path="(benchmark)")
    (work / "ur10_calibrated.urdf").write_text(urdf.text, encoding="utf-8")
    urdf_1000 = pose_diff(pinocchio_poses(urdf.text, desc.actuated, "probe", q1000), model_1000)
    # the re-expanded xacro, calibrated on nothing, has the calibrated accuracy on series B
    return {"t_import": t_import, "t_cal": t_cal, "nominal": nominal, "rows": rows,
            "rows_hand": rows_hand, "yaml_1000": yaml_1000, "yaml_a": yaml_a,
            "urdf_1000": urdf_1000, "yaml": ur.text, "flange": ur.side["flange_correction"],
            "n_params": len(res.keys), "poses_a": len(qa)}


def write_page(d: dict[str, Any], path: Path) -> list[str]:
    diff = max(abs(a[k] - b[k]) for (_, *ra), (_, *rb) in zip(d["rows"], d["rows_hand"],
                                                              strict=True)
               for a, b in zip(ra, rb, strict=True) for k in ("mean", "max"))
    lines = [
        "# UR10 from its vendor description: xacro in, calibration, UR kinematics out",
        "",
        "Generated by `benchmarks/urdf_roundtrip_ur10.py` (do not edit by hand); "
        f"{platform.machine()} {platform.processor() or ''}, Python "
        f"{platform.python_version()} ({os.cpu_count()} cores).",
        "",
        "1. `ur_description/urdf/ur.urdf.xacro` with `ur_type:=ur10 name:=ur10` imported "
        f"(xacro + URDF + exact DH/Hayati conversion) in {d['t_import']:.2f} s; nominal FK of "
        "`tool0` against pinocchio's FK of the same URDF, 1 000 random configurations: "
        f"largest difference {d['nominal'][0]:.1e} m, {d['nominal'][1]:.1e} rad.",
        f"2. IPA series A ({d['poses_a']} poses) calibrated with the imported robot, model 1 "
        f"({d['n_params']} parameters, {d['t_cal']:.1f} s with the validations), validated "
        "as in [ur10.md](ur10.md). Mean / max position error (mm):",
        "",
        "| set | nominal (imported) | calibrated (imported) | nominal (hand DH) | "
        "calibrated (hand DH) |",
        "|---|---|---|---|---|",
    ]
    for (label, b, a), (_, bh, ah) in zip(d["rows"], d["rows_hand"], strict=True):
        lines.append(f"| {label} | {b['mean']:.3f} / {b['max']:.3f} | {a['mean']:.3f} / "
                     f"{a['max']:.3f} | {bh['mean']:.3f} / {bh['max']:.3f} | "
                     f"{ah['mean']:.3f} / {ah['max']:.3f} |")
    lines += [
        "",
        f"Largest difference between the imported and the hand-written robot over the table: "
        f"{diff:.1e} mm (the requirement: 0.002 mm).",
        "",
        "3. Exported as `default_kinematics.yaml` (`plugcell export --format ur-kinematics`), "
        "the official xacro expanded again with `kinematics_params:=` that file, and "
        "pinocchio's FK of `tool0` (with BASE and the TCP of the side file) compared with "
        "plugcell's calibrated model: 1 000 random configurations "
        f"{d['yaml_1000'][0]:.1e} m / {d['yaml_1000'][1]:.1e} rad; the {d['poses_a']} poses "
        f"of series A {d['yaml_a'][0]:.1e} m / {d['yaml_a'][1]:.1e} rad.",
        "4. Exported as URDF with BASE and PROBE (`--format urdf --include-base "
        "--include-probe`): pinocchio's FK of `probe` against the calibrated model, 1 000 "
        f"configurations: {d['urdf_1000'][0]:.1e} m / {d['urdf_1000'][1]:.1e} rad.",
        "",
        "The exported kinematics file:",
        "",
        "```yaml",
        d["yaml"].rstrip(),
        "```",
        "",
        "A UR kinematics file holds joint origins only: the calibrated offset of the flange "
        "across / its tilt against the last axis (Δa, Δα of the last row, identified "
        "together with the probe) has no place in it and goes into the TCP of the side "
        "file (`tcp_in_tip`); here it is "
        f"{np.linalg.norm(np.array(d['flange']['xyz_mm'])):.3f} mm.",
        "",
        "The same with the command line:",
        "",
        "```",
        "X=../shared/data/urdf/ur_description/urdf/ur.urdf.xacro",
        "plugcell calibrate --robot $X --robot-arg ur_type=ur10 --robot-arg name=ur10 \\",
        "    --model serial --data WORK/series_A.csv --validate WORK/series_B.csv \\",
        "    --validate-refit base --out ur10_params.json",
        "plugcell export --params ur10_params.json --format ur-kinematics "
        "--out default_kinematics.yaml",
        "plugcell kin describe --robot $X --robot-arg ur_type=ur10 --robot-arg name=ur10 \\",
        "    --robot-arg kinematics_params:=$PWD/default_kinematics.yaml --format toml",
        "```",
        "",
        "(`WORK/series_*.csv`: written by `benchmarks/calibration_ur10.py`.)",
        "",
    ]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines), encoding="utf-8")
    return lines


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shared", type=Path, default=ROOT.parent / "shared")
    ap.add_argument("--work-dir", type=Path, default=Path("/tmp/plugcell-urdf-ur10"))
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "results" / "urdf_ur10.md")
    args = ap.parse_args()
    if not (args.shared / "data" / "urdf").is_dir():
        print(f"skipped: {args.shared / 'data'} not found (give --shared DIR)")
        return 0
    d = run(args.shared, args.work_dir)
    lines = write_page(d, args.out)
    print("\n".join(ln for ln in lines if ln.startswith(("|", "1.", "2.", "3.", "4.", "Largest"))))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
