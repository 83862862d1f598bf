"""Helpers shared by the calibration tests (importable: the test directory is on sys.path)."""

from __future__ import annotations

import numpy as np

from plugcell.kinematics import RobotDescription
from plugcell.kinematics.transforms import so3_exp


def ur10_description() -> RobotDescription:
    """A plain 6R robot without a loop: the UR10's nominal DH (issue 3), with masses."""
    a = [0.0, -0.612, -0.5723, 0.0, 0.0, 0.0]
    d = [0.1273, 0.0, 0.0, 0.163941, 0.1157, 0.0922]
    alpha = [90.0, 0.0, 0.0, 90.0, -90.0, 0.0]
    mass = [7.1, 12.7, 4.3, 2.0, 2.0, 0.4]
    com = [[0, -0.02, 0], [0.3, 0, 0.15], [0.25, 0, 0.03], [0, 0, 0], [0, 0, 0], [0, 0, -0.02]]
    links = []
    for i in range(6):
        links.append({
            "name": str(i + 1), "parent": "base" if i == 0 else str(i), "joint": "actuated",
            "d": d[i], "a": a[i], "alpha": alpha[i], "limits": [-360.0, 360.0],
            "mass": mass[i], "com": com[i],
        })
    return RobotDescription.from_dict({
        "name": "ur10-test", "actuated": [str(i + 1) for i in range(6)], "flange": "6",
        "links": links, "home": [0.0, -90.0, 90.0, 0.0, 90.0, 0.0],
    })



def random_frame(rng: np.random.Generator, angle: float = 1.0, dist: float = 1.0) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = so3_exp(rng.normal(size=3) * angle)
    T[:3, 3] = rng.normal(size=3) * dist
    return T
