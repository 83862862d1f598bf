"""PDL positions ↔ homogeneous transforms.

A PDL POSITION is x, y, z in millimetres and Comau ZYZ Euler angles a, b, c in
degrees (thesis eq. A.4); plugcell's kinematics works in metres and radians with
4×4 transforms.  Used by the simulated controller (its arm) and by the robot
service (the joint increment of 8.3.2).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from plugcell.kinematics import matrix_to_pose, pose_to_matrix

__all__ = ["pose_matrix", "pose_values"]


def pose_matrix(values: Sequence[float]) -> np.ndarray:
    """``(x, y, z, a, b, c)`` (mm, ZYZ degrees) → 4×4 transform in metres.

    ValueError if there are not six finite numbers.
    """
    v = np.asarray([float(x) for x in values], dtype=float)
    if v.shape != (6,) or not np.all(np.isfinite(v)):
        raise ValueError(f"a position needs 6 finite numbers x, y, z, a, b, c; got {list(values)}")
    return pose_to_matrix(v[:3] / 1000.0, np.radians(v[3:]), "zyz")


def pose_values(T: np.ndarray) -> tuple[float, float, float, float, float, float]:
    """4×4 transform in metres → ``(x, y, z, a, b, c)`` (mm, ZYZ degrees)."""
    xyz, angles = matrix_to_pose(np.asarray(T, dtype=float), "zyz")
    x, y, z = (float(c) * 1000.0 for c in xyz)
    a, b, c = (float(d) for d in np.degrees(angles))
    return (x, y, z, a, b, c)
