"""Manipulator Jacobian (6.37, 6.39) against central finite differences of forward()."""

from __future__ import annotations

import numpy as np
import pytest
from kinematics_testlib import perturbed_params, random_configs

from plugcell.kinematics import (
    forward,
    manipulator_jacobian,
    pose_error,
    so3_log,
    translation,
)


def _fd_jacobian(desc, params, q, point, closure, h=1e-6):
    """Central differences: linear part of the point, rotation vector of R(q+h) R(q−h)ᵀ."""
    n = desc.n_actuated
    cols = []
    for j in range(n):
        dq = np.zeros(n)
        dq[j] = h
        fp = forward(desc, params, q + dq, closure)
        fm = forward(desc, params, q - dq, closure)
        Tp, Tm = (fp.tcp, fm.tcp) if point == "tcp" else (fp.flange, fm.flange)
        lin = (Tp[..., :3, 3] - Tm[..., :3, 3]) / (2 * h)
        ang = so3_log(Tp[..., :3, :3] @ np.swapaxes(Tm[..., :3, :3], -1, -2)) / (2 * h)
        cols.append(np.concatenate([lin, ang], -1))
    return np.stack(cols, -1)


@pytest.mark.parametrize("closure", ["fourbar", "nominal"])
@pytest.mark.parametrize("point", ["flange", "tcp"])
def test_h4_jacobian_matches_finite_differences(h4, closure, point):
    params = perturbed_params(h4, 12).replace(tool=translation([0.05, -0.02, 0.3]))
    q = random_configs(h4, 200, 13)
    J = manipulator_jacobian(h4, params, q, point=point, closure=closure)
    J_fd = _fd_jacobian(h4, params, q, point, closure)
    assert J.shape == (200, 6, 6)
    scale = np.abs(J_fd).max(axis=(-2, -1), keepdims=True)
    assert (np.abs(J - J_fd) / scale).max() < 1e-7


def test_elbow_jacobian_matches_finite_differences(elbow):
    params = perturbed_params(elbow, 14)
    q = random_configs(elbow, 200, 15)
    J = manipulator_jacobian(elbow, params, q)
    J_fd = _fd_jacobian(elbow, params, q, "flange", "fourbar")
    assert (np.abs(J - J_fd) / np.abs(J_fd).max(axis=(-2, -1), keepdims=True)).max() < 1e-7


def test_loop_columns_are_6_39(h4):
    """Nominal closure: K_2 = K_3' − K_4', K_2' = K_2' − K_3' + K_4' (primes restored),
    K_i = [z_{i−1} × (p_n − p_{i−1}); z_{i−1}] (6.37)."""
    q = random_configs(h4, 20, 16)
    fk = forward(h4, None, q, "nominal")
    J = manipulator_jacobian(h4, None, q, closure="nominal")
    pn = fk.flange[:, :3, 3]

    def K(link):  # geometric column of the joint of ``link`` (axis of its parent frame)
        T = fk.frame(h4.link(link).parent)
        z, o = T[:, :3, 2], T[:, :3, 3]
        return np.concatenate([np.cross(z, pn - o), z], -1)

    np.testing.assert_allclose(J[:, :, h4.joint_index("2")], K("3'") - K("4'"), atol=1e-14)
    np.testing.assert_allclose(
        J[:, :, h4.joint_index("2'")], K("2'") - K("3'") + K("4'"), atol=1e-14
    )
    for j in ("1", "4", "5", "6"):
        np.testing.assert_allclose(J[:, :, h4.joint_index(j)], K(j), atol=1e-14)


def test_pose_error_small_motion_matches_jacobian(h4):
    """pose_error(T(q + dq), T(q)) = J dq + O(|dq|²): the one convention, end to end."""
    q = random_configs(h4, 300, 17)
    params = perturbed_params(h4, 18)
    J = manipulator_jacobian(h4, params, q)
    rng = np.random.default_rng(19)
    for eps in (1e-4, 1e-6):
        dq = rng.normal(size=q.shape) * eps
        e = pose_error(forward(h4, params, q + dq).flange, forward(h4, params, q).flange)
        lin = np.einsum("nij,nj->ni", J, dq)
        assert np.abs(e - lin).max() < 50 * eps**2


def test_batch_shape(h4):
    q = random_configs(h4, 6, 20).reshape(3, 2, 6)
    J = manipulator_jacobian(h4, None, q)
    assert J.shape == (3, 2, 6, 6)
    np.testing.assert_allclose(J[2, 1], manipulator_jacobian(h4, None, q[2, 1]))
    with pytest.raises(ValueError, match="point"):
        manipulator_jacobian(h4, None, q, point="wrist")


@pytest.mark.parametrize("closure", ["fourbar", "nominal"])
@pytest.mark.parametrize("point", ["flange", "tcp"])
def test_one_configuration_matches_finite_differences_and_its_batch_row(h4, elbow, closure,
                                                                        point):
    """One configuration (or a batch of one) takes the float path of the Jacobian: the
    same matrix as its row in a batch (to the last bit here; 1e-12 for machines whose
    math and numpy sines differ by an ulp) and central differences of forward()."""
    for desc, seed in ((h4, 21), (elbow, 22)):
        params = perturbed_params(desc, seed).replace(tool=translation([0.05, -0.02, 0.3]))
        q = random_configs(desc, 8, seed)
        batch = manipulator_jacobian(desc, params, q, point=point, closure=closure)
        for i in range(len(q)):
            one = manipulator_jacobian(desc, params, q[i], point=point, closure=closure)
            in_one = manipulator_jacobian(desc, params, q[i][None], point=point,
                                          closure=closure)
            assert one.shape == (6, desc.n_actuated) and in_one.shape == (1, *one.shape)
            np.testing.assert_allclose(one, batch[i], rtol=1e-12, atol=1e-14)
            np.testing.assert_array_equal(in_one[0], one)
            J_fd = _fd_jacobian(desc, params, q[i], point, closure)
            assert (np.abs(one - J_fd) / np.abs(J_fd).max()).max() < 1e-7
