"""Shared fixtures of the calibration tests."""

from __future__ import annotations

import pytest
from calibration_testlib import ur10_description

from plugcell.io.robots import load_robot
from plugcell.kinematics import RobotDescription


@pytest.fixture(scope="session")
def h4() -> RobotDescription:
    return load_robot("smart_h4")


@pytest.fixture(scope="session")
def ur10() -> RobotDescription:
    return ur10_description()
