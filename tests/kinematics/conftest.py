"""Fixtures of the kinematics tests (robots are loaded once per session)."""

from __future__ import annotations

import pytest

from plugcell.io.robots import load_robot
from plugcell.kinematics import RobotDescription


@pytest.fixture(scope="session")
def h4() -> RobotDescription:
    return load_robot("smart_h4")


@pytest.fixture(scope="session")
def elbow() -> RobotDescription:
    return load_robot("elbow6")
