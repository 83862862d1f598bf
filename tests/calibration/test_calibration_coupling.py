"""A robot with a vendor joint convention calibrates and compensates on its readings.

The coupled Fanuc M-20iA (readings J1..J6, θ_kin = M·J + offset) and its hand-converted
twin (the same DH rows, offsets folded into θ, joint values M·J converted outside
plugcell) must give the same identified parameters, the same residuals and the same
compensation, whose joint targets come back as readings (docs/robot-description.md,
"Vendor joint conventions").
"""

from __future__ import annotations

import numpy as np
import pytest
from coupling_testlib import hand_converted
from derivatives import central_differences

from plugcell.calibration import CalibrationData, Calibrator, ErrorModel
from plugcell.calibration.identifiability import random_configurations, structural_identifiability
from plugcell.compensation import IdentifiedModel, compensate, compensate_joints, nominal_joints
from plugcell.io.params import params_document, result_from_params
from plugcell.kinematics import forward, pose_error
from plugcell.kinematics.transforms import so3_exp

TRACKER = np.eye(4)
TRACKER[:3, :3] = so3_exp([0.2, -0.1, 2.0])
TRACKER[:3, 3] = [2.5, -1.0, 0.3]
TMAC = np.eye(4)
TMAC[:3, 3] = [0.02, -0.05, 0.12]


@pytest.fixture(scope="module")
def hand(fanuc):
    return hand_converted(fanuc)


@pytest.fixture(scope="module")
def campaign(fanuc):
    """A seeded simulated campaign: hidden errors (0.5 mm, 0.03°) and gravity compliance,
    80 poses of readings, tracker noise 10 µm / 10 µrad."""
    rng = np.random.default_rng(161)
    truth = ErrorModel.create(fanuc, "serial", gravity=True, base=TRACKER, probe=TMAC)
    v = np.zeros(len(truth.space))
    for k in structural_identifiability(truth).kept:
        p = truth.space[k]
        v[truth.space.index(k)] = (2e-7 if p.unit == "rad/(N·m)" else 5e-4) * rng.normal()
    truth = truth.with_values(v)
    q = random_configurations(truth, 80, seed=162)
    T = truth.predict(q).copy()
    T[:, :3, 3] += rng.normal(0, 1e-5, (len(q), 3))
    T[:, :3, :3] = so3_exp(rng.normal(0, 1e-5, (len(q), 3))) @ T[:, :3, :3]
    return truth, q, T


@pytest.fixture(scope="module")
def results(fanuc, hand, campaign):
    _, q, T = campaign
    M = fanuc.coupling.matrix
    res_c = Calibrator(fanuc, "serial+gravity").fit(CalibrationData.from_poses(q, T))
    res_h = Calibrator(hand, "serial+gravity").fit(CalibrationData.from_poses(q @ M.T, T))
    return res_c, res_h


def test_coupled_and_hand_converted_calibrate_identically(results, campaign):
    truth = campaign[0]
    res_c, res_h = results
    assert res_c.converged and res_h.converged
    assert res_c.keys == res_h.keys
    assert {"theta2", "theta3", "theta4", "theta5"} <= set(res_c.keys)  # joint offsets Δθ
    for k in res_c.keys:
        assert res_c.value(k) == pytest.approx(res_h.value(k), abs=1e-9), k
    assert res_c.calibration.position.norm.mean == pytest.approx(
        res_h.calibration.position.norm.mean, abs=1e-12)
    assert res_c.calibration.position.norm.mean < 3e-5  # the noise, not the model
    # the identified joint offsets are the hidden ones (within the noise)
    for k in ("theta2", "theta3", "theta4", "theta5"):
        assert res_c.value(k) == pytest.approx(truth.value(k), abs=3e-5), k
    qv = random_configurations(truth, 10, seed=163)  # readings
    np.testing.assert_allclose(res_c.predict(qv), truth.predict(qv), atol=5e-5)


def test_result_round_trip_keeps_readings(results, fanuc, campaign):
    res_c, _ = results
    back = result_from_params(params_document(res_c), fanuc)
    qv = random_configurations(campaign[0], 5, seed=164)
    np.testing.assert_allclose(back.predict(qv), res_c.predict(qv), atol=1e-12)


def test_compensated_joint_targets_come_back_as_readings(results, fanuc, campaign):
    res_c, res_h = results
    M = fanuc.coupling.matrix
    model_c, model_h = IdentifiedModel(res_c.model), IdentifiedModel(res_h.model)
    q_true = random_configurations(campaign[0], 12, seed=165)
    T = forward(fanuc, None, q_true).flange @ model_c.tool  # nominal TCP poses to reach
    q_nom, ok, _ = nominal_joints(model_c, T, seed=q_true)
    assert ok.all()
    np.testing.assert_allclose(q_nom, q_true, atol=1e-8)  # nominal IK gives readings back
    # Newton's step is invariant under the linear change of joint variables q_h = M q
    out_c = compensate_joints(model_c, T, q_nom)
    out_h = compensate_joints(model_h, T, q_nom @ M.T)
    assert out_c.ok.all() and out_h.ok.all()
    np.testing.assert_allclose(out_c.q @ M.T, out_h.q, atol=1e-10)
    assert fanuc.within_limits(out_c.q).all()
    np.testing.assert_allclose(model_c.pose(out_c.q), T, atol=1e-6)
    # the whole 6.5.1 (nominal IK + compensation) agrees too
    full_c = compensate(model_c, T, seed=q_true)
    full_h = compensate(model_h, T, seed=q_true @ M.T)
    np.testing.assert_allclose(full_c.q @ M.T, full_h.q, atol=1e-8)
    np.testing.assert_allclose(fanuc.kinematic_joints(full_c.q) - fanuc.coupling.offset,
                               full_h.q, atol=1e-8)


def test_compensation_jacobian_is_wrt_readings(results, campaign):
    """IdentifiedModel.evaluate's J (chain rule through the coupling) = central differences
    of its pose in the readings (deflections off: J then is the exact derivative)."""
    em = results[0].model
    v = np.array(em.values)
    v[em.space.indices(em.compliance_keys)] = 0.0
    model = IdentifiedModel(em.with_values(v))
    q = random_configurations(campaign[0], 5, seed=166)
    T, J = model.evaluate(q)
    fd = central_differences(lambda qq: pose_error(model.pose(qq), T), q)
    np.testing.assert_allclose(J, fd, atol=1e-8)
