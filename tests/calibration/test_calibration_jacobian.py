"""The error model and its analytic identification Jacobian.

Every analytic column is proven against central finite differences of the exact
forward model (exact four-bar closure, exact deflection terms) at random
configurations, random BASE/PROBE references and perturbed parameters; the loop
columns reduce to the thesis's m_ij (6.19, 6.22) at the nominal parallelogram.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from calibration_testlib import fd_columns, perturbed_model, random_frame

from plugcell.calibration.identifiability import random_configurations
from plugcell.calibration.jacobian import identification_jacobian
from plugcell.calibration.model import ErrorModel
from plugcell.kinematics import forward, manipulator_jacobian

CASES = [("h4", "loop"), ("h4", "serial"), ("ur10", "serial"),
         # robots with a joint coupling (readings ≠ kinematic joints)
         ("fanuc", "serial"), ("h4_flipped", "loop"), ("h4_flipped", "serial"),
         ("elbow_gear", "serial"), ("elbow_mimic", "serial")]


@pytest.mark.parametrize(("robot", "family"), CASES)
def test_every_analytic_column_matches_central_differences(robot, family, request):
    desc = request.getfixturevalue(robot)
    rng = np.random.default_rng(7)
    model = perturbed_model(desc, family, rng, gravity=True, payload=True, payload_ref_kg=36.0)
    q = random_configurations(model, 6, seed=3)
    batch = model.batch(q, rng.uniform(0.0, 40.0, len(q)))
    keys = model.space.keys
    jac = identification_jacobian(model, batch)
    np.testing.assert_allclose(jac.poses, model.predict_batch(batch), atol=1e-14)
    fd = fd_columns(model, batch, keys)
    for c, k in enumerate(keys):
        an = jac.H[:, :, c]
        scale = max(np.abs(an).max(), np.abs(fd[:, :, c]).max())
        err = np.abs(an - fd[:, :, c]).max()
        assert err <= 1e-7 * scale + 1e-9, f"{robot}/{family} {k}: error {err:.3g} of {scale:.3g}"


def test_columns_exact_at_nominal_and_vectorised_over_poses(h4):
    model = ErrorModel.create(h4, "loop", gravity=True, payload=True, payload_ref_kg=18.0)
    q = random_configurations(model, 5, seed=11)
    batch = model.batch(q, 18.0)
    H = identification_jacobian(model, batch).H
    fd = fd_columns(model, batch, model.space.keys)
    assert np.abs(H - fd).max() <= 1e-7 * np.abs(H).max()
    for i in range(len(q)):
        Hi = identification_jacobian(model, model.batch(q[i:i + 1], 18.0)).H
        np.testing.assert_allclose(Hi[0], H[i], rtol=0, atol=1e-12)


def test_nominal_model_predicts_forward_kinematics(h4):
    rng = np.random.default_rng(1)
    B, P = random_frame(rng), random_frame(rng, 0.3, 0.2)
    q = random_configurations(ErrorModel.create(h4), 8, seed=2)
    flange = forward(h4, None, q, closure="fourbar").flange
    for family in ("loop", "serial"):
        m = ErrorModel.create(h4, family, base=B, probe=P)
        # at the nominal parallelogram the serial model (6.3) is exact
        np.testing.assert_allclose(m.predict(q), B @ flange @ P, atol=1e-12)
    assert ErrorModel.create(h4, "serial").structure.desc.actuated == ("1", "2", "3", "4", "5", "6")


def _open_chain(h4, q):
    """Open-chain columns (6.12/B.13 in our convention) of θ and a at the flange, base = I."""
    fk = forward(h4, None, q)
    p = fk.flange[..., :3, 3]

    def frame(name):
        return np.broadcast_to(np.eye(4), fk.flange.shape) if name == "base" else fk.frame(name)

    def h_theta(name):
        P = frame(h4.link(name).parent)
        z = P[..., :3, 2]
        return np.concatenate([np.cross(z, p - P[..., :3, 3]), z], axis=-1)

    def h_a(name):
        return np.concatenate([fk.frame(name)[..., :3, 0], np.zeros_like(p)], axis=-1)

    return h_theta, h_a


def _mij(h4, q):
    """Thesis eq. (6.19), primes restored: m11, m12 with a2; m21, m22 with a2'."""
    a2, a2p = h4.link("2").a, h4.link("2'").a
    diff = q[:, 1] - q[:, 2]  # θ2 − θ2' (zero offsets)
    c, s = np.cos(diff), np.sin(diff)
    m11 = c / (a2 * s)
    m12 = -1.0 / (a2 * s)
    m21 = 1.0 / (a2p * s) - m11
    m22 = -c / (a2p * s) - m12
    return m11, m12, m21, m22


