"""Helpers of the motion tests."""

from __future__ import annotations

import numpy as np

from plugcell.kinematics import RobotDescription, forward, so3_exp


def tcp(desc: RobotDescription, q: np.ndarray) -> np.ndarray:
    """TCP pose(s) by the controller's model (nominal closure)."""
    return forward(desc, None, q, "nominal").tcp


def moved(T: np.ndarray, dp: list[float], axis: list[float] | None = None,
          angle: float = 0.0) -> np.ndarray:
    """``T`` translated by ``dp`` (m, base frame) and turned by ``angle`` about ``axis``
    (base frame, through the TCP)."""
    out = np.array(T, dtype=float)
    out[:3, 3] += dp
    if axis is not None:
        k = np.asarray(axis, float) / np.linalg.norm(axis)
        out[:3, :3] = so3_exp(k * angle) @ out[:3, :3]
    return out
