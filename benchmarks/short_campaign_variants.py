"""What else a short campaign with a prior could do (issue 36 §2), measured on the IPA UR10:
variants of ``plugcell calibrate --prior`` that were tried and not (or partly) adopted.

Same protocol as ``short_campaign_ur10.py`` (series A the earlier set-up; grouped 5-fold
over the new series' 0.4 m cells; a seeded random campaign of n poses among the training
cells' poses, or ``--selection planned``; scored on the held-out cells only).  Per campaign:

* **fixed variants** (no CV: what each would give if always used) — the MAP
  (:meth:`~plugcell.calibration.prior.PriorCalibrator.solve`) freeing only some groups of
  A's parameters (``frames``: BASE + PROBE only; ``offsets``: + joint offsets θ;
  ``compliance``: + c_k; ``offsets+compliance``; ``all``), τ ∈ {1, 3, 10, 30, 100}, with
  A's layer's correction scaled by α ∈ {0, 0.5, 1} (an offset of the fit and added to
  the prediction); and ``+gp``: on top of the α = 1 fit (``frames`` and ``all`` at τ = 3),
  a Gaussian process on the base-frame target position (RBF × constant + white noise,
  hyper-parameters by marginal likelihood, scikit-learn) fitted on what the fit and A's
  layer leave of the campaign;
* **CV rules** — the grouped CV over the campaign's own cells (5 folds), scoring each
  candidate of ``--prior`` (τ with A's layer, τ without it, moved, alone) and the ``+gp``
  candidates, then choosing by (R0) :func:`~plugcell.calibration.prior.pick`, (R1) R0 with
  a one-standard-error guard — a candidate other than the better baseline only when it
  beats that baseline by at least one cluster-robust standard error over the cells — and
  (R2) R0 with the ``+gp`` candidates (after the MAP ones).

Prints, per n, each variant's mean held-out error (mm, the mean over folds and draws of
the per-fold mean) and its change against the better of (i) and (ii).

    .venv/bin/python benchmarks/short_campaign_variants.py --series B --sizes 50,100
        [--selection random|planned] [--draws K] [--cache A.pkl]

Single-threaded.  Without the data folder it says so and exits 0.
"""

from __future__ import annotations

import argparse
import itertools
import math
import sys
import warnings
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from plugcell.calibration import CalibrationData, Calibrator
from plugcell.calibration.identify import refit_base
from plugcell.calibration.prior import (
    CANDIDATES,
    Prior,
    PriorCalibrator,
    _label,
    parse_choice,
    pick,
)
from plugcell.calibration.residual_model import (
    ResidualLearner,
    _remove_correction,
    hybrid_poses,
    workspace_cells,
)
from residual_ur10 import find_data
from short_campaign_ur10 import MODEL, choose, earlier, outer_folds, ur10_and_sets

TAUS = (1.0, 3.0, 10.0, 30.0, 100.0)
ALPHAS = (0.0, 0.5, 1.0)
GP_CANDIDATES = ("gp:0", "gp:3")


def groups_of(prior: Prior) -> dict[str, list[str]]:
    """A's identified keys by group (the frames are always free)."""
    offs = [k for k in prior.keys if k.startswith("theta")]
    comp = [k for k in prior.keys if k.startswith("c")]
    return {"frames": [], "offsets": offs, "compliance": comp,
            "offsets+compliance": offs + comp, "all": list(prior.keys)}


def _sub(prior: Prior, keys: list[str]) -> Prior:
    idx = [i for i, k in enumerate(prior.keys) if k in keys]
    return replace(prior, keys=tuple(prior.keys[i] for i in idx), sigma=prior.sigma[idx])


def _gp(X: np.ndarray, Y: np.ndarray) -> Any:
    from sklearn.gaussian_process import GaussianProcessRegressor
    from sklearn.gaussian_process.kernels import RBF, WhiteKernel
    from sklearn.gaussian_process.kernels import ConstantKernel as C

    k = C(1e-8, (1e-12, 1e-5)) * RBF(0.3, (0.05, 3.0)) + WhiteKernel(1e-8, (1e-12, 1e-5))
    return GaussianProcessRegressor(k, random_state=0).fit(X, Y)


