"""Model-based compensation (thesis 6.5.1): round trip, Jacobian, failures, batching."""

from __future__ import annotations

import math

import numpy as np
import pytest
from compensation_testlib import perturbed_error_model
from derivatives import central_differences

from plugcell.compensation import (
    CompensationError,
    IdentifiedModel,
    NominalModel,
    compensate,
    compensate_joints,
)
from plugcell.kinematics import forward
from plugcell.kinematics.pose_error import pose_error, pose_error_exact
from plugcell.kinematics.transforms import invert, so3_exp


def _targets(model, q, rng, mm=3.0, deg=0.2):
    """Tool poses near the model's poses at ``q`` (displaced like real errors)."""
    T = model.pose(q, 36.0)
    T[:, :3, 3] += rng.normal(0, mm * 1e-3, (len(q), 3))
    T[:, :3, :3] = so3_exp(rng.normal(0, math.radians(deg), (len(q), 3))) @ T[:, :3, :3]
    return T


def test_identified_model_matches_error_model_prediction(model5, workspace_q):
    em = model5.error_model
    T = model5.pose(workspace_q, 36.0)
    P = em.predict(workspace_q, 36.0)
    np.testing.assert_allclose(invert(em.base()) @ P @ invert(em.probe()) @ model5.tool, T,
                               atol=1e-12)
    np.testing.assert_allclose(model5.predict_measurement(workspace_q, 36.0), P, atol=1e-12)


def test_jacobian_matches_finite_differences_without_deflection(h4, workspace_q):
    em = perturbed_error_model(h4, seed=2, payload=False)
    comp = em.space.indices(em.compliance_keys)
    v = np.array(em.values)
    v[comp] = 0.0  # no deflection: J is then the exact derivative
    model = IdentifiedModel(em.with_values(v))
    q = workspace_q[:5]
    T, J = model.evaluate(q)
    fd = central_differences(lambda qq: pose_error(model.pose(qq), T), q)
    np.testing.assert_allclose(J, fd, atol=1e-7)


def test_round_trip_predicts_the_target_to_1e_6(model5, workspace_q):
    """predict(compensated joints) == target, in the tracker frame through the ErrorModel."""
    rng = np.random.default_rng(11)
    T = _targets(model5, workspace_q, rng)
    res = compensate(model5, T, 36.0)
    assert res.ok.all()
    assert res.residual.max() < 1e-6
    em = model5.error_model
    predicted = em.predict(res.q, 36.0)  # BASE·T6(q + Δq)·PROBE
    wanted = em.base() @ T  # the tool is the PROBE
    e = pose_error_exact(wanted, predicted)
    assert np.linalg.norm(e, axis=1).max() < 1e-6
    # the compensation really changed the joints (the model differs from nominal)
    assert np.abs(res.q - res.q_start).max() > 1e-4
    assert res.iterations.max() <= 5


def test_batched_equals_one_by_one(model5, workspace_q):
    rng = np.random.default_rng(12)
    T = _targets(model5, workspace_q[:6], rng)
    batch = compensate(model5, T, 36.0)
    for k in range(6):
        one = compensate(model5, T[k], 36.0)
        np.testing.assert_allclose(one.q[0], batch.q[k], atol=1e-9)


def test_payload_changes_the_compensated_joints(model5, workspace_q):
    rng = np.random.default_rng(13)
    T = _targets(model5, workspace_q[:5], rng)
    loaded = compensate(model5, T, 36.0)
    empty = compensate(model5, T, 0.0)
    assert np.abs(loaded.q - empty.q).max() > 1e-5
    np.testing.assert_allclose(model5.pose(empty.q, 0.0)[:, :3, 3], T[:, :3, 3], atol=1e-6)


def test_serial_structure_model_round_trip(h4, workspace_q):
    """Model 3 on the serial structure of eq. 6.3: readings map to chain joints linearly."""
    model = IdentifiedModel(perturbed_error_model(h4, seed=5, family="serial", payload=False))
    T = _targets(model, workspace_q[:10], np.random.default_rng(14))
    res = compensate(model, T)
    assert res.ok.all()
    e = pose_error_exact(T, model.pose(res.q))
    assert np.linalg.norm(e, axis=1).max() < 1e-6


def test_nominal_model_compensation_is_the_nominal_ik(h4, workspace_q):
    tool = np.eye(4)
    tool[:3, 3] = [0.05, 0.0, 0.1]
    model = NominalModel(h4, tool)
    T = forward(h4, h4.nominal_parameters().replace(tool=tool), workspace_q[:5]).tcp
    res = compensate(model, T)
    assert res.ok.all()
    assert res.iterations.max() == 0  # nominal IK already solves the nominal model


def test_no_convergence_is_a_clear_failure(model5, workspace_q):
    T = _targets(model5, workspace_q[:3], np.random.default_rng(15))
    with pytest.raises(CompensationError) as ei:
        compensate(model5, T, 36.0, max_iterations=1, tol=1e-12)
    assert ei.value.kind == "no_convergence"
    assert ei.value.index == 0
    assert "did not converge in 1 iterations" in str(ei.value)
    res = compensate(model5, T, 36.0, max_iterations=1, tol=1e-12, raise_errors=False)
    assert not res.converged.any()
    assert all(k == "no_convergence" for k in res.kind)


def test_divergence_from_a_wild_start_is_reported(model5, workspace_q):
    T = _targets(model5, workspace_q[:2], np.random.default_rng(16))
    q0 = workspace_q[:2] + np.radians([40.0, 0, 0, 0, 0, 0])
    res = compensate_joints(model5, T, q0, 36.0, raise_errors=False)
    assert not res.converged.any()
    assert "diverged" in res.reason[0]


def test_leaving_the_joint_limits_is_a_clear_failure(h4, model5):
    """A target the nominal model reaches just inside joint 1's limit, while the model
    needs joint 1 past it."""
    lim = h4.joint_limits[0, 1]
    q = np.array([lim - 1e-5, math.radians(-80), math.radians(-150), 0.1, 1.2, 0.2])
    nominal = NominalModel(h4, model5.tool)
    T = nominal.pose(q[None])
    em = model5.error_model
    shifted = IdentifiedModel(em.updated({"theta1": -1e-3}))  # model: joint 1 reads 1 mrad high
    with pytest.raises(CompensationError) as ei:
        compensate_joints(shifted, T, q[None])
    err = ei.value
    assert err.kind == "joint_limit" and err.joint == "1"
    assert err.value > lim
    assert "outside its limits" in str(err)


def test_unreachable_target_is_a_clear_failure(model5):
    T = np.eye(4)
    T[:3, 3] = [6.0, 0.0, 1.0]
    with pytest.raises(CompensationError) as ei:
        compensate(model5, T)
    assert ei.value.kind == "unreachable"
    assert "no nominal joint solution" in str(ei.value)


def test_bad_input_shapes(model5):
    with pytest.raises(ValueError):
        compensate_joints(model5, np.eye(3), np.zeros(6))
    with pytest.raises(ValueError):
        compensate_joints(model5, np.eye(4), np.zeros(6), payload_kg=-1.0)
    with pytest.raises(ValueError):
        compensate_joints(model5, np.full((4, 4), np.nan), np.zeros(6))
