"""Shared fixtures: PARAMS.json of a calibrated Smart H4 twin and of its nominal model."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from plugcell.calibration.identify import Calibrator
from plugcell.calibration.result import CalibrationResult
from plugcell.io.params import params_json
from plugcell.sim.twin.campaign import measure_poses, working_volume_joints
from plugcell.sim.twin.robot import RobotTwin
from plugcell.sim.twin.scenario import TwinScenario
from plugcell.sim.twin.tracker import LaserTracker


@pytest.fixture(scope="session")
def calibrated_result() -> CalibrationResult:
    """The 36 kg twin (seed 3) calibrated with model 5 from 60 simulated poses."""
    sc = TwinScenario(seed=3, payload_kg=36.0)
    robot = RobotTwin(sc)
    q = working_volume_joints(robot.description, robot.reveal_truth().profile, 60,
                              np.random.default_rng(4))
    ms, _ = measure_poses(robot, LaserTracker(seed=3), q)
    return Calibrator(robot.description, 5).fit(ms)


@pytest.fixture(scope="session")
def params_file(calibrated_result, tmp_path_factory) -> Path:
    p = tmp_path_factory.mktemp("params") / "params.json"
    p.write_text(params_json(calibrated_result))
    return p


@pytest.fixture(scope="session")
def nominal_result(calibrated_result) -> CalibrationResult:
    """The same result with every identified parameter zero: the controller's own model."""
    m = calibrated_result.model
    return replace(calibrated_result, model=m.with_values(np.zeros(len(m.space))))


@pytest.fixture(scope="session")
def nominal_params(nominal_result, tmp_path_factory) -> Path:
    p = tmp_path_factory.mktemp("params") / "nominal.json"
    p.write_text(params_json(nominal_result))
    return p