def predict(prior: Prior, train: CalibrationData, q: np.ndarray, tau: float, alpha: float,
            gp: bool = False) -> np.ndarray:
    """Positions (N, 3) m at ``q`` of the MAP at ``τ`` on ``train`` with A's layer's
    correction × ``alpha`` (offset and prediction), plus the task-space GP when ``gp``."""
    layer = prior.layer
    moved = refit_base(prior.model, train, probe=True)
    off = _remove_correction(train, moved.base()[:3, :3],
                             alpha * layer.predict(train.q).correction)
    m, *_ = PriorCalibrator(prior).solve(off, tau)
    B = m.base()
    Rb = B[:3, :3]
    P = hybrid_poses(m.predict(q), Rb, alpha * layer.predict(q).correction)[:, :3, 3]
    if gp:
        Pc = hybrid_poses(m.predict(train.q), Rb,
                          alpha * layer.predict(train.q).correction)[:, :3, 3]
        g = _gp((Pc - B[:3, 3]) @ Rb, (train.positions - Pc) @ Rb)
        P = P + g.predict((P - B[:3, 3]) @ Rb) @ Rb.T
    return P


def fixed(prior: Prior, camp: CalibrationData, test: CalibrationData) -> dict[str, float]:
    """The held-out mean error (mm) of every fixed variant (module docstring)."""
    out: dict[str, float] = {}

    def err(P: np.ndarray) -> float:
        return float(np.linalg.norm(test.positions - P, axis=1).mean() * 1e3)

    for alpha, (g, keys) in itertools.product(ALPHAS, groups_of(prior).items()):
        for tau in ((0.0,) if g == "frames" else TAUS):
            out[f"α={alpha:g} {g} τ={tau:g}"] = err(
                predict(_sub(prior, keys), camp, test.q, tau, alpha))
    for g, tau in (("frames", 0.0), ("all", 3.0)):
        out[f"α=1 {g} τ={tau:g} +gp"] = err(
            predict(_sub(prior, groups_of(prior)[g]), camp, test.q, tau, 1.0, gp=True))
    return out


def _cluster_se(d: np.ndarray, g: np.ndarray) -> float:
    """Cluster-robust standard error of the mean of ``d`` over the clusters ``g``."""
    if not np.all(np.isfinite(d)):
        return math.inf
    cells = np.unique(g)
    s = np.array([(d[g == c] - d.mean()).sum() for c in cells])
    return math.sqrt(len(cells) / max(len(cells) - 1, 1) * float((s ** 2).sum())) / len(d)


def rules(prior: Prior, camp: CalibrationData, test: CalibrationData) -> dict[str, float]:
    """The held-out mean error (mm) of the candidate each CV rule chooses (module
    docstring): per-pose CV errors over the campaign's cells, then R0, R1, R2."""
    from sklearn.model_selection import GroupKFold

    pc = PriorCalibrator(prior)
    off, _ = pc.offset_data(camp)
    start = refit_base(prior.model, camp, probe=True)
    targets = (np.linalg.inv(start.base()) @ start.predict(camp.q))[:, :3, 3]
    cells = workspace_cells(targets, 0.4)
    folds = list(GroupKFold(n_splits=min(5, int(cells.max()) + 1)).split(targets, groups=cells))
    cv = {_label(c): pc._cv_errors(camp, off, folds, c) for c in CANDIDATES}
    for c in GP_CANDIDATES:
        e = np.empty(len(camp))
        for tr, te in folds:
            P = predict(prior, camp.subset(tr), camp.q[te], float(c[3:]), 1.0, gp=True)
            e[te] = np.linalg.norm(camp.positions[te] - P, axis=1)
        cv[c] = e
    scores = {k: float(v.mean()) for k, v in cv.items()}
    r0 = _label(pick({k: v for k, v in scores.items() if k not in GP_CANDIDATES}))
    base = min(("moved", "alone"), key=lambda k: scores[k])
    r1 = r0 if r0 == base or scores[r0] + _cluster_se(cv[r0] - cv[base], cells) \
        <= scores[base] else base
    with_gp = [c for c in scores if c not in ("moved", "alone")]
    best = min(scores.values())
    bound = min(best * 1.01, scores["alone"], scores["moved"])
    r2 = next((c for c in [*with_gp, "moved", "alone"] if scores[c] <= bound), r0)
    chosen = {"R0 pick": r0, "R1 pick + 1-SE guard": r1, "R2 pick with +gp": r2}
    return {name: _test_error(prior, camp, test, c) for name, c in chosen.items()}


