"""Shared fixtures: the Smart H4, a perturbed model 5, a calibrated twin (seeded)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from plugcell.calibration.identify import Calibrator
from plugcell.calibration.model import ErrorModel
from plugcell.calibration.result import CalibrationResult
from plugcell.compensation import IdentifiedModel
from plugcell.io.robots import load_robot
from plugcell.kinematics import RobotDescription
from plugcell.twin.campaign import measure_poses, working_volume_joints
from plugcell.twin.robot import RobotTwin
from plugcell.twin.scenario import TwinScenario
from plugcell.twin.tracker import LaserTracker


@pytest.fixture(scope="session")
def h4() -> RobotDescription:
    return load_robot("smart_h4")


def perturbed_error_model(desc: RobotDescription, seed: int = 1, family: str = "loop",
                          payload: bool = True) -> ErrorModel:
    """Model 5 (or the serial family) with every parameter perturbed at a realistic size."""
    em = ErrorModel.create(desc, family, gravity=True, payload=payload, payload_ref_kg=36.0)
    rng = np.random.default_rng(seed)
    scale = np.array([5e-4 if p.unit == "m" else 5e-4 if p.kind in ("gravity", "payload")
                      else np.radians(0.05) for p in em.space])
    return em.with_values(scale * rng.standard_normal(len(em.space)))


@pytest.fixture(scope="session")
def model5(h4: RobotDescription) -> IdentifiedModel:
    return IdentifiedModel(perturbed_error_model(h4))


@pytest.fixture(scope="session")
def workspace_q(h4: RobotDescription) -> np.ndarray:
    """40 joint configurations whose nominal flange is in the working volume."""
    from plugcell.twin.scenario import TwinProfile

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
    robot = RobotTwin(sc)
    q = working_volume_joints(robot.description, robot.reveal_truth().profile, 60,
                              np.random.default_rng(4))
    ms, _ = measure_poses(robot, LaserTracker(seed=3), q)
    return Calibrated(sc, Calibrator(robot.description, 5).fit(ms))
