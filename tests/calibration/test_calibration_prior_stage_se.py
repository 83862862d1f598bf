"""The campaign stage's k-standard-error rule (issue 36): the stage is adopted only when its
grouped CV beats the fit without it by more than k standard errors of the paired difference
(:func:`plugcell.calibration.se_rule.beats`, the rule of the candidate choice), k its own
knob (``--prior-stage-se``, default 0: the plain comparison).  On the simulated UR10 of
calibration_testlib — seeded, deterministic."""

from __future__ import annotations

import math

import numpy as np
import pytest
from calibration_testlib import harmonic_campaign, random_frame
from hypothesis import given, settings
from hypothesis import strategies as st

from plugcell.calibration import CalibrationError, Calibrator
from plugcell.calibration.campaign_stage import STAGE_SE_K, fit_campaign_stage
from plugcell.calibration.identify import refit_base
from plugcell.calibration.prior import FRAMES_ONLY, Prior, PriorCalibrator
from plugcell.calibration.se_rule import beats, paired_difference

#: Where the robot stands in the new set-up (the tracker moved).
NEW_BASE = random_frame(np.random.default_rng(3), 1.0, 2.0)
#: The new set-up's reducer error (rad): small, so the stage's CV gain is near its noise.
AMPLITUDE = 2e-4


@pytest.fixture(scope="module")
def earlier():
    """Set-up A of a robot the serial model describes exactly (noise only), fitted."""
    desc, data = harmonic_campaign(300, 0, amplitude_rad=0.0)
    return Calibrator(desc, "serial").fit(data)


def _campaign(earlier, seed: int):
    """40 poses of the new set-up (a reducer error A did not have) and A moved onto them."""
    _, camp = harmonic_campaign(40, seed, amplitude_rad=AMPLITUDE, base=NEW_BASE)
    return camp, refit_base(earlier.model, camp, probe=True)


# ------------------------------------------------------------------------ the rule itself
@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), shift=st.floats(-0.05, 0.05),
       folds=st.integers(2, 10), k=st.floats(0.0, 5.0))
def test_beats_is_the_k_se_rule_and_k_zero_the_plain_comparison(seed, shift, folds, k):
    """``beats`` is ``d̄ + k·SE < 0``; at k = 0 it is the comparison of the CV means (the
    old ``useful``, away from exact ties); a gain adopted at k is adopted at every
    smaller k."""
    rng = np.random.default_rng(seed)
    n = 4 * folds
    fold = np.arange(n) % folds
    e_ref = rng.uniform(0.1, 0.5, n)
    e = e_ref + shift + rng.normal(0.0, 0.02, n)
    better, mean, se = beats(e, e_ref, fold, k)
    assert (mean, se) == paired_difference(e, e_ref, fold)
    assert better == (mean + k * se < 0)
    if abs(e.mean() - e_ref.mean()) > 1e-12:
        assert beats(e, e_ref, fold, 0.0)[0] == (e.mean() < e_ref.mean())
    if better:
        assert beats(e, e_ref, fold, k / 2)[0]


@pytest.mark.parametrize("k", [-1.0, math.inf, math.nan, "1"])
def test_a_bad_k_is_refused_by_name(earlier, k):
    """k negative, infinite, not a number: a CalibrationError naming the factor, from the
    rule, the stage and the calibrator alike."""
    with pytest.raises(CalibrationError, match="standard-error factor k"):
        beats(np.zeros(4), np.zeros(4), np.arange(4) % 2, k)
    camp, moved = _campaign(earlier, 7)
    with pytest.raises(CalibrationError, match="standard-error factor k"):
        fit_campaign_stage(moved, camp, None, robot="r", se_k=k)
    for kw in ("se_k", "stage_se_k"):
        with pytest.raises(CalibrationError, match="standard-error factor k"):
            PriorCalibrator(Prior.from_result(earlier), **{kw: k})


