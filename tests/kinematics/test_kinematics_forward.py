"""Forward kinematics through the parallelogram, eqs. (6.1)–(6.3)."""

from __future__ import annotations

import numpy as np
import pytest
from kinematics_testlib import perturbed_params, random_configs

from plugcell.io.robots import load_robot
from plugcell.kinematics import (
    FIELDS,
    LoopClosureError,
    branch_cut_transform,
    dh_hayati,
    forward,
    rot_z,
    translation,
)


def test_home_pose_by_hand(h4):
    """θ = (0, −90°, −187°, 0, 90°, 0): upper arm vertical, forearm horizontal."""
    fk = forward(h4, None, h4.home)
    np.testing.assert_allclose(fk.frame("1")[:3, 3], [0.2, 0, 1.0], atol=1e-15)
    np.testing.assert_allclose(fk.frame("2")[:3, 3], [0.2, 0, 2.05], atol=1e-15)  # elbow
    np.testing.assert_allclose(fk.frame("4'")[:3, 3], [0.2, 0, 2.05], atol=1e-12)  # loop closed
    np.testing.assert_allclose(fk.frame("3")[:3, 3], [0.2, 0, 2.3], atol=1e-12)
    np.testing.assert_allclose(fk.frame("3")[:3, 2], [1, 0, 0], atol=1e-12)  # forearm axis
    np.testing.assert_allclose(fk.frame("4")[:3, 3], [0.2 + 1.1395, 0, 2.3], atol=1e-12)
    np.testing.assert_allclose(fk.passive, [np.radians(97), np.radians(83)], atol=1e-12)
    np.testing.assert_allclose(fk.passive_angle("3'"), np.radians(97), atol=1e-12)
    assert fk.flange.shape == (4, 4) and fk.frames.shape == (9, 4, 4)


def test_chain_is_product_of_link_transforms(h4):
    """Eq. (6.1) with branch (6.2): T_6^0 = T1 T2' T3' T4' T3 T4 T5 T6."""
    p = perturbed_params(h4, 1)
    q = random_configs(h4, 5, 2)
    fk = forward(h4, p, q)
    T = np.broadcast_to(np.eye(4), (5, 4, 4))
    for i in h4.chain:
        T = T @ dh_hayati(fk.theta[:, i], p.d[i], p.a[i], p.alpha[i], p.beta[i])
    np.testing.assert_allclose(fk.flange, T, atol=1e-14)
    # actuated θ = reading + offset; fixed θ = constant
    np.testing.assert_allclose(fk.theta[:, h4.index("4")], q[:, 3] + p.theta[h4.index("4")])
    np.testing.assert_allclose(fk.theta[:, h4.index("3")], p.theta[h4.index("3")])


@pytest.mark.parametrize("closure", ["fourbar", "nominal"])
def test_branches_6_2_and_6_3_agree_for_a_parallelogram(h4, closure):
    q = random_configs(h4, 300, 3)
    fk = forward(h4, None, q, closure)
    T62 = fk.frame("4'")
    T63 = branch_cut_transform(h4, fk)
    np.testing.assert_allclose(T62, T63, atol=1e-12)
    # and the frame of link 3 via (6.3): T_2^1 · T_3^2 with the cut-joint angle
    link3 = h4.link("3")
    T3_via_63 = T63 @ dh_hayati(link3.theta, link3.d, link3.a, link3.alpha)
    np.testing.assert_allclose(fk.frame("3"), T3_via_63, atol=1e-12)


def test_fourbar_closes_with_perturbed_lengths_nominal_does_not(h4):
    p = h4.nominal_parameters().perturbed(
        {("2", "a"): 2e-3, ("3'", "a"): -1e-3, ("4'", "a"): 1.5e-3}
    )
    q = random_configs(h4, 300, 4)
    ex = forward(h4, p, q, "fourbar")
    gap = np.linalg.norm(ex.frame("4'")[:, :3, 3] - ex.frame("2")[:, :3, 3], axis=1)
    assert gap.max() < 1e-12
    np.testing.assert_allclose(ex.frame("4'"), branch_cut_transform(h4, ex), atol=1e-12)
    nom = forward(h4, p, q, "nominal")
    gap_nom = np.linalg.norm(nom.frame("4'")[:, :3, 3] - nom.frame("2")[:, :3, 3], axis=1)
    assert gap_nom.min() > 1e-4  # the nominal formula ignores the length errors


