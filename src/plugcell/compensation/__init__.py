"""plugcell.compensation — the two-stage error compensation of thesis 6.5 (pure math).

1. **Model-based** (6.5.1, eqs. 4.11–4.12): the commanded joints for which the
   identified model predicts the desired tool pose, starting from the controller's
   nominal IK — :func:`compensate`, :func:`compensate_joints`, and program filtering
   (:func:`filter_program`: Cartesian targets in ZYZ/RPY, robot or user frame →
   compensated joint targets).
2. **Sensor-based** (6.5.2): the tracker-guided 6-DOF loop δθ = J⁻¹Δx
   (:func:`correct_6dof`) and the 3-DOF loop of relative moves (:func:`correct_3dof`)
   against small device protocols (:mod:`.protocols`), measurements brought into the
   robot base frame with the identified BASE and PROBE (:mod:`.frames`); and the same
   correction converging while the robot settles, from a streaming tracker
   (:func:`correct_while_settling`, :mod:`.settling`, issue 38 §3).

Targets are **tool-point poses in the robot base frame**; by default the tool point
is the T-MAC (the identified PROBE), as in thesis 8.3.  No I/O, no framework or
twin imports.  See docs/compensation.md.
"""

from plugcell.compensation.errors import CompensationError, CorrectionError, SensorError
from plugcell.compensation.frames import MetrologyFrames, RobotFrameSensor
from plugcell.compensation.model_based import (
    CompensationResult,
    compensate,
    compensate_joints,
    nominal_joints,
)
from plugcell.compensation.pose_model import IdentifiedModel, NominalModel, PoseModel
from plugcell.compensation.program import filter_program, frame_matrix, target_poses
from plugcell.compensation.protocols import (
    CartesianRobot,
    JointRobot,
    MovingRobot,
    PoseSensor,
    PoseStream,
    PositionSensor,
    Reading,
    StreamReading,
)
from plugcell.compensation.sensor_based import (
    CorrectionResult,
    CorrectionSettings,
    CorrectionStep,
    correct_3dof,
    correct_6dof,
)
from plugcell.compensation.settling import (
    RestEstimate,
    SettlingResult,
    SettlingSettings,
    SettlingStep,
    bounded_step,
    correct_while_settling,
    estimate_rest_pose,
)

__all__ = [
    "CartesianRobot",
    "CompensationError",
    "CompensationResult",
    "CorrectionError",
    "CorrectionResult",
    "CorrectionSettings",
    "CorrectionStep",
    "IdentifiedModel",
    "JointRobot",
    "MetrologyFrames",
    "MovingRobot",
    "NominalModel",
    "PoseModel",
    "PoseSensor",
    "PoseStream",
    "PositionSensor",
    "Reading",
    "RestEstimate",
    "RobotFrameSensor",
    "SensorError",
    "SettlingResult",
    "SettlingSettings",
    "SettlingStep",
    "StreamReading",
    "bounded_step",
    "compensate",
    "compensate_joints",
    "correct_3dof",
    "correct_6dof",
    "correct_while_settling",
    "estimate_rest_pose",
    "filter_program",
    "frame_matrix",
    "nominal_joints",
    "target_poses",
]