def _test_error(prior: Prior, camp: CalibrationData, test: CalibrationData, c: str) -> float:
    """The held-out mean error (mm) of candidate ``c`` fitted on the whole campaign."""
    if c in GP_CANDIDATES:
        P = predict(prior, camp, test.q, float(c[3:]), 1.0, gp=True)
    elif c == "alone":
        P = Calibrator(prior.model.structure.desc, MODEL).fit(camp).predict(test.q)[:, :3, 3]
    else:
        tau, layer = parse_choice(c)
        P = predict(prior, camp, test.q, float(tau), 1.0 if layer else 0.0)
    return float(np.linalg.norm(test.positions - P, axis=1).mean() * 1e3)


def run(desc: Any, sets: dict[str, CalibrationData], key: str, sizes: tuple[int, ...],
        selection: str, draws: int, cache: Path | None) -> dict[int, dict[str, list[float]]]:

    resA = earlier(desc, sets["A"], ResidualLearner(), cache)
    prior = Prior.from_result(resA)
    d = sets[key]
    out: dict[int, dict[str, list[float]]] = {n: {} for n in sizes}
    for f_no, (tr, te, rng_model) in enumerate(outer_folds(resA.model, d)[2]):
        test = d.subset(te)
        for n, k in itertools.product(sizes, range(1 if selection == "planned" else draws)):
            rng = np.random.default_rng(["BCD".index(key), f_no, n] + ([k] if k else []))
            camp = d.subset(choose(rng_model, d, tr, n, selection, rng))
            row = {"(i) alone": float(np.linalg.norm(test.positions - Calibrator(
                       desc, MODEL).fit(camp).predict(test.q)[:, :3, 3], axis=1).mean() * 1e3),
                   "(ii) moved": float(np.linalg.norm(test.positions - refit_base(
                       resA.model, camp, probe=True).predict(test.q)[:, :3, 3],
                       axis=1).mean() * 1e3)}
            row |= fixed(prior, camp, test) | rules(prior, camp, test)
            for name, v in row.items():
                out[n].setdefault(name, []).append(v)
            print(f"  {key} fold {f_no + 1}, n = {n}, draw {k}: alone {row['(i) alone']:.3f}, "
                  f"moved {row['(ii) moved']:.3f}, R0 {row['R0 pick']:.3f} mm", flush=True)
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=None)
    ap.add_argument("--series", default="B", choices=("B", "C", "D"))
    ap.add_argument("--sizes", default="50,100")
    ap.add_argument("--selection", choices=("planned", "random"), default="random")
    ap.add_argument("--draws", type=int, default=1)
    ap.add_argument("--cache", type=Path, metavar="FILE",
                    help="pickle of set-up A's fit, as short_campaign_ur10.py --cache")
    ap.add_argument("--top", type=int, default=12, help="variants printed per n")
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
        out = run(desc, sets, args.series, sizes, args.selection, args.draws, args.cache)
    for n, rows in out.items():
        mean = {k: float(np.mean(v)) for k, v in rows.items()}
        ref = min(mean["(i) alone"], mean["(ii) moved"])
        print(f"\n{args.series}, {args.selection}, n = {n} ({len(rows['R0 pick'])} campaigns): "
              f"(i) {mean['(i) alone']:.3f}, (ii) {mean['(ii) moved']:.3f} mm")
        ranked = sorted((k for k in mean if not k.startswith("(")), key=mean.get)
        shown = ranked[:args.top] + [k for k in ranked[args.top:] if k.startswith("R")]
        for k in shown:
            print(f"  {k:32s} {mean[k]:.3f} mm ({(mean[k] / ref - 1) * 100:+.0f}%)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
