"""Calibrate a real UR10 from the IPA robot-accuracy data set (Landgraf et al. 2021, MIT).

The data (../shared/data/ipa-robot-accuracy/, four series, 16 811 poses): joint
readings of a UR10 and Leica tracker measurements of a T-MAC on its flange (mm,
degrees).  The tracker-to-base and flange-to-T-MAC transforms are unknown; the
calibrator estimates them from the data (AX = YB) and identifies the standard
30-parameter serial model (4·6 + 6, thesis model 1; the UR10 has no loop).

For each series as the calibration set, the other three validate.  The script
converts each series to plugcell's measurement-file format (degrees, mm) and
writes a UR10 description file (the issue's nominal DH) into ``--work-dir``, so
the same result can be obtained with ``plugcell calibrate``; it writes the
results to ``docs/results/ur10.md``.

    .venv/bin/python benchmarks/calibration_ur10.py [--data DIR] [--work-dir DIR]
                                                    [--out docs/results/ur10.md] [--json]
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from plugcell.calibration import CalibrationData, Calibrator
from plugcell.io.measurements import MeasurementSet, write_measurements
from plugcell.io.robots import load_robot
from plugcell.kinematics.rotations import angles_to_matrix, matrix_to_angles

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_DATA = ROOT.parent / "shared" / "data" / "ipa-robot-accuracy"
SERIES = {
    "A": ("Series_A/measurements_grid.csv", "grid"),
    "B": ("Series_B/measurements_joint_configurations.csv", "joint configurations"),
    "C": ("Series_C/measurements_random_poses.csv", "random poses"),
    "D": ("Series_D/measurements_iso_cubes.csv", "ISO cubes"),
}
JOINTS = ("shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint",
          "wrist_2_joint", "wrist_3_joint")

#: The UR10 nominal DH (issue 3), a and d in m, α in degrees, θ offsets 0.
UR10_TOML = """# Universal Robots UR10, nominal DH (issue 3); by benchmarks/calibration_ur10.py.
format_version = 1
name = "ur10"
actuated = ["1", "2", "3", "4", "5", "6"]
flange = "6"
home = [0.0, -90.0, 90.0, -90.0, -90.0, 0.0]
{links}
"""
_A = (0.0, -0.612, -0.5723, 0.0, 0.0, 0.0)
_D = (0.1273, 0.0, 0.0, 0.163941, 0.1157, 0.0922)
_ALPHA = (90.0, 0.0, 0.0, 90.0, -90.0, 0.0)


#: Link masses (kg) of the UR10 as Universal Robots publish them for its dynamic model;
#: the centres of mass (m, link frames) are our rough estimates — for the gravity
#: compliance of model 3 only.
_MASS = (7.1, 12.7, 4.27, 2.0, 2.0, 0.365)
_COM = ((0.0, -0.02, 0.0), (0.306, 0.0, 0.175), (0.286, 0.0, 0.05), (0.0, 0.0, 0.0),
        (0.0, 0.0, 0.0), (0.0, 0.0, -0.02))


def ur10_toml(masses: bool = False) -> str:
    links = []
    for i in range(6):
        extra = f"mass = {_MASS[i]}\ncom = {list(_COM[i])}\n" if masses else ""
        links.append(
            "[[links]]\n"
            f'name = "{i + 1}"\nparent = "{"base" if i == 0 else i}"\njoint = "actuated"\n'
            f"d = {_D[i]}\na = {_A[i]}\nalpha = {_ALPHA[i]}\nlimits = [-360.0, 360.0]\n{extra}")
    return UR10_TOML.format(links="\n".join(links))


def read_series(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Joint readings (rad), T-MAC positions (m) and rx, ry, rz (rad) of one series."""
    lines = path.read_text(encoding="utf-8").splitlines()
    header = lines[0].split(";")
    col = {h: i for i, h in enumerate(header)}
    rows = np.array([[float(x.replace(",", ".")) for x in ln.split(";")]
                     for ln in lines[1:] if ln.strip()])
    q = rows[:, [col[c] for c in JOINTS]]
    p = rows[:, [col[c] for c in ("measurement_x", "measurement_y", "measurement_z")]] / 1e3
    a = np.radians(rows[:, [col[c] for c in ("measurement_rx", "measurement_ry",
                                             "measurement_rz")]])
    return q, p, a


def _summary(stats: Any) -> dict[str, float]:
    p = stats.position.norm
    out = {"mean_mm": p.mean * 1e3, "std_mm": p.std * 1e3, "max_mm": p.max * 1e3}
    if stats.orientation is not None:
        out["orientation_mean_deg"] = math.degrees(stats.orientation.norm.mean)
    return out


