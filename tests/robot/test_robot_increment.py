"""δθ = J⁻¹Δx, the joint increment the CALC routine delegates to the robot service (8.3.2)."""

from __future__ import annotations

import numpy as np
import pytest

from plugcell.devices.robot.increment import joint_increment, pose_error_sizes
from plugcell.devices.robot.poses import pose_matrix, pose_values
from plugcell.io.robots import load_robot
from plugcell.kinematics import forward

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


def test_pose_error_sizes_are_in_millimetres_and_degrees() -> None:
    """SENSOR_COM's tolerance test (0.08 mm, 0.05°) reads these numbers."""
    target = (1500.0, 0.0, 1200.0, 10.0, 120.0, -30.0)
    measured = (1500.03, -0.04, 1200.0, 10.0, 120.0, -30.0)  # 0.05 mm off, same rotation
    mm, deg = pose_error_sizes(target, measured)
    assert mm == pytest.approx(0.05, abs=1e-9) and deg == pytest.approx(0.0, abs=1e-6)
    R = pose_matrix(target)[:3, :3]
    turned = np.eye(4)
    turned[:3, :3] = R @ np.array([[np.cos(1e-3), -np.sin(1e-3), 0], [np.sin(1e-3),
                                                                     np.cos(1e-3), 0], [0, 0, 1]])
    turned[:3, 3] = pose_matrix(target)[:3, 3]
    mm, deg = pose_error_sizes(target, pose_values(turned))
    assert mm == pytest.approx(0.0, abs=1e-6) and deg == pytest.approx(np.degrees(1e-3), rel=1e-6)
    # near the Euler wrap-around: a = 179.99° and a = -179.99° are 0.02° apart, not 359.98°
    a, b = (0.0, 0.0, 0.0, 179.99, 90.0, 0.0), (0.0, 0.0, 0.0, -179.99, 90.0, 0.0)
    assert pose_error_sizes(a, b)[1] == pytest.approx(0.02, abs=1e-6)
