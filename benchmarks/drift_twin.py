"""The drift watch over a simulated 8-hour shift on the digital twin (issue 19 §3).

The Smart H4 twin is calibrated (model 4, 150 poses) at 20 °C; four reference nests on
the robot's foundation are registered with the identified BASE.  Then the hall warms
up through a shift (``plugcell.sim.twin.thermal.shift_temperature``: +6 K, a gate opened
at 4 h) and the cell drifts with it (``ThermalDrift``: BASE moves ~10 µm/K and turns
~5 µrad/K as seen from the tracker; the arm's lengths grow 12·10⁻⁶/K).  Every 15
minutes twelve fixed test poses are measured and compared with the model's
prediction — with the BASE of the calibration (no watch) and with the BASE the watch
keeps: every 30 minutes it measures the nests, estimates the 6-DOF drift and
re-registers BASE when the displacement at the nests exceeds 0.05 mm.  The shift is
run twice: with the full drift, and with the arm's expansion off (BASE drift only), to
show what the watch removes and what it cannot (the arm's own growth — the thermal
term κT of the calibration is for that, given a campaign that spans temperatures).
Writes docs/results/drift-watch.md (+ a plot).

    .venv/bin/python benchmarks/drift_twin.py [--seed 0] [--json]
                                              [--out docs/results/drift-watch.md]
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from plugcell.calibration import CalibrationData, Calibrator
from plugcell.metrology.drift import estimate_base_drift, nests_in_base
from plugcell.sim.twin.campaign import measure_nests, measure_poses, working_volume_joints
from plugcell.sim.twin.robot import RobotTwin
from plugcell.sim.twin.scenario import TwinScenario
from plugcell.sim.twin.thermal import ThermalDrift, shift_temperature
from plugcell.sim.twin.tracker import LaserTracker

ROOT = Path(__file__).resolve().parents[1]
THRESHOLD_M = 0.05e-3


def with_base(model: Any, base: np.ndarray) -> Any:
    """``model`` with BASE replaced (reference = base, BASE parameters zero)."""
    v = np.array(model.values)
    for i, p in enumerate(model.space):
        if p.kind == "base":
            v[i] = 0.0
    return model.with_references(base=base).with_values(v)


def run_shift(drift: ThermalDrift, seed: int, hours: float = 8.0) -> dict[str, Any]:
    robot = RobotTwin(TwinScenario(seed=seed))
    robot.set_thermal_drift(drift, 20.0)
    tracker = LaserTracker(seed=seed)
    profile = robot.reveal_truth().profile
    rng = np.random.default_rng(seed + 7)
    q_cal = working_volume_joints(robot.description, profile, 150, rng)
    cal, _ = measure_poses(robot, tracker, q_cal)
    res = Calibrator(robot.description, "loop+gravity").fit(CalibrationData.from_measurements(cal))
    nests = nests_in_base(res.model.base(), measure_nests(robot, tracker))
    q_test = working_volume_joints(robot.description, profile, 12, rng)
    base_watch = res.model.base()
    rows = []
    for k, t_h in enumerate(np.arange(0.0, hours + 1e-9, 0.25)):
        T = float(shift_temperature(t_h))
        robot.set_temperature(T)
        event = None
        if k % 2 == 0:  # every 30 minutes
            est = estimate_base_drift(base_watch, nests, measure_nests(robot, tracker),
                                      threshold_m=THRESHOLD_M)
            event = {"displacement_mm": est.displacement_m * 1e3, "alarm": est.alarm,
                     "consistent": est.consistent}
            if est.alarm and est.consistent:
                base_watch = est.base
        m, _ = measure_poses(robot, tracker, q_test)
        d = CalibrationData.from_measurements(m)
        err = {}
        for name, model in (("no_watch", res.model), ("watch", with_base(res.model, base_watch))):
            P = model.predict(d.q, d.payload_kg)
            err[name] = float(np.linalg.norm(d.positions - P[:, :3, 3], axis=1).mean() * 1e3)
        rows.append({"t_h": float(t_h), "temperature_c": T, **err, "check": event})
    alarms = sum(1 for r in rows if r["check"] and r["check"]["alarm"])
    checks = sum(1 for r in rows if r["check"])
    return {"drift": {"length_per_k": drift.length_per_k,
                      "base_translation_m_per_k": list(drift.base_translation_m_per_k),
                      "base_rotation_rad_per_k": list(drift.base_rotation_rad_per_k)},
            "calibrated_mm": res.calibration.position.norm.mean * 1e3, "rows": rows,
            "alarms": alarms, "checks": checks}


def plot(d: dict[str, Any], path: Path) -> bool:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return False
    fig, ax = plt.subplots(figsize=(7.0, 3.8))
    for run, style in ((d["full"], "-"), (d["base_only"], "--")):
        t = [r["t_h"] for r in run["rows"]]
        lab = "full drift" if style == "-" else "BASE drift only"
        ax.plot(t, [r["no_watch"] for r in run["rows"]], "C3" + style, label=f"no watch, {lab}")
        ax.plot(t, [r["watch"] for r in run["rows"]], "C0" + style, label=f"watch, {lab}")
    ax.set_xlabel("time into the shift (h)")
    ax.set_ylabel("mean position error (mm)")
    ax2 = ax.twinx()
    run = d["full"]
    ax2.plot([r["t_h"] for r in run["rows"]], [r["temperature_c"] for r in run["rows"]],
             "0.6", lw=1)
    ax2.set_ylabel("temperature (°C)", color="0.5")
    ax.legend(fontsize=7, loc="upper left")
    ax.set_title("Smart H4 twin, 8-hour shift: drift watch every 30 min (0.05 mm)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return True


def write_page(d: dict[str, Any], path: Path, image: bool) -> None:
    L = ["# Drift watch over an 8-hour shift (digital twin)", "",
         "Generated by `benchmarks/drift_twin.py` (do not edit by hand); "
         f"{d['machine']}, twin seed {d['seed']}, {d['elapsed_s']:.0f} s.", "",
         "Protocol: model 4 calibrated at 20 °C from 150 poses; four reference nests on the "
         "foundation registered with its BASE (`plugcell drift register`). Through the shift "
         "the hall warms by up to 6 K (`plugcell.sim.twin.thermal.shift_temperature`, a gate "
         "opened at 4 h), BASE drifts as seen from the tracker and the arm's lengths grow "
         "(`ThermalDrift`, assumed: "
         f"{np.array(d['full']['drift']['base_translation_m_per_k']) * 1e6} µm/K, "
         f"{np.array(d['full']['drift']['base_rotation_rad_per_k']) * 1e6} µrad/K, arm "
         f"{d['full']['drift']['length_per_k'] * 1e6:g}·10⁻⁶/K). Every 30 min the watch "
         "measures the nests, estimates the 6-DOF drift of BASE and re-registers it above "
         "0.05 mm at the nests (`plugcell drift check --update`); every 15 min twelve fixed "
         "test poses are measured and predicted with the calibration's BASE (no watch) and "
         "with the watched BASE. Mean position error of the test poses (mm):", "",
         "| t (h) | T (°C) | full drift: no watch | full drift: watch | BASE drift only: "
         "no watch | BASE drift only: watch | check (full drift) |",
         "|---|---|---|---|---|---|---|"]
    for a, b in zip(d["full"]["rows"], d["base_only"]["rows"], strict=True):
        if abs(a["t_h"] * 2 - round(a["t_h"] * 2)) > 1e-9:
            continue
        c = a["check"]
        chk = "" if c is None else (f"{c['displacement_mm']:.3f} mm"
                                    + (" **alarm → re-registered**" if c["alarm"] else ""))
        L.append(f"| {a['t_h']:.1f} | {a['temperature_c']:.2f} | {a['no_watch']:.3f} | "
                 f"{a['watch']:.3f} | {b['no_watch']:.3f} | {b['watch']:.3f} | {chk} |")
    f, b = d["full"], d["base_only"]

    def worst(run: dict[str, Any], key: str) -> float:
        return max(r[key] for r in run["rows"])

    L += ["", f"Calibrated accuracy at 20 °C: {f['calibrated_mm']:.3f} mm. Worst test-pose "
          f"mean error over the shift — full drift: no watch {worst(f, 'no_watch'):.3f}, "
          f"watch {worst(f, 'watch'):.3f} mm ({f['alarms']} alarms in {f['checks']} checks); "
          f"BASE drift only: no watch {worst(b, 'no_watch'):.3f}, watch "
          f"{worst(b, 'watch'):.3f} mm ({b['alarms']} alarms). The watch removes the drift "
          "of BASE; what is left with the full drift is the arm's own thermal growth, which "
          "fixed nests cannot see — the thermal term κT (`calibrate --thermal`) from a "
          "campaign that spans temperatures models it, with the cell's temperature reading.",
          ""]
    if image:
        L += ["![drift watch](drift-watch.png)", ""]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(L), encoding="utf-8")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "results" / "drift-watch.md")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    t0 = time.perf_counter()
    drift = ThermalDrift()
    full = run_shift(drift, args.seed)
    base_only = run_shift(replace(drift, length_per_k=0.0), args.seed)
    d = {"machine": f"{platform.machine()}, Python {platform.python_version()}",
         "seed": args.seed, "full": full, "base_only": base_only,
         "elapsed_s": time.perf_counter() - t0}
    image = plot(d, args.out.parent / "drift-watch.png")
    write_page(d, args.out, image)
    for name, run in (("full drift", full), ("BASE drift only", base_only)):
        print(f"{name}: worst no watch {max(r['no_watch'] for r in run['rows']):.3f} mm, "
              f"watch {max(r['watch'] for r in run['rows']):.3f} mm, "
              f"{run['alarms']}/{run['checks']} alarms")
    if args.json:
        print(json.dumps(d, indent=2, default=float))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
