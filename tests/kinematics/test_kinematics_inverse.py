"""Nominal inverse kinematics: round trips, default seed, unreachable poses, limits."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from kinematics_testlib import perturbed_params, random_configs

from plugcell.kinematics import (
    JointLimitError,
    UnreachableError,
    forward,
    inverse,
    manipulator_jacobian,
    pose_error,
    rot_y,
    so3_exp,
    translation,
)


def _well_conditioned(desc, q, threshold=1e-3):
    sv = np.linalg.svd(manipulator_jacobian(desc, None, q), compute_uv=False)
    return sv[:, -1] > threshold


@pytest.mark.parametrize("robot", ["h4", "elbow"])
def test_round_trip_10000_configurations_seed_near_truth(robot, request):
    desc = request.getfixturevalue(robot)
    q = random_configs(desc, 10_000, 31)
    T = forward(desc, None, q).flange
    seed = q + np.random.default_rng(32).normal(0, 1e-3, q.shape)
    res = inverse(desc, None, T, seed)
    assert res.converged.all() and res.within_limits.all()
    assert res.position_error.max() < 1e-10 and res.orientation_error.max() < 1e-10
    np.testing.assert_allclose(forward(desc, None, res.q).flange, T, atol=1e-9)
    good = _well_conditioned(desc, q)
    assert good.mean() > 0.95
    np.testing.assert_allclose(res.q[good], q[good], atol=1e-7)  # the truth, not another branch


@pytest.mark.parametrize(("robot", "n"), [("h4", 10_000), ("elbow", 2000)])
def test_default_seed_finds_a_valid_solution(robot, n, request):
    desc = request.getfixturevalue(robot)
    q = random_configs(desc, n, 33)
    T = forward(desc, None, q).flange
    res = inverse(desc, None, T)  # seed: desc.home
    assert res.converged.all()
    assert desc.within_limits(res.q).all()
    e = pose_error(T, forward(desc, None, res.q).flange)
    assert np.abs(e).max() < 1e-9


def test_branch_nearest_the_seed(h4):
    """Two seeds near two different solutions of the same pose return those solutions."""
    qa = np.radians([10.0, -80.0, -190.0, 30.0, 60.0, -20.0])
    T = forward(h4, None, qa).flange
    flip = np.array([0, 0, 0, np.pi, -2 * qa[4], np.pi])
    qb = inverse(h4, None, T, seed=qa + flip).q  # the other wrist branch
    assert np.abs(qb - qa).max() > 0.1
    np.testing.assert_allclose(forward(h4, None, qb).flange, T, atol=1e-9)
    np.testing.assert_allclose(inverse(h4, None, T, seed=qa + 0.05).q, qa, atol=1e-8)
    np.testing.assert_allclose(inverse(h4, None, T, seed=qb + 0.05).q, qb, atol=1e-8)


def test_working_volume_is_inside_the_limits(h4, elbow):
    """The thesis's calibration box (8.2.1) is reachable inside the limits with the flange
    pointing forward or down — every point of a 5×5×5 grid incl. the corners."""
    for desc in (h4, elbow):
        wv = desc.working_volume
        g = np.linspace(0, 1, 5)
        P = np.array(
            [wv.lower + np.array(f) * (wv.upper - wv.lower) for f in itertools.product(g, g, g)]
        )
        for R in (rot_y(np.pi / 2), rot_y(np.pi)):
            T = np.broadcast_to(R, (len(P), 4, 4)).copy()
            T[:, :3, 3] = P
            res = inverse(desc, None, T)
            assert res.converged.all() and desc.within_limits(res.q).all()


def test_upper_arm_up_with_any_loop_angle_in_30_150(h4):
    q = np.tile(h4.home, (25, 1))
    q[:, 2] = q[:, 1] - np.radians(np.linspace(30, 150, 25))  # θ2 − θ2' over 30°…150°
    assert h4.within_limits(q).all()
    T = forward(h4, None, q).flange
    res = inverse(h4, None, T, seed=h4.home)
    assert res.converged.all() and h4.within_limits(res.q).all()


def test_unreachable_out_of_reach(h4):
    T = translation([4.0, 0.0, 1.0])
    with pytest.raises(UnreachableError, match="out of reach") as exc:
        inverse(h4, None, T)
    assert exc.value.reason == "out of reach"
    assert exc.value.index is None


def test_unreachable_no_convergence(h4):
    """Inside the reach bound but not reachable: the flange 5 cm from the column axis."""
    T = rot_y(np.pi) @ np.eye(4)
    T[:3, 3] = [0.0, 0.05, 1.0]
    with pytest.raises(UnreachableError, match="no joint solution") as exc:
        inverse(h4, None, T)
    assert exc.value.reason == "no convergence"


def test_batch_error_names_the_target_and_no_raise_mode(h4):
    T = forward(h4, None, np.stack([h4.home, h4.home])).flange
    T[1] = translation([5.0, 0, 0])
    with pytest.raises(UnreachableError, match=r"^target 1: pose is out of reach") as exc:
        inverse(h4, None, T)
    assert exc.value.index == (1,)
    res = inverse(h4, None, T, raise_errors=False)
    np.testing.assert_array_equal(res.converged, [True, False])
    assert res.reason[0] == "" and "out of reach" in res.reason[1]


def test_joint_limit_error(h4):
    """Upper arm leaning far forward: θ2 = 10°, beyond its −15° limit."""
    q = h4.home.copy()
    q[1] = np.radians(10.0)  # beyond −15°
    q[2] = q[1] - np.radians(100.0)
    assert not h4.within_limits(q)
    T = forward(h4, None, q).flange
    with pytest.raises(JointLimitError) as exc:
        inverse(h4, None, T, seed=q)
    assert exc.value.limit == pytest.approx(tuple(h4.joint_limits[1]))
    assert exc.value.joint == "2"
    assert "joint 2 =" in str(exc.value) and "outside [-165°, -15°]" in str(exc.value)
    res = inverse(h4, None, T, seed=q, enforce_limits=False)
    assert res.converged and not res.within_limits
    np.testing.assert_allclose(res.q, q, atol=1e-8)


def test_coupled_limit_error(h4):
    """Arm stretched: θ2 − θ2' = 170° > 155°; no other branch reaches that far."""
    q = np.radians([0.0, -60.0, -230.0, 0.0, 30.0, 0.0])
    T = forward(h4, None, q).flange
    with pytest.raises(JointLimitError, match="2 − 2' =") as exc:
        inverse(h4, None, T, seed=q)
    assert exc.value.joint == "2 - 2'"


