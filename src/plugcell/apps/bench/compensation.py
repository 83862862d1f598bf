"""Throughput of model-based compensation (``plugcell bench compensation``, issue 4).

A deterministic batch of ``n`` target tool poses inside the robot's working volume
(random joint configurations within the limits whose nominal T-MAC point lies in
the working-volume box, each pose displaced by a few millimetres and tenths of a
degree), an identified-like model 5 (loop + gravity + payload, every parameter
drawn at the size the twin's errors have), 36 kg.  Two timings:

* ``model_stage`` — steps b.–f. of 6.5.1 from the controller's nominal joints
  (:func:`~plugcell.compensation.model_based.compensate_joints`): what the thesis's
  ``H4Compensation`` does with the joints ``POS_TO_JNTP`` hands it (8.3.2);
* ``with_nominal_ik`` — the whole of 6.5.1 including the nominal inverse kinematics
  (:func:`~plugcell.compensation.model_based.compensate`): program filtering.

The robot description is the one file this module reads (lazily, through
:mod:`plugcell.io.robots`), because a benchmark needs a real robot.
"""

from __future__ import annotations

import platform
import time
from typing import Any

import numpy as np
from numpy.typing import NDArray

from plugcell.calibration.model import ErrorModel
from plugcell.compensation.model_based import compensate, compensate_joints, nominal_joints
from plugcell.compensation.pose_model import IdentifiedModel
from plugcell.kinematics import RobotDescription, so3_exp

Array = NDArray[np.float64]

__all__ = ["bench_model", "bench_targets", "run"]

#: The issue's throughput target (targets per second).
TARGET_PER_S = 10_000.0


def bench_model(desc: RobotDescription, seed: int = 0, payload_ref_kg: float = 36.0
                ) -> IdentifiedModel:
    """Model 5 of ``desc`` with every error drawn at the twin's size (0.5 mm, 0.03°;
    deflection constants giving ~1 mm at the TCP), seeded."""
    em = ErrorModel.create(desc, "loop", gravity=True, payload=True,
                           payload_ref_kg=payload_ref_kg)
    rng = np.random.default_rng(seed)
    angle = np.radians(0.03)
    scale = np.array([angle if p.is_geometric and p.is_angle else 5e-4 for p in em.space])
    return IdentifiedModel(em.with_values(scale * rng.standard_normal(len(em.space))))


def bench_targets(model: IdentifiedModel, n: int, seed: int = 0) -> Array:
    """``n`` target poses ``(n, 4, 4)`` in the working volume (module docstring)."""
    desc = model.description
    rng = np.random.default_rng(seed)
    lo, hi = desc.joint_limits[:, 0], desc.joint_limits[:, 1]
    box = desc.working_volume
    found: list[Array] = []
    count = 0
    while count < n:
        q = lo + rng.random((4 * n + 64, desc.n_readings)) * (hi - lo)
        q = q[desc.within_limits(q)]
        T = model.pose(q, 0.0)
        keep = box.contains(T[:, :3, 3]) if box is not None else np.ones(len(T), bool)
        found.append(T[keep])
        count += int(keep.sum())
    T = np.concatenate(found)[:n]
    T[:, :3, 3] += rng.normal(0.0, 3e-3, (n, 3))
    T[:, :3, :3] = so3_exp(rng.normal(0.0, 3e-3, (n, 3))) @ T[:, :3, :3]
    return T


def run(n: int = 10_000, seed: int = 0, payload_kg: float = 36.0) -> dict[str, Any]:
    """Time model-based compensation of ``n`` targets; returns a JSON-ready dict."""
    from plugcell.io.robots import load_robot

    if n < 1:
        raise ValueError(f"n must be positive, got {n}")
    desc = load_robot("smart_h4")
    model = bench_model(desc, seed)
    T = bench_targets(model, n, seed + 1)
    t0 = time.perf_counter()
    q_nom, ok, _ = nominal_joints(model, T)
    t_ik = time.perf_counter() - t0
    T_ok, q_ok = T[ok], q_nom[ok]
    compensate_joints(model, T_ok[: min(64, len(T_ok))], q_ok[:64], payload_kg)  # warm-up
    t0 = time.perf_counter()
    stage = compensate_joints(model, T_ok, q_ok, payload_kg, raise_errors=False)
    t_stage = time.perf_counter() - t0
    t0 = time.perf_counter()
    full = compensate(model, T, payload_kg, raise_errors=False)
    t_full = time.perf_counter() - t0
    m = len(T_ok)
    return {
        "benchmark": "model-based compensation (thesis 6.5.1)",
        "robot": desc.name, "model": "5 (loop + gravity + payload)",
        "parameters": len(model.error_model.space), "payload_kg": payload_kg,
        "n": n, "nominal_ik_ok": m,
        "model_stage": {
            "targets": m, "seconds": t_stage, "targets_per_s": m / t_stage,
            "iterations_mean": float(stage.iterations.mean()),
            "iterations_max": int(stage.iterations.max()),
            "converged": int(stage.ok.sum()), "residual_max": float(stage.residual.max()),
        },
        "nominal_ik": {"targets": n, "seconds": t_ik, "targets_per_s": n / t_ik},
        "with_nominal_ik": {
            "targets": n, "seconds": t_full, "targets_per_s": n / t_full,
            "converged": int(full.ok.sum()),
        },
        "target_per_s": TARGET_PER_S,
        "meets_target": m / t_stage >= TARGET_PER_S,
        "machine": {"python": platform.python_version(), "numpy": np.__version__,
                    "processor": platform.machine()},
    }


def format_report(r: dict[str, Any]) -> str:
    """A small table of :func:`run`'s result."""
    rows = [
        ("model stage (6.5.1 b–f, from nominal joints)", r["model_stage"]),
        ("nominal IK alone (POS_TO_JNTP)", r["nominal_ik"]),
        ("whole 6.5.1 incl. nominal IK", r["with_nominal_ik"]),
    ]
    out = [f"model-based compensation, {r['robot']}, model {r['model']}, "
           f"all {r['parameters']} of its parameters set (a calibration identifies those its "
           f"data determine), {r['payload_kg']:g} kg, {r['n']} targets",
           f"{'':48s} {'targets':>8s} {'seconds':>8s} {'targets/s':>10s}"]
    for label, d in rows:
        out.append(f"{label:48s} {d['targets']:8d} {d['seconds']:8.3f} {d['targets_per_s']:10.0f}")
    ms = r["model_stage"]
    out.append(f"model stage: {ms['iterations_mean']:.2f} iterations on average (max "
               f"{ms['iterations_max']}), residual ≤ {ms['residual_max']:.1e}; target "
               f"≥ {r['target_per_s']:.0f}/s: {'met' if r['meets_target'] else 'NOT met'}")
    return "\n".join(out)
