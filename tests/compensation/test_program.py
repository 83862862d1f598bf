"""Program filtering: ZYZ/RPY targets, robot or user frame → compensated joints."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from plugcell.compensation import filter_program, frame_matrix, target_poses
from plugcell.compensation.program import joint_program, pose_angles
from plugcell.kinematics.pose_error import pose_error_exact
from plugcell.kinematics.rotations import matrix_to_angles
from plugcell.kinematics.transforms import invert


@pytest.fixture()
def program(model5, workspace_q):
    """Eight targets (robot frame): the model's own poses moved by a few mm."""
    T = model5.pose(workspace_q[:8], 36.0)
    T[:, :3, 3] += np.random.default_rng(21).normal(0, 2e-3, (8, 3))
    return T


@pytest.mark.parametrize("convention", ["zyz", "rpy"])
def test_targets_in_either_convention_reach_the_same_joints(model5, program, convention):
    p = program[:, :3, 3]
    a = matrix_to_angles(program[:, :3, :3], convention)
    res = filter_program(model5, p, a, convention, payload_kg=36.0)
    assert res.ok.all()
    e = pose_error_exact(program, model5.pose(res.q, 36.0))
    assert np.linalg.norm(e, axis=1).max() < 1e-6
    np.testing.assert_allclose(pose_angles(target_poses(p, a, convention), convention), a,
                               atol=1e-12)


def test_user_frame_targets(model5, program):
    U = frame_matrix([1.2, -0.3, 0.5], np.radians([30.0, 10.0, -5.0]), "zyz")
    local = invert(U) @ program  # the same targets written in the user frame
    p, a = local[:, :3, 3], matrix_to_angles(local[:, :3, :3], "zyz")
    res = filter_program(model5, p, a, "zyz", user_frame=U, payload_kg=36.0)
    direct = filter_program(model5, program[:, :3, 3],
                            matrix_to_angles(program[:, :3, :3], "zyz"), payload_kg=36.0)
    np.testing.assert_allclose(res.q, direct.q, atol=1e-9)
    np.testing.assert_allclose(joint_program(res), np.degrees(res.q))


def test_target_validation():
    with pytest.raises(ValueError):
        target_poses(np.zeros((2, 3)), np.zeros((3, 3)))
    with pytest.raises(ValueError):
        target_poses([[0, 0, math.nan]], [[0, 0, 0]])
    with pytest.raises(ValueError):
        target_poses(np.zeros((1, 3)), np.zeros((1, 3)), "abc")
    with pytest.raises(ValueError):
        frame_matrix([0, 0], [0, 0, 0])


def test_joint_program_converts_only_revolute_joints():
    """A prismatic joint's reading stays in metres; the revolute ones go to degrees."""
    from plugcell.compensation.model_based import CompensationResult
    from plugcell.kinematics import Link, RobotDescription

    desc = RobotDescription(
        name="track_arm",
        links=(Link("track", "base", "prismatic", 0.0, 0.0, 0.0, 0.0),
               Link("j1", "track", "actuated", 0.0, 0.1, 0.3, 0.0)),
        actuated=("track", "j1"), flange="j1", loops=(), base=np.eye(4), tool=np.eye(4),
        joint_limits=[[0.0, 3.0], [-3.0, 3.0]], home=[1.0, 0.0],
    )
    q = np.array([[2.5, math.pi / 2], [0.5, -math.pi / 4]])
    n = len(q)
    res = CompensationResult(
        q=q, q_start=q.copy(), converged=np.ones(n, bool), within_limits=np.ones(n, bool),
        iterations=np.ones(n, int), residual=np.zeros(n), position_error=np.zeros(n),
        orientation_error=np.zeros(n), reason=np.full(n, "", object),
        kind=np.full(n, "", object))
    np.testing.assert_allclose(joint_program(res, desc), [[2.5, 90.0], [0.5, -45.0]])
    np.testing.assert_allclose(joint_program(res, desc, degrees=False), q)
    assert joint_program(res, desc, degrees=False) is not res.q
    with pytest.raises(ValueError, match="2 joint readings"):
        joint_program(dataclasses.replace(res, q=q[:, :1]), desc)