def test_closure_derivatives_reduce_to_thesis_mij(h4):
    q = random_configurations(ErrorModel.create(h4), 20, seed=4)
    fk = forward(h4, None, q, closure="fourbar")
    m11, m12, m21, m22 = _mij(h4, q)
    D = fk.passive_d_a  # (N, passive (3', 4'), links)
    i2, i2p, i3p, i4p = (h4.index(n) for n in ("2", "2'", "3'", "4'"))
    # (6.18): Δθ3' = m11(Δa3' − Δa2) + m12(Δa4' − Δa2'), Δθ4' likewise with m21, m22
    for row, (u, v) in enumerate(((m11, m12), (m21, m22))):
        np.testing.assert_allclose(D[:, row, i3p], u, rtol=1e-9)
        np.testing.assert_allclose(D[:, row, i2], -u, rtol=1e-9)
        np.testing.assert_allclose(D[:, row, i4p], v, rtol=1e-9)
        np.testing.assert_allclose(D[:, row, i2p], -v, rtol=1e-9)
    # (6.16): driven-angle derivatives
    np.testing.assert_allclose(fk.passive_jacobian[:, :, 1], [[1.0, -1.0]] * len(q), atol=1e-9)
    np.testing.assert_allclose(fk.passive_jacobian[:, :, 2], [[-1.0, 1.0]] * len(q), atol=1e-9)


def test_loop_columns_are_thesis_6_22_at_the_nominal_parallelogram(h4):
    model = ErrorModel.create(h4, "loop")
    q = random_configurations(model, 10, seed=5)
    jac = identification_jacobian(model, model.batch(q), ["theta2", "theta2'", "a2", "a2'",
                                                            "a3'", "a4'"])
    H = dict(zip(jac.keys, np.moveaxis(jac.H, -1, 0), strict=True))
    h_theta, h_a = _open_chain(h4, q)
    m11, m12, m21, m22 = (m[:, None] for m in _mij(h4, q))
    H3, H4 = h_theta("3'"), h_theta("4'")
    expect = {
        "theta2": H3 - H4,
        "theta2'": h_theta("2'") - H3 + H4,
        "a2'": h_a("2'") - m12 * H3 - m22 * H4,
        "a4'": h_a("4'") + m12 * H3 + m22 * H4,
        "a3'": h_a("3'") + m11 * H3 + m21 * H4,
        "a2": -m11 * H3 - m21 * H4,
    }
    for k, e in expect.items():
        np.testing.assert_allclose(H[k], e, atol=1e-9, err_msg=k)
    # 6.2.3: link 4' parallel to 2' (x4' = −x2') makes H_a4' = −H_a2'
    np.testing.assert_allclose(H["a4'"], -H["a2'"], atol=1e-9)


def test_base_columns_are_appendix_d5_with_the_translation_at_the_tcp(h4):
    a0, b0, al0, be0 = 0.8, -0.4, 0.3, -0.2
    model = ErrorModel.create(h4, "loop").updated(
        {"a0": a0, "b0": b0, "alpha0": al0, "beta0": be0})
    q = random_configurations(model, 4, seed=6)
    jac = identification_jacobian(model, model.batch(q), ["a0", "b0", "alpha0", "beta0"])
    p = jac.poses[:, :3, 3]
    d5 = {  # (D.5): spatial twists, translation referenced at the metrology origin
        "a0": [1, 0, 0, 0, 0, 0], "b0": [0, 1, 0, 0, 0, 0], "alpha0": [0, 0, -b0, 1, 0, 0],
        "beta0": [b0 * math.sin(al0), -a0 * math.sin(al0), a0 * math.cos(al0), 0,
                  math.cos(al0), math.sin(al0)],
    }
    for c, k in enumerate(jac.keys):
        v = np.array(d5[k], float)
        ours = np.concatenate([v[:3] + np.cross(v[3:], p), np.broadcast_to(v[3:], p.shape)], -1)
        np.testing.assert_allclose(jac.H[:, :, c], ours, atol=1e-12, err_msg=k)


