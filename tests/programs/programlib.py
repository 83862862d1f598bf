"""Helpers of the robot-program tests: models from PARAMS results, reachable poses."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from plugcell.compensation import IdentifiedModel, NominalModel
from plugcell.io.robots import load_robot
from plugcell.io.units import notation_from_pose, pose_from_notation
from plugcell.sim.twin.campaign import working_volume_joints
from plugcell.sim.twin.profile import TwinProfile

FIXTURES = Path(__file__).parent / "fixtures"
H4 = load_robot("smart_h4")
#: 40 joint configurations in the working volume (seeded)
WORK_Q = working_volume_joints(H4, TwinProfile.load("smart_h4"), 40, np.random.default_rng(7))


def model_for(result):
    """``TOOL → IdentifiedModel`` of a calibration result (the command's factory)."""
    return lambda tool: IdentifiedModel(result.model, tool)


def poses_in(notation: str, base_values, tool_values, k: np.ndarray) -> np.ndarray:
    """Reachable target numbers in ``notation``: the nominal TCP at ``WORK_Q[k]``
    with the tool, expressed in the base frame."""
    B = pose_from_notation(np.asarray(base_values, float), notation)
    tool = pose_from_notation(np.asarray(tool_values, float), notation)
    T = np.linalg.inv(B) @ NominalModel(H4, tool).pose(WORK_Q[k])
    ref = np.zeros((len(k), 7 if notation == "abb" else 6))
    if notation == "abb":
        ref[:, 3] = 1.0
    return notation_from_pose(T, notation, ref)
