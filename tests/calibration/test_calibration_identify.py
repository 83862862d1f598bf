"""Identification (Fig. 6-9): recovery, options, statistics, errors, serialisation, speed."""

from __future__ import annotations

import json

import numpy as np
import pytest
from calibration_testlib import random_frame

from plugcell.calibration import (
    CalibrationData,
    CalibrationError,
    Calibrator,
    DivergenceError,
    ErrorModel,
)
from plugcell.calibration.identifiability import random_configurations, structural_identifiability
from plugcell.io.params import params_json, result_from_params
from plugcell.io.robot_schema import description_from_dict, description_to_dict
from plugcell.kinematics.transforms import so3_exp

TRACKER = np.eye(4)
TRACKER[:3, :3] = so3_exp([0.3, -0.2, 2.5])  # tracker anywhere, turned and tilted
TRACKER[:3, 3] = [3.0, -1.0, 0.5]
TMAC = np.eye(4)
TMAC[:3, :3] = so3_exp([0.5, 0.4, -1.0])  # T-MAC mounted at an odd angle
TMAC[:3, 3] = [0.05, -0.10, 0.15]


def _truth(desc, family, *, gravity, payload, seed, only_kept=True, position_only=False):
    """A model with random errors of realistic size (0.5 mm, 0.03°) and compliance."""
    rng = np.random.default_rng(seed)
    m = ErrorModel.create(desc, family, gravity=gravity, payload=payload, base=TRACKER,
                          probe=TMAC, payload_ref_kg=36.0 if payload else 0.0)
    keys = m.space.keys
    if only_kept:
        keys = structural_identifiability(m, position_only=position_only).kept
    v = np.zeros(len(m.space))
    for k in keys:
        p = m.space[k]
        i = m.space.index(k)
        v[i] = {"m": 5e-4, "rad": 5e-4, "rad/m": 2e-4}.get(p.unit, 0.0) * rng.normal()
        if p.unit == "rad/(N·m)":
            v[i] = 2e-7 * rng.normal()
    return m.with_values(v)


@pytest.fixture(scope="module")
def full_truth(h4):
    return _truth(h4, "loop", gravity=True, payload=True, seed=1)


def _frame_free(res):
    """Identified keys whose values do not depend on the BASE/PROBE references."""
    fl = res.model.structure.desc.flange
    tied = {"theta1", "d1", f"theta{fl}", f"d{fl}", f"a{fl}", f"alpha{fl}"}
    return [k for k in res.keys if res.model.space[k].kind not in ("base", "probe")
            and k not in tied]


def _data(truth, n, seed, payloads=(0.0, 18.0, 36.0), noise=0.0, position_only=False):
    rng = np.random.default_rng(seed)
    q = random_configurations(truth, n, seed)
    m = np.resize(np.asarray(payloads, float), n)
    T = truth.predict(q, m)
    if noise:
        T = T.copy()
        T[:, :3, 3] += rng.normal(0, noise, (n, 3))
        T[:, :3, :3] = so3_exp(rng.normal(0, noise, (n, 3))) @ T[:, :3, :3]
    return CalibrationData.from_poses(q, T, m, position_only=position_only)


def test_full_model_recovers_every_parameter_from_a_file_of_poses(h4, full_truth):
    data = _data(full_truth, 150, 2)
    res = Calibrator(h4, "full").fit(data)  # BASE and PROBE estimated: AX = YB
    assert res.converged and res.iterations <= 6
    assert res.calibration.position.norm.mean < 1e-9
    assert res.calibration_before.position.norm.mean > 1e-3
    for k in _frame_free(res):
        assert res.value(k) == pytest.approx(full_truth.value(k), abs=1e-9), k
    # BASE up to θ0, d0 (grouped into θ1, d1): the robot's z0 axis in the tracker frame
    np.testing.assert_allclose(res.model.base()[:3, 2], full_truth.base()[:3, 2], atol=1e-9)
    # mixed payloads separate A2 from G1: 34 + 3 + 14
    assert len(res.keys) == 51 and "A2" in res.keys
    qv = random_configurations(full_truth, 20, 99)
    np.testing.assert_allclose(res.predict(qv, 27.0), full_truth.predict(qv, 27.0), atol=1e-9)


def test_positions_only_with_rigid_registration(h4):
    truth = _truth(h4, "loop", gravity=True, payload=False, seed=3, position_only=True)
    data = _data(truth, 60, 4, payloads=(0.0,), position_only=True)
    res = Calibrator(h4, "loop+gravity").fit(data)
    assert not res.six_dof and res.converged
    assert res.calibration.position.norm.mean < 1e-9
    qv = random_configurations(truth, 20, 98)
    np.testing.assert_allclose(res.predict(qv)[:, :3, 3], truth.predict(qv)[:, :3, 3], atol=1e-9)


