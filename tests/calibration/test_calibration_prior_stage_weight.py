"""The campaign stage weighted by its own grouped CV (issue 36 §2): ``w̃`` the value of the
grid ``W`` (``PriorCalibrator(stage_weights=…)``, ``--prior-stage-weights``) whose CV
error ``m(w) = mean_i ‖e_i − w ê_i‖`` is least, the weighted stage judged by the k-SE rule
against the fit; ``W = {0}`` is no stage, ``W = {1}`` the rule before the weight.  On the
simulated UR10 of calibration_testlib — seeded, deterministic."""

from __future__ import annotations

import hashlib
import math
from dataclasses import replace

import numpy as np
import pytest
from calibration_testlib import harmonic_campaign, random_frame
from hypothesis import given, settings
from hypothesis import strategies as st

from plugcell.calibration import CalibrationError, Calibrator
from plugcell.calibration.campaign_stage import (
    STAGE_WEIGHT_GRID,
    STAGE_WEIGHTS,
    check_weights,
    fit_campaign_stage,
    judge_stage,
    weighted_cv,
)
from plugcell.calibration.identify import refit_base
from plugcell.calibration.prior import Prior, PriorCalibrator
from plugcell.calibration.residual_model import ResidualModelError
from plugcell.calibration.se_rule import beats

#: Where the robot stands in the new set-up (the tracker moved).
NEW_BASE = random_frame(np.random.default_rng(3), 1.0, 2.0)


@pytest.fixture(scope="module")
def harmonic():
    """Set-up A of a robot with a reducer error no physical model has (1 mrad), fitted."""
    desc, data = harmonic_campaign(300, 0, amplitude_rad=1e-3)
    res = Calibrator(desc, "serial").fit(data)
    return res, Prior.from_result(res)


def _campaign(res, seed: int, amplitude: float = 1e-3):
    """40 poses of the new set-up and A's model moved onto them."""
    _, camp = harmonic_campaign(40, seed, amplitude_rad=amplitude, base=NEW_BASE)
    return camp, refit_base(res.model, camp, probe=True)


@pytest.fixture(scope="module")
def fitted(harmonic):
    """A campaign stage as fitted (the grid {1}: weight 1), on 40 poses."""
    camp, moved = _campaign(harmonic[0], 1)
    stage = fit_campaign_stage(moved, camp, None, robot="r", weights=(1.0,))
    assert stage.layer is not None
    return stage.layer, camp, moved


def _with_cv(layer, E, P):
    """``layer`` with its CV's targets ``E`` and out-of-fold predictions ``P`` replaced."""
    cv = replace(layer.cv, targets=E, predictions=P, physical_errors=np.linalg.norm(E, axis=1),
                 hybrid_errors=np.linalg.norm(E - P, axis=1))
    return replace(layer, cv=cv)


# ------------------------------------------------------------------- the choice of w
@pytest.mark.parametrize(("scale", "expected"), [
    (1 / 0.25, 0.25), (1 / 0.5, 0.5), (1 / 0.75, 0.75), (1.0, 1.0), (1 / 0.6, 0.5),
    (1 / 0.7, 0.75), (0.5, 1.0)])
def test_the_weight_is_the_cv_minimiser_where_it_is_known(fitted, scale, expected):
    """Out-of-fold predictions ``ê = s·e``: ``m(w) = |1 − w s| · mean ‖e‖``, least at the
    grid value nearest ``1/s`` (``s = 1/0.6``: ½ (|1 − 0.5/0.6| = 1/6 < 1/4 at ¾);
    ``s = ½``: 1, the grid's end) — the weight chosen and the layer's weight."""
    layer = fitted[0]
    E = np.random.default_rng(0).normal(0.0, 1e-4, (len(layer.cv.fold), 3))
    out = judge_stage(_with_cv(layer, E, scale * E), STAGE_WEIGHT_GRID, 0.0)
    assert out.adopted and out.weight == expected and out.layer.weight == expected
    assert out.layer.useful
    m = {w: float(np.mean(np.abs(1 - w * scale))) for w in STAGE_WEIGHT_GRID}
    assert min(m, key=lambda w: (m[w], w)) == expected  # the model above, independently
    assert out.cv_mm[0.0] == pytest.approx(np.linalg.norm(E, axis=1).mean() * 1e3, abs=1e-15)
    s = out.summary()
    assert s["weight"] == expected and s["weights"] == list(STAGE_WEIGHT_GRID)
    assert s["cv_by_weight_mm"][f"{expected:g}"] == min(s["cv_by_weight_mm"].values())


