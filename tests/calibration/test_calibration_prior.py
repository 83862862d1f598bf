"""A robot moved to a new set-up: a short campaign with the earlier calibration as a prior
(:mod:`plugcell.calibration.prior`, issue 36 part 2) — the MAP problem, its Jacobian, its
limits (no information → the prior; many poses → the plain calibration), the twin case."""

from __future__ import annotations

import numpy as np
import pytest
from calibration_testlib import random_frame, ur10_description

from plugcell.calibration import CalibrationData, CalibrationError, Calibrator, ErrorModel
from plugcell.calibration.identifiability import random_configurations, structural_identifiability
from plugcell.calibration.identify import _Problem, refit_base
from plugcell.calibration.prior import Prior, PriorCalibrator, augmented_residual, frame_keys
from plugcell.kinematics.transforms import so3_exp

TMAC = np.eye(4)
TMAC[:3, 3] = [0.0, 0.0, 0.09]
#: What moving the robot changed besides BASE (re-zeroed joints 2 and 3, a re-shimmed base).
DRIFT = {"theta2": 3e-4, "theta3": -2e-4, "beta2": 2e-4}


@pytest.fixture(scope="module")
def desc():
    return ur10_description()


@pytest.fixture(scope="module")
def truth_a(desc):
    rng = np.random.default_rng(0)
    m = ErrorModel.create(desc, "serial", gravity=True, payload=False,
                          base=random_frame(rng, 1.0, 2.0), probe=TMAC)
    v = np.zeros(len(m.space))
    for k in structural_identifiability(m).kept:
        p = m.space[k]
        v[m.space.index(k)] = {"m": 5e-4, "rad": 5e-4, "rad/(N·m)": 2e-7}.get(p.unit, 0.0) \
            * rng.normal()
    return m.with_values(v)


def _campaign(truth, n, seed, noise=2e-5, position_only=False):
    rng = np.random.default_rng(seed)
    q = random_configurations(truth, n, seed)
    T = truth.predict(q).copy()
    if noise:
        T[:, :3, 3] += rng.normal(0, noise, (n, 3))
        T[:, :3, :3] = so3_exp(rng.normal(0, noise, (n, 3))) @ T[:, :3, :3]
    return CalibrationData.from_poses(q, T, position_only=position_only)


@pytest.fixture(scope="module")
def earlier(desc, truth_a):
    """Set-up A: 300 poses, model 3, and its prior."""
    res = Calibrator(desc, 3).fit(_campaign(truth_a, 300, 1))
    return res, Prior.from_result(res)


def _moved(truth_a, drift=True):
    t = truth_a.with_references(base=random_frame(np.random.default_rng(5), 1.0, 2.0))
    return t.updated({k: v for k, v in DRIFT.items() if k in t.space}) if drift else t


def _error_mm(model, val):
    return float(np.linalg.norm(val.positions - model.predict(val.q)[:, :3, 3], axis=1)
                 .mean() * 1e3)


@pytest.mark.parametrize("six_dof", [False, True])
def test_the_augmented_jacobian_is_the_derivative_of_the_augmented_residual(earlier, truth_a,
                                                                           six_dof):
    """∂F/∂x = −[W H; Λ] of F = [W (y − f(x)); Λ (x_p − x)] against central differences of
    the exact model (h = 1e-7 in each parameter's unit, 1e-7 / the largest torque for a
    compliance), orientation rows weighted by w = 2.  Positions of the drifted robot; 6-DOF
    poses the model explains (there the orientation residual log(R_M Rᵀ) is differentiated
    exactly by H: away from zero its derivative carries the SO(3) factor J_r⁻¹(φ) ≈ I + φ×/2,
    which Gauss–Newton, as the thesis, leaves out)."""
    res, prior = earlier
    truth = res.model.with_references(base=random_frame(np.random.default_rng(7), 1.0, 2.0)) \
        if six_dof else _moved(truth_a)
    data = _campaign(truth, 12, 3, noise=0.0, position_only=not six_dof)
    model = refit_base(res.model, data, probe=True)
    keys = frame_keys(model)[:6] + [k for k in prior.keys if k not in frame_keys(model)]
    batch = model.batch(data.q)
    problem = _Problem(model, data, batch, 2.0)
    x_p = np.array([model.value(k) for k in keys]) + 1e-4
    lam = np.linspace(0.0, 3.0, len(keys))
    F, J = augmented_residual(model, problem, keys, x_p, lam)
    assert F.shape == (12 * data.rows + len(keys),) and J.shape == (len(F), len(keys))
    fd = np.empty_like(J)
    for j, k in enumerate(keys):
        h = 1e-7
        if k in model.compliance_keys:
            reg = batch.regressors[:, :, model.compliance_keys.index(k)]
            h /= max(1.0, float(np.abs(reg).max()))
        step = np.zeros(len(keys))
        step[j] = h
        Fp, _ = augmented_residual(model.updated(keys=keys, step=step), problem, keys, x_p, lam)
        Fm, _ = augmented_residual(model.updated(keys=keys, step=-step), problem, keys, x_p, lam)
        fd[:, j] = (Fp - Fm) / (2 * h)
    np.testing.assert_allclose(J, fd, rtol=1e-5, atol=1e-6)


