"""Shared fixtures: a perturbed model 5 of the Smart H4 (``h4``: tests/conftest.py), a
calibrated twin (seeded)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
from compensation_testlib import perturbed_error_model

from plugcell.calibration.result import CalibrationResult
from plugcell.compensation import IdentifiedModel
from plugcell.kinematics import RobotDescription
from plugcell.sim.twin.calibrated import calibrate_twin
from plugcell.sim.twin.campaign import working_volume_joints
from plugcell.sim.twin.robot import RobotTwin
from plugcell.sim.twin.scenario import TwinScenario


@pytest.fixture(scope="session")
def model5(h4: RobotDescription) -> IdentifiedModel:
    return IdentifiedModel(perturbed_error_model(h4))


@pytest.fixture(scope="session")
def workspace_q(h4: RobotDescription) -> np.ndarray:
    """40 joint configurations whose nominal flange is in the working volume."""
    from plugcell.sim.twin.profile import TwinProfile

    return working_volume_joints(h4, TwinProfile.load("smart_h4"), 40,
                                 np.random.default_rng(7))


@dataclass
class Calibrated:
    scenario: TwinScenario
    result: CalibrationResult


@pytest.fixture(scope="session")
def calibrated() -> Calibrated:
    """The 36 kg twin (seed 3) calibrated with model 5 from 60 simulated poses."""
    sc = TwinScenario(seed=3, payload_kg=36.0)
    return Calibrated(sc, calibrate_twin(RobotTwin(sc), 60, joints_seed=4, tracker_seed=3))
