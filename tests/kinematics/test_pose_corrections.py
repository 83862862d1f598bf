"""KUKA RSI's Cartesian corrections (RKorr) as poses: applied, recovered and taken off
(round trips, hypothesis), and the correction of a joint step checked against the
manipulator Jacobian by central finite differences (issue 37, mode (b))."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from plugcell.io.robots import load_robot
from plugcell.kinematics import forward
from plugcell.kinematics.jacobian import manipulator_jacobian
from plugcell.kinematics.pose_corrections import (
    correct_pose,
    pose_correction,
    uncorrect_pose,
)
from plugcell.kinematics.rotations import rpy_to_matrix

_angle = st.floats(-3.1, 3.1)
_pitch = st.floats(-1.5, 1.5)
_mm = st.floats(-2.0, 2.0)
FRAMES = st.sampled_from(["base", "tool"])


def _pose(x, y, z, a, b, c) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = rpy_to_matrix(c, b, a)
    T[:3, 3] = [x, y, z]
    return T


_poses = st.builds(_pose, _mm, _mm, _mm, _angle, _pitch, _angle)
_corrections = st.tuples(_mm, _mm, _mm, _angle, _pitch, _angle).map(np.array)


@settings(max_examples=300, deadline=None)
@given(_poses, _corrections, FRAMES)
def test_a_correction_applied_is_recovered_and_taken_off(T_path, o, frame):
    T_c = correct_pose(T_path, o, frame)
    np.testing.assert_allclose(pose_correction(T_path, T_c, frame), o, atol=1e-9)
    np.testing.assert_allclose(uncorrect_pose(T_c, o, frame), T_path, atol=1e-9)


@settings(max_examples=300, deadline=None)
@given(_poses, _poses, FRAMES)
def test_the_correction_between_two_poses_takes_one_to_the_other(T_path, T_c, frame):
    np.testing.assert_allclose(correct_pose(T_path, pose_correction(T_path, T_c, frame), frame),
                               T_c, atol=1e-9)


def test_the_frames_differ_as_kukas_do():
    """Base: along the base frame's axes, the rotation about them; tool: along the TCP's."""
    T = _pose(1.0, 0.5, 1.2, 0.0, 0.0, np.pi / 2)  # the tool's y is the base's z
    o = np.array([0.0, 1e-3, 0.0, 0.0, 0.0, 0.0])
    np.testing.assert_allclose(correct_pose(T, o, "base")[:3, 3] - T[:3, 3], [0, 1e-3, 0],
                               atol=1e-15)
    np.testing.assert_allclose(correct_pose(T, o, "tool")[:3, 3] - T[:3, 3], [0, 0, 1e-3],
                               atol=1e-15)
    A = np.array([0, 0, 0, 0.1, 0, 0])  # A: about z (base's, or the tool's)
    np.testing.assert_allclose(correct_pose(T, A, "base")[:3, :3],
                               rpy_to_matrix(0, 0, 0.1) @ T[:3, :3], atol=1e-15)
    np.testing.assert_allclose(correct_pose(T, A, "tool")[:3, :3],
                               T[:3, :3] @ rpy_to_matrix(0, 0, 0.1), atol=1e-15)
    with pytest.raises(ValueError, match="unknown correction frame 'world': one of base, tool"):
        correct_pose(T, A, "world")


@pytest.mark.parametrize("frame", ["base", "tool"])
def test_the_correction_of_a_joint_step_is_the_jacobian_to_first_order(frame):
    """d o / d δθ at 0 by central differences = [J_v; P J_ω] (base) or
    [Rᵀ J_v; P Rᵀ J_ω] (tool), P the swap of x and z (A, B, C about z, y, x)."""
    desc = load_robot("smart_h4")
    q = np.radians([-15.0, -75.0, -190.0, 10.0, 75.0, 20.0])
    T = forward(desc, None, q, "nominal").tcp
    J = manipulator_jacobian(desc, None, q, "tcp", "nominal")
    R = np.eye(3) if frame == "base" else T[:3, :3].T
    P = np.eye(3)[::-1]
    want = np.vstack([R @ J[:3], P @ R @ J[3:]])
    h = 1e-6
    fd = np.empty((6, 6))
    for i in range(6):
        d = np.zeros(6)
        d[i] = h
        plus = pose_correction(T, forward(desc, None, q + d, "nominal").tcp, frame)
        minus = pose_correction(T, forward(desc, None, q - d, "nominal").tcp, frame)
        fd[:, i] = (plus - minus) / (2 * h)
    np.testing.assert_allclose(fd, want, atol=1e-6)