def test_no_new_information_returns_the_prior(earlier, truth_a):
    """A campaign the earlier model explains exactly (the robot moved, nothing else):
    the regularised parameters stay at the prior, BASE is the new one."""
    res, prior = earlier
    moved = res.model.with_references(base=random_frame(np.random.default_rng(7), 1.0, 2.0))
    out = PriorCalibrator(prior, scale=10.0).fit(_campaign(moved, 25, 4, noise=0.0))
    for k in out.settings["prior"]["regularised"]:
        assert out.value(k) == pytest.approx(res.value(k), abs=1e-9), k
    np.testing.assert_allclose(out.model.base(), moved.base(), atol=1e-8)
    assert out.calibration.position.norm.mean < 1e-9


def test_the_prior_pulls_where_the_data_say_little(earlier, truth_a):
    """Eight noisy poses of the moved robot: a strong prior (τ = 1) keeps the parameters
    near the earlier values; a weak one (τ = 1000) lets the data move them."""
    res, prior = earlier
    data = _campaign(_moved(truth_a), 8, 6, noise=5e-5)
    strong = PriorCalibrator(prior, scale=1.0).fit(data)
    weak = PriorCalibrator(prior, scale=1000.0).fit(data)
    keys = strong.settings["prior"]["regularised"]

    def dist(r):
        return np.linalg.norm([(r.value(k) - res.value(k)) / res.sigma(k) for k in keys])

    assert dist(strong) < 0.2 * dist(weak)
    assert strong.settings["prior"]["scale"] == 1.0
    assert strong.settings["prior"]["scale_chosen_by"] == "given"


@pytest.mark.slow
def test_the_prior_vanishes_with_many_poses(desc, earlier, truth_a):
    """With τ fixed, the MAP estimate approaches the plain calibration as the campaign
    grows (the prior's rows stay, the data's grow): the gap in the predicted positions
    shrinks at least fivefold from 40 to 640 noise-free poses."""
    _, prior = earlier
    truth = _moved(truth_a)
    val = _campaign(truth, 200, 9, noise=0.0)
    gaps = []
    for n in (40, 640):
        data = _campaign(truth, n, 10 + n, noise=0.0)
        plain = Calibrator(desc, 3).fit(data)
        gaps.append(abs(_error_mm(PriorCalibrator(prior, scale=3.0).fit(data).model, val)
                        - _error_mm(plain.model, val)) + 1e-12)
    assert gaps[1] < gaps[0] / 5


@pytest.mark.slow
def test_a_moved_robot_from_30_poses_beats_both_baselines(desc, earlier, truth_a):
    """The twin case: a calibrated robot moved (new BASE, joints 2, 3 re-zeroed, the base
    re-shimmed), 30 positions measured (0.05 mm noise).  The prior (its candidate chosen
    by the default random 10-fold CV with the one-SE rule) beats the model calibrated on the
    30 positions alone and the earlier model with BASE + PROBE re-identified, on 400 other poses."""
    res, prior = earlier
    truth = _moved(truth_a)
    data = _campaign(truth, 30, 2, noise=5e-5, position_only=True)
    val = _campaign(truth, 400, 3, noise=0.0)
    alone = _error_mm(Calibrator(desc, 3).fit(data).model, val)
    moved = _error_mm(refit_base(res.model, data, probe=True), val)
    out = PriorCalibrator(prior).fit(data)
    with_prior = _error_mm(out.model, val)
    assert out.settings["prior"]["scale_chosen_by"] == "random 10-fold CV"
    assert with_prior < 0.9 * alone and with_prior < 0.5 * moved


def test_bad_input_is_refused(desc, earlier, truth_a):
    _, prior = earlier
    data = _campaign(truth_a, 10, 1)
    wrong = CalibrationData(data.q[:, :5], data.positions, data.rotations)
    with pytest.raises(CalibrationError, match=r"5 joint columns.*'ur10-test' has 6"):
        PriorCalibrator(prior).fit(wrong)
    with pytest.raises(CalibrationError,
                       match=r"τ must be 0 \(BASE \+ PROBE only\) or a number ≥ 1"):
        PriorCalibrator(prior, scale=0.5)
    with pytest.raises(CalibrationError, match="residual σ̂"):
        Prior(prior.robot, prior.config, prior.model, prior.keys, prior.sigma, float("nan"))
    with pytest.raises(CalibrationError, match="3 σ for"):
        Prior(prior.robot, prior.config, prior.model, prior.keys, prior.sigma[:3], 1e-5)