def run(data_dir: Path, work_dir: Path, convention: str = "xyz") -> dict[str, Any]:
    work_dir.mkdir(parents=True, exist_ok=True)
    (work_dir / "ur10.toml").write_text(ur10_toml(), encoding="utf-8")
    (work_dir / "ur10_masses.toml").write_text(ur10_toml(masses=True), encoding="utf-8")
    desc = load_robot(work_dir / "ur10.toml")
    desc_m = load_robot(work_dir / "ur10_masses.toml")
    sets: dict[str, CalibrationData] = {}
    for key, (rel, _) in SERIES.items():
        q, p, a = read_series(data_dir / rel)
        R = angles_to_matrix(a, convention)
        sets[key] = CalibrationData(q, p, R)
        ms = MeasurementSet(q, p, matrix_to_angles(R, "rpy"), "rpy", None)
        write_measurements(work_dir / f"series_{key}.csv", ms,
                           comments=[f"IPA robot-accuracy data set, series {key} "
                                     f"({SERIES[key][1]}); converted by calibration_ur10.py"])
    out: dict[str, Any] = {"convention": convention, "poses": {k: len(v) for k, v in sets.items()},
                           "runs": []}
    for cal_key in sets:
        t = time.perf_counter()
        res = Calibrator(desc, "serial").fit(sets[cal_key])
        elapsed = time.perf_counter() - t
        run_d: dict[str, Any] = {
            "calibration_series": cal_key, "parameters": len(res.keys),
            "iterations": res.iterations, "condition_number": res.statistics.condition_number,
            "time_s": elapsed, "warnings": list(res.warnings),
            "calibration": {"before": _summary(res.calibration_before),
                            "after": _summary(res.calibration)},
            "validation": {},
        }
        for val_key, val in sets.items():
            if val_key == cal_key:
                continue
            # the tracker stood elsewhere for each series: BASE re-identified on it for
            # both the nominal and the calibrated robot (geometry and PROBE kept) — and,
            # in case the T-MAC was remounted, BASE and PROBE re-identified
            before, after = res.evaluate(val, refit_base=True)
            b2, a2 = res.evaluate(val, refit_base=True, refit_probe=True)
            run_d["validation"][val_key] = {"before": _summary(before), "after": _summary(after),
                                            "before_probe_refit": _summary(b2),
                                            "after_probe_refit": _summary(a2)}
        g = Calibrator(desc_m, "serial+gravity").fit(sets[cal_key])
        run_d["model3"] = {"parameters": len(g.keys),
                           "calibration": _summary(g.calibration), "validation": {}}
        for val_key, val in sets.items():
            if val_key != cal_key:
                run_d["model3"]["validation"][val_key] = _summary(
                    g.evaluate(val, refit_base=True, refit_probe=True)[1])
        out["runs"].append(run_d)
        if cal_key == "C":
            out["parameters_from_C"] = res.parameter_table()
    return out