def test_gravity_columns_are_eq_6_32(h4):
    model = ErrorModel.create(h4, "loop", gravity=True)
    q = random_configurations(model, 6, seed=8)
    jac = identification_jacobian(model, model.batch(q), ["G1", "G2", "G3", "theta2", "theta2'"])
    H = dict(zip(jac.keys, np.moveaxis(jac.H, -1, 0), strict=True))
    c2, c2p, s2p = np.cos(q[:, 1])[:, None], np.cos(q[:, 2])[:, None], np.sin(q[:, 2])[:, None]
    np.testing.assert_allclose(H["G1"], c2 * H["theta2"], atol=1e-12)
    np.testing.assert_allclose(H["G2"], c2p * H["theta2'"], atol=1e-12)
    np.testing.assert_allclose(H["G3"], s2p * H["theta2'"], atol=1e-12)


def test_payload_columns_are_eq_6_42_and_table_6_3_zeros(h4):
    model = ErrorModel.create(h4, "loop", payload=True, payload_ref_kg=36.0)
    q = random_configurations(model, 6, seed=9)
    keys = model.space.of_kind("payload")
    jac = identification_jacobian(model, model.batch(q, 36.0), keys)
    H = dict(zip(keys, np.moveaxis(jac.H, -1, 0), strict=True))
    Hq = manipulator_jacobian(h4, None, q, point="flange")  # J; K = Jᵀ (6.37, 6.39)
    R = forward(h4, None, q).flange[:, :3, :3]
    Hth = identification_jacobian(model, model.batch(q), ["theta1", "theta2", "theta2'",
                                                          "theta4", "theta5", "theta6"]).H
    for j, name in enumerate(h4.actuated):
        K = Hq[:, :, j]
        n, s, a = R[:, :, 0], R[:, :, 1], R[:, :, 2]
        reg = {"A": K[:, 2], "B": K[:, 3] * n[:, 1] - K[:, 4] * n[:, 0],
               "C": K[:, 3] * s[:, 1] - K[:, 4] * s[:, 0],
               "D": K[:, 3] * a[:, 1] - K[:, 4] * a[:, 0]}
        for f, r in reg.items():
            np.testing.assert_allclose(H[f + name], Hth[:, :, j] * r[:, None], atol=1e-12)
    scale = np.abs(jac.H).max()
    # Table 6-3: joint 1 (axis ∥ gravity), B2 = C2 = D2 = 0, A6 = D6 = 0
    for k in ("A1", "B1", "C1", "D1", "B2", "C2", "D2", "A6", "D6"):
        assert np.abs(H[k]).max() < 1e-12 * scale, k


def test_folding_the_frames_into_the_references_keeps_the_prediction(h4):
    from plugcell.calibration.model import fold_frames

    rng = np.random.default_rng(12)
    m = perturbed_model(h4, "loop", rng, gravity=False, payload=False, payload_ref_kg=36.0)
    q = random_configurations(m, 8, seed=13)
    f = fold_frames(m)
    np.testing.assert_allclose(f.predict(q), m.predict(q), atol=1e-12)
    assert f.value("a0") == f.value("theta6") == f.value("d7") == 0.0
    assert f.value("a2'") == m.value("a2'")


def test_serial_gravity_torques_are_minus_the_potential_gradient(ur10):
    from plugcell.calibration.compliance import GRAVITY, _gravity_torques

    q = random_configurations(ErrorModel.create(ur10, "serial"), 5, seed=14)
    ref = ur10.nominal_parameters()

    def potential(qq):
        fk = forward(ur10, ref, qq)
        V = np.zeros(len(qq))
        for i, lk in enumerate(ur10.links):
            c = fk.frames[:, i, :3, :3] @ np.asarray(lk.com) + fk.frames[:, i, :3, 3]
            V += lk.mass * GRAVITY * c[:, 2]
        return V

    h = 1e-6
    tau = _gravity_torques(ur10, ref, q)
    for j in range(6):
        dq = np.zeros(6)
        dq[j] = h
        grad = (potential(q + dq) - potential(q - dq)) / (2 * h)
        np.testing.assert_allclose(tau[:, j], -grad, rtol=1e-6, atol=1e-6)