def test_a_stage_that_points_the_wrong_way_gets_weight_zero(fitted):
    """``ê = −e``: every ``w > 0`` is worse than none — not adopted, weight 0, the layer
    as fitted (weight 1, not used), the reason names the weight the rule judged."""
    layer = fitted[0]
    E = np.random.default_rng(1).normal(0.0, 1e-4, (len(layer.cv.fold), 3))
    out = judge_stage(_with_cv(layer, E, -E), STAGE_WEIGHT_GRID, 0.0)
    assert not out.adopted and out.weight == 0.0 and out.layer.weight == 1.0
    assert "did not beat the physical fit" in out.reason and "at weight 0.25" in out.reason


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), shrink=st.floats(-0.5, 3.0),
       grid=st.sets(st.sampled_from((*STAGE_WEIGHT_GRID, 0.1, 0.6, 0.9)), min_size=1))
def test_the_chosen_weight_is_the_argmin_of_the_cv_over_the_grid(fitted, seed, shrink, grid):
    """For any targets, predictions and grid: ``w̃`` is the grid's ``w > 0`` of least
    ``mean ‖e − w ê‖`` (brute force here), adopted (k = 0) exactly when it beats
    ``mean ‖e‖``; ``m`` at 0 and 1 are the CV's physical and hybrid errors to the bit."""
    layer = fitted[0]
    rng = np.random.default_rng(seed)
    E = rng.normal(0.0, 1e-4, (len(layer.cv.fold), 3))
    P = shrink * E + rng.normal(0.0, 5e-5, E.shape)
    lay = _with_cv(layer, E, P)
    errs = weighted_cv(lay.cv, (0.0, 1.0))
    np.testing.assert_array_equal(errs[0.0], lay.cv.physical_errors)
    np.testing.assert_array_equal(errs[1.0], lay.cv.hybrid_errors)
    W = check_weights(grid)
    out = judge_stage(lay, W, 0.0) if max(W) > 0 else None
    means = {w: np.linalg.norm(E - w * P, axis=1).mean() for w in W if w > 0}
    if out is None:
        return
    best = min(means, key=lambda w: (means[w], w))
    assert out.adopted == (means[best] < np.linalg.norm(E, axis=1).mean())
    assert out.weight == (best if out.adopted else 0.0)


# ----------------------------------------------------------- the grid's two ends
@pytest.mark.parametrize("seed", [1, 2, 5, 7])
@pytest.mark.parametrize("k", [0.0, 1.0])
def test_the_grid_one_is_the_rule_before_the_weight(harmonic, seed, k):
    """``W = {1}``: adopted exactly when the stage's CV beats the fit (``useful``) and
    ``d̄ + k·SE < 0`` for the whole stage (``hybrid_errors`` against ``physical_errors``,
    the rule before the weight), with the same gain and SE; an adopted layer is the
    layer as fitted (weight 1). A small new-set-up error (0.2 mrad): both verdicts
    occur."""
    camp, moved = _campaign(harmonic[0], seed, 2e-4)
    stage = fit_campaign_stage(moved, camp, None, robot="r", se_k=k, weights=(1.0,))
    cv = stage.layer.cv
    better, mean, se = beats(cv.hybrid_errors, cv.physical_errors, cv.fold, k)
    assert stage.adopted == (stage.layer.useful and better)
    assert (stage.gain_mm, stage.se_mm) == (mean * 1e3, se * 1e3)
    assert stage.layer.weight == 1.0 and stage.weight == (1.0 if stage.adopted else 0.0)


