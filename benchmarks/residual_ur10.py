"""The learned residual layer on a real UR10 (IPA robot-accuracy data set): honest validation.

Physical model: thesis model 3 (serial + joint compliance from the published link
masses), the model of docs/results/ur10.md.  On top of it the learned residual layer
(:mod:`plugcell.calibration.residual_model`: gradient boosting on sin/cos of the six
joint readings, residual in the robot base frame, in-domain test).

Protocol (stated on the page it writes, docs/results/ur10-residual.md):

(a) series A, **nested grouped 5-fold by 0.4 m cells**: each outer fold holds out
    whole 0.4 m cells of the workspace (target position in the robot base frame); on
    the other cells the physical model is identified, then the layer is fitted with
    its hyper-parameters chosen by an inner grouped 5-fold CV of those cells; the
    held-out cells are predicted by the physical and by the hybrid model.  No pose
    is ever evaluated by a model that saw it.
(b) calibrated on all of A (physical + layer), validated on B, C, D with BASE and
    PROBE re-identified on each (tracker moved, T-MAC perhaps remounted): physical
    vs hybrid, with the in-domain test and (for the record) without it.
(c) diagnostics: each series' own residual learned by grouped CV inside it (is the
    rest learnable there?), and A with the temperature column as a feature.
(d) the physical joint-angle harmonics (issue 19 §1): model 3 + harmonics of order 1
    and 2 identified on A (their σ), validated on B, C, D as in (b).
(e) the thermal expansion term κT (issue 19 §3) on each series' temperature column.
(f) how the representation was chosen (issue 19 "Show (b)"): the identified PROBE of
    each series (is the T-MAC lever the same?), and single-stage candidates — base
    frame vs joint-1 frame, all joints vs the arm-shape joints, position at the point vs
    a flange twist — scored on **A alone** by grouped CV over 0.4 m cells and over
    joint-1 sectors (the A-only stand-in for a set-up at another azimuth); their
    transfer to B, C, D is printed for the record and is not used for the choice.
    Two hypotheses for the part that does not transfer: H4, lost motion — candidates
    with the approach direction of each joint, sign(q_j[i] − q_j[i−1]) in timestamp
    order, as six more features; H5, a length scale per series (tracker scale,
    temperature) — after BASE + PROBE re-identification on B, C, D a similarity
    e ≈ δt + δθ × x + δs·x (x the target in the base frame) fitted by linear least
    squares to the physical and to the arm-shape candidate's position residuals, with
    and without δs.  H6, the tracker's own errors along its line of sight — A's position
    residual in the tracker frame (``E R_Bᵀ``) learned as a function of the measured
    target's azimuth, elevation and range, scored on A by the same grouped CV over cells,
    its transfer to B, C, D (each in its own re-identified tracker frame) recorded, with
    each series' spans of azimuth, elevation and range.  And an oracle bound: the
    arm-shape candidates' correction scaled by the α ∈ {0, 0.1, …, 1.5} best on each of
    B, C, D itself — chosen on the validation series, an upper bound, not a model.
(g) what a short campaign in the new set-up adds: on B, C, D (BASE + PROBE re-identified
    as in (b)), grouped 5-fold over each series' 0.4 m cells; in each fold a campaign of
    n poses drawn (seeded; the mean of 3 draws) from the training cells, a stage learned
    on it — on top of
    A's arm-shape correction ('joint-1 frame, q2, q3' fitted on all of A), and alone for
    comparison — and the held-out cells predicted: never a campaign pose, never a
    neighbour in the same cell.

    .venv/bin/python benchmarks/residual_ur10.py [--data DIR] [--quick] [--json]
                                                 [--out docs/results/ur10-residual.md]

Runs single-threaded (threadpoolctl) — the figures are accuracies, the times are
for orientation only.  Without the data folder it says so and exits 0.
"""

from __future__ import annotations

import argparse
import json
import math
import platform
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from calibration_ur10 import SERIES, read_series, ur10_toml
from plugcell.calibration import CalibrationData, Calibrator
from plugcell.calibration.residual_model import (
    DEFAULT_GRID,
    MIN_POSES,
    ResidualLearner,
    from_joint1_frame,
    hybrid_residuals,
    residual_targets,
    shape_features,
    to_joint1_frame,
    workspace_cells,
)
from plugcell.io.robots import load_robot
from plugcell.kinematics.rotations import angles_to_matrix

ROOT = Path(__file__).resolve().parents[1]
DATA_CANDIDATES = [ROOT.parent / "shared" / "data" / "ipa-robot-accuracy",
                   ROOT.parent.parent / "shared" / "data" / "ipa-robot-accuracy"]


def find_data() -> Path | None:
    return next((p for p in DATA_CANDIDATES if p.is_dir()), None)


def read_column(path: Path, name: str) -> np.ndarray:
    lines = path.read_text(encoding="utf-8").splitlines()
    i = lines[0].split(";").index(name)
    return np.array([float(ln.split(";")[i].replace(",", ".")) for ln in lines[1:] if ln.strip()])


def read_temperature(path: Path) -> np.ndarray:
    return read_column(path, "measurement_temperature")


def approach_directions(q: np.ndarray, stamps: np.ndarray) -> np.ndarray:
    """H4: ``sign(q_j[i] − q_j[i−1])`` per joint, poses in timestamp order (ties: file
    order — B, C, D carry one timestamp for the whole file), the first pose 0."""
    order = np.argsort(stamps, kind="stable")
    s = np.zeros_like(q)
    s[order[1:]] = np.sign(np.diff(q[order], axis=0))
    return s


def load_directions(data_dir: Path, sets: dict[str, CalibrationData]) -> dict[str, np.ndarray]:
    return {k: approach_directions(sets[k].q, read_column(data_dir / rel, "Timestamp"))
            for k, (rel, _) in SERIES.items()}


def load_sets(data_dir: Path) -> dict[str, CalibrationData]:
    sets = {}
    for key, (rel, _) in SERIES.items():
        q, p, a = read_series(data_dir / rel)
        sets[key] = CalibrationData(q, p, angles_to_matrix(a, "xyz"),
                                    temperature_c=read_temperature(data_dir / rel))
    return sets


def _without_temperature(d: CalibrationData) -> CalibrationData:
    return CalibrationData(d.q, d.positions, d.rotations, d.payload_kg)


def _mm(x: np.ndarray) -> float:
    return float(np.mean(x) * 1e3)


def nested_cv(desc: Any, A: CalibrationData, learner: ResidualLearner, cell_m: float,
              folds: int = 5) -> dict[str, Any]:
    """(a): outer grouped folds over the cells of series A (module docstring)."""
    from sklearn.model_selection import GroupKFold

    base_model = Calibrator(desc, "serial+gravity").fit(A).model
    _, p_b = residual_targets(base_model, A)
    groups = workspace_cells(p_b, cell_m)
    phys = np.empty(len(A))
    hyb = np.empty(len(A))
    inside = np.zeros(len(A), dtype=bool)
    rows = []
    for k, (tr, te) in enumerate(GroupKFold(n_splits=folds).split(p_b, groups=groups)):
        t0 = time.perf_counter()
        train, test = A.subset(tr), A.subset(te)
        res = Calibrator(desc, "serial+gravity").fit(train)
        layer = learner.fit(res.model, train, robot=desc.name)
        r, pred = hybrid_residuals(res.model, layer, test)
        phys[te], hyb[te], inside[te] = r.norms("before"), r.norms("after"), pred.in_domain
        rows.append({"fold": k + 1, "train": len(tr), "test": len(te),
                     "test_cells": len(np.unique(groups[te])), "params": layer.params,
                     "inner_cv_mm": layer.cv.hybrid_mm, "physical_mm": _mm(r.norms("before")),
                     "hybrid_mm": _mm(r.norms("after")), "in_domain": float(pred.in_domain.mean()),
                     "time_s": time.perf_counter() - t0})
        print(f"  (a) fold {k + 1}/{folds}: {len(te)} held-out poses in "
              f"{rows[-1]['test_cells']} cells: physical {rows[-1]['physical_mm']:.3f} -> "
              f"hybrid {rows[-1]['hybrid_mm']:.3f} mm ({rows[-1]['time_s']:.0f} s)", flush=True)
    return {"cells": int(groups.max()) + 1, "cell_size_m": cell_m, "folds": rows,
            "physical_mm": _mm(phys), "hybrid_mm": _mm(hyb), "in_domain": float(inside.mean()),
            "physical_norms_mm": (phys * 1e3).tolist(), "hybrid_norms_mm": (hyb * 1e3).tolist()}


