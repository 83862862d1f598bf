"""δθ = J⁻¹Δx, the joint increment the CALC routine delegates to the robot service (8.3.2)."""

from __future__ import annotations

import numpy as np
import pytest

from plugcell.controller.poses import pose_matrix, pose_values
from plugcell.io.robots import load_robot
from plugcell.kinematics import forward
from plugcell.services.robot_increment import joint_increment

DESC = load_robot("smart_h4")
Q0 = np.degrees(DESC.home) + np.array([5.0, 10.0, 20.0, -15.0, -20.0, 30.0])


def tcp(q_deg: np.ndarray) -> tuple[float, ...]:
    return pose_values(forward(DESC, None, np.radians(q_deg), closure="nominal").tcp)


def test_the_increment_moves_the_measured_pose_onto_the_target() -> None:
    step = np.array([0.01, -0.02, 0.015, 0.03, -0.01, 0.02])  # degrees
    target, measured = tcp(Q0 + step), tcp(Q0)
    dq = joint_increment(DESC, Q0, target, measured)
    assert np.allclose(dq, step, atol=2e-5)  # first order: second-order terms ~ (5e-4 rad)²
    # a sensor-based correction loop converges: a few iterations, as in 8.3.2
    q, goal = Q0.copy(), np.array(tcp(Q0 + 50 * step))
    for _ in range(4):
        q = q + joint_increment(DESC, q, goal, tcp(q))
    err = pose_matrix(goal)[:3, 3] - pose_matrix(tcp(q))[:3, 3]
    assert np.linalg.norm(err) < 1e-9


def test_a_singular_or_bad_configuration_is_refused() -> None:
    wrist_flat = np.degrees(DESC.home).copy()
    wrist_flat[4] = 0.0  # θ5 = 0: axes 4 and 6 line up
    with pytest.raises(ValueError, match="singularity"):
        joint_increment(DESC, wrist_flat, tcp(wrist_flat), tcp(wrist_flat))
    with pytest.raises(ValueError, match="has 6 axes"):
        joint_increment(DESC, [0.0, 1.0], tcp(Q0), tcp(Q0))
    with pytest.raises(ValueError, match="6 finite numbers"):
        joint_increment(DESC, Q0, [1, 2, 3], tcp(Q0))
