"""Program filtering: ZYZ/RPY targets, robot or user frame → compensated joints."""

from __future__ import annotations

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