def test_nominal_and_fourbar_agree_for_nominal_lengths(h4):
    q = random_configs(h4, 300, 5)
    p = perturbed_params(h4, 6).replace(a=h4.nominal_parameters().a)
    np.testing.assert_allclose(
        forward(h4, p, q, "fourbar").frames, forward(h4, p, q, "nominal").frames, atol=1e-12
    )


def test_every_parameter_acts_on_fk(h4):
    """FK reads the parameter set, loop links and Hayati β included."""
    p0 = h4.nominal_parameters()
    q = random_configs(h4, 3, 7)
    fk0 = forward(h4, p0, q)
    silent_on_flange = {("2", "d"), ("2", "alpha"), ("2", "beta")}  # off-chain arm: frame only
    for name in h4.link_names:
        for f in FIELDS:
            fk = forward(h4, p0.perturbed({(name, f): 1e-6}), q)
            assert np.abs(fk.frames - fk0.frames).max() > 1e-8, (name, f)
            moved = np.abs(fk.flange - fk0.flange).max() > 1e-8
            assert moved != ((name, f) in silent_on_flange), (name, f)


def test_base_and_tool(h4):
    T_base = translation([1.0, 2.0, 0.5]) @ rot_z(0.3)
    T_tool = translation([0.0, 0.05, 0.3])
    p = h4.nominal_parameters().replace(base=T_base, tool=T_tool)
    fk = forward(h4, p, h4.home)
    np.testing.assert_allclose(fk.tcp, fk.flange @ T_tool)
    np.testing.assert_allclose(fk.world_flange, T_base @ fk.flange)
    np.testing.assert_allclose(fk.world_tcp, T_base @ fk.flange @ T_tool)
    np.testing.assert_allclose(fk.flange, forward(h4, None, h4.home).flange)  # base frame


def test_batch_shapes_and_input_errors(h4):
    q = random_configs(h4, 6, 8).reshape(2, 3, 6)
    fk = forward(h4, None, q)
    assert fk.frames.shape == (2, 3, 9, 4, 4)
    assert fk.flange.shape == (2, 3, 4, 4)
    assert fk.passive.shape == (2, 3, 2)
    assert fk.passive_jacobian.shape == (2, 3, 2, 6)
    np.testing.assert_allclose(fk.flange[1, 2], forward(h4, None, q[1, 2]).flange)
    with pytest.raises(ValueError, match=r"expected shape \(\.\.\., 6\)"):
        forward(h4, None, np.zeros(5))
    with pytest.raises(ValueError, match="closure"):
        forward(h4, None, h4.home, "exact")
    with pytest.raises(KeyError, match="unknown link"):
        fk.frame("7")
    with pytest.raises(LoopClosureError, match="collapses"):
        forward(h4, None, [0, -1.0, -1.0, 0, 0, 0])
    with pytest.raises(ValueError, match="link names"):
        forward(h4, load_robot("elbow6").nominal_parameters(), h4.home)


def test_limits_are_not_enforced_by_fk(h4):
    q = h4.home.copy()
    q[0] = np.radians(400)  # = 40° + one turn: evaluated, only reported
    q40 = h4.home.copy()
    q40[0] = np.radians(40)
    np.testing.assert_allclose(
        forward(h4, None, q).flange, forward(h4, None, q40).flange, atol=1e-12
    )
    assert h4.limit_violations(q) == ["joint 1 = 400.0000° outside [-180°, 180°]"]
    assert h4.limit_violations(q40) == []
    assert not h4.within_limits(q) and h4.within_limits(q40)


def test_d5_correction_matches_the_stated_reach(h4):
    """Table 6-1's d5 = 1.1588 m puts the flange ~3.4 m out; 0.1588 m is consistent with the
    2.318 m maximum horizontal reach (design.md, Known defects)."""
    q = random_configs(h4, 20000, 9)
    p = h4.nominal_parameters()
    fk = forward(h4, p, q)
    wrist = fk.frame("4")[:, :3, 3]
    reach_wrist = np.hypot(wrist[:, 0], wrist[:, 1]).max()
    assert abs(reach_wrist - 2.318) / 2.318 < 0.05
    fk_bad = forward(h4, p.perturbed({("5", "d"): 1.0}), q)
    reach_bad = np.hypot(fk_bad.flange[:, 0, 3], fk_bad.flange[:, 1, 3]).max()
    assert reach_bad > 3.3