def test_all_errors_present_identified_as_their_combinations(h4):
    truth = _truth(h4, "loop", gravity=False, payload=False, seed=5, only_kept=False)
    res = Calibrator(h4, "loop").fit(_data(truth, 100, 6, payloads=(0.0,)))
    assert res.calibration.position.norm.mean < 1e-6  # second order only
    qv = random_configurations(truth, 20, 97)
    err = np.linalg.norm(res.predict(qv)[:, :3, 3] - truth.predict(qv)[:, :3, 3], axis=1)
    assert err.max() < 1e-5


def test_noise_statistics_are_honest(h4):
    truth = _truth(h4, "loop", gravity=True, payload=False, seed=7)
    res = Calibrator(h4, 4).fit(_data(truth, 120, 8, payloads=(0.0,), noise=2e-5))
    st = res.statistics
    assert st.sigma2 == pytest.approx(4e-10, rel=0.25)  # σ² (8.3) ≈ the noise variance
    z = np.array([(res.value(k) - truth.value(k)) / res.sigma(k) for k in _frame_free(res)])
    assert np.mean(np.abs(z) < 3) > 0.9  # parameter σ (8.5) covers the errors
    assert 1.0 < st.condition_number < 1e4


def test_levenberg_marquardt_and_robust_loss(h4):
    truth = _truth(h4, "loop", gravity=False, payload=False, seed=9)
    clean = _data(truth, 80, 10, payloads=(0.0,), noise=1e-5)
    gn = Calibrator(h4, 2).fit(clean)
    lm = Calibrator(h4, 2, method="lm").fit(clean)
    for k in gn.keys:
        assert lm.value(k) == pytest.approx(gn.value(k), abs=1e-8)
    T = clean.poses.copy()
    bad = [5, 40, 63]
    T[bad, :3, 3] += [[4e-3, 0, 0], [0, -5e-3, 0], [0, 0, 6e-3]]
    dirty = CalibrationData.from_poses(clean.q, T)
    plain = Calibrator(h4, 2).fit(dirty)
    robust = Calibrator(h4, 2, loss="cauchy").fit(dirty)
    qv = random_configurations(truth, 30, 96)

    def val_err(r):
        return np.linalg.norm(r.predict(qv)[:, :3, 3] - truth.predict(qv)[:, :3, 3], axis=1).mean()

    assert val_err(robust) < 0.2 * val_err(plain)
    assert val_err(robust) < 3e-5
    assert any("#6 " in w and "#41 " in w and "#64 " in w for w in robust.warnings)
    assert robust.pose_weights[bad].max() < 0.05


def test_too_few_poses_missing_payload_and_divergence_are_clear_errors(h4, full_truth):
    data = _data(full_truth, 8, 11)
    with pytest.raises(CalibrationError, match=r"too few poses.*measure at least"):
        Calibrator(h4, 5).fit(data)
    unloaded = _data(full_truth, 30, 12, payloads=(0.0,))
    with pytest.raises(CalibrationError, match="carry no payload"):
        Calibrator(h4, "full").fit(unloaded)
    swapped = CalibrationData.from_poses(unloaded.q[:, [0, 2, 1, 3, 4, 5]], unloaded.poses)
    with pytest.raises(DivergenceError, match=r"do not match robot.*joint order"):
        Calibrator(h4, 2).fit(swapped)
    far = full_truth.with_values(full_truth.values * 20)  # 10 mm errors: not settled in 2
    with pytest.raises(DivergenceError, match=r"diverged: still moving after 2 iterations"):
        Calibrator(h4, 4, max_iterations=2).fit(_data(far, 60, 12, payloads=(0.0,)))
    with pytest.raises(CalibrationError, match="unknown model"):
        Calibrator(h4, 7)
    with pytest.raises(CalibrationError, match="joint columns"):
        Calibrator(h4, 2).fit(CalibrationData(np.zeros((20, 5)), np.zeros((20, 3))))