def test_the_grid_one_verdicts_differ_across_these_campaigns(harmonic):
    """The campaigns of the test above are not all one verdict (else it proves little)."""
    verdicts = set()
    for seed in (1, 2, 5, 7):
        camp, moved = _campaign(harmonic[0], seed, 2e-4)
        verdicts.add(fit_campaign_stage(moved, camp, None, robot="r", se_k=1.0,
                                        weights=(1.0,)).adopted)
    assert verdicts == {True, False}


def test_the_default_is_the_rule_before_the_weight(harmonic):
    """The default grid is {1} (the grid measured was worse at 200–400 poses on the IPA
    UR10, docs/results/short-campaign-bounds.md §8): the calibrator's result is that of
    ``stage_weights=(1,)`` to the bit, the stage whole (weight 1) where adopted."""
    _, prior = harmonic
    camp, _ = _campaign(harmonic[0], 1)
    _, val = harmonic_campaign(60, 2, amplitude_rad=1e-3, base=NEW_BASE)
    assert STAGE_WEIGHTS == (1.0,)
    default = PriorCalibrator(prior).fit(camp)
    one = PriorCalibrator(prior, stage_weights=(1.0,)).fit(camp)
    np.testing.assert_array_equal(default.predict_hybrid(val.q)[0], one.predict_hybrid(val.q)[0])
    s = default.settings["prior"]["stage"]
    assert s["adopted"] and s["weight"] == 1.0 and default.residual_model.weight == 1.0


def test_the_grid_zero_is_no_stage_bit_for_bit(harmonic):
    """``W = {0}`` gives the result of ``stage=False`` to the bit (model, predictions, no
    layer) where the default adopts a stage that changes the prediction."""
    _, prior = harmonic
    camp, _ = _campaign(harmonic[0], 1)
    _, val = harmonic_campaign(60, 2, amplitude_rad=1e-3, base=NEW_BASE)
    zero = PriorCalibrator(prior, stage_weights=(0.0,)).fit(camp)
    none = PriorCalibrator(prior, stage=False).fit(camp)
    default = PriorCalibrator(prior).fit(camp)
    assert zero.residual_model is None and none.residual_model is None
    np.testing.assert_array_equal(zero.predict_hybrid(val.q)[0], none.predict_hybrid(val.q)[0])
    np.testing.assert_array_equal(zero.model.values, none.model.values)
    s = zero.settings["prior"]["stage"]
    assert not s["adopted"] and s["weight"] == 0.0 and "{0}" in s["reason"]
    assert default.settings["prior"]["stage"]["adopted"]
    assert not np.array_equal(default.predict_hybrid(val.q)[0], none.predict_hybrid(val.q)[0])


def test_the_grid_records_its_weight_and_applies_it(harmonic):
    """The grid measured (:data:`STAGE_WEIGHT_GRID`): PARAMS.json's stage record holds the
    weight, the result's layer carries it, and the hybrid prediction is the fit plus ``w̃``
    times the stage's regressors (its correction at weight 1 scaled)."""
    _, prior = harmonic
    camp, _ = _campaign(harmonic[0], 1)
    _, val = harmonic_campaign(60, 2, amplitude_rad=1e-3, base=NEW_BASE)
    out = PriorCalibrator(prior, stage_weights=STAGE_WEIGHT_GRID).fit(camp)
    s = out.settings["prior"]["stage"]
    layer = out.residual_model
    assert s["adopted"] and s["weight"] == layer.weight and s["weights"] == list(STAGE_WEIGHT_GRID)
    whole = replace(layer, weight=1.0).predict(val.q).correction
    np.testing.assert_allclose(layer.predict(val.q).correction, layer.weight * whole,
                               rtol=0, atol=1e-18)
    assert 0 < layer.weight < 1 and np.abs(whole).max() > 1e-5  # a shrunk, acting stage
    p = out.predict(val.q)[:, :3, 3]
    P, _ = out.predict_hybrid(val.q)
    P1, _ = out.with_residual_model(replace(layer, weight=1.0)).predict_hybrid(val.q)
    np.testing.assert_allclose(P[:, :3, 3] - p, layer.weight * (P1[:, :3, 3] - p), atol=1e-15)


# ------------------------------------------------------------------- bad grids
_BAD = st.sampled_from([math.nan, math.inf, -math.inf, -0.25, 1.5, True, "0.5", None])
_GOOD = st.sampled_from(STAGE_WEIGHT_GRID)


