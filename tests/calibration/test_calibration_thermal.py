"""The thermal expansion term κT (issue 19 §3): exact column, identification with σ,
the temperature column's path from the file to the fit, and its refusals."""

from __future__ import annotations

import numpy as np
import pytest
from calibration_testlib import fd_columns, harmonic_campaign, perturbed_model

from plugcell.calibration import (
    CalibrationData,
    CalibrationError,
    Calibrator,
    ErrorModel,
)
from plugcell.calibration.identifiability import random_configurations
from plugcell.calibration.jacobian import identification_jacobian
from plugcell.calibration.model import THERMAL_KEY
from plugcell.io.params import params_document, result_from_params


@pytest.mark.parametrize(("robot", "family"), [("h4", "loop"), ("ur10", "serial")])
def test_every_column_with_the_thermal_term_matches_central_differences(robot, family,
                                                                         request):
    """With κT ≠ 0 and temperatures off the reference every column changes (lengths
    scaled): all of them, κT's own included, against central differences."""
    desc = request.getfixturevalue(robot)
    rng = np.random.default_rng(3)
    m = perturbed_model(desc, family, rng, gravity=True, harmonics=1, thermal=True,
                        temperature_ref_c=20.0)
    q = random_configurations(m, 6, seed=5)
    batch = m.batch(q, None, rng.uniform(15.0, 30.0, len(q)))
    keys = m.space.keys
    jac = identification_jacobian(m, batch, keys)
    np.testing.assert_allclose(jac.poses, m.predict_batch(batch), atol=1e-14)
    fd = fd_columns(m, batch, keys)
    for c, k in enumerate(keys):
        scale = max(np.abs(jac.H[:, :, c]).max(), np.abs(fd[:, :, c]).max())
        err = np.abs(jac.H[:, :, c] - fd[:, :, c]).max()
        assert err <= 1e-7 * scale + 1e-9, f"{robot}/{family} {k}: {err:.3g} of {scale:.3g}"


def _expanding(kappa: float, n: int, seed: int) -> tuple:
    """The test robot measured at 18–26 °C with every length growing by κ per K
    (about 22 °C): positions scaled about the base (flange) as the model defines it."""
    desc, d = harmonic_campaign(n, seed=seed, amplitude_rad=0.0, noise_m=5e-6)
    rng = np.random.default_rng(seed + 10)
    t = rng.uniform(18.0, 26.0, n)
    m = ErrorModel.create(desc, "serial", base=np.eye(4))
    B = np.eye(4)
    B[:3, 3] = [2.0, -1.0, 0.3]
    probe = np.eye(4)
    probe[:3, 3] = [0.02, 0.03, 0.08]
    fl = m.predict(d.q)  # flange in the base frame (BASE = I, PROBE = I)
    fl[:, :3, 3] *= (1 + kappa * (t - 22.0))[:, None]
    T = B @ fl @ probe
    T[:, :3, 3] += rng.normal(scale=5e-6, size=(n, 3))
    return desc, CalibrationData(d.q, T[:, :3, 3], T[:, :3, :3], temperature_c=t)


def test_identifies_the_expansion_coefficient_with_sigma():
    desc, cal = _expanding(23e-6, 300, 1)  # aluminium
    res = Calibrator(desc, "serial", thermal=True).fit(cal)
    k, s = res.value(THERMAL_KEY), res.sigma(THERMAL_KEY)
    assert k == pytest.approx(23e-6, abs=4 * s) and s < 2e-6  # significant: > 10 σ
    assert res.model.temperature_ref_c == pytest.approx(np.mean(cal.temperature_c))
    plain = Calibrator(desc, "serial").fit(cal)
    assert res.calibration.position.norm.mean < 0.5 * plain.calibration.position.norm.mean
    back = result_from_params(params_document(res), desc)
    np.testing.assert_allclose(back.predict(cal.q, None, cal.temperature_c),
                               res.predict(cal.q, None, cal.temperature_c), atol=1e-12)
    # a robot that does not expand: κT not significant
    desc0, cal0 = _expanding(0.0, 300, 2)
    r0 = Calibrator(desc0, "serial", thermal=True).fit(cal0)
    assert abs(r0.value(THERMAL_KEY)) < 4 * r0.sigma(THERMAL_KEY)


def test_thermal_term_needs_temperatures():
    desc, cal = harmonic_campaign(100, seed=1)
    with pytest.raises(CalibrationError, match="no temperature_c column"):
        Calibrator(desc, "serial", thermal=True).fit(cal)
    iso = CalibrationData(cal.q, cal.positions, cal.rotations, temperature_c=np.full(100, 21.0))
    res = Calibrator(desc, "serial", thermal=True).fit(iso)
    assert THERMAL_KEY not in res.keys
    assert any("span only 0.00 K" in w for w in res.warnings)
    assert any("κT not identified" in w for w in res.warnings)


def test_compensation_model_applies_the_thermal_term():
    """IdentifiedModel at a temperature = the thermal model's prediction in the base
    frame; its Jacobian against central differences of that prediction."""
    from plugcell.compensation import IdentifiedModel

    desc, cal = _expanding(23e-6, 300, 1)
    res = Calibrator(desc, "serial", thermal=True).fit(cal)
    q = cal.q[:5]
    im = IdentifiedModel(res.model, temperature_c=25.0)
    T, J = im.evaluate(q)
    P = res.predict(q, None, 25.0)
    np.testing.assert_allclose(im.base @ T, P, atol=1e-12)
    h = 1e-7
    for j in range(q.shape[1]):
        dq = np.zeros_like(q)
        dq[:, j] = h
        Tp, Tm = im.evaluate(q + dq)[0], im.evaluate(q - dq)[0]
        v = (Tp[:, :3, 3] - Tm[:, :3, 3]) / (2 * h)
        np.testing.assert_allclose(J[:, :3, j], v, atol=1e-3 * np.abs(v).max() + 1e-9)
