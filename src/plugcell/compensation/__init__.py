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

from plugcell.lazy import exports

#: Module → the public names it defines (imported on first use: :mod:`plugcell.lazy`).
_NAMES = {
    "errors": ("CompensationError", "CorrectionError", "SensorError"),
    "frames": ("MetrologyFrames", "RobotFrameSensor"),
    "model_based": ("CompensationResult", "compensate", "compensate_joints", "nominal_joints"),
    "pose_model": ("IdentifiedModel", "NominalModel", "PoseModel"),
    "program": ("filter_program", "frame_matrix", "target_poses"),
    "protocols": (
        "CartesianRobot", "JointRobot", "MovingRobot", "PoseSensor", "PoseStream",
        "PositionSensor", "Reading", "StreamReading",
    ),
    "sensor_based": (
        "CorrectionResult", "CorrectionSettings", "CorrectionStep", "correct_3dof", "correct_6dof",
    ),
    "settling": (
        "RestEstimate", "SettlingResult", "SettlingSettings", "SettlingStep", "bounded_step",
        "correct_while_settling", "estimate_rest_pose",
    ),
}
__getattr__, __dir__, __all__ = exports(__name__, _NAMES)
