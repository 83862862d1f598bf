"""Helpers of the vendor-joint-convention tests: the "hand-converted" twin of a coupled robot."""

from __future__ import annotations

import numpy as np

from plugcell.kinematics import RobotDescription


def hand_converted(desc: RobotDescription) -> RobotDescription:
    """What a user did before couplings existed: readings converted outside plugcell.

    The same DH rows with the coupling offsets folded into the links' ``theta``; the
    description's joint values are ``M · readings`` (limits: the box of those values,
    home: ``M · home``).  Forward kinematics of it at ``M · q`` equals that of
    ``desc`` at the readings ``q``.
    """
    d = desc.to_dict()
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
    return RobotDescription.from_dict(d)
