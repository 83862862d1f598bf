"""PDL positions ↔ homogeneous transforms.

A PDL POSITION is x, y, z in millimetres and Comau ZYZ Euler angles a, b, c in
degrees (thesis eq. A.4); plugcell's kinematics works in metres and radians with
4×4 transforms — the conversion is :mod:`plugcell.io.units` (the one units boundary);
this module adds the check a PDL position needs.  Used by the simulated controller (its
arm) and by the robot service (the joint increment of 8.3.2).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from plugcell.io.units import pose_from_robot, robot_from_pose

__all__ = ["pose_matrix", "pose_values"]


def pose_matrix(values: Sequence[float]) -> np.ndarray:
    """``(x, y, z, a, b, c)`` (mm, ZYZ degrees) → 4×4 transform in metres.

    ValueError if there are not six finite numbers.
    """
    v = np.asarray([float(x) for x in values], dtype=float)
    if v.shape != (6,) or not np.all(np.isfinite(v)):
        raise ValueError(f"a position needs 6 finite numbers x, y, z, a, b, c; got {list(values)}")
    return pose_from_robot(v, "zyz")


def pose_values(T: np.ndarray) -> tuple[float, float, float, float, float, float]:
    """4×4 transform in metres → ``(x, y, z, a, b, c)`` (mm, ZYZ degrees)."""
    x, y, z, a, b, c = (float(v) for v in robot_from_pose(T, "zyz"))
    return (x, y, z, a, b, c)
