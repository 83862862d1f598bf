"""How far a short campaign in a new set-up can go (issue 36 §2), measured on the IPA UR10:
the noise floor, a small new layer on top of A's, and the CV's choice on I-optimal campaigns.

Same data and protocol as ``short_campaign_ur10.py`` (series A the earlier set-up, fitted
on all of A or read from ``--cache``; grouped 5-fold over the new series' 0.4 m cells; the
campaign drawn with the same seeds, at random or ``--selection planned``; scored on the
held-out cells only, pooled mean over all held-out poses, mm).  Three parts:

* ``--part floor`` — what of a series' error is repeatable at all.  Pairs of poses of one
  series whose six joint readings agree within ``--pair-rad`` (max-norm) are the same pose
  measured twice (a few poses apart in time).  With ``r = p_M − p(q)`` the residual of A's
  model moved to the series (BASE + PROBE on all its poses), the pair difference
  ``Δ = r_i − r_j`` cancels every repeatable error (and the model's response to the small
  joint difference); ``σ_n = rms|Δ| / √2`` is the per-pose RMS of the non-repeatable
  part (tracker noise, robot repeatability, short-term drift), and ``√(8 / 3π) σ_n`` the
  mean error it alone leaves for an isotropic Gaussian (no model can go below it).  Pairs
  with ``|Δ|`` above ten times the median are counted and left out of the RMS.  Also the
  tracker's own reported standard deviations (``measurement_std_x/y/z``).
* ``--part small-layer`` — (a) A's learned layer kept and a small new layer on top: the MAP
  at ``τ = --tau`` with A's layer (``PriorCalibrator(scale=τ, stage=False)``), then ridge
  regression (standardised features, α ∈ 10⁻⁴ … 10³) of what it leaves of the campaign
  (base frame) on few features — ``h1``: sin, cos q_j (12); ``h2``: + sin, cos 2q_j (24);
  ``lin``: the base-frame target position (3); ``poly2``: its quadratic monomials (9) —,
  and a Gaussian process on (sin q, cos q) (RBF + white noise, marginal likelihood).  ``cv``:
  α by grouped CV over the campaign's cells, the layer used only when that CV beats no
  layer; ``oracle``: α chosen on the held-out cells (a bound, not a method).  A's layer
  mapped by a 3 × 3 matrix fitted on the campaign (``E₀ ≈ L M``: what the MAP's physical
  model leaves against A's layer's correction, both in the base frame; ``M = I`` is A's
  layer kept), always, by the same grouped CV, and with ``M`` from the training cells
  (hindsight).  And a bound
  on what 100 poses can teach at all: a Gaussian process on (sin q, cos q) with one length
  scale per feature, its kernel learnt on what the fit leaves of up to 800 of the training
  cells' poses (hindsight: the covariance of the new set-up's rest, known), then
  conditioned on the campaign only — the best linear predictor from the campaign's poses
  if that covariance is right — and, for reference, on all the training cells.
* ``--part choice`` — (b) the CV's choice among ``--prior``'s candidates
  (:data:`~plugcell.calibration.prior.CANDIDATES`, no campaign stage): every candidate's
  per-pose CV errors over the campaign's cells and its held-out error fitted on the
  whole campaign.  Rules: ``pick`` (today's, 0.4 m cells); ``nested``: the pick made
  without each CV fold's poses is scored on that fold (the outer estimate of the whole
  selection procedure); when it is above the better baseline's CV score, that baseline;
  ``pick, 0.2 m cells`` and ``pick, 10-fold``: the same rule on other CV splits; ``fixed``:
  each candidate always; ``oracle``: the best candidate on the held-out cells per campaign.

    .venv/bin/python benchmarks/short_campaign_bounds.py --part floor
    .venv/bin/python benchmarks/short_campaign_bounds.py --part small-layer --series B
        --sizes 100,200,400 --cache A.pkl
    .venv/bin/python benchmarks/short_campaign_bounds.py --part choice --series C
        --selection planned --sizes 50,100 --cache A.pkl

Single-threaded.  Without the data folder it says so and exits 0.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
import warnings
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from calibration_ur10 import SERIES
from plugcell.calibration import CalibrationData, Calibrator
from plugcell.calibration.identify import refit_base
from plugcell.calibration.prior import (
    ALONE,
    CANDIDATES,
    MOVED,
    Prior,
    PriorCalibrator,
    _label,
    parse_choice,
    pick,
)
from plugcell.calibration.residual_model import (
    ResidualLearner,
    calibration_fingerprint,
    hybrid_poses,
    workspace_cells,
)
from residual_ur10 import find_data, read_column
from short_campaign_ur10 import MODEL, choose, earlier, outer_folds, ur10_and_sets

RIDGE_ALPHAS = np.logspace(-4, 3, 15)
FEATURES = ("h1", "h2", "lin", "poly2")
#: Training-cell poses the oracle GP's kernel is learnt on (a random subset, seeded).
ORACLE_POSES = 800


def _campaigns(resA: Any, d: CalibrationData, sizes: tuple[int, ...], selection: str):
    """(fold, n, campaign, held-out set, training cells' poses) with the seeds of
    ``short_campaign_ur10.py`` run on one series (draw 0)."""
    for f_no, (tr, te, rng_model) in enumerate(outer_folds(resA.model, d)[2]):
        for n in sizes:
            rng = np.random.default_rng([0, f_no, n])
            yield (f_no, n, d.subset(choose(rng_model, d, tr, n, selection, rng)),
                   d.subset(te), d.subset(tr))


def _err(test: CalibrationData, P: np.ndarray) -> np.ndarray:
    return np.linalg.norm(test.positions - P, axis=1)


# --------------------------------------------------------------------------- floor
def floor(resA: Any, sets: dict[str, CalibrationData], data: Path, pair_rad: float) -> None:
    """``--part floor`` (module docstring)."""
    from scipy.spatial import cKDTree

    print(f"| series | poses | repeated pairs (joints within {pair_rad * 1e3:g} mrad) | "
          "median |Δ| (mm) | outliers | σ_n (mm) | mean error of the noise alone (mm) | "
          "tracker std, mean |σ_xyz| (mm) |")
    print("|---|---|---|---|---|---|---|---|")
    for key in ("B", "C", "D"):
        d = sets[key]
        rel = SERIES[key][0]
        std = np.column_stack([read_column(data / rel, f"measurement_std_{c}")
                               for c in "xyz"])
        tracker = float(np.linalg.norm(std, axis=1).mean())  # file unit: mm
        pairs = np.array(sorted(cKDTree(d.q).query_pairs(pair_rad, p=np.inf)), int)
        if len(pairs) == 0:
            print(f"| {key} | {len(d)} | 0 | – | – | – | – | {tracker:.4f} |")
            continue
        moved = refit_base(resA.model, d, probe=True)
        r = d.positions - moved.predict(d.q)[:, :3, 3]
        delta = np.linalg.norm(r[pairs[:, 0]] - r[pairs[:, 1]], axis=1)
        med = float(np.median(delta))
        keep = delta <= 10 * med
        sigma = float(np.sqrt(np.mean(delta[keep] ** 2) / 2))
        print(f"| {key} | {len(d)} | {len(pairs)} | {med * 1e3:.4f} | {int((~keep).sum())} | "
              f"{sigma * 1e3:.4f} | {math.sqrt(8 / (3 * math.pi)) * sigma * 1e3:.4f} | "
              f"{tracker:.4f} |")


# --------------------------------------------------------------------------- small layer
def _features(kind: str, q: np.ndarray, pb: np.ndarray) -> np.ndarray:
    if kind == "h1":
        return np.hstack([np.sin(q), np.cos(q)])
    if kind == "h2":
        return np.hstack([np.sin(q), np.cos(q), np.sin(2 * q), np.cos(2 * q)])
    if kind == "lin":
        return pb
    x, y, z = pb.T
    return np.column_stack([x, y, z, x * x, y * y, z * z, x * y, x * z, y * z])


def _ridge(X: np.ndarray, Y: np.ndarray, Xt: np.ndarray, alpha: float) -> np.ndarray:
    from sklearn.linear_model import Ridge
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler

    return make_pipeline(StandardScaler(), Ridge(alpha=alpha)).fit(X, Y).predict(Xt)


def _gp(X: np.ndarray, Y: np.ndarray) -> Any:
    from sklearn.gaussian_process import GaussianProcessRegressor
    from sklearn.gaussian_process.kernels import RBF, WhiteKernel
    from sklearn.gaussian_process.kernels import ConstantKernel as C

    k = C(1e-8, (1e-12, 1e-5)) * RBF(1.0, (0.1, 10.0)) + WhiteKernel(1e-8, (1e-12, 1e-5))
    return GaussianProcessRegressor(k, random_state=0).fit(X, Y)


def small_layer_row(prior: Prior, camp: CalibrationData, test: CalibrationData,
                    tau: float, train: CalibrationData) -> dict[str, np.ndarray]:
    """Per held-out pose errors (m) of the MAP with A's layer and of each small layer on
    top, and the oracle-kernel GP's (module docstring; ``train``: the training cells' poses,
    the campaign among them)."""
    from sklearn.model_selection import GroupKFold

    res = PriorCalibrator(prior, scale=tau, stage=False).fit(camp)
    res = res.with_residual_model(replace(prior.layer,
                                          fingerprint=calibration_fingerprint(res.model)))
    B = res.model.base()
    Rb = B[:3, :3]
    Pc = res.predict_hybrid(camp.q)[0][:, :3, 3]
    Pt = res.predict_hybrid(test.q)[0][:, :3, 3]
    E = (camp.positions - Pc) @ Rb  # what the MAP and A's layer leave, base frame
    pbc, pbt = (Pc - B[:3, 3]) @ Rb, (Pt - B[:3, 3]) @ Rb
    cells = workspace_cells(pbc, 0.4)
    folds = list(GroupKFold(n_splits=min(5, int(cells.max()) + 1)).split(pbc, groups=cells))
    cv0 = float(np.linalg.norm(E, axis=1).mean())
    out = {"A's layer kept (MAP)": _err(test, Pt)}
    for kind in FEATURES:
        Xc, Xt = _features(kind, camp.q, pbc), _features(kind, test.q, pbt)
        cvs = []
        for a in RIDGE_ALPHAS:
            e = np.empty(len(camp))
            for tr, te in folds:
                e[te] = np.linalg.norm(E[te] - _ridge(Xc[tr], E[tr], Xc[te], a), axis=1)
            cvs.append(e.mean())
        errs = [_err(test, Pt + _ridge(Xc, E, Xt, a) @ Rb.T) for a in RIDGE_ALPHAS]
        i = int(np.argmin(cvs))
        out[f"+ ridge {kind}, cv"] = errs[i] if cvs[i] < cv0 else out["A's layer kept (MAP)"]
        out[f"+ ridge {kind}, oracle α"] = min([out["A's layer kept (MAP)"], *errs],
                                               key=np.mean)
    out |= _mapped_layer(res, (camp, Pc), (test, Pt), train, folds, cv0,
                         out["A's layer kept (MAP)"])
    Xc = np.hstack([np.sin(camp.q), np.cos(camp.q)])
    Xt = np.hstack([np.sin(test.q), np.cos(test.q)])
    e = np.empty(len(camp))
    for tr, te in folds:
        e[te] = np.linalg.norm(E[te] - _gp(Xc[tr], E[tr]).predict(Xc[te]), axis=1)
    gp = _err(test, Pt + _gp(Xc, E).predict(Xt) @ Rb.T)
    out["+ GP on (sin q, cos q), always"] = gp
    out["+ GP on (sin q, cos q), cv"] = gp if e.mean() < cv0 else out["A's layer kept (MAP)"]
    return out | _oracle_gp(res, train, Xc, E, Xt, Pt, test)


def _mapped_layer(res: Any, camp: tuple[CalibrationData, np.ndarray],
                  test: tuple[CalibrationData, np.ndarray], train: CalibrationData,
                  folds: list, cv0: float, kept: np.ndarray) -> dict[str, np.ndarray]:
    """A's layer mapped by a 3 × 3 matrix: with ``p₀(q)`` the MAP's physical prediction
    and ``L(q) = R_Bᵀ (p_hybrid − p₀)`` A's layer's correction (base frame), the campaign's
    ``E₀ = R_Bᵀ (p_M − p₀) ≈ L M`` by least squares (9 parameters; ``M = I`` is A's layer
    as it is); *cv*: adopted when its grouped CV over the campaign's cells beats A's layer
    kept; *oracle*: ``M`` from all the training cells' poses (hindsight).  ``camp`` and
    ``test`` come with their hybrid positions (``small_layer_row``'s)."""
    Rb = res.model.base()[:3, :3]

    def parts(d: CalibrationData, hybrid: np.ndarray) -> tuple[np.ndarray, ...]:
        p0 = res.model.predict(d.q)[:, :3, 3]
        return p0, (hybrid - p0) @ Rb, (d.positions - p0) @ Rb

    def fit(L: np.ndarray, E: np.ndarray) -> np.ndarray:
        return np.linalg.lstsq(L, E, rcond=None)[0]

    _, Lc, Ec = parts(*camp)
    p0t, Lt, _ = parts(*test)
    _, La, Ea = parts(train, res.predict_hybrid(train.q)[0][:, :3, 3])
    e = np.empty(len(Lc))
    for tr, te in folds:
        e[te] = np.linalg.norm(Ec[te] - Lc[te] @ fit(Lc[tr], Ec[tr]), axis=1)
    mapped = _err(test[0], p0t + (Lt @ fit(Lc, Ec)) @ Rb.T)
    return {"+ A's layer mapped by 3 × 3 (least squares), always": mapped,
            "+ A's layer mapped by 3 × 3, cv": mapped if e.mean() < cv0 else kept,
            "+ A's layer mapped by 3 × 3 from the training cells (oracle)":
            _err(test[0], p0t + (Lt @ fit(La, Ea)) @ Rb.T)}


def _oracle_gp(res: Any, train: CalibrationData, Xc: np.ndarray, E: np.ndarray,
               Xt: np.ndarray, Pt: np.ndarray, test: CalibrationData) -> dict[str, np.ndarray]:
    """The bound of ``--part small-layer``: an ARD Gaussian process on (sin q, cos q) whose
    kernel is learnt (marginal likelihood) on what the MAP and A's layer leave of up to
    :data:`ORACLE_POSES` of the training cells' poses — hindsight no campaign has —, then
    conditioned on the campaign alone (and, for reference, on all the training cells)."""
    from sklearn.gaussian_process import GaussianProcessRegressor
    from sklearn.gaussian_process.kernels import RBF, WhiteKernel
    from sklearn.gaussian_process.kernels import ConstantKernel as C

    Rb = res.model.base()[:3, :3]
    Xa = np.hstack([np.sin(train.q), np.cos(train.q)])
    Ea = (train.positions - res.predict_hybrid(train.q)[0][:, :3, 3]) @ Rb
    sub = np.random.default_rng(0).permutation(len(train))[:ORACLE_POSES]
    k = (C(1e-8, (1e-12, 1e-5)) * RBF(np.ones(Xa.shape[1]), (0.05, 100.0))
         + WhiteKernel(1e-9, (1e-12, 1e-5)))
    kernel = GaussianProcessRegressor(k, random_state=0).fit(Xa[sub], Ea[sub]).kernel_
    fixed = GaussianProcessRegressor(kernel, optimizer=None)
    return {"+ GP, kernel learnt on the training cells (oracle), on the campaign":
            _err(test, Pt + fixed.fit(Xc, E).predict(Xt) @ Rb.T),
            "+ GP, the same kernel, on all the training cells (reference)":
            _err(test, Pt + fixed.fit(Xa, Ea).predict(Xt) @ Rb.T)}


def small_layer(resA: Any, d: CalibrationData, sizes: tuple[int, ...], selection: str,
                tau: float) -> None:
    """``--part small-layer`` (module docstring)."""
    prior = Prior.from_result(resA)
    pooled: dict[int, dict[str, list[np.ndarray]]] = {n: {} for n in sizes}
    for f_no, n, camp, test, train in _campaigns(resA, d, sizes, selection):
        t0 = time.perf_counter()
        row = small_layer_row(prior, camp, test, tau, train)
        for k, v in row.items():
            pooled[n].setdefault(k, []).append(v)
        print(f"  fold {f_no + 1}, n = {n}: " + ", ".join(
            f"{k} {v.mean() * 1e3:.3f}" for k, v in row.items())
            + f" mm ({time.perf_counter() - t0:.0f} s)", flush=True)
    names = list(pooled[sizes[0]])
    print("\n| variant | " + " | ".join(f"n = {n}" for n in sizes) + " |")
    print("|---|" + "---|" * len(sizes))
    for k in names:
        print(f"| {k} | " + " | ".join(f"{np.concatenate(pooled[n][k]).mean() * 1e3:.3f}"
                                       for n in sizes) + " |")


# --------------------------------------------------------------------------- choice
def _cv_folds(targets: np.ndarray, scheme: str) -> list[tuple[np.ndarray, np.ndarray]]:
    from sklearn.model_selection import GroupKFold, KFold

    if scheme == "kfold10":
        return list(KFold(n_splits=10, shuffle=True, random_state=0).split(targets))
    cells = workspace_cells(targets, float(scheme.removeprefix("cells")))
    return list(GroupKFold(n_splits=min(5, int(cells.max()) + 1)).split(targets, groups=cells))


def nested_choice(cv: dict[str, np.ndarray],
                  folds: list[tuple[np.ndarray, np.ndarray]]) -> tuple[str, float]:
    """The nested rule (module docstring): the outer estimate of ``pick`` — each fold scored
    with the pick made on the other folds' poses — and the candidate it leads to."""
    e = np.empty(len(cv[MOVED]))
    for _, te in folds:
        rest = np.ones(len(e), bool)
        rest[te] = False
        c = _label(pick({k: float(v[rest].mean()) for k, v in cv.items()}))
        e[te] = cv[c][te]
    scores = {k: float(v.mean()) for k, v in cv.items()}
    base = min((MOVED, ALONE), key=lambda k: scores[k])
    return (_label(pick(scores)) if e.mean() <= scores[base] else base), float(e.mean())


def _candidate_errors(prior: Prior, pc: PriorCalibrator, camp: CalibrationData,
                      off: CalibrationData, test: CalibrationData) -> dict[str, np.ndarray]:
    """Each candidate fitted on the whole campaign: its held-out errors (m)."""
    out = {}
    for c in CANDIDATES:
        tau, layer = parse_choice(c)
        if tau is None:
            P = Calibrator(prior.model.structure.desc, MODEL).fit(camp).predict(test.q)
        else:
            m, *_ = pc.solve(off if layer else camp, tau)
            P = m.predict(test.q)
            if layer:
                P = hybrid_poses(P, m.base()[:3, :3], prior.layer.predict(test.q).correction)
        out[_label(c)] = _err(test, P[:, :3, 3])
    return out


def choice(resA: Any, d: CalibrationData, sizes: tuple[int, ...], selection: str) -> None:
    """``--part choice`` (module docstring)."""
    prior = Prior.from_result(resA)
    pc = PriorCalibrator(prior, stage=False)
    rules = ("pick", "nested", "pick, 0.2 m cells", "pick, 10-fold", "oracle")
    pooled: dict[int, dict[str, list[np.ndarray]]] = {n: {} for n in sizes}
    for f_no, n, camp, test, _ in _campaigns(resA, d, sizes, selection):
        t0 = time.perf_counter()
        off, _ = pc.offset_data(camp)
        start = refit_base(prior.model, camp, probe=True)
        targets = (np.linalg.inv(start.base()) @ start.predict(camp.q))[:, :3, 3]
        cv = {}
        for scheme in ("cells0.4", "cells0.2", "kfold10"):
            folds = _cv_folds(targets, scheme)
            cv[scheme] = ({_label(c): pc._cv_errors(camp, off, folds, c) for c in CANDIDATES},
                          folds)
        held = _candidate_errors(prior, pc, camp, off, test)
        sc = {s: {k: float(v.mean()) for k, v in cv[s][0].items()} for s in cv}
        chosen = {"pick": _label(pick(sc["cells0.4"])),
                  "nested": nested_choice(*cv["cells0.4"])[0],
                  "pick, 0.2 m cells": _label(pick(sc["cells0.2"])),
                  "pick, 10-fold": _label(pick(sc["kfold10"])),
                  "oracle": min(held, key=lambda k: held[k].mean())}
        for k, v in held.items():
            pooled[n].setdefault(f"fixed {k}", []).append(v)
        for r in rules:
            pooled[n].setdefault(r, []).append(held[chosen[r]])
        print(f"  fold {f_no + 1}, n = {n}: " + ", ".join(
            f"{r} {chosen[r]} {held[chosen[r]].mean() * 1e3:.3f}" for r in rules)
            + f"; held-out moved {held[MOVED].mean() * 1e3:.3f}, alone "
            f"{held[ALONE].mean() * 1e3:.3f}; CV (0.4 m) moved "
            f"{sc['cells0.4'][MOVED] * 1e3:.3f}, alone {sc['cells0.4'][ALONE] * 1e3:.3f} mm "
            f"({time.perf_counter() - t0:.0f} s)", flush=True)
    mean = {n: {k: float(np.concatenate(v).mean() * 1e3) for k, v in pooled[n].items()}
            for n in sizes}
    print("\n| rule | " + " | ".join(f"n = {n}" for n in sizes) + " |")
    print("|---|" + "---|" * len(sizes))
    fixed = [k for k in mean[sizes[0]] if k.startswith("fixed")]
    best_fixed = min(fixed, key=lambda k: sum(mean[n][k] for n in sizes))
    for k in (f"fixed {MOVED}", f"fixed {ALONE}", *rules, best_fixed):
        cells = []
        for n in sizes:
            ref = min(mean[n][f"fixed {MOVED}"], mean[n][f"fixed {ALONE}"])
            cells.append(f"{mean[n][k]:.3f} ({(mean[n][k] / ref - 1) * 100:+.1f} %)")
        print(f"| {k} | " + " | ".join(cells) + " |")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--part", choices=("floor", "small-layer", "choice"), required=True)
    ap.add_argument("--data", type=Path, default=None)
    ap.add_argument("--series", default="B", choices=("B", "C", "D"))
    ap.add_argument("--sizes", default="100")
    ap.add_argument("--selection", choices=("planned", "random"), default="random")
    ap.add_argument("--tau", type=float, default=1.0,
                    help="small-layer: the MAP's τ under the new layer (default 1)")
    ap.add_argument("--pair-rad", type=float, default=5e-4,
                    help="floor: joints within this (rad, max-norm) make a repeated pose")
    ap.add_argument("--cache", type=Path, metavar="FILE",
                    help="pickle of set-up A's fit, as short_campaign_ur10.py --cache")
    args = ap.parse_args()
    data = args.data or find_data()
    if data is None or not data.is_dir():
        print("IPA robot-accuracy data not found (../shared/data/ipa-robot-accuracy): skipped")
        return 0
    from threadpoolctl import threadpool_limits

    warnings.filterwarnings("ignore", module="sklearn")  # GP bound warnings
    desc, sets = ur10_and_sets(data)
    sizes = tuple(int(x) for x in args.sizes.split(","))
    with threadpool_limits(1):
        resA = earlier(desc, sets["A"], ResidualLearner(), args.cache)
        if args.part == "floor":
            floor(resA, sets, data, args.pair_rad)
        elif args.part == "small-layer":
            small_layer(resA, sets[args.series], sizes, args.selection, args.tau)
        else:
            choice(resA, sets[args.series], sizes, args.selection)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