def test_result_serialises_and_predicts_after_reload(h4, full_truth):
    cal = _data(full_truth, 60, 13)
    val = _data(full_truth, 30, 14)
    res = Calibrator(h4, 5).fit(cal, validation=val)
    d = json.loads(params_json(res))
    assert d["model"]["number"] == 5 and d["iterations"] == res.iterations
    assert d["calibration"]["mean_mm"] < 1e-6 and d["validation"]["mean_mm"] < 1e-6
    assert d["validation"]["before"]["mean_mm"] > 1.0
    row = next(p for p in d["parameters"] if p["key"] == "a2'")
    assert row["stands_for"] == "Δa2' − Δa4'" and row["unit"] == "m" and row["sigma"] is not None
    assert {"mean_mm", "std_mm", "max_mm"} <= set(d["calibration"])
    back = result_from_params(d, h4)
    q = random_configurations(full_truth, 10, 95)
    np.testing.assert_allclose(back.predict(q, 36.0), res.predict(q, 36.0), atol=1e-12)


def test_serial_robot_with_masses(ur10):
    truth = _truth(ur10, "serial", gravity=True, payload=False, seed=15)
    res = Calibrator(ur10, "serial+gravity").fit(_data(truth, 60, 16, payloads=(0.0,)))
    assert res.config.family == "serial" and res.calibration.position.norm.mean < 1e-9
    assert {"c2", "c3"} <= set(res.keys)
    with pytest.raises(CalibrationError, match="neither a parallelogram nor link masses"):
        from calibration_testlib import ur10_description

        d = description_to_dict(ur10_description())
        for lk in d["links"]:
            lk["mass"] = 0.0

        Calibrator(description_from_dict(d), 3).fit(_data(truth, 30, 17, payloads=(0.0,)))


def test_model_5_with_150_poses_identifies_50_parameters(h4, full_truth):
    # its speed (≈ 0.05 s) is measured by `plugcell bench calibration`, never asserted here
    data = _data(full_truth, 150, 18, payloads=(36.0,), noise=2e-5)
    res = Calibrator(h4, 5).fit(data)
    assert len(res.keys) == 50  # one payload: A2 is −a2·G1 (see identifiability tests)


def test_random_base_probe_estimate_is_exact_on_nominal_robot(h4):
    rng = np.random.default_rng(19)
    B, P = random_frame(rng, 2.0, 3.0), random_frame(rng, 2.0, 0.2)
    m = ErrorModel.create(h4, "loop", base=B, probe=P)
    q = random_configurations(m, 20, 20)
    T = m.predict(q)
    cal = Calibrator(h4, 2)
    b6, p6, rms6 = cal.initial_frames(CalibrationData.from_poses(q, T))
    np.testing.assert_allclose(b6, B, atol=1e-9)
    np.testing.assert_allclose(p6, P, atol=1e-9)
    b3, p3, rms3 = cal.initial_frames(CalibrationData.from_poses(q, T, position_only=True))
    np.testing.assert_allclose(b3, B, atol=1e-8)
    np.testing.assert_allclose(p3[:3, 3], P[:3, 3], atol=1e-8)
    assert rms6 < 1e-9 and rms3 < 1e-9


def test_validation_after_the_tracker_moved(h4, full_truth):
    cal = _data(full_truth, 60, 21, payloads=(36.0,), noise=1e-5)
    val = _data(full_truth, 30, 22, payloads=(36.0,), noise=1e-5)
    moved = np.eye(4)
    moved[:3, :3] = so3_exp([0.1, -0.05, 1.2])
    moved[:3, 3] = [0.8, -2.0, 0.3]
    val_moved = CalibrationData.from_poses(val.q, moved @ val.poses, val.payload_kg)
    res = Calibrator(h4, 5).fit(cal)
    same = res.evaluate(val)[1].position.norm.mean
    assert res.evaluate(val_moved)[1].position.norm.mean > 100 * same  # BASE is stale
    _, after = res.evaluate(val_moved, refit_base=True)
    assert after.position.norm.mean == pytest.approx(same, rel=0.2, abs=2e-6)


