"""A short campaign in a new set-up, issue 36: the grouped CV over the campaign's cells also
decides whether the earlier calibration's learned layer is kept — the MAP candidates
without it (``"τ/physical"``, :func:`plugcell.calibration.prior.parse_choice`) compete with
those with it — on the simulated UR10 of calibration_testlib (a reducer error no physical
model has, which the earlier layer learned), where that layer is right (the same reducers
in the new set-up) and where it is wrong (reducers replaced); seeded and deterministic."""

from __future__ import annotations

import math

import numpy as np
import pytest
from calibration_testlib import harmonic_campaign, random_frame
from hypothesis import given
from hypothesis import strategies as st

from plugcell.calibration import CalibrationError, Calibrator
from plugcell.calibration.prior import (
    ALONE,
    CANDIDATES,
    FRAMES_ONLY,
    MOVED,
    PHYSICAL,
    PHYSICAL_SCALES,
    Prior,
    PriorCalibrator,
    _label,
    parse_choice,
)
from plugcell.calibration.residual_model import ResidualLearner

NEW_BASE = random_frame(np.random.default_rng(5), 1.0, 2.0)
#: The reducer error of set-up A (rad): the earlier layer learns it.
AMPLITUDE = 1e-3


@given(st.sampled_from(CANDIDATES))
def test_every_candidate_parses_and_its_label_parses_the_same(c):
    """A candidate and its CV key (:func:`_label`) describe the same fit: τ ≥ 0 (``None``
    only for the campaign alone) and whether the earlier layer is in it — with it exactly
    the plain τ of the scales."""
    tau, layer = parse_choice(c)
    assert parse_choice(_label(c)) == (tau, layer)
    assert (tau is None) == (c == ALONE)
    assert layer == isinstance(c, float)
    if tau is not None:
        assert math.isfinite(tau) and tau >= 0


@given(st.floats(min_value=1.0, max_value=1e6, allow_nan=False))
def test_a_physical_label_gives_its_tau_without_the_layer(tau):
    assert parse_choice(f"{tau:g}{PHYSICAL}") == (float(f"{tau:g}"), False)


@given(st.text(max_size=20))
def test_anything_else_is_refused_by_name(text):
    """A string is a τ (0 or finite ≥ 1), that τ + "/physical", moved or alone — anything
    else is refused, naming it."""
    body = text[:-len(PHYSICAL)] if text.endswith(PHYSICAL) else text
    try:
        tau = float(body)
    except ValueError:
        tau = math.nan
    known = text in (MOVED, ALONE) or tau == 0 or (math.isfinite(tau) and tau >= 1)
    if known:
        parse_choice(text)
    else:
        with pytest.raises(CalibrationError, match="unknown candidate"):
            parse_choice(text)


def test_the_physical_candidates_and_moved_are_the_fits_without_the_layer():
    assert parse_choice(MOVED) == (FRAMES_ONLY, False)
    assert [parse_choice(f"{t:g}{PHYSICAL}")[0] for t in PHYSICAL_SCALES] == list(
        PHYSICAL_SCALES)
    assert parse_choice(ALONE) == (None, False)
    for bad in ("ten/physical", "0.5", "nan/physical", "inf", "-3/physical"):
        with pytest.raises(CalibrationError, match=f"unknown candidate '{bad}'"):
            parse_choice(bad)


@pytest.fixture(scope="module")
def earlier():
    """Set-up A: a robot with a 1 mrad reducer error, the serial model and a learned layer
    on what it leaves (which the layer's own grouped CV finds useful)."""
    desc, data = harmonic_campaign(400, 0, amplitude_rad=AMPLITUDE)
    res = Calibrator(desc, "serial").fit(data)
    layer = ResidualLearner(grid=({"max_leaf_nodes": 15, "min_samples_leaf": 10},),
                            trees=100).fit(res.model, data, robot=desc.name)
    assert layer.useful
    return res, Prior.from_result(res.with_residual_model(layer))


def _mean_mm(val, P) -> float:
    return float(np.linalg.norm(val.positions - P[:, :3, 3], axis=1).mean() * 1e3)


def _fit(prior, amplitude, seed):
    _, camp = harmonic_campaign(60, seed, amplitude_rad=amplitude, base=NEW_BASE)
    _, val = harmonic_campaign(300, 100 + seed, amplitude_rad=amplitude, base=NEW_BASE)
    out = PriorCalibrator(prior, stage=False).fit(camp)
    alone = Calibrator(prior.model.structure.desc, "serial").fit(camp)
    P, _ = out.predict_hybrid(val.q)
    return out.settings["prior"], _mean_mm(val, P), _mean_mm(val, alone.predict(val.q))


@pytest.mark.slow
def test_a_right_layer_is_kept(earlier):
    """The new set-up has A's reducers: the CV keeps A's layer (its correction the fit's
    offset) and the result is far below the campaign alone on 300 poses it never saw."""
    _, prior = earlier
    pri, err, alone = _fit(prior, AMPLITUDE, 21)
    assert pri["layer_offset"], pri["cv_mm"]
    assert pri["cv_mm"]["0"] < pri["cv_mm"][MOVED]
    assert err < 0.8 * alone


@pytest.mark.slow
def test_a_wrong_layer_is_left_out(earlier):
    """The reducers were replaced (no error in the new set-up): A's layer would add a
    wrong correction. The CV leaves it out (a candidate without it wins) and the result is
    within 5 % of the campaign alone on 300 poses it never saw."""
    _, prior = earlier
    pri, err, alone = _fit(prior, 0.0, 22)
    assert not pri["layer_offset"], pri["cv_mm"]
    assert pri["choice"] in (MOVED, ALONE) or pri["choice"].endswith(PHYSICAL)
    assert err <= 1.05 * alone


@pytest.mark.slow
def test_the_summary_says_the_layer_was_left_out(earlier):
    """`plugcell calibrate --prior`'s summary of a fit the CV chose without A's layer
    (forced here: ``10/physical`` the only candidate better than the rest) says so and
    prints the candidate's CV key."""
    import json

    from plugcell.apps.commands.calibrate import _summary
    from plugcell.io.params import params_json

    _, prior = earlier
    _, camp = harmonic_campaign(60, 23, amplitude_rad=0.0, base=NEW_BASE)
    scores = {_label(c): 1e-3 for c in CANDIDATES} | {f"10{PHYSICAL}": 0.5e-3}
    calib = PriorCalibrator(prior, stage=False)
    calib.choose = lambda data, offset=None: (f"10{PHYSICAL}", scores)  # type: ignore[method-assign]
    out = calib.fit(camp)
    pri = out.settings["prior"]
    assert pri["choice"] == f"10{PHYSICAL}" and pri["scale"] == 10 and not pri["layer_offset"]
    assert out.residual_model is None
    text = _summary(json.loads(params_json(out)))
    assert "its learned layer left out" in text and f"τ = 10{PHYSICAL} 0.500" in text
