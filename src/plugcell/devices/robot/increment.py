"""The corrective joint increment δθ = J⁻¹·Δx of the sensor-based correction (thesis 8.3.2).

"Since it is not possible to calculate the inverse Jacobian matrix (section 6.5.2)
in the PDL language, this routine [CALC] actually delegates the work to the robot
service and retrieves the result."  The robot program sends the target and the
measured pose (PDL POSITIONs of the TCP in the robot base frame: mm, Comau ZYZ
degrees); the service takes the first-order pose error Δx = [p_t − p_m;
vee(R_t·R_mᵀ − …)] (:func:`plugcell.kinematics.pose_error`, base frame), the
manipulator Jacobian of the *nominal* model at the current joint readings
(through the parallelogram, eqs. 6.37, 6.39) and solves J·δθ = Δx.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from plugcell.devices.robot.poses import pose_matrix
from plugcell.kinematics import RobotDescription, manipulator_jacobian, pose_error

__all__ = ["MAX_CONDITION", "joint_increment", "pose_error_sizes"]

#: Beyond this condition number of J the arm is at a singularity: no increment.
MAX_CONDITION = 1e8


def joint_increment(
    description: RobotDescription,
    joints_deg: Sequence[float],
    target: Sequence[float],
    measured: Sequence[float],
) -> np.ndarray:
    """δθ (degrees, one per axis) moving the TCP from ``measured`` to ``target``.

    ValueError (with the reason) for bad input or a singular configuration.
    """
    q = np.radians(np.asarray([float(v) for v in joints_deg], dtype=float))
    n = description.n_readings
    if q.shape != (n,) or not np.all(np.isfinite(q)):
        raise ValueError(f"{description.name} has {n} axes; got joints {list(joints_deg)}")
    dx = pose_error(pose_matrix(target), pose_matrix(measured))
    J = manipulator_jacobian(description, None, q, point="tcp", closure="nominal")
    condition = float(np.linalg.cond(J))
    if not np.isfinite(condition) or condition > MAX_CONDITION:
        raise ValueError(f"the arm is at a singularity (condition number of J {condition:.3g})")
    if J.shape[0] == J.shape[1]:
        dq = np.linalg.solve(J, dx)
    else:  # not 6 axes: least squares (minimum norm)
        dq = np.linalg.lstsq(J, dx, rcond=None)[0]
    return np.degrees(dq)


def pose_error_sizes(target: Sequence[float], measured: Sequence[float]) -> tuple[float, float]:
    """‖position error‖ (mm) and rotation angle between the poses (°): the tolerance
    test of SENSOR_COM (8.3.2: 0.08 mm, 0.05°), which PDL cannot do on Euler angles
    near their wrap-around."""
    T_t, T_m = pose_matrix(target), pose_matrix(measured)
    position_mm = float(np.linalg.norm(T_t[:3, 3] - T_m[:3, 3])) * 1e3
    R = T_t[:3, :3] @ T_m[:3, :3].T
    angle = float(np.degrees(np.arccos(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0))))
    return position_mm, angle
