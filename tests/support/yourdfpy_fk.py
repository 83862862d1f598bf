"""Forward kinematics of a URDF by yourdfpy — mimic joints included (pinocchio's URDF
reader takes a mimic joint for an independent one), for the loop-robot export tests."""

from __future__ import annotations

import io

import numpy as np


def yourdfpy_tip_poses(urdf_text: str, joint_names: tuple[str, ...], tip: str,
                       q: np.ndarray, root: str | None = None) -> np.ndarray:
    """``(N, 4, 4)`` poses of link ``tip`` in the root link for joint values ``q``.

    ``joint_names`` orders the columns of ``q`` (radians); they must be exactly the
    URDF's independent (non-mimic, non-fixed) joints, whose ``mimic`` joints follow
    them as ``multiplier · value + offset``.
    """
    import yourdfpy

    urdf = yourdfpy.URDF.load(io.BytesIO(urdf_text.encode("utf-8")), load_meshes=False,
                              build_collision_scene_graph=False, load_collision_meshes=False)
    names = list(urdf.actuated_joint_names)
    assert sorted(names) == sorted(joint_names), (names, joint_names)
    order = [names.index(n) for n in joint_names]
    frame = urdf.base_link if root is None else root
    out = np.empty((len(q), 4, 4))
    for k, row in enumerate(np.asarray(q, dtype=float)):
        cfg = np.zeros(len(names))
        cfg[order] = row
        urdf.update_cfg(cfg)
        out[k] = urdf.get_transform(tip, frame)
    return out
