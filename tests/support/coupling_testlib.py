"""Helpers of the vendor-joint-convention tests: the "hand-converted" twin of a coupled robot."""

from __future__ import annotations

import math

import numpy as np

from plugcell.io.robot_schema import description_from_dict, description_to_dict
from plugcell.kinematics import RobotDescription


def hand_converted(desc: RobotDescription) -> RobotDescription:
    """What a user did before couplings existed: readings converted outside plugcell.

    The same DH rows with the coupling offsets folded into the links' ``theta``; the
    description's joint values are ``M · readings`` (limits: the box of those values,
    home: ``M · home``).  Forward kinematics of it at ``M · q`` equals that of
    ``desc`` at the readings ``q``.
    """
    d = description_to_dict(desc)
    c = d.pop("coupling")
    M = np.array(c["matrix"])
    lo, hi = np.radians(np.array(c["limits"])).T
    klo = np.degrees(np.minimum(M * lo, M * hi).sum(axis=1))
    khi = np.degrees(np.maximum(M * lo, M * hi).sum(axis=1))
    act = {n: k for k, n in enumerate(d["actuated"])}
    for lk in d["links"]:
        if lk["name"] in act:
            k = act[lk["name"]]
            lk["theta"] += c["offsets"][k]
            lk["limits"] = [float(klo[k]), float(khi[k])]
    d["home"] = [float(x) for x in np.degrees(M @ np.radians(d["home"]))]
    d["coupled_limits"] = []
    return description_from_dict(d)


def sign_flipped_h4(h4: RobotDescription) -> RobotDescription:
    """Smart H4 whose controller counts axes 4 and 6 backwards and axis 1 from 10°
    (readings A1..A6): a loop robot with a coupling."""
    d = description_to_dict(h4)
    lims = [lk.pop("limits") for lk in d["links"] if lk["joint"] == "actuated"]
    M = np.diag([1.0, 1.0, 1.0, -1.0, 1.0, -1.0])
    lims[0] = [lims[0][0] + 10.0, lims[0][1] + 10.0]
    lims[3] = [-lims[3][1], -lims[3][0]]
    lims[5] = [-lims[5][1], -lims[5][0]]
    d["coupling"] = {"readings": ["A1", "A2", "A3", "A4", "A5", "A6"], "matrix": M.tolist(),
                     "offsets": [-10.0, 0, 0, 0, 0, 0], "limits": lims}
    d["home"] = list(np.array(d["home"]) * np.diag(M) + [10.0, 0, 0, 0, 0, 0])
    for cl in d["coupled_limits"]:
        cl["joints"] = ["A2", "A3"]
    return description_from_dict(d)


def wrist_gear_elbow(elbow: RobotDescription) -> RobotDescription:
    """elbow6 with a gear-coupled wrist and vendor zero offsets (readings A1..A6):
    θ5 = A5 + 0.37·A4 + 5°, θ6 = A6 − 0.21·A4 + 0.5·A5 − 6°."""
    d = description_to_dict(elbow)
    lims = [lk.pop("limits") for lk in d["links"]]
    gear = np.eye(6)
    gear[4, 3], gear[5, 3], gear[5, 4] = 0.37, -0.21, 0.5
    d["coupling"] = {"readings": [f"A{i}" for i in range(1, 7)], "matrix": gear.tolist(),
                     "offsets": [1.0, -2.0, 3.0, 0.0, 5.0, -6.0], "limits": lims}
    return description_from_dict(d)


def mimic_elbow(elbow: RobotDescription) -> RobotDescription:
    """elbow6 with five readings R1, R2, R4, R5, R6: joint 3 mimics R2 (θ3 = −0.8·R2 +
    0.1 rad), the way an imported URDF ``mimic`` joint becomes an extra coupling row."""
    d = description_to_dict(elbow)
    lims = [lk.pop("limits") for lk in d["links"]]
    mimic = np.zeros((6, 5))
    for r, c in ((0, 0), (1, 1), (3, 2), (4, 3), (5, 4)):
        mimic[r, c] = 1.0
    mimic[2, 1] = -0.8
    d["coupling"] = {"readings": ["R1", "R2", "R4", "R5", "R6"], "matrix": mimic.tolist(),
                     "offsets": [0.0, 0.0, math.degrees(0.1), 0.0, 0.0, 0.0],
                     "limits": [lims[i] for i in (0, 1, 3, 4, 5)]}
    d["home"] = [d["home"][i] for i in (0, 1, 3, 4, 5)]
    return description_from_dict(d)