def write_page(d: dict[str, Any], path: Path) -> None:
    lines = [
        "# Real data: a UR10 calibrated from the IPA robot-accuracy data set",
        "",
        "Generated by `benchmarks/calibration_ur10.py` (do not edit by hand).",
        "",
        "Data: Landgraf et al. 2021 (MIT licence), a UR10 measured by a Leica tracker with a "
        "T-MAC, four series. The tracker-to-base and flange-to-T-MAC transforms are unknown and "
        "estimated from the data (AX = YB), then the standard serial model (thesis model 1, "
        "4·6 + 6 = 30 parameters; the UR10 has no loop) is identified on one series and "
        "validated on the three others. Orientation angles of the files: intrinsic X-Y-Z "
        f"(`{d['convention']}`) — the convention under which the data are consistent (rpy and "
        "zyz leave errors of hundreds of mm). *nominal*: nominal DH with BASE/PROBE fitted by "
        "least squares on the calibration series.",
        "",
        "Poses per series: " + ", ".join(f"{k} {n}" for k, n in d["poses"].items()) + ".",
        "",
        "| calibrated on | params | iter. | κ | time (s) | set | nominal mean / max (mm) | "
        "calibrated mean / max (mm) | orientation nominal → calibrated (°) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in d["runs"]:
        rows = [("calibration " + r["calibration_series"], r["calibration"]["before"],
                 r["calibration"]["after"])]
        rows += [(f"validation {k}, BASE refit", v["before"], v["after"])
                 for k, v in r["validation"].items()]
        rows += [(f"validation {k}, BASE + PROBE refit", v["before_probe_refit"],
                  v["after_probe_refit"]) for k, v in r["validation"].items()]
        for i, (label, b, a) in enumerate(rows):
            head = (f"| {r['calibration_series']} | {r['parameters']} | {r['iterations']} | "
                    f"{r['condition_number']:.0f} | {r['time_s']:.2f} " if i == 0
                    else "| | | | | ")
            lines.append(
                f"{head}| {label} | {b['mean_mm']:.3f} / {b['max_mm']:.3f} | "
                f"{a['mean_mm']:.3f} / {a['max_mm']:.3f} | "
                f"{b.get('orientation_mean_deg', math.nan):.4f} → "
                f"{a.get('orientation_mean_deg', math.nan):.4f} |")
    lines += [
        "",
        "Reading the table. The tracker stood at a different place for each series (the "
        "nominal BASE of one series is metres off for another), so a validation series needs "
        "its own BASE: it is re-identified on that series for the nominal and the calibrated "
        "robot alike (6 parameters from hundreds of poses; the robot's geometry stays as "
        "identified). Whether the T-MAC was remounted between series is not documented, so "
        "the table also shows BASE + PROBE re-identified. Series D measures (almost) one "
        "orientation — ISO 9283 cubes — so its PROBE offset along the flange axis cannot be "
        "separated from BASE: calibrated on D, the geometry transfers only with PROBE "
        "re-identified. Series C (random poses) covers a joint region of its own (joint 1 "
        "in [−308°, −180°], elbow angle ≥ 0) and transfers worst: a geometric model identified "
        "in one region extrapolates poorly to another. The ~0.4 mm left after every fit is "
        "not geometric; joint compliance (model 3, below) explains a part of it.",
    ]
    lines += ["", "### With joint compliance (model 3, serial + gravity)", "",
              "The description above has no masses. With the link masses Universal Robots "
              "publish (centres of mass estimated by us) the calibrator adds one compliance per "
              "joint whose gravity torque varies (eq. 4.15); validation with BASE + PROBE "
              "re-identified, calibrated mean position error (mm):", "",
              "| calibrated on | params | calibration | " + " | ".join(
                  f"validation {k}" for k in "ABCD") + " |",
              "|---|---|---|---|---|---|---|"]
    for r in d["runs"]:
        m3 = r["model3"]
        cells = []
        for k in "ABCD":
            if k == r["calibration_series"]:
                cells.append("—")
            else:
                v1 = r["validation"][k]["after_probe_refit"]["mean_mm"]
                cells.append(f"{m3['validation'][k]['mean_mm']:.3f} (model 1: {v1:.3f})")
        lines.append(f"| {r['calibration_series']} | {m3['parameters']} | "
                     f"{m3['calibration']['mean_mm']:.3f} | " + " | ".join(cells) + " |")
    lines += ["", "Warnings of the fits:", ""]
    for r in d["runs"]:
        for w in r["warnings"]:
            lines.append(f"* series {r['calibration_series']}: {w}")
    lines += ["", "Identified parameters (calibrated on series C):", "",
              "| parameter | value | σ | unit | stands for |", "|---|---|---|---|---|"]
    for p in d.get("parameters_from_C", []):
        scale, unit = (1e3, "mm") if p["unit"] == "m" else (
            (math.degrees(1.0), "deg") if p["unit"] == "rad" else (1.0, p["unit"]))
        lines.append(f"| {p['name']} | {p['value'] * scale:.4g} | {p['sigma'] * scale:.2g} | "
                     f"{unit} | {p['stands_for']} |")
    lines += ["", "The same with the command line (files written by the script):", "",
              "```", "plugcell calibrate --robot WORK/ur10.toml --model serial \\",
              "    --data WORK/series_B.csv --validate WORK/series_D.csv \\",
              "    --validate-refit base+probe \\",
              "    --out ur10_params.json --report ur10_report.html", "```", ""]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines), encoding="utf-8")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA)
    ap.add_argument("--work-dir", type=Path, default=Path("/tmp/plugcell-ur10"))
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "results" / "ur10.md")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    d = run(args.data, args.work_dir)
    write_page(d, args.out)
    if args.json:
        print(json.dumps(d, indent=2, default=float))
    else:
        for r in d["runs"]:
            v = "; ".join(f"{k} {s['before']['mean_mm']:.3f} -> {s['after']['mean_mm']:.3f} mm"
                          for k, s in r["validation"].items())
            c = r["calibration"]
            print(f"calibrated on {r['calibration_series']}: "
                  f"{c['before']['mean_mm']:.3f} -> {c['after']['mean_mm']:.3f} mm; "
                  f"validation {v}")
        print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