def transfer(desc: Any, sets: dict[str, CalibrationData], learner: ResidualLearner
             ) -> dict[str, Any]:
    """(b): calibrated on A, validated on B, C, D with BASE + PROBE re-identified."""
    res = Calibrator(desc, "serial+gravity").fit(sets["A"])
    layer = learner.fit(res.model, sets["A"], robot=desc.name)
    out: dict[str, Any] = {"calibration": {"physical_mm": res.calibration.position.norm.mean
                                           * 1e3,
                                           "cv_physical_mm": layer.cv.physical_mm,
                                           "cv_hybrid_mm": layer.cv.hybrid_mm,
                                           "params": layer.params, "threshold": layer.threshold},
                           "validation": {}}
    unguarded = replace(layer, threshold=math.inf, shape=None if layer.shape is None
                        else replace(layer.shape, threshold=math.inf))
    out["calibration"]["shape"] = None if layer.shape is None else layer.shape.summary()
    for key in "BCD":
        val = sets[key]
        r, pred = hybrid_residuals(res.model, layer, val, refit_base=True, refit_probe=True)
        ru, _ = hybrid_residuals(res.model, unguarded, val, refit_base=True, refit_probe=True)
        o = r.accuracy("before").orientation, r.accuracy("after").orientation
        out["validation"][key] = {
            "poses": len(val), "physical_mm": _mm(r.norms("before")),
            "hybrid_mm": _mm(r.norms("after")), "in_domain": float(pred.in_domain.mean()),
            "local_in_domain": float(np.mean(pred.local)) if pred.local is not None else None,
            "hybrid_without_domain_test_mm": _mm(ru.norms("after")),
            "physical_orientation_deg": math.degrees(o[0].norm.mean) if o[0] else None,
            "hybrid_orientation_deg": math.degrees(o[1].norm.mean) if o[1] else None,
            "distance_median": float(np.median(pred.distance))}
        v = out["validation"][key]
        print(f"  (b) A -> {key}: physical {v['physical_mm']:.3f}, hybrid {v['hybrid_mm']:.3f} mm "
              f"({v['in_domain']:.0%} in domain; without the test "
              f"{v['hybrid_without_domain_test_mm']:.3f})", flush=True)
    return out


def diagnostics(desc: Any, sets: dict[str, CalibrationData], learner_kw: dict[str, Any]
                ) -> dict[str, Any]:
    """(c): each series' own residual by grouped CV; A with the temperature feature."""
    out: dict[str, Any] = {"own": {}}
    for key, d in sets.items():
        res = Calibrator(desc, "serial+gravity").fit(_without_temperature(d))
        try:
            layer = ResidualLearner(**learner_kw).fit(res.model, _without_temperature(d))
            out["own"][key] = {"physical_mm": layer.cv.physical_mm,
                               "hybrid_mm": layer.cv.hybrid_mm, "cells": layer.cv.cells}
        except ValueError as exc:
            out["own"][key] = {"error": str(exc)}
        print(f"  (c) {key} own grouped CV: {out['own'][key]}", flush=True)
        if key == "A":
            lt = ResidualLearner(**learner_kw, use_temperature=True).fit(res.model, d)
            out["A_temperature"] = {"physical_mm": lt.cv.physical_mm, "hybrid_mm": lt.cv.hybrid_mm}
    out["temperature_c"] = {k: [float(d.temperature_c.min()), float(d.temperature_c.max())]
                            for k, d in sets.items() if d.temperature_c is not None}
    return out


def harmonics(desc: Any, sets: dict[str, CalibrationData]) -> dict[str, Any]:
    """(d): model 3 with joint-angle harmonics of order 0, 1, 2 (module docstring)."""
    out: dict[str, Any] = {"runs": []}
    for order in (0, 1, 2):
        res = Calibrator(desc, "serial+gravity", harmonics=order).fit(sets["A"])
        run = {"order": order, "parameters": len(res.keys),
               "calibration_mm": res.calibration.position.norm.mean * 1e3, "validation": {}}
        for key in "BCD":
            run["validation"][key] = res.evaluate(sets[key], refit_base=True, refit_probe=True
                                                  )[1].position.norm.mean * 1e3
        out["runs"].append(run)
        print(f"  (d) harmonics {order}: {len(res.keys)} parameters, A "
              f"{run['calibration_mm']:.3f} mm, " + ", ".join(
                  f"{k} {v:.3f}" for k, v in run["validation"].items()), flush=True)
        if order == 2:
            out["terms"] = [{"name": p["name"], "value_urad": p["value"] * 1e6,
                             "sigma_urad": p["sigma"] * 1e6}
                            for p in res.parameter_table() if p["kind"] == "harmonic"]
            out["unidentified"] = [w for w in res.warnings if "not identified" in w]
    return out


def thermal(desc: Any, sets: dict[str, CalibrationData]) -> dict[str, Any]:
    """(e): model 3 + κT on each series (its own temperature column)."""
    from plugcell.calibration.model import THERMAL_KEY

    out: dict[str, Any] = {}
    for key, d in sets.items():
        res = Calibrator(desc, "serial+gravity", thermal=True).fit(d)
        ok = THERMAL_KEY in res.keys
        out[key] = {"span_k": float(np.ptp(d.temperature_c)),
                    "kappa_per_k": res.value(THERMAL_KEY) if ok else None,
                    "sigma_per_k": res.sigma(THERMAL_KEY) if ok else None,
                    "mean_mm": res.calibration.position.norm.mean * 1e3}
        print(f"  (e) {key}: ΔT span {out[key]['span_k']:.2f} K, κT "
              f"{out[key]['kappa_per_k']} ± {out[key]['sigma_per_k']} /K", flush=True)
    return out


#: (f) single-stage candidates: name, residual frame ("base" | "joint 1"), joints
#: (0-based) of the sin/cos features, whether the position is learned as a flange twist,
#: and whether the six approach directions (H4, :func:`approach_directions`) are features
CANDIDATES = (
    ("base frame, q1…q6 (format 1)", "base", (0, 1, 2, 3, 4, 5), False, False),
    ("base frame, q1…q6, flange twist", "base", (0, 1, 2, 3, 4, 5), True, False),
    ("base frame, q2…q6", "base", (1, 2, 3, 4, 5), False, False),
    ("joint-1 frame, q2…q6", "joint 1", (1, 2, 3, 4, 5), False, False),
    ("joint-1 frame, q2…q4", "joint 1", (1, 2, 3), False, False),
    ("joint-1 frame, q2, q3", "joint 1", (1, 2), False, False),
    ("base frame, q1…q6 + approach direction", "base", (0, 1, 2, 3, 4, 5), False, True),
    ("joint-1 frame, q2, q3 + approach direction", "joint 1", (1, 2), False, True),
)
#: (f) H5: the similarity is fitted to the residuals of the arm-shape stage's representation
SHAPE_CANDIDATE = "joint-1 frame, q2, q3"
#: (f) oracle bound: candidates whose transferred correction is scaled by each α, the best
#: α chosen on the validation series itself
ORACLE_CANDIDATES = (SHAPE_CANDIDATE, "joint-1 frame, q2…q4")
ALPHAS = np.round(np.arange(16) * 0.1, 1)


