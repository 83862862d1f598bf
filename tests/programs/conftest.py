"""Shared fixtures: PARAMS.json of a calibrated Smart H4 twin and of its nominal model."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from plugcell.calibration.result import CalibrationResult
from plugcell.io.params import params_json
from plugcell.sim.twin.calibrated import calibrate_twin
from plugcell.sim.twin.robot import RobotTwin
from plugcell.sim.twin.scenario import TwinScenario


@pytest.fixture(scope="session")
def calibrated_result() -> CalibrationResult:
    """The 36 kg twin (seed 3) calibrated with model 5 from 60 simulated poses."""
    twin = RobotTwin(TwinScenario(seed=3, payload_kg=36.0))
    return calibrate_twin(twin, 60, joints_seed=4, tracker_seed=3)


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
