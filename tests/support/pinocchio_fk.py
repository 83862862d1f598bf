"""Forward kinematics of a URDF by pinocchio — the independent reference of the import tests."""

from __future__ import annotations

import numpy as np


def pinocchio_tip_poses(urdf_text: str, joint_names: tuple[str, ...], tip: str,
                        q: np.ndarray) -> np.ndarray:
    """``(N, 4, 4)`` poses of frame ``tip`` for joint values ``q`` (N, n) in radians.

    ``joint_names`` orders the columns of ``q``; continuous joints (pinocchio's
    cos/sin pair) are handled.
    """
    import pinocchio as pin

    model = pin.buildModelFromXML(urdf_text)
    data = model.createData()
    fid = model.getFrameId(tip)
    assert fid < model.nframes, f"no frame {tip!r} in pinocchio's model"
    slots = []
    for name in joint_names:
        jid = model.getJointId(name)
        assert jid < model.njoints, f"no joint {name!r} in pinocchio's model"
        slots.append((model.joints[jid].idx_q, model.joints[jid].nq))
    out = np.empty((len(q), 4, 4))
    for k, row in enumerate(np.asarray(q, dtype=float)):
        qp = pin.neutral(model)
        for (i, nq), v in zip(slots, row, strict=True):
            if nq == 2:
                qp[i:i + 2] = (np.cos(v), np.sin(v))
            else:
                qp[i] = v
        pin.framesForwardKinematics(model, data, qp)
        out[k] = data.oMf[fid].homogeneous
    return out