def _geometry(model: Any, d: CalibrationData) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Target point and flange origin in the robot base frame, base-frame residual (N, 6)."""
    E, x = residual_targets(model, d)
    B = model.base()
    F = np.linalg.inv(B) @ model.predict(d.q) @ np.linalg.inv(model.probe())
    return x, F[:, :3, 3], E


def _encode(frame: str, twist: bool, q: np.ndarray, x: np.ndarray, o: np.ndarray,
            E: np.ndarray) -> np.ndarray:
    """Base-frame point residual → what the candidate learns."""
    e, phi = E[:, :3], E[:, 3:]
    if twist:  # the flange's translation: δp = e_F + φ × (x − o)
        e = e - np.cross(phi, x - o)
    Y = np.hstack([e, phi])
    return to_joint1_frame(q[:, 0], Y) if frame == "joint 1" else Y


def _decode(frame: str, twist: bool, q: np.ndarray, x: np.ndarray, o: np.ndarray,
            Y: np.ndarray) -> np.ndarray:
    Y = from_joint1_frame(q[:, 0], Y) if frame == "joint 1" else Y
    e, phi = Y[:, :3], Y[:, 3:]
    if twist:
        e = e + np.cross(phi, x - o)
    return e


def _similarity(x: np.ndarray, e: np.ndarray) -> dict[str, float]:
    """H5: ``e ≈ δt + δθ × x (+ δs·x)`` by linear least squares (x in the base frame, m)."""
    cols = ([np.broadcast_to(u, x.shape) for u in np.eye(3)]
            + [np.cross(u, x) for u in np.eye(3)] + [x])
    M = np.stack([c.ravel() for c in cols], axis=1)
    out = {"reidentified_mm": _mm(np.linalg.norm(e, axis=1))}
    for tag, m in (("rigid_mm", M[:, :6]), ("scaled_mm", M)):
        sol = np.linalg.lstsq(m, e.ravel(), rcond=None)[0]
        out[tag] = _mm(np.linalg.norm(e - (m @ sol).reshape(-1, 3), axis=1))
    out["scale_ppm"] = float(sol[6] * 1e6)
    return out


def _sight(model: Any, d: CalibrationData) -> tuple[np.ndarray, np.ndarray]:
    """H6: the measured target in spherical tracker coordinates (azimuth, elevation in rad,
    range in m) and the position residual in the tracker frame, ``E R_Bᵀ`` (m)."""
    p = d.positions
    r = np.linalg.norm(p, axis=1)
    X = np.column_stack([np.arctan2(p[:, 1], p[:, 0]), np.arcsin(p[:, 2] / r), r])
    return X, residual_targets(model, d)[0][:, :3] @ model.base()[:3, :3].T


def screening(desc: Any, sets: dict[str, CalibrationData], params: dict[str, Any],
              trees: int, directions: dict[str, np.ndarray]) -> dict[str, Any]:
    """(f): PROBE per series, single-stage candidates on A (module docstring), and the
    per-series similarity H5 on B, C, D, the line-of-sight layer H6 and the oracle α."""
    from sklearn.ensemble import HistGradientBoostingRegressor
    from sklearn.model_selection import GroupKFold

    from plugcell.calibration.identify import refit_base

    def reg() -> Any:
        return HistGradientBoostingRegressor(max_iter=trees, learning_rate=0.1,
                                             early_stopping=False, random_state=0, **params)

    A = sets["A"]
    mA = Calibrator(desc, "serial+gravity").fit(A).model
    models = {"A": mA, **{k: refit_base(mA, sets[k], probe=True) for k in "BCD"}}
    out: dict[str, Any] = {"probe": {}, "candidates": [], "params": params, "trees": trees,
                           "scale": {}, "oracle": {}, "approach_median_step_deg": {
                               k: np.degrees(np.median(np.abs(np.diff(d.q, axis=0)), axis=0))
                               .tolist() for k, d in sets.items()}}
    PA = mA.probe()
    for k, m in models.items():
        P = m.probe()
        ang = np.arccos(np.clip((np.trace(PA[:3, :3].T @ P[:3, :3]) - 1) / 2, -1, 1))
        out["probe"][k] = {"translation_mm": (P[:3, 3] * 1e3).tolist(),
                           "offset_from_A_mm": float(np.linalg.norm(P[:3, 3] - PA[:3, 3]) * 1e3),
                           "rotation_from_A_mrad": float(ang * 1e3),
                           "lever_mm": float(np.linalg.norm(P[:3, 3]) * 1e3)}
    xA, oA, EA = _geometry(mA, A)
    cells = workspace_cells(xA, 0.4)
    q1 = A.q[:, 0]
    sectors = np.digitize(q1, np.quantile(q1, [0.2, 0.4, 0.6, 0.8]))
    pos = np.linalg.norm(EA[:, :3], axis=1)
    def features(k: str, joints: tuple[int, ...], approach: bool) -> np.ndarray:
        X = shape_features(sets[k].q, joints)
        return np.hstack([X, directions[k]]) if approach else X

    for name, frame, joints, twist, approach in CANDIDATES:
        X = features("A", joints, approach)
        Y = _encode(frame, twist, A.q, xA, oA, EA)
        row: dict[str, Any] = {"name": name, "physical_mm": _mm(pos), "frame": frame,
                               "joints": list(joints), "twist": twist, "approach": approach}
        for tag, groups in (("cells_mm", cells), ("sectors_mm", sectors)):
            pred = np.zeros_like(Y)
            for tr, te in GroupKFold(n_splits=5).split(X, Y, groups):
                pred[te] = np.column_stack([reg().fit(X[tr], Y[tr, j]).predict(X[te])
                                            for j in range(6)])
            row[tag] = _mm(np.linalg.norm(EA[:, :3] - _decode(frame, twist, A.q, xA, oA, pred),
                                          axis=1))
        ests = [reg().fit(X, Y[:, j]) for j in range(6)]
        row["transfer"] = {}
        for k in "BCD":
            x, o, E = _geometry(models[k], sets[k])
            Yk = np.column_stack([e.predict(features(k, joints, approach)) for e in ests])
            rest = E[:, :3] - _decode(frame, twist, sets[k].q, x, o, Yk)
            row["transfer"][k] = {"physical_mm": _mm(np.linalg.norm(E[:, :3], axis=1)),
                                  "hybrid_mm": _mm(np.linalg.norm(rest, axis=1))}
            if name == SHAPE_CANDIDATE:
                out["scale"][k] = {"physical": _similarity(x, E[:, :3]),
                                   "hybrid": _similarity(x, rest)}
            if name in ORACLE_CANDIDATES:
                P = _decode(frame, twist, sets[k].q, x, o, Yk)
                curve = [_mm(np.linalg.norm(E[:, :3] - a * P, axis=1)) for a in ALPHAS]
                i = int(np.argmin(curve))
                out["oracle"].setdefault(name, {})[k] = {
                    "alpha": float(ALPHAS[i]), "best_mm": curve[i], "physical_mm": curve[0],
                    "alphas": ALPHAS.tolist(), "curve_mm": curve}
        out["candidates"].append(row)
        print(f"  (f) {name}: A cells {row['cells_mm']:.3f}, A sectors {row['sectors_mm']:.3f} mm;"
              " " + ", ".join(f"{k} {v['physical_mm']:.3f} -> {v['hybrid_mm']:.3f}"
                              for k, v in row["transfer"].items()), flush=True)
    XA, EtA = _sight(mA, A)
    pred = np.zeros_like(EtA)
    for tr, te in GroupKFold(n_splits=5).split(XA, EtA, cells):
        pred[te] = np.column_stack([reg().fit(XA[tr], EtA[tr, j]).predict(XA[te])
                                    for j in range(3)])
    ests = [reg().fit(XA, EtA[:, j]) for j in range(3)]
    los: dict[str, Any] = {"span": {}, "result": {}}
    for k in sets:
        X, Et = _sight(models[k], sets[k])
        deg = np.degrees(X[:, :2])
        los["span"][k] = {"azimuth_deg": [float(deg[:, 0].min()), float(deg[:, 0].max())],
                          "elevation_deg": [float(deg[:, 1].min()), float(deg[:, 1].max())],
                          "range_m": [float(X[:, 2].min()), float(X[:, 2].max())]}
        P = pred if k == "A" else np.column_stack([e.predict(X) for e in ests])
        los["result"][k] = {"physical_mm": _mm(np.linalg.norm(Et, axis=1)),
                            "hybrid_mm": _mm(np.linalg.norm(Et - P, axis=1))}
        print(f"  (f) H6 {k}" + (" held-out cells" if k == "A" else "") + ": "
              f"{los['result'][k]['physical_mm']:.3f} -> {los['result'][k]['hybrid_mm']:.3f} mm; "
              + ", ".join(f"{n} {lo:.4g}…{hi:.4g}" for n, (lo, hi) in los["span"][k].items()),
              flush=True)
    out["line_of_sight"] = los
    for name, v in out["oracle"].items():
        print(f"  (f) oracle {name}: " + ", ".join(
            f"{k} α={o['alpha']:.1f} {o['physical_mm']:.3f} -> {o['best_mm']:.3f}"
            for k, o in v.items()), flush=True)
    for k, v in out["scale"].items():
        print(f"  (f) H5 {k}: δs {v['physical']['scale_ppm']:+.0f} ppm; " + ", ".join(
            f"{m} {v[m]['reidentified_mm']:.3f} / {v[m]['rigid_mm']:.3f} / "
            f"{v[m]['scaled_mm']:.3f}" for m in ("physical", "hybrid"))
              + " mm (re-identified / + δt, δθ / + δs)", flush=True)
    return out


#: (g): poses of the short campaign in the new set-up.
CAMPAIGNS = (100, 200, 400)


def short_campaign(desc: Any, sets: dict[str, CalibrationData], params: dict[str, Any],
                   trees: int, sizes: tuple[int, ...] = CAMPAIGNS, draws: int = 3,
                   grid: tuple[dict[str, Any], ...] = ()) -> dict[str, Any]:
    """(g): A's arm-shape correction plus a stage learned on n poses of the new set-up,
    scored on held-out cells of that series (module docstring); the mean over ``draws``
    seeded draws of the campaigns.  With ``grid``, also what ``plugcell calibrate
    --residual-model learned --residual-prior`` does on each campaign: a
    :class:`ResidualLearner` over ``grid`` fitted on it with A's layer's arm-shape stage as
    prior (its own grouped CV, in-domain tests, the prior inside its region only)."""
    from sklearn.ensemble import HistGradientBoostingRegressor
    from sklearn.model_selection import GroupKFold

    from plugcell.calibration.identify import refit_base

    def reg(leaf: int) -> Any:
        return HistGradientBoostingRegressor(
            max_iter=trees, learning_rate=0.1, early_stopping=False, random_state=0,
            **{**params, "min_samples_leaf": leaf})

    def leaf_for(n: int) -> int:  # a campaign's stage: ≥ n / 10 poses a leaf, 5 … the grid's
        return max(5, min(int(params["min_samples_leaf"]), n // 10))

    A = sets["A"]
    mA = Calibrator(desc, "serial+gravity").fit(A).model
    _, _, EA = _geometry(mA, A)
    prior = None
    if grid:
        prior = ResidualLearner(grid=grid, trees=trees).fit(mA, A, robot=desc.name).shape
    joints = (1, 2)
    YA = to_joint1_frame(A.q[:, 0], EA)
    shape = [reg(int(params["min_samples_leaf"])).fit(shape_features(A.q, joints), YA[:, j])
             for j in range(3)]
    out: dict[str, Any] = {"sizes": list(sizes), "leaf": {str(n): leaf_for(n) for n in sizes},
                           "draws": draws, "series": {}}
    for s_no, k in enumerate("BCD"):
        d = sets[k]
        mk = refit_base(mA, d, probe=True)
        x, _, E = _geometry(mk, d)
        Ys = np.column_stack([e.predict(shape_features(d.q, joints)) for e in shape])
        S = from_joint1_frame(d.q[:, 0], np.hstack([Ys, np.zeros_like(Ys)]))[:, :3]
        X = shape_features(d.q, tuple(range(d.q.shape[1])))
        groups = workspace_cells(x, 0.4)
        row: dict[str, Any] = {"physical_mm": _mm(np.linalg.norm(E[:, :3], axis=1)),
                               "shape_mm": _mm(np.linalg.norm(E[:, :3] - S, axis=1)),
                               "cells": int(groups.max()) + 1, "stacked_mm": {},
                               "alone_mm": {}, "stacked_draws_mm": {}, "alone_draws_mm": {},
                               "command_mm": {}, "command_draws_mm": {}}
        for n in sizes:
            tags = ["stacked", "alone"] + (["command"] if prior is not None
                                           and n >= MIN_POSES else [])
            means: dict[str, list[float]] = {t: [] for t in tags}
            for draw in range(draws):  # each draw its own seed: figures do not depend on sizes
                rng = np.random.default_rng([s_no, n, draw])
                err = {t: np.empty(len(d)) for t in tags}
                for tr, te in GroupKFold(n_splits=5).split(X, E, groups):
                    pick = rng.choice(tr, size=min(n, len(tr)), replace=False)
                    for tag, base in (("stacked", S), ("alone", 0.0)):
                        R = E[:, :3] - base
                        pred = np.column_stack([reg(leaf_for(n)).fit(X[pick], R[pick, j])
                                                .predict(X[te]) for j in range(3)])
                        err[tag][te] = np.linalg.norm(R[te] - pred, axis=1)
                    if "command" in err:
                        layer = ResidualLearner(grid=grid, trees=trees).fit(
                            mk, d.subset(pick), robot=desc.name, prior=prior)
                        c = layer.predict(d.q[te]).correction[:, :3]
                        err["command"][te] = np.linalg.norm(E[te, :3] - c, axis=1)
                for tag in means:
                    means[tag].append(_mm(err[tag]))
            for tag, v in means.items():
                row[f"{tag}_mm"][str(n)] = float(np.mean(v))
                row[f"{tag}_draws_mm"][str(n)] = v
        out["series"][k] = row
        print(f"  (g) {k}: command " + ", ".join(
            f"{n}: {v:.3f}" for n, v in row["command_mm"].items()), flush=True)
        print(f"  (g) {k}: physical {row['physical_mm']:.3f}, A's arm-shape stage "
              f"{row['shape_mm']:.3f}; with a campaign of " + ", ".join(
                  f"{n}: {row['stacked_mm'][str(n)]:.3f} (alone {row['alone_mm'][str(n)]:.3f})"
                  for n in sizes) + " mm", flush=True)
    return out


def plots(d: dict[str, Any], out_dir: Path) -> list[str]:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return []
    names = []
    a = d["nested_cv"]
    fig, ax = plt.subplots(figsize=(6.4, 3.6))
    bins = np.linspace(0, 1.5, 61)
    ax.hist(a["physical_norms_mm"], bins, alpha=0.6, label=f"physical {a['physical_mm']:.3f} mm")
    ax.hist(a["hybrid_norms_mm"], bins, alpha=0.6, label=f"hybrid {a['hybrid_mm']:.3f} mm")
    ax.set_xlabel("position error of held-out poses (mm)")
    ax.set_ylabel("poses")
    ax.set_title("IPA UR10, series A, nested grouped 5-fold (0.4 m cells)")
    ax.legend()
    fig.tight_layout()
    fig.savefig(out_dir / "ur10-residual-cv.png", dpi=110)
    plt.close(fig)
    names.append("ur10-residual-cv.png")
    fig, ax = plt.subplots(figsize=(6.4, 3.6))
    keys = ["A (CV)", *d["transfer"]["validation"]]
    phys = [a["physical_mm"]] + [v["physical_mm"] for v in d["transfer"]["validation"].values()]
    hyb = [a["hybrid_mm"]] + [v["hybrid_mm"] for v in d["transfer"]["validation"].values()]
    unguarded = [math.nan] + [v["hybrid_without_domain_test_mm"]
                              for v in d["transfer"]["validation"].values()]
    x = np.arange(len(keys))
    ax.bar(x - 0.27, phys, 0.27, label="physical (model 3)")
    ax.bar(x, hyb, 0.27, label="hybrid (in-domain test)")
    ax.bar(x + 0.27, unguarded, 0.27, label="hybrid without the test")
    ax.set_xticks(x, keys)
    ax.set_ylabel("mean position error (mm)")
    ax.set_title("calibrated on A; B, C, D with BASE + PROBE re-identified")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out_dir / "ur10-residual-transfer.png", dpi=110)
    plt.close(fig)
    names.append("ur10-residual-transfer.png")
    return names


def write_page(d: dict[str, Any], path: Path, images: list[str]) -> None:
    a, t, c = d["nested_cv"], d["transfer"], d["diagnostics"]
    L = ["# The learned residual layer on a real UR10 (IPA data set)", "",
         "Generated by `benchmarks/residual_ur10.py` (do not edit by hand); "
         f"{d['machine']}, {d['elapsed_s']:.0f} s single-threaded"
         + (", **quick mode** (fewer trees, one candidate)" if d["quick"] else "") + ".",
         "Hyper-parameter candidates of the grouped CV: "
         + "; ".join(f"{g['max_leaf_nodes']} leaves, ≥ {g['min_samples_leaf']} poses per leaf"
                     for g in d["grid"]) + f", {d['trees']} trees, learning rate 0.1.", "",
         "Physical model: thesis model 3 (serial + joint compliance from the published link "
         "masses, 34 parameters), as in [ur10.md](ur10.md). Hybrid: the same plus the learned "
         "residual layer (`plugcell calibrate --residual-model learned`): gradient-boosted trees "
         "(scikit-learn), position and orientation residual in the robot base frame, in two "
         "stages: the set-up's own stage on sin/cos of the six joint readings, used where a "
         "pose is inside its region, else an arm-shape stage (the residual in the frame that "
         "turns with joint 1, a function of sin/cos q2, q3 — the part meant to carry over to "
         "another set-up) inside its own region, else the physical model; "
         "hyper-parameters by grouped CV, an in-domain test per stage "
         "(docs/calibration.md, *Learned residual layer*; the choice of the representation: "
         "section (f)).", "",
         "## Protocol", "",
         "* **(a) series A, nested grouped 5-fold.** The workspace is cut into cubes of "
         f"{a['cell_size_m']:g} m (target position in the robot base frame; {a['cells']} cells "
         "hold poses). Each outer fold holds out whole cells; on the remaining cells the physical "
         "model is identified, and the layer is fitted with hyper-parameters chosen by an inner "
         "grouped 5-fold CV over those cells only. The held-out cells are then predicted by "
         "both models. No pose is evaluated by a model that saw it; no random split of "
         "neighbouring poses.",
         "* **(b) transfer.** Physical model and layer fitted on all of A; series B, C and D "
         "(tracker elsewhere) are predicted with BASE and PROBE re-identified on each — for the "
         "physical model on the raw measurements, for the hybrid one on the measurements with "
         "the learned correction taken out. Poses outside both stages' regions use the "
         "physical model (in-domain tests); the column *without the tests* shows what the "
         "set-up stage would do applied everywhere.",
         "* **(c) diagnostics**: each series' own residual learned by grouped CV inside it; "
         "series A with its temperature column as a feature.",
         "* **(f) choice of the representation**: on series A alone (module docstring of the "
         "benchmark); B, C, D only for the record. With it three hypotheses for what does not "
         "transfer: H4, the joints' approach direction (lost motion), H5, a length scale "
         "per series in the re-registration, and H6, the tracker's own errors along its line "
         "of sight; and an oracle bound on rescaling the arm-shape correction.", "",
         "## (a) Series A, held-out workspace cells", "",
         "| fold | training poses | held-out poses (cells) | chosen | inner CV (mm) | "
         "physical (mm) | hybrid (mm) | in domain |", "|---|---|---|---|---|---|---|---|"]
    for r in a["folds"]:
        p = r["params"]
        L.append(f"| {r['fold']} | {r['train']} | {r['test']} ({r['test_cells']}) | "
                 f"{p['max_leaf_nodes']} leaves, ≥ {p['min_samples_leaf']} per leaf, "
                 f"{p['max_iter']} trees | {r['inner_cv_mm']:.3f} | {r['physical_mm']:.3f} | "
                 f"**{r['hybrid_mm']:.3f}** | {r['in_domain']:.0%} |")
    L += ["", f"All held-out poses: physical **{a['physical_mm']:.3f} mm** → hybrid "
          f"**{a['hybrid_mm']:.3f} mm** mean position error "
          f"({1 - a['hybrid_mm'] / a['physical_mm']:.0%} lower; issue target ≤ 0.20, goal 0.15; "
          f"{a['in_domain']:.0%} of the held-out poses inside the trained region).", ""]
    if "ur10-residual-cv.png" in images:
        L += ["![held-out errors](ur10-residual-cv.png)", ""]
    L += ["## (b) Calibrated on A, validated on B, C, D (BASE + PROBE re-identified)", "",
          f"Layer fitted on all {d['poses']['A']} poses of A (its own grouped CV: "
          f"{t['calibration']['cv_physical_mm']:.3f} → {t['calibration']['cv_hybrid_mm']:.3f} mm); "
          f"in-domain threshold {t['calibration']['threshold']:.3f} (feature-space distance)"
          + (f"; arm-shape stage: held-out cells {sh['physical_mm']:.3f} → {sh['cv_mm']:.3f} mm "
             f"alone, threshold {sh['threshold']:.3f}" if (sh := t["calibration"].get("shape"))
             else "") + ".", "",
          "| series | poses | physical (mm) | hybrid (mm) | change | in domain (shape stage) | "
          "in domain (set-up stage) | hybrid without the tests (mm) | orientation physical → "
          "hybrid (°) |",
          "|---|---|---|---|---|---|---|---|---|"]
    for k, v in t["validation"].items():
        ch = v["hybrid_mm"] / v["physical_mm"] - 1
        loc = v.get("local_in_domain")
        L.append(f"| {k} | {v['poses']} | {v['physical_mm']:.3f} | {v['hybrid_mm']:.3f} | "
                 f"{ch:+.1%} | {v['in_domain']:.0%} | "
                 f"{'–' if loc is None else f'{loc:.0%}'} | "
                 f"{v['hybrid_without_domain_test_mm']:.3f} | "
                 f"{v['physical_orientation_deg']:.4f} → {v['hybrid_orientation_deg']:.4f} |")
    L += [""]
    if "ur10-residual-transfer.png" in images:
        L += ["![transfer](ur10-residual-transfer.png)", ""]
    L += ["## (c) Diagnostics", "",
          "| series | poses | own grouped CV: physical → hybrid (mm) |", "|---|---|---|"]
    for k, v in c["own"].items():
        cell = (f"{v['physical_mm']:.3f} → {v['hybrid_mm']:.3f} ({v['cells']} cells)"
                if "error" not in v else v["error"])
        L.append(f"| {k} | {d['poses'][k]} | {cell} |")
    at = c["A_temperature"]
    L += ["", f"Series A with the temperature column as a feature: {at['physical_mm']:.3f} → "
          f"{at['hybrid_mm']:.3f} mm (grouped CV). Temperature ranges (°C): "
          + ", ".join(f"{k} {lo:.2f}–{hi:.2f}" for k, (lo, hi) in c["temperature_c"].items())
          + ".", ""]
    h = d["harmonics"]
    L += ["## (d) Joint-angle harmonics in the physical model (§1)", "",
          "Model 3 plus `Δθ_j = Σ_k s_jk sin(k q_j) + c_jk cos(k q_j)` for every joint, "
          "k ≤ order (`plugcell calibrate --harmonics 1|2`), identified on all of A; "
          "validation as in (b), BASE + PROBE re-identified. Mean position error (mm):", "",
          "| harmonics | parameters | A (calibration) | B | C | D |", "|---|---|---|---|---|---|"]
    for r in h["runs"]:
        L.append(f"| {r['order']} | {r['parameters']} | {r['calibration_mm']:.3f} | "
                 + " | ".join(f"{r['validation'][k]:.3f}" for k in "BCD") + " |")
    L += ["", "Order 2 on A, the identified terms (µrad) and their significance "
          "(|value| / σ; σ from eq. 8.5, which assumes independent pose errors — the "
          "residuals are correlated, so read the σ as optimistic):", "",
          "| term | value (µrad) | σ (µrad) | |value|/σ |", "|---|---|---|---|"]
    for t_ in h["terms"]:
        L.append(f"| {t_['name']} | {t_['value_urad']:.1f} | {t_['sigma_urad']:.1f} | "
                 f"{abs(t_['value_urad']) / t_['sigma_urad']:.1f} |")
    L += [""] + [f"* {w}" for w in h.get("unidentified", [])]
    L += ["", "## (e) Thermal expansion term κT (§3)", "",
          "Model 3 plus κT — every length of the arm scaled by `1 + κT (T − T̄)`, T̄ the "
          "series' mean temperature (`plugcell calibrate --thermal`; the measurement file's "
          "`temperature_c` column) — identified on each series alone:", "",
          "| series | temperature span (K) | κT (10⁻⁶/K) | σ (10⁻⁶/K) | |κT|/σ | mean error (mm) |",
          "|---|---|---|---|---|---|"]
    for k, v in d["thermal"].items():
        if v["kappa_per_k"] is None:
            L.append(f"| {k} | {v['span_k']:.2f} | not identified | | | {v['mean_mm']:.3f} |")
        else:
            L.append(f"| {k} | {v['span_k']:.2f} | {v['kappa_per_k'] * 1e6:.1f} | "
                     f"{v['sigma_per_k'] * 1e6:.1f} | "
                     f"{abs(v['kappa_per_k']) / v['sigma_per_k']:.1f} | {v['mean_mm']:.3f} |")
    L += ["", "(For comparison: aluminium 23 × 10⁻⁶/K, steel 12 × 10⁻⁶/K. Over a span of "
          "under 1 K, 23 × 10⁻⁶/K moves a point 1.3 m from the base by under 0.03 mm.)", ""]
    sc = d.get("screening")
    if sc:
        L += ["## (f) Choice of the representation (series A alone)", "",
              "Identified PROBE (T-MAC in the flange frame; BASE + PROBE re-identified on B, C, "
              "D from A's model):", "",
              "| series | PROBE translation (mm) | offset from A's (mm) | rotation from A's "
              "(mrad) |", "|---|---|---|---|"]
        for k, v in sc["probe"].items():
            L.append(f"| {k} | " + ", ".join(f"{x:.2f}" for x in v["translation_mm"])
                     + f" | {v['offset_from_A_mm']:.3f} | {v['rotation_from_A_mrad']:.2f} |")
        L += ["", "Single-stage candidates ({} leaves, ≥ {} per leaf, {} trees), mean position "
              "error (mm). The choice uses only the A columns; the B, C, D columns (fitted on all "
              "of A, BASE + PROBE re-identified on the raw measurements, no in-domain test) are "
              "the record.".format(sc["params"]["max_leaf_nodes"],
                                   sc["params"]["min_samples_leaf"], sc["trees"]), "",
              "| candidate | A: held-out cells | A: held-out joint-1 sectors | B | C | D |",
              "|---|---|---|---|---|---|"]
        c0 = sc["candidates"][0]
        L.append(f"| physical model | {c0['physical_mm']:.3f} | {c0['physical_mm']:.3f} | "
                 + " | ".join(f"{c0['transfer'][k]['physical_mm']:.3f}" for k in "BCD") + " |")
        for r in sc["candidates"]:
            L.append(f"| {r['name']} | {r['cells_mm']:.3f} | {r['sectors_mm']:.3f} | "
                     + " | ".join(f"{r['transfer'][k]['hybrid_mm']:.3f}" for k in "BCD") + " |")
        L.append("")
        if "approach_median_step_deg" in sc:
            L += ["*+ approach direction* (H4, lost motion): the six signs "
                  "sign(q_j[i] − q_j[i−1]), poses in timestamp order (B, C, D carry one "
                  "timestamp per file: file order), the first pose 0, as six more features. "
                  "Median |q_j[i] − q_j[i−1]| of joints 1…6 (°): " + "; ".join(
                      f"{k} " + ", ".join(f"{x:.3g}" for x in v)
                      for k, v in sc["approach_median_step_deg"].items()) + ".", ""]
        if sc.get("scale"):
            L += ["H5, a length scale per series in the re-registration: after BASE + PROBE "
                  "re-identification, a similarity — translation δt, rotation δθ and scale δs "
                  "about the robot base origin — fitted by linear least squares to the "
                  "base-frame position residuals, `e ≈ δt + δθ × x + δs·x` (x the target in the "
                  "base frame, e = measured − predicted, so δs > 0: the tracker sees the arm "
                  "longer than the model), for the physical model and for the hybrid of the "
                  f"arm-shape candidate ({SHAPE_CANDIDATE!r} above, no in-domain test). "
                  "*Without δs* "
                  "fits δt and δθ alone, so the two columns differ only by the scale. Mean "
                  "position error (mm):", "",
                  "| series | δs (ppm), physical | δs (ppm), hybrid | physical: without δs → "
                  "with | hybrid: without δs → with | hybrid vs physical: without δs → with |",
                  "|---|---|---|---|---|---|"]
            for k, v in sc["scale"].items():
                ph, hy = v["physical"], v["hybrid"]
                L.append(f"| {k} | {ph['scale_ppm']:+.0f} | {hy['scale_ppm']:+.0f} | "
                         f"{ph['rigid_mm']:.3f} → {ph['scaled_mm']:.3f} | "
                         f"{hy['rigid_mm']:.3f} → {hy['scaled_mm']:.3f} | "
                         f"{hy['rigid_mm'] / ph['rigid_mm'] - 1:+.1%} → "
                         f"{hy['scaled_mm'] / ph['scaled_mm'] - 1:+.1%} |")
            L.append("")
        los = sc.get("line_of_sight")
        if los:
            L += ["H6, the tracker's own errors along its line of sight: A's position residual "
                  "in the tracker frame (the base-frame residual turned by BASE's rotation, "
                  "`E R_Bᵀ`) learned as a function of the measured target in spherical tracker "
                  "coordinates — azimuth atan2(y, x), elevation asin(z / r), range r — by the "
                  "same trees; A: held-out 0.4 m cells (grouped 5-fold, as above); B, C, D: "
                  "fitted on all of A, each series' residual in its own re-identified tracker "
                  "frame (BASE + PROBE), no in-domain test. Spans of each series' measured "
                  "points and mean position error (mm):", "",
                  "| series | azimuth (°) | elevation (°) | range (m) | physical | "
                  "line-of-sight layer | change |", "|---|---|---|---|---|---|---|"]
            for k, v in los["span"].items():
                r = los["result"][k]
                az, el, rg = v["azimuth_deg"], v["elevation_deg"], v["range_m"]
                L.append(f"| {k}{' (held-out cells)' if k == 'A' else ''} | "
                         f"{az[0]:.1f} … {az[1]:.1f} | {el[0]:.1f} … {el[1]:.1f} | "
                         f"{rg[0]:.2f} … {rg[1]:.2f} | {r['physical_mm']:.3f} | "
                         f"{r['hybrid_mm']:.3f} | {r['hybrid_mm'] / r['physical_mm'] - 1:+.1%} |")
            L.append("")
        if sc.get("oracle"):
            L += ["Oracle bound on rescaling the arm-shape correction: each candidate fitted "
                  "on all of A, its transferred position correction P multiplied by α ∈ {0, "
                  "0.1, …, 1.5}, mean ‖E − α·P‖ on each series after BASE + PROBE "
                  "re-identification (α = 0 is the physical model, α = 1 the table above). "
                  "**The α is chosen on the validation series itself**: an upper bound on what "
                  "any shrinking or scaling of the layer can achieve there, not a usable "
                  "model. Mean position error (mm):", "",
                  "| candidate | series | physical | α = 1 | best α | at best α | "
                  "vs physical |", "|---|---|---|---|---|---|---|"]
            for name, v in sc["oracle"].items():
                for k, o in v.items():
                    one = o["curve_mm"][o["alphas"].index(1.0)]
                    L.append(f"| {name} | {k} | {o['physical_mm']:.3f} | {one:.3f} | "
                             f"{o['alpha']:.1f} | {o['best_mm']:.3f} | "
                             f"{o['best_mm'] / o['physical_mm'] - 1:+.1%} |")
            L.append("")
    g = d.get("campaign")
    if g:
        sizes = g["sizes"]
        L += ["## (g) A short campaign in the new set-up", "",
              "B, C, D with BASE + PROBE re-identified as in (b); grouped 5-fold over each "
              "series' 0.4 m cells. In each fold a campaign of n poses is drawn (seeded) from "
              "the training cells, a stage is learned on it — gradient-boosted trees on sin/cos "
              "of the six joint readings, position residual in the base frame, ≥ "
              + ", ".join(f"{g['leaf'][str(n)]}" for n in sizes)
              + " poses per leaf for n = " + ", ".join(map(str, sizes))
              + " — and the held-out cells are predicted: never a campaign pose nor a "
              "neighbour in its cell. *Stacked*: on top of A's arm-shape correction "
              "('joint-1 frame, q2, q3' fitted on all of A, no in-domain test); *alone*: on "
              f"the physical residual. Mean position error (mm; change against the physical "
              f"model), the mean over {g.get('draws', 1)} seeded draws of the campaigns (each "
              "draw in the JSON):", "",
              "| series | cells | physical | A's arm-shape stage | "
              + " | ".join(f"stacked, n = {n} | alone, n = {n}" for n in sizes) + " |",
              "|---|---|---|---|" + "---|---|" * len(sizes)]
        cmd = {k: r.get("command_mm", {}) for k, r in g["series"].items()}
        cmd_sizes = sorted({int(n) for v in cmd.values() for n in v})
        for k, r in g["series"].items():
            ph = r["physical_mm"]

            def cell(v: float, ph: float = ph) -> str:
                return f"{v:.3f} ({v / ph - 1:+.0%})"

            L.append(f"| {k} | {r['cells']} | {ph:.3f} | {cell(r['shape_mm'])} | "
                     + " | ".join(f"{cell(r['stacked_mm'][str(n)])} | "
                                  f"{cell(r['alone_mm'][str(n)])}" for n in sizes) + " |")
        L.append("")
        if cmd_sizes:
            L += ["What the command does on the same campaigns — `plugcell calibrate "
                  "--residual-model learned --residual-prior A/params.json`, i.e. "
                  "`ResidualLearner.fit(…, prior=…)` with A's layer's arm-shape stage: its own "
                  "grouped CV over the campaign's cells (the benchmark's grid and trees), its "
                  "in-domain tests, A's stage only inside A's region; at least "
                  f"{MIN_POSES} poses. Mean position error (mm; change against the physical "
                  "model), same folds and draws:", "",
                  "| series | physical | " + " | ".join(f"command, n = {n}"
                                                       for n in cmd_sizes) + " |",
                  "|---|---|" + "---|" * len(cmd_sizes)]
            for k, r in g["series"].items():
                ph = r["physical_mm"]
                L.append(f"| {k} | {ph:.3f} | " + " | ".join(
                    f"{r['command_mm'][str(n)]:.3f} ({r['command_mm'][str(n)] / ph - 1:+.0%})"
                    for n in cmd_sizes) + " |")
            L.append("")
    L += ["", "## Reading the results", "", d["reading"], ""]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(L), encoding="utf-8")


def _hypotheses(sc: dict[str, Any], temp: dict[str, list[float]]) -> str:
    """The reading of H4 (approach direction) and H5 (length scale) in section (f)."""
    txt = ""
    plain = {(r.get("frame"), tuple(r.get("joints", ())), r.get("twist")): r
             for r in sc["candidates"] if not r.get("approach")}
    pairs = [(plain[key], r) for r in sc["candidates"] if r.get("approach")
             and (key := (r["frame"], tuple(r["joints"]), r["twist"])) in plain]
    if pairs:
        dA = max(abs(w[t] - o[t]) for o, w in pairs for t in ("cells_mm", "sectors_mm"))
        dT = max(abs(w["transfer"][k]["hybrid_mm"] - o["transfer"][k]["hybrid_mm"])
                 for o, w in pairs for k in "BCD")
        steps = sc.get("approach_median_step_deg", {})
        still = {k: [j + 1 for j, x in enumerate(v) if x < 0.01] for k, v in steps.items()}
        txt += (" H4, lost motion (the rest depends on the direction from which each joint "
                "approached the pose): with the six approach directions as features, "
                + " and ".join(repr(o["name"]) for o, _ in pairs)
                + f" change by at most {dA:.3f} mm on A's held-out cells and sectors and by at "
                f"most {dT:.3f} mm on B, C, D"
                + (" — no effect these data show" if max(dA, dT) < 0.01 else "") + ".")
        if "A" in steps:
            noisy = [f"joint{'s' * (len(v) > 1)} {', '.join(map(str, v))} in {k}"
                     for k, v in still.items() if v]
            txt += (" The test is weak on these data: series A is a fine grid (median joint "
                    f"steps {min(steps['A']):.2g}–{max(steps['A']):.2g}°), so there the signs "
                    "mostly carry the grid's scan direction"
                    + (", and " + "; ".join(noisy) + " move by under 0.01° between most poses "
                       "(median), so there their signs are the readings' jitter" if noisy else "")
                    + ".")
    scl = sc.get("scale", {})
    if scl:
        ph = {k: v["physical"] for k, v in scl.items()}
        hy = {k: v["hybrid"] for k, v in scl.items()}
        ch = {k: (hy[k]["rigid_mm"] / ph[k]["rigid_mm"] - 1,
                  hy[k]["scaled_mm"] / ph[k]["scaled_mm"] - 1) for k in scl}
        met = all(ch[k][1] <= -0.20 for k in "BD" if k in ch)
        txt += (" H5, a length scale per series (tracker scale, temperature): fitted after BASE "
                "+ PROBE, the similarity's scale is " + ", ".join(
                    f"{ph[k]['scale_ppm']:+.0f} ppm ({k})" for k in scl)
                + " on the physical residual; against translation and rotation alone it takes "
                "the physical error " + ", ".join(
                    f"{ph[k]['rigid_mm']:.3f} → {ph[k]['scaled_mm']:.3f} ({k})" for k in scl)
                + " mm and the arm-shape hybrid's " + ", ".join(
                    f"{hy[k]['rigid_mm']:.3f} → {hy[k]['scaled_mm']:.3f} ({k})" for k in scl)
                + " mm, so the hybrid's change against the physical model goes " + ", ".join(
                    f"{a:+.1%} → {b:+.1%} ({k})" for k, (a, b) in ch.items())
                + f" (at most {max(abs(b - a) for a, b in ch.values()) * 100:.1f} points): "
                + ("with the scale the target's 20 % on B and D is reached"
                   if met else "the scale does not bring the target's 20 % on B and D") + ".")
        if "A" in temp:
            span = max(hi for _, hi in temp.values()) - min(lo for lo, _ in temp.values())
            big = max(abs(v["scale_ppm"]) for v in ph.values())
            colder = [k for k in scl if temp[k][1] < temp["A"][0] and ph[k]["scale_ppm"] > 0]
            txt += (f" All temperature readings lie within {span:.2f} K, over which aluminium's "
                    f"23 ppm/K gives at most {23 * span:.0f} ppm; |δs| reaches {big:.0f} ppm"
                    + (f", and {', '.join(colder)}, colder than A throughout, give δs > 0 where "
                       "a cooler, shorter arm gives δs < 0" if colder else "")
                    + (": the scales are not the arm's thermal expansion; whether they are the "
                       "tracker's scale, the registration or something else, these data do not "
                       "say." if big > 2 * 23 * span else "."))
    return txt


def _bounds(sc: dict[str, Any]) -> str:
    """The reading of H6 (line of sight) and of the oracle α in section (f)."""
    txt = ""
    los = sc.get("line_of_sight")
    if los:
        res, span = los["result"], los["span"]
        a = res["A"]
        lo, hi = span["A"]["azimuth_deg"]
        over = [k for k in span if k != "A" and span[k]["azimuth_deg"][0] <= hi
                and span[k]["azimuth_deg"][1] >= lo]
        gain = 1 - a["hybrid_mm"] / a["physical_mm"]
        txt += (" H6, the tracker's own errors along its line of sight: learned on A as a "
                "function of the measured target's azimuth, elevation and range (residual in "
                f"the tracker frame), A's held-out cells go {a['physical_mm']:.3f} → "
                f"{a['hybrid_mm']:.3f} mm"
                + (" — across cells A's rest is not a learnable function of the tracker's "
                   "line of sight" if gain < 0.05 else f" ({gain:.0%} lower)")
                + "; carried to the other series it changes the error by " + ", ".join(
                    f"{res[k]['hybrid_mm'] / res[k]['physical_mm'] - 1:+.1%} ({k})"
                    for k in res if k != "A")
                + ". In azimuth the lines of sight of "
                + (" and ".join(over) + " overlap" if over else "no other series overlap")
                + f" A's ({lo:.1f} … {hi:.1f}°)" + "".join(
                    f"; {k}'s lie at {span[k]['azimuth_deg'][0]:.1f} … "
                    f"{span[k]['azimuth_deg'][1]:.1f}°" for k in span if k not in ["A", *over])
                + ".")
    orc = sc.get("oracle", {})
    if orc:
        chg = {(n, k): o["best_mm"] / o["physical_mm"] - 1 for n, v in orc.items()
               for k, o in v.items()}
        met = any(all(chg[(n, k)] <= -0.20 for k in "BD" if (n, k) in chg) for n in orc)
        txt += (" The oracle bound — the arm-shape correction scaled by the α best on each "
                "validation series itself, an upper bound rather than a model — gives "
                + "; ".join(f"{n!r} " + ", ".join(
                    f"{chg[(n, k)]:+.1%} ({k}, α = {o['alpha']:.1f})" for k, o in v.items())
                            for n, v in orc.items())
                + (": even with α chosen on B and D themselves, the target's 20 % on B and D "
                   "is not reached." if not met else ": only with α chosen on B and D "
                   "themselves is the target's 20 % on B and D reached."))
    return txt


def _campaign(g: dict[str, Any] | None) -> str:
    """The reading of (g): what a short campaign in the new set-up adds."""
    if not g:
        return ""
    ser = g["series"]

    def ch(k: str, tag: str, n: int) -> float:
        return ser[k][f"{tag}_mm"][str(n)] / ser[k]["physical_mm"] - 1

    sizes = g["sizes"]
    enough = next((n for n in sizes if all(ch(k, "stacked", n) <= -0.20 for k in "BD"
                                           if k in ser)), None)
    txt = (" Section (g), a short campaign in the new set-up (held-out cells of each series, "
           "never a campaign pose): with A's arm-shape stage plus a stage learned on n poses "
           "of the series, the error changes by " + "; ".join(
               f"n = {n}: " + ", ".join(f"{ch(k, 'stacked', n):+.0%} ({k})" for k in ser)
               for n in sizes)
           + "; learned from the campaign alone, by " + "; ".join(
               f"n = {n}: " + ", ".join(f"{ch(k, 'alone', n):+.0%} ({k})" for k in ser)
               for n in sizes) + ".")
    if enough is not None:
        txt += (f" So with the benchmark's stacked fit the issue's 20 % on B and D is reached "
                f"from a campaign of {enough} poses in the new set-up on top of what A teaches "
                "— not from A alone, which (b) asks.")
    else:
        txt += " No campaign size tried reaches 20 % on both B and D."
    cmd = sorted({int(m) for r in ser.values() for m in r.get("command_mm", {})})
    if cmd:
        txt += (" The command itself (--residual-prior: its own grouped CV and in-domain "
                "tests, A's stage only inside A's region) on the same campaigns: " + "; ".join(
                    f"n = {m}: " + ", ".join(
                        f"{ser[k]['command_mm'][str(m)] / ser[k]['physical_mm'] - 1:+.0%} ({k})"
                        for k in ser) for m in cmd) + ".")
        met = [m for m in cmd if all(ser[k]["command_mm"][str(m)] / ser[k]["physical_mm"]
                                     <= 0.80 for k in "BD" if k in ser)]
        txt += (f" With the command the 20 % on B and D is reached from {met[0]} poses."
                if met else " With the command no campaign size tried reaches 20 % on both "
                "B and D.")
    n = enough or sizes[-1]
    helps = [k for k in ser if ch(k, "stacked", n) < ch(k, "alone", n)]
    hurts = [k for k in ser if k not in helps]
    if helps:
        txt += (f" At n = {n}, A's arm-shape stage underneath helps on "
                + ", ".join(f"{k} ({ch(k, 'stacked', n):+.0%} against "
                            f"{ch(k, 'alone', n):+.0%} alone)" for k in helps))
        txt += ((", and costs on " + ", ".join(
            f"{k} ({ch(k, 'stacked', n):+.0%} against {ch(k, 'alone', n):+.0%})"
            for k in hurts) + ", where carried alone it made the error worse (above)")
            if hurts else "") + "."
    return txt


def reading(d: dict[str, Any]) -> str:
    """The page's interpretation, built from the numbers (nothing hard-coded)."""
    a, t = d["nested_cv"], d["transfer"]["validation"]
    worst = max((v["hybrid_mm"] / v["physical_mm"] - 1, k) for k, v in t.items())
    change = {k: v["hybrid_mm"] / v["physical_mm"] - 1 for k, v in t.items()}
    unguarded = {k: v["hybrid_without_domain_test_mm"] / v["physical_mm"] - 1
                 for k, v in t.items()}
    inside = {k: v["in_domain"] for k, v in t.items()}
    own = {k: v for k, v in d["diagnostics"]["own"].items() if "hybrid_mm" in v}
    local = {k: v.get("local_in_domain") for k, v in t.items()}
    met = all(change[k] <= -0.20 for k in "BD" if k in change) and worst[0] <= 0.02
    txt = (f"Inside series A the rest the physical model leaves is a learnable function of "
           f"the joint angles: held-out cells drop from {a['physical_mm']:.3f} to "
           f"{a['hybrid_mm']:.3f} mm ({1 - a['hybrid_mm'] / a['physical_mm']:.0%} lower). "
           "Across series, with BASE and PROBE re-identified, the in-domain tests find "
           + ", ".join(f"{inside[k]:.0%} of {k}" for k in t)
           + " inside the arm-shape stage's region ("
           + ", ".join(f"{local[k]:.0%}" for k in t if local[k] is not None)
           + " inside the set-up stage's), and the hybrid model changes the error by "
           + ", ".join(f"{change[k]:+.1%} ({k})" for k in t)
           + f" (worst {worst[1]}, {worst[0]:+.1%}); without the tests the layer would change "
           "it by " + ", ".join(f"{unguarded[k]:+.1%} ({k})" for k in t) + ". "
           + ("The issue's target (≥ 20 % lower on B and D, never more than 2 % worse) is met. "
              if met else "The issue's target (≥ 20 % lower on B and D, never more than 2 % "
              "worse) is not met: the part of A's rest that is a function of the arm's shape in "
              "the joint-1 frame carries over, the rest of it does not. "))
    txt += ("Each series' own rest, learned by the same grouped CV inside that series, drops "
            + ", ".join(f"{v['physical_mm']:.3f} → {v['hybrid_mm']:.3f} mm ({k})"
                        for k, v in own.items())
            + ", so the rest is systematic within a set-up but not the same function of the "
            "joint angles from one series to the next. The series differ in where the tracker "
            "stood (a tracker's own angular and ranging errors follow the line of sight), "
            "the temperature (ranges above), where joint 1 points and the joint combinations they "
            "visit (series D turns joint 1 beyond +180°, C below −180° and the wrists "
            "elsewhere) — not the T-MAC mounting (section (f)); which of the others dominates, "
            "these data do not say. A learned layer is therefore worth most where it is learned "
            "from a campaign in the set-up and pose region where it is used; carried to another "
            "set-up only its arm-shape part carries over (the figures above), the rest must be "
            "re-learned, and the in-domain tests keep it from doing harm meanwhile.")
    sc = d.get("screening")
    if sc:
        pr = [v for k, v in sc["probe"].items() if k != "A"]
        best = min(sc["candidates"], key=lambda r: r["sectors_mm"])
        txt += (" Why this representation (section (f)): the identified PROBEs of B, C, D lie "
                f"within {max(v['offset_from_A_mm'] for v in pr):.2f} mm and "
                f"{max(v['rotation_from_A_mrad'] for v in pr):.1f} mrad of A's — the T-MAC sits "
                "at the same place on the flange in every series (the differing "
                "Trafo_TM_F_init_calib files are initial guesses), so a flange twist mapped to "
                "each series' PROBE gives the same point correction: a lever that differs by "
                "under 0.1 mm moves the correction of an orientation error of ~1 mrad by under "
                "0.0001 mm; the twist candidate's figures differ from the point candidate's "
                "because the trees fit a different target, not because of the lever, and on A "
                "the two score alike. On A alone, the lowest "
                f"error on held-out joint-1 sectors is {best['name']!r} "
                f"({best['sectors_mm']:.3f} mm); every candidate without q1 loses on held-out "
                "cells of A, which is why the set-up stage stays on top of the shape stage.")
        txt += _hypotheses(sc, d["diagnostics"].get("temperature_c", {})) + _bounds(sc)
    runs = {r["order"]: r for r in d["harmonics"]["runs"]}
    h0, h2 = runs[0], runs[2]
    sig = sum(abs(t_["value_urad"]) > 3 * t_["sigma_urad"] for t_ in d["harmonics"]["terms"])
    txt += (f" The physical joint-angle harmonics (order 2, {sig} of "
            f"{len(d['harmonics']['terms'])} terms beyond 3σ) explain "
            f"{1 - h2['calibration_mm'] / h0['calibration_mm']:.0%} of A's rest "
            f"({h0['calibration_mm']:.3f} → {h2['calibration_mm']:.3f} mm); on the other series "
            + ", ".join(f"{k} {h0['validation'][k]:.3f} → {h2['validation'][k]:.3f}"
                        for k in "BCD")
            + " mm: the rest is not, for the most part, a per-joint transmission error.")
    th = d.get("thermal", {})
    if th:
        sig_t = [k for k, v in th.items() if v["kappa_per_k"] is not None
                 and abs(v["kappa_per_k"]) > 3 * v["sigma_per_k"]]
        txt += (f" Within a series the temperature spans at most "
                f"{max(v['span_k'] for v in th.values()):.2f} K, little for the thermal term: it "
                "is beyond 3σ on " + (", ".join(
                    f"{k} ({th[k]['kappa_per_k'] * 1e6:.0f}·10⁻⁶/K, "
                    f"{abs(th[k]['kappa_per_k']) / 23e-6:.1f}× aluminium's expansion)"
                    for k in sig_t) if sig_t else "no series")
                + (" — a value no metal arm has, so there it absorbs something else that "
                   "varies along with the temperature reading, not an expansion" if any(
                       abs(th[k]["kappa_per_k"]) > 2 * 23e-6 for k in sig_t) else "")
                + "; the other series show no significant expansion.")
    return txt + _campaign(d.get("campaign"))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=None)
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "results" / "ur10-residual.md")
    ap.add_argument("--quick", action="store_true",
                    help="one hyper-parameter candidate, 100 trees (for make bench)")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--from-json", type=Path, metavar="FILE",
                    help="re-render the page from the JSON a previous run wrote next to it "
                         "(no computation; the plots are kept; the JSON's reading is renewed)")
    args = ap.parse_args()
    if args.from_json is not None:
        d = json.loads(args.from_json.read_text(encoding="utf-8"))
        d["reading"] = reading(d)
        images = [n for n in ("ur10-residual-cv.png", "ur10-residual-transfer.png")
                  if (args.out.parent / n).is_file()]
        write_page(d, args.out, images)
        args.from_json.write_text(json.dumps(d, indent=1, default=float), encoding="utf-8")
        print(f"wrote {args.out} (and the reading into {args.from_json})")
        return 0
    data = args.data or find_data()
    if data is None or not data.is_dir():
        print("IPA robot-accuracy data not found (../shared/data/ipa-robot-accuracy): skipped")
        return 0
    # load the native thread pools (OpenMP, OpenBLAS) before limiting them: a pool first
    # loaded inside threadpool_limits keeps its default thread count
    import scipy.linalg  # noqa: F401
    import sklearn.ensemble  # noqa: F401
    from threadpoolctl import threadpool_limits

    t0 = time.perf_counter()
    # two of the library's default candidates and 200 trees: the 2-core machine is shared
    kw: dict[str, Any] = ({"grid": DEFAULT_GRID[1:2], "trees": 100} if args.quick
                          else {"grid": (DEFAULT_GRID[1], DEFAULT_GRID[2]), "trees": 200})
    work = Path("/tmp/plugcell-ur10-residual")
    work.mkdir(parents=True, exist_ok=True)
    (work / "ur10_masses.toml").write_text(ur10_toml(masses=True), encoding="utf-8")
    desc = load_robot(work / "ur10_masses.toml")
    sets = load_sets(data)
    plain = {k: _without_temperature(v) for k, v in sets.items()}
    with threadpool_limits(1):
        learner = ResidualLearner(**kw)
        print("(a) nested grouped CV on series A", flush=True)
        a = nested_cv(desc, plain["A"], learner, 0.4)
        print("(b) calibrated on A, validated on B, C, D", flush=True)
        t = transfer(desc, plain, learner)
        print("(c) diagnostics", flush=True)
        c = diagnostics(desc, sets, kw)
        print("(d) joint-angle harmonics", flush=True)
        hm = harmonics(desc, plain)
        print("(e) thermal expansion", flush=True)
        th = thermal(desc, sets)
        print("(f) choice of the representation (A alone; B, C, D for the record)", flush=True)
        sc = screening(desc, plain, dict(DEFAULT_GRID[2]), kw["trees"],
                       load_directions(data, sets))
        print("(g) a short campaign in the new set-up", flush=True)
        g = short_campaign(desc, plain, dict(DEFAULT_GRID[2]), kw["trees"],
                           grid=tuple(kw["grid"]))
    d: dict[str, Any] = {
        "machine": f"{platform.machine()} {platform.processor() or ''}, Python "
                   f"{platform.python_version()}".replace("  ", " "),
        "quick": args.quick, "grid": list(kw["grid"]), "trees": kw["trees"],
        "poses": {k: len(v) for k, v in sets.items()},
        "nested_cv": a, "transfer": t, "diagnostics": c, "harmonics": hm,
        "thermal": th, "screening": sc, "campaign": g,
        "elapsed_s": time.perf_counter() - t0}
    d["reading"] = reading(d)
    images = plots(d, args.out.parent)
    write_page(d, args.out, images)
    slim = {k: v for k, v in d.items() if k != "nested_cv"}
    slim["nested_cv"] = {k: v for k, v in a.items() if not k.endswith("norms_mm")}
    args.out.with_suffix(".json").write_text(json.dumps(slim, indent=1, default=float),
                                             encoding="utf-8")
    if args.json:
        print(json.dumps(slim, indent=2, default=float))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
