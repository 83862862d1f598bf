"""Shared fixtures of the calibration tests."""

from __future__ import annotations

import pytest
from calibration_testlib import ur10_description
from coupling_testlib import mimic_elbow, sign_flipped_h4, wrist_gear_elbow

from plugcell.io.robots import load_robot
from plugcell.kinematics import RobotDescription


@pytest.fixture(scope="session")
def ur10() -> RobotDescription:
    return ur10_description()


@pytest.fixture(scope="session")
def h4_flipped(h4) -> RobotDescription:
    return sign_flipped_h4(h4)


@pytest.fixture(scope="session")
def elbow_gear() -> RobotDescription:
    return wrist_gear_elbow(load_robot("elbow6"))


@pytest.fixture(scope="session")
def elbow_mimic() -> RobotDescription:
    return mimic_elbow(load_robot("elbow6"))
