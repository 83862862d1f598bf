"""A twin calibrated from its own campaign: what the compensation, program and path tests
and benchmarks start from (thesis 8.2 on the twin)."""

from __future__ import annotations

import numpy as np

from plugcell.calibration.identify import Calibrator
from plugcell.calibration.result import CalibrationResult
from plugcell.sim.twin.campaign import measure_poses, working_volume_joints
from plugcell.sim.twin.robot import RobotTwin
from plugcell.sim.twin.tracker import LaserTracker


def calibrate_twin(twin: RobotTwin, poses: int, *, joints_seed: int, tracker_seed: int,
                   model: int | str = 5) -> CalibrationResult:
    """Identify ``model`` of ``twin`` from a campaign of its own.

    ``poses`` joint configurations drawn in the working volume
    (:func:`~plugcell.sim.twin.campaign.working_volume_joints`, seeded ``joints_seed``), each
    measured by a laser tracker (seed ``tracker_seed``) at the twin's payload
    (:func:`~plugcell.sim.twin.campaign.measure_poses`), fitted by
    :class:`~plugcell.calibration.identify.Calibrator`.

    Parameters
    ----------
    twin : RobotTwin
        The robot, its payload in its scenario.
    poses : int
        Poses of the campaign.
    joints_seed, tracker_seed : int
        Seeds of the configurations drawn and of the tracker's noise.
    model : int or str
        The error model (default 5: the Smart H4's with compliance and payload).

    Returns
    -------
    CalibrationResult
    """
    q = working_volume_joints(twin.description, twin.reveal_truth().profile, poses,
                              np.random.default_rng(joints_seed))
    measured, _ = measure_poses(twin, LaserTracker(seed=tracker_seed), q)
    return Calibrator(twin.description, model).fit(measured)
