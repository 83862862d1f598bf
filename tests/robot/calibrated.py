"""A calibration to compensate with: the 36 kg twin (seed 3) identified with model 5 from
60 simulated poses, and its PARAMS.json."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from plugcell.calibration.identify import Calibrator
from plugcell.calibration.result import CalibrationResult
from plugcell.io.params import params_json
from plugcell.sim.twin.campaign import measure_poses, working_volume_joints
from plugcell.sim.twin.robot import RobotTwin
from plugcell.sim.twin.scenario import TwinScenario
from plugcell.sim.twin.tracker import LaserTracker


def calibrated(folder: Path) -> tuple[CalibrationResult, Path]:
    """The calibration and its PARAMS.json written into ``folder``."""
    robot = RobotTwin(TwinScenario(seed=3, payload_kg=36.0))
    q = working_volume_joints(robot.description, robot.reveal_truth().profile, 60,
                              np.random.default_rng(4))
    ms, _ = measure_poses(robot, LaserTracker(seed=3), q)
    result = Calibrator(robot.description, 5).fit(ms)
    path = folder / "params.json"
    path.write_text(params_json(result))
    return result, path