@pytest.mark.parametrize(("n", "position_only"), [(15, False), (30, True)])
def test_few_equations_warning_counts_equations(h4, n, position_only):
    """15 poses × 6 = 90 or 30 positions × 3 = 90 equations: fewer than 3 per parameter
    of model 2; the warning says so and how many poses would do."""
    truth = _truth(h4, "loop", gravity=False, payload=False, seed=5,
                   position_only=position_only)
    res = Calibrator(h4, 2).fit(_data(truth, n, 6, payloads=(0.0,),
                                      position_only=position_only))
    k = len(res.keys)
    what, rows = ("positions", 3) if position_only else ("poses", 6)
    need = -(-3 * k // rows)
    assert 3 * k > 90 and need > n
    warning = next(w for w in res.warnings if w.startswith("few"))
    assert warning == (f"few equations: {n} {what} × {rows} = 90 equations for {k} "
                       f"parameters, fewer than 3 per parameter; measure at least {need} "
                       f"{what} (the thesis used 90–150 poses)")
    enough = Calibrator(h4, 2).fit(_data(truth, need, 7, payloads=(0.0,),
                                         position_only=position_only))
    assert not [w for w in enough.warnings if w.startswith("few")]


def test_refit_after_the_tracker_moved_honours_the_rotation_weight(h4, full_truth):
    """The target's measured orientations are off by a constant 0.57° (a T-MAC whose
    orientation is less trusted): the refit BASE follows them in proportion to the
    rotation weight; on positions alone it does not see them at all."""
    cal = _data(full_truth, 60, 21, payloads=(36.0,), noise=1e-5)
    val = _data(full_truth, 30, 22, payloads=(36.0,), noise=1e-5)
    moved = np.eye(4)
    moved[:3, :3] = so3_exp([0.1, -0.05, 1.2])
    moved[:3, 3] = [0.8, -2.0, 0.3]
    T = moved @ val.poses
    T[:, :3, :3] = T[:, :3, :3] @ so3_exp([0.01, 0.0, 0.0])
    val_moved = CalibrationData.from_poses(val.q, T, val.payload_kg)
    res = Calibrator(h4, 5, rotation_weight=10.0).fit(cal)
    same = res.evaluate(val)[1].position.norm.mean

    def after(**kw):
        return res.evaluate(val_moved, refit_base=True, **kw)[1].position.norm.mean

    heavy, unit, light = after(rotation_weight=10.0), after(rotation_weight=1.0), \
        after(rotation_weight=1e-3)
    assert heavy > 2 * unit > 20 * same  # the orientations pull BASE, more so when weighed more
    assert light == pytest.approx(same, rel=0.2, abs=2e-6)
    positions = after(refit_positions_only=True)
    assert positions == pytest.approx(same, rel=0.2, abs=2e-6)
    assert after() == heavy  # default: the weight the model was fitted with
    refit = res.with_validation(val_moved, refit_base=True, refit_positions_only=True)
    assert refit.validation.position.norm.mean == positions
    assert refit.validation.orientation is not None  # still reported, from 6-DOF data
    with pytest.raises(CalibrationError, match="rotation_weight"):
        res.evaluate(val_moved, refit_base=True, rotation_weight=float("nan"))


def test_scipy_least_squares_finds_what_gauss_newton_finds(h4):
    """``method="least-squares"`` (SciPy's trust-region reflective, x_scale="jac", the
    analytic Jacobian) reaches the same minimum as the thesis's Gauss–Newton, and its
    robust loss keeps outliers out as the IRLS weights do."""
    truth = _truth(h4, "loop", gravity=False, payload=False, seed=9)
    clean = _data(truth, 80, 10, payloads=(0.0,), noise=1e-5)
    gn = Calibrator(h4, 2).fit(clean)
    ls = Calibrator(h4, 2, method="least-squares").fit(clean)
    assert ls.converged and ls.keys == gn.keys
    for k in gn.keys:
        assert ls.value(k) == pytest.approx(gn.value(k), abs=1e-8)
    assert ls.settings["method"] == "least-squares"
    T = clean.poses.copy()
    bad = [5, 40, 63]
    T[bad, :3, 3] += [[4e-3, 0, 0], [0, -5e-3, 0], [0, 0, 6e-3]]
    dirty = CalibrationData.from_poses(clean.q, T)
    plain = Calibrator(h4, 2, method="least-squares").fit(dirty)
    robust = Calibrator(h4, 2, method="least-squares", loss="cauchy").fit(dirty)
    qv = random_configurations(truth, 30, 96)

    def val_err(r):
        return np.linalg.norm(r.predict(qv)[:, :3, 3] - truth.predict(qv)[:, :3, 3], axis=1).mean()

    assert val_err(robust) < 0.2 * val_err(plain)
    assert robust.pose_weights[bad].max() < 0.05


def test_an_unknown_method_is_refused_with_the_choices(h4):
    with pytest.raises(CalibrationError) as caught:
        Calibrator(h4, 2, method="newton")
    assert str(caught.value) == (
        "method must be one of ('gauss-newton', 'lm', 'least-squares'), got 'newton'")


def test_a_payload_under_a_gram_is_no_payload(h4, full_truth):
    # the payload compliances scale with m / m_ref: a reference of 0.5 g would blow them up
    crumbs = _data(full_truth, 30, 12, payloads=(0.0005,))
    with pytest.raises(CalibrationError, match="carry no payload"):
        Calibrator(h4, "full").fit(crumbs)
