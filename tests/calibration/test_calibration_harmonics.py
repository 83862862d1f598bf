"""Joint-angle harmonics in the physical model (issue 19 §1): exact analytic columns,
identifiability, and identification of a simulated transmission error."""

from __future__ import annotations

import numpy as np
import pytest
from calibration_testlib import fd_columns, harmonic_campaign, perturbed_model

from plugcell.calibration import CalibrationError, Calibrator, ErrorModel
from plugcell.calibration.identifiability import random_configurations, structural_identifiability
from plugcell.calibration.jacobian import identification_jacobian
from plugcell.io.params import params_document, result_from_params


@pytest.mark.parametrize(("robot", "family"), [("h4", "loop"), ("ur10", "serial")])
def test_harmonic_columns_match_central_differences(robot, family, request):
    desc = request.getfixturevalue(robot)
    rng = np.random.default_rng(11)
    m = perturbed_model(desc, family, rng, gravity=True, harmonics=2)
    keys = [p.key for p in m.space if p.kind == "harmonic"]
    assert len(keys) == 4 * desc.n_actuated
    q = random_configurations(m, 6, seed=4)
    batch = m.batch(q)
    an = identification_jacobian(m, batch, keys).H
    fd = fd_columns(m, batch, keys)
    for c, k in enumerate(keys):
        scale = max(np.abs(an[:, :, c]).max(), np.abs(fd[:, :, c]).max())
        err = np.abs(an[:, :, c] - fd[:, :, c]).max()
        assert err <= 1e-7 * scale + 1e-9, f"{k}: {err:.3g} of {scale:.3g}"


def test_harmonics_are_structurally_identifiable_on_a_6r_robot(ur10):
    m = ErrorModel.create(ur10, "serial", harmonics=2)
    ident = structural_identifiability(m)
    kept = {k for k in ident.kept if m.space[k].kind == "harmonic"}
    # joint 1's sin/cos of order 1 and 2 rotate the whole arm about a vertical axis:
    # all separable from the constant offset given configurations spread over q1
    assert len(kept) >= 20, sorted(set(m.space.keys) - set(ident.kept))


def test_identifies_a_transmission_error_and_reports_sigma(tmp_path):
    desc, cal = harmonic_campaign(500, seed=1, noise_m=5e-6)
    _, val = harmonic_campaign(200, seed=2, noise_m=5e-6)
    plain = Calibrator(desc, "serial").fit(cal, validation=val)
    harm = Calibrator(desc, "serial", harmonics=2).fit(cal, validation=val)
    assert harm.validation.position.norm.mean < 0.3 * plain.validation.position.norm.mean
    # the simulated terms: Δθ_j = 4e-4 sin(2 q_j + j), j = 2, 3, 4 (1-based)
    for j in (1, 2, 3):
        s, c = harm.value(f"h2s_{j + 1}"), harm.value(f"h2c_{j + 1}")
        assert np.hypot(s, c) == pytest.approx(4e-4, rel=0.05)
        assert np.arctan2(c, s) == pytest.approx(j, abs=0.05)
        assert harm.sigma(f"h2s_{j + 1}") < 0.05 * 4e-4   # significant (> 20 σ)
    # joint 1, 5, 6 have none: not significant
    for k in ("h2s_1", "h2s_5", "h1c_6"):
        if k in harm.keys:
            assert abs(harm.value(k)) < 5 * harm.sigma(k) + 2e-5
    back = result_from_params(params_document(harm), desc)
    np.testing.assert_allclose(back.predict(val.q), harm.predict(val.q), atol=1e-12)
    with pytest.raises(CalibrationError, match="order 0, 1 or 2"):
        Calibrator(desc, "serial", harmonics=3)