# ------------------------------------------------------------------------ the stage
def test_a_clear_gain_is_adopted(earlier):
    """Seed 7: the stage's grouped CV gain (≈ 0.016 mm) is about 3 standard errors: adopted
    at k = 1, the record holds the paired difference, its SE and k."""
    camp, moved = _campaign(earlier, 7)
    stage = fit_campaign_stage(moved, camp, None, robot="r", se_k=1.0)
    s = stage.summary()
    assert stage.adopted and stage.reason == ""
    assert s["gain_mm"] + s["se_k"] * s["se_mm"] < 0 and s["se_k"] == 1.0
    assert s["gain_mm"] == pytest.approx(
        s["cv_by_weight_mm"][f"{s['weight']:g}"] - s["physical_mm"], abs=1e-9)
    assert s["cv_by_weight_mm"]["0"] == pytest.approx(s["physical_mm"], abs=1e-12)
    assert s["cv_by_weight_mm"]["1"] == pytest.approx(s["hybrid_mm"], abs=1e-12)


def test_a_gain_within_one_standard_error_is_refused(earlier):
    """Seed 2, the stage whole or not at all (weights {1}): the stage's CV is better than
    the fit (``useful``, adopted by the plain comparison at k = 0) but by less than one
    standard error: refused at k = 1, and the reason gives the gain and the SE."""
    camp, moved = _campaign(earlier, 2)
    at1 = fit_campaign_stage(moved, camp, None, robot="r", se_k=1.0, weights=(1.0,))
    at0 = fit_campaign_stage(moved, camp, None, robot="r", se_k=0.0, weights=(1.0,))
    assert at1.layer is not None and at1.layer.useful
    assert not at1.adopted and "within 1 standard error" in at1.reason
    assert -at1.se_mm < at1.gain_mm < 0
    assert at0.adopted


@pytest.mark.parametrize("seed", [1, 2, 5, 7])
def test_k_zero_is_the_plain_comparison(earlier, seed):
    """The property the rule keeps (weights {1}): at k = 0 the stage is adopted exactly when
    its grouped CV mean beats the fit's (``LearnedResidual.useful``, the rule before the
    SE); at k = 1 only when it is adopted at k = 0 too."""
    camp, moved = _campaign(earlier, seed)
    at0 = fit_campaign_stage(moved, camp, None, robot="r", se_k=0.0, weights=(1.0,))
    at1 = fit_campaign_stage(moved, camp, None, robot="r", se_k=1.0, weights=(1.0,))
    assert at0.layer is not None
    assert at0.adopted == at0.layer.useful
    assert not at1.adopted or at0.adopted


def test_the_calibrator_gives_its_stage_k_to_the_stage(earlier):
    """``PriorCalibrator(stage_se_k=…)`` (``--prior-stage-se``) rules the stage, the
    choice's ``se_k`` does not: on seed 2's campaign (τ = 0 given: no candidate choice)
    the stage (whole or not at all: weights {1}) is refused at stage k = 1 — the result has
    no layer — and adopted by the default (:data:`STAGE_SE_K` = 0) whatever ``se_k``;
    PARAMS.json's stage record says which k."""
    assert STAGE_SE_K == 0.0
    prior = Prior.from_result(earlier)
    camp, _ = _campaign(earlier, 2)
    out1 = PriorCalibrator(prior, scale=FRAMES_ONLY, stage_se_k=1.0,
                           stage_weights=(1.0,)).fit(camp)
    out0 = PriorCalibrator(prior, scale=FRAMES_ONLY, se_k=3.0, stage_weights=(1.0,)).fit(camp)
    s1, s0 = out1.settings["prior"]["stage"], out0.settings["prior"]["stage"]
    assert not s1["adopted"] and s1["se_k"] == 1.0 and out1.residual_model is None
    assert "within 1 standard error" in s1["reason"]
    assert s0["adopted"] and s0["se_k"] == 0.0 and out0.residual_model is not None
