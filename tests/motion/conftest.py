"""Fixtures of the motion tests: the robots, limits of a 200 kg-class arm, helpers."""

from __future__ import annotations

import numpy as np
import pytest

from plugcell.io.robots import load_robot
from plugcell.kinematics import RobotDescription, forward
from plugcell.motion import CartesianLimits, JointLimits


@pytest.fixture(scope="session")
def h4() -> RobotDescription:
    return load_robot("smart_h4")


@pytest.fixture(scope="session")
def elbow() -> RobotDescription:
    return load_robot("elbow6")


@pytest.fixture(scope="session")
def jl() -> JointLimits:
    return JointLimits(np.radians([120, 115, 120, 190, 180, 260]),
                       np.radians([400, 350, 400, 600, 600, 800]),
                       np.radians([3000, 2500, 3000, 5000, 5000, 7000]))


@pytest.fixture(scope="session")
def cl() -> CartesianLimits:
    return CartesianLimits(1.0, 4.0, 40.0, 2.0, 8.0, 80.0)


def tcp(desc: RobotDescription, q: np.ndarray) -> np.ndarray:
    """TCP pose(s) by the controller's model (nominal closure)."""
    return forward(desc, None, q, "nominal").tcp


def moved(T: np.ndarray, dp: list[float], axis: list[float] | None = None,
          angle: float = 0.0) -> np.ndarray:
    """``T`` translated by ``dp`` (m, base frame) and turned by ``angle`` about ``axis``
    (base frame, through the TCP)."""
    from plugcell.kinematics import so3_exp

    out = np.array(T, dtype=float)
    out[:3, 3] += dp
    if axis is not None:
        k = np.asarray(axis, float) / np.linalg.norm(axis)
        out[:3, :3] = so3_exp(k * angle) @ out[:3, :3]
    return out