@settings(max_examples=60, deadline=None)
@given(st.one_of(
    st.just([]),
    st.tuples(st.lists(_GOOD, max_size=3), _BAD, st.lists(_GOOD, max_size=3)).map(
        lambda t: [*t[0], t[1], *t[2]]),
    st.lists(_GOOD, min_size=1, max_size=3).map(lambda xs: [*xs, xs[0]]),
    st.sampled_from(["0,0.5", 0.5, None])))
def test_a_bad_grid_is_refused_by_name(harmonic, bad):
    """Empty, a weight not a number in [0, 1] (NaN, ±inf, out of range, a bool, a
    string), a weight twice, or not a sequence: a CalibrationError naming the campaign
    stage's weights, from the check, the stage and the calibrator alike."""
    with pytest.raises(CalibrationError, match="campaign stage"):
        check_weights(bad)
    with pytest.raises(CalibrationError, match="campaign stage"):
        PriorCalibrator(harmonic[1], stage_weights=bad)


@settings(max_examples=40, deadline=None)
@given(st.sets(st.floats(0.0, 1.0), min_size=1, max_size=6))
def test_a_good_grid_is_kept_in_order(ws):
    """Any distinct numbers in [0, 1]: kept, sorted, as floats."""
    assert check_weights(list(ws)) == tuple(sorted(float(w) for w in ws))


def test_a_bad_layer_weight_is_refused(fitted):
    """A layer's weight outside [0, 1]: refused when the layer is built."""
    layer = fitted[0]
    for w in (1.5, -0.1, math.nan):
        with pytest.raises(ResidualModelError, match="weight must be a number in"):
            replace(layer, weight=w)


# ------------------------------------------------------------------- the side file
def test_the_side_file_keeps_the_weight_and_an_older_file_reads_as_weight_one(fitted,
                                                                              tmp_path):
    """Format 4 writes ``weight``; it loads back with the same prediction.  A file
    without it (format 3, before the weight) loads with weight 1; a bad weight is
    refused naming it."""
    import skops.io as sio

    from plugcell.io.residual_models import ResidualFileError, load_residual, save_residual

    layer, camp, model = fitted
    half = replace(layer, weight=0.5)
    params = tmp_path / "p.json"
    entry = save_residual(half, tmp_path / "p.residual.skops")
    assert entry["weight"] == 0.5
    blob = (tmp_path / "p.residual.skops").read_bytes()
    assert sio.loads(blob, trusted=sio.get_untrusted_types(data=blob))["format_version"] == 4
    whole = save_residual(layer, tmp_path / "whole.skops")  # weight 1: what older plugcell reads
    blob = (tmp_path / "whole.skops").read_bytes()
    assert sio.loads(blob, trusted=sio.get_untrusted_types(data=blob))["format_version"] == 3
    assert load_residual(whole, params, robot="r", model=model).weight == 1.0
    back = load_residual(entry, params, robot="r", model=model)
    assert back.weight == 0.5
    np.testing.assert_array_equal(back.predict(camp.q).correction,
                                  half.predict(camp.q).correction)

    def rewrite(edit, name):
        blob = (tmp_path / "p.residual.skops").read_bytes()
        obj = sio.loads(blob, trusted=sio.get_untrusted_types(data=blob))
        edit(obj)
        out = sio.dumps(obj)
        (tmp_path / name).write_bytes(out)
        return {**entry, "file": name, "sha256": hashlib.sha256(out).hexdigest()}

    def old(obj):
        obj["format_version"] = 3
        obj["meta"].pop("weight")
    back3 = load_residual(rewrite(old, "three.skops"), params, robot="r", model=model)
    assert back3.weight == 1.0
    np.testing.assert_array_equal(back3.predict(camp.q).correction,
                                  layer.predict(camp.q).correction)
    for bad in (1.5, -1.0, "0.5", None, True):
        e = rewrite(lambda obj, b=bad: obj["meta"].update(weight=b), "bad.skops")
        with pytest.raises(ResidualFileError, match=r"bad\.skops: the layer's 'weight' must be"):
            load_residual(e, params, robot="r", model=model)