def test_identified_model_tool_and_nominal_closure(h4):
    """IK on a perturbed parameter set (model-based compensation) and at a TCP."""
    params = perturbed_params(h4, 34).replace(tool=translation([0.0, 0.1, 0.25]))
    q = random_configs(h4, 300, 35)
    for closure in ("fourbar", "nominal"):
        T = forward(h4, params, q, closure).tcp
        res = inverse(h4, params, T, q + 1e-3, target="tcp", closure=closure)
        assert res.converged.all()
        np.testing.assert_allclose(forward(h4, params, res.q, closure).tcp, T, atol=1e-9)


def test_angles_are_wrapped_near_the_seed(elbow):
    q = np.radians([170.0, -60.0, 30.0, 200.0, 50.0, -300.0])
    T = forward(elbow, None, q).flange
    np.testing.assert_allclose(inverse(elbow, None, T, seed=q).q, q, atol=1e-8)
    # a seed one turn away on joint 6 still returns the representative nearest the seed
    seed = q.copy()
    seed[5] += 2 * np.pi  # 60°, inside ±350°
    np.testing.assert_allclose(inverse(elbow, None, T, seed=seed).q[5], q[5] + 2 * np.pi, atol=1e-8)


def test_input_validation(h4):
    with pytest.raises(ValueError, match="4, 4"):
        inverse(h4, None, np.eye(3))
    with pytest.raises(ValueError, match="seed"):
        inverse(h4, None, np.eye(4), seed=np.zeros(5))
    with pytest.raises(ValueError, match="target"):
        inverse(h4, None, np.eye(4), target="wrist")


def test_orientation_only_targets_near_home(h4):
    """Small rotations about the home pose (what a tracker correction asks for)."""
    T0 = forward(h4, None, h4.home).flange
    rng = np.random.default_rng(36)
    T = np.broadcast_to(T0, (200, 4, 4)).copy()
    T[:, :3, :3] = so3_exp(rng.normal(0, 0.05, (200, 3))) @ T0[:3, :3]
    T[:, :3, 3] += rng.normal(0, 0.01, (200, 3))
    res = inverse(h4, None, T)
    assert res.converged.all()
    assert np.abs(res.q - h4.home).max() < 0.5
