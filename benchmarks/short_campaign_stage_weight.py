"""The campaign stage weighted by its own CV instead of adopted or not (issue 36 §2, B).

Before ``--prior-stage-weights``, ``plugcell calibrate --prior`` adopted the campaign's own
stage (trees on what the fit leaves, :mod:`plugcell.calibration.campaign_stage`) or not: a
weight w ∈ {0, 1} (still the default, ``--prior-stage-weights 1``). Here w is chosen on
the fixed grid {0, ¼, ½, ¾, 1} by the same grouped CV over the campaign's cells (a
one-weight stacking of the stage, Breiman 1996), recomputed independently of the product
— the measurement behind ``--prior-stage-weights 0,0.25,0.5,0.75,1``
(:data:`~plugcell.calibration.campaign_stage.STAGE_WEIGHT_GRID`)::

    w* = argmin_w  mean_i ‖E_i − w ê_i‖          (ê: the stage's out-of-fold predictions)
    p_w = p_MAP + R_B (c_shape,A + w ê_c(q))     (w > 0; ê_c only where the stage's
                                                  in-domain test passes)
    w* = 0: the fit without the stage, as ``--prior`` gives it then

``E`` the stage's targets (what the fit leaves minus A's arm-shape stage), its folds and
trees those :func:`~plugcell.calibration.campaign_stage.fit_campaign_stage` chose (the
out-of-fold predictions are recomputed and checked against the stage's recorded CV
errors). The grid is fixed in advance, w is chosen per campaign on the campaign alone,
the held-out cells are only scored. Same campaigns as ``short_campaign_ur10.py`` (its
seeds, its grouped 5-fold over the series' 0.4 m cells, draw k of its ``--draws``) and
``--prior``'s defaults but the stage whole or not at all (``stage_weights=(1,)``, "today"
in the printout: the rule before the weight); prints per campaign the CV error and the
held-out error per w, the weight ``--prior`` chose with that grid (``product w``, which
must be w* at k = 0), and per draw the pooled held-out mean error (mm) of the rule before and of
w*.

    .venv/bin/python benchmarks/short_campaign_stage_weight.py --series B --size 100
        [--draws 3] [--folds 5] [--quick] [--cache A.pkl]

Single-threaded. Without the data folder it says so and exits 0.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from plugcell.calibration import CalibrationData
from plugcell.calibration.campaign_stage import STAGE_WEIGHT_GRID, fit_campaign_stage
from plugcell.calibration.prior import Prior, PriorCalibrator
from plugcell.calibration.residual_model import (
    calibration_fingerprint,
    residual_targets,
    workspace_cells,
)
from residual_ur10 import find_data
from short_campaign_ur10 import (
    _errors,
    choose,
    earlier,
    outer_folds,
    set_up_a,
    ur10_and_sets,
)

WEIGHTS = STAGE_WEIGHT_GRID


def cv_weights(res: Any, camp: CalibrationData, layer: Any) -> tuple[dict[float, float], float]:
    """The stage's grouped-CV mean error (m) for each weight of :data:`WEIGHTS`, and the
    largest deviation (m) of the recomputed out-of-fold errors at w = 1 from the stage's
    recorded ones (0: the same CV)."""
    from sklearn.ensemble import HistGradientBoostingRegressor
    from sklearn.model_selection import GroupKFold

    E, p_b = residual_targets(res.model, camp)
    E = E[:, :3].copy()
    if layer.prior is not None:
        E -= layer.prior.predict(camp.q)[0][:, :3]
    X = layer.features(camp.q, camp.payload_kg)
    cells = workspace_cells(p_b, layer.cv.cell_size_m)
    pred = np.zeros_like(E)
    for tr, te in GroupKFold(n_splits=layer.cv.folds).split(X, E, cells):
        for j in range(3):
            reg = HistGradientBoostingRegressor(random_state=0, **layer.params)
            pred[te, j] = reg.fit(X[tr], E[tr, j]).predict(X[te])
    check = float(np.abs(np.linalg.norm(E - pred, axis=1) - layer.cv.hybrid_errors).max())
    return {w: float(np.linalg.norm(E - w * pred, axis=1).mean()) for w in WEIGHTS}, check


def held_out(res: Any, prior: Prior, layer: Any, test: CalibrationData) -> dict[float, Any]:
    """Held-out errors (m, per pose) of ``p_w`` for each weight (w = 0: without the stage)."""
    with_layer = res.settings["prior"]["choice"] == "map"
    no_stage = (res.with_residual_model(replace(
        prior.layer, fingerprint=calibration_fingerprint(res.model))) if with_layer
        else replace(res, residual_model=None))
    out = {0.0: _errors(test, no_stage.predict_hybrid(test.q)[0])}
    P_full, _ = res.with_residual_model(layer).predict_hybrid(test.q)
    pr = layer.predict(test.q, np.zeros(len(test)))
    ec = np.column_stack([est.predict(layer.features(test.q, np.zeros(len(test))))
                          for est in layer.estimators[:3]])
    R = res.model.base()[:3, :3]
    P_shape = P_full.copy()  # the stage's part only where predict() applied it
    P_shape[:, :3, 3] -= (ec * pr.local[:, None]) @ R.T
    dom = (pr.distance <= layer.threshold)[:, None]
    for w in WEIGHTS[1:]:
        P = P_shape.copy()
        P[:, :3, 3] += w * ((ec * dom) @ R.T)
        out[w] = _errors(test, P)
    return out


def campaign(prior: Prior, camp: CalibrationData, test: CalibrationData
             ) -> tuple[Any, dict[float, float], float, dict[float, Any], Any]:
    """One campaign: today's ``--prior``, the stage's CV per weight, held-out per weight."""
    res = PriorCalibrator(prior, stage_weights=(1.0,)).fit(camp)
    earlier_layer = prior.layer if res.settings["prior"]["choice"] == "map" else None
    layer = fit_campaign_stage(res.model, camp, earlier_layer, robot=prior.robot,
                               weights=(1.0,)).layer
    cv, check = cv_weights(res, camp, layer)
    return res, cv, check, held_out(res, prior, layer, test), _errors(
        test, res.predict_hybrid(test.q)[0])


def run(sets: dict[str, CalibrationData], resA: Any, key: str, n: int, draws: int,
        folds: int = 5) -> None:
    prior = Prior.from_result(resA)
    d = sets[key]
    split = outer_folds(resA.model, d, folds)[2]
    today = np.full((draws, len(d)), np.nan)
    chosen = np.full((draws, len(d)), np.nan)
    for f_no, (tr, te, rng_model) in enumerate(split):
        test = d.subset(te)
        for k in range(draws):
            t1 = time.perf_counter()
            # short_campaign_ur10.py's seeds (one series per run: series index 0)
            rng = np.random.default_rng([0, f_no, n] + ([k] if k else []))
            camp = d.subset(choose(rng_model, d, tr, n, "random", rng))
            res, cv, check, err, e_today = campaign(prior, camp, test)
            w = min(WEIGHTS, key=lambda x: cv[x])
            product = PriorCalibrator(prior, stage_weights=WEIGHTS).fit(camp).settings[
                "prior"]["stage"]["weight"]
            today[k, te], chosen[k, te] = e_today, err[w]
            pri = res.settings["prior"]
            print(f"  {key} fold {f_no + 1}, n = {n}, draw {k}: {pri['choice']} "
                  f"{pri['scale']}, stage {pri['stage']['adopted']}; CV check {check:.0e} m; "
                  "CV " + " ".join(f"{x:g}: {cv[x] * 1e3:.4f}" for x in WEIGHTS)
                  + f" -> w {w:g} (product w {product:g}); held-out: today "
                  f"{e_today.mean() * 1e3:.3f}, "
                  + " ".join(f"{x:g}: {err[x].mean() * 1e3:.3f}" for x in WEIGHTS)
                  + f" mm ({time.perf_counter() - t1:.0f} s)", flush=True)
    for k in range(draws):
        print(f"{key} n = {n} draw {k}: today {np.nanmean(today[k]) * 1e3:.4f} mm, "
              f"w by the stage's CV {np.nanmean(chosen[k]) * 1e3:.4f} mm")
    print(f"{key} n = {n}, mean over {draws} draw(s): today "
          f"{np.nanmean(today, axis=1).mean() * 1e3:.4f} mm, w by the stage's CV "
          f"{np.nanmean(chosen, axis=1).mean() * 1e3:.4f} mm")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=None)
    ap.add_argument("--series", default="B", choices=("B", "C", "D"))
    ap.add_argument("--size", type=int, default=100)
    ap.add_argument("--draws", type=int, default=1)
    ap.add_argument("--folds", type=int, default=5)
    ap.add_argument("--quick", action="store_true",
                    help="set-up A as short_campaign_ur10.py --quick")
    ap.add_argument("--cache", type=Path, default=None, metavar="FILE",
                    help="set-up A's fit, as short_campaign_ur10.py --cache")
    args = ap.parse_args()
    data = args.data or find_data()
    if data is None or not data.is_dir():
        print("IPA robot-accuracy data not found (../shared/data/ipa-robot-accuracy): skipped")
        return 0
    from threadpoolctl import threadpool_limits

    desc, sets = ur10_and_sets(data)
    with threadpool_limits(1):
        resA = earlier(desc, *set_up_a(sets["A"], args.quick), args.cache)
        run(sets, resA, args.series, args.size, args.draws, args.folds)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
