"""Manipulator Jacobian of the actuated joints, thesis eqs. (6.37) and (6.39).

For every revolute joint i on the chain to the flange (actuated or passive) the
geometric column at point p is (Spong 5.1.27, thesis 6.37)::

    J_i = [ z_{i−1} × (p − p_{i−1}) ;  z_{i−1} ]

with z_{i−1}, p_{i−1} the axis and origin of the parent frame (the DH θ rotates
about the parent's z, also for Hayati links) in the robot base frame; a prismatic
joint (its reading moves d along z_{i−1}) has the column ``[z_{i−1}; 0]``.  Passive
joints are driven through the loop closure, so the column of actuated joint j is

    K_j = J_j [if j is on the chain] + Σ_passive (∂θ_passive/∂q_j) · J_passive.

With the nominal closure (6.16) ∂θ3'/∂(θ2, θ2') = (1, −1) and
∂θ4'/∂(θ2, θ2') = (−1, 1), which gives exactly eq. (6.39) with its primes
restored: K_2 = K_3' − K_4' and K_2' = K_2' − K_3' + K_4'.  With the exact
four-bar closure the derivatives come from the implicit-function theorem.

A description with a joint ``coupling`` (θ_kin = M·q + offset) has its readings
q as joint variables: by the chain rule the columns w.r.t. the readings are
``J_q = J_θkin · M`` (:func:`kinematic_jacobian_from_fk` gives ``J_θkin``).

Sign/convention: the columns are the derivative of
``pose_error(T(q + dq), T(q))`` (see :mod:`plugcell.kinematics.pose_error`),
i.e. linear velocity of the point and angular velocity, both in the base frame.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from plugcell.kinematics.description import RobotDescription
from plugcell.kinematics.forward import FKResult, forward
from plugcell.kinematics.parameters import GeometricParameters
from plugcell.kinematics.transforms import cross

Array = NDArray[np.float64]

__all__ = ["jacobian_from_fk", "kinematic_jacobian_from_fk", "manipulator_jacobian"]


def jacobian_from_fk(desc: RobotDescription, fk: FKResult, point: str = "flange") -> Array:
    """Manipulator Jacobian w.r.t. the joint readings, from an :class:`FKResult`.

    ``J_q = J_θkin · M`` with ``M`` the coupling matrix (``desc.coupling.matrix``;
    without a coupling ``J_q = J_θkin``), ``J_θkin`` from
    :func:`kinematic_jacobian_from_fk` (eqs. 6.37, 6.39).

    Parameters
    ----------
    desc : RobotDescription
        The robot ``fk`` was computed for.
    fk : FKResult
        Forward kinematics at the configurations of interest.
    point : {"flange", "tcp"}
        The point whose velocity the rows 0–2 give.

    Returns
    -------
    J : (..., 6, n_readings) array
        Rows 0–2: linear velocity of the point (m per rad of reading; m/m for a
        prismatic reading); rows 3–5: angular velocity (rad/rad), base frame.

    Raises
    ------
    ValueError
        Unknown ``point``.
    """
    J = kinematic_jacobian_from_fk(desc, fk, point)
    if desc.coupling is None:
        return J
    return J @ desc.coupling.matrix


def kinematic_jacobian_from_fk(
    desc: RobotDescription, fk: FKResult, point: str = "flange"
) -> Array:
    """Manipulator Jacobian w.r.t. the kinematic joints θ_kin, eqs. (6.37), (6.39).

    Column of actuated joint j::

        K_j = J_j [if j is on the chain] + Σ_passive (∂θ_passive/∂θ_kin,j) · J_passive
        J_i = [z_{i−1} × (p − p_{i−1}); z_{i−1}]   (revolute),   [z_{i−1}; 0]  (prismatic)

    with ``z_{i−1}``, ``p_{i−1}`` the axis and origin of the parent frame in the robot
    base frame and ``p`` the point (module docstring).

    Parameters
    ----------
    desc : RobotDescription
        The robot ``fk`` was computed for.
    fk : FKResult
        Forward kinematics (its ``passive_jacobian`` supplies ∂θ_passive/∂θ_kin).
    point : {"flange", "tcp"}
        The point ``p``.

    Returns
    -------
    J : (..., 6, n_actuated) array
        Linear (m/rad) over angular (rad/rad) velocity rows, base frame.

    Raises
    ------
    ValueError
        Unknown ``point``.
    """
    if point == "flange":
        p = fk.flange[..., :3, 3]
    elif point == "tcp":
        p = fk.tcp[..., :3, 3]
    else:
        raise ValueError(f"point must be 'flange' or 'tcp', got {point!r}")
    batch = fk.frames.shape[:-3]
    if math.prod(batch) == 1:
        return _kinematic_jacobian_one(desc, fk, p).reshape(*batch, 6, desc.n_actuated)
    J = np.zeros((*batch, 6, desc.n_actuated))
    passive_pos = {name: k for k, name in enumerate(fk.passive_names)}
    act_pos = {name: j for j, name in enumerate(desc.actuated)}
    for i in desc.chain:
        lk = desc.links[i]
        if lk.is_fixed:
            continue
        if lk.parent == "base":
            z = np.broadcast_to(np.array([0.0, 0.0, 1.0]), (*batch, 3))
            o = np.zeros((*batch, 3))
        else:
            Tp = fk.frames[..., desc.index(lk.parent), :, :]
            z = Tp[..., :3, 2]
            o = Tp[..., :3, 3]
        if lk.is_prismatic:  # d moves along the parent's z: [z; 0]
            col = np.concatenate([z, np.zeros_like(z)], axis=-1)
        else:
            col = np.concatenate([cross(z, p - o), z], axis=-1)  # (..., 6)
        if lk.is_actuated:
            J[..., :, act_pos[lk.name]] += col
        else:
            dq = fk.passive_jacobian[..., passive_pos[lk.name], :]  # (..., n)
            J += col[..., :, None] * dq[..., None, :]
    return J


def _kinematic_jacobian_one(desc: RobotDescription, fk: FKResult, p: Array) -> Array:
    """:func:`kinematic_jacobian_from_fk` of one configuration on floats, ``(6,
    n_actuated)``: the same columns ``[z × (p − o); z]`` (``[z; 0]`` prismatic), added in
    the same order, so the same Jacobian — without numpy's per-call cost, which is most
    of it for one configuration (a real-time cycle's Newton steps ask for one)."""
    n_a = desc.n_actuated
    frames = fk.frames.reshape(-1, 4, 4).tolist()
    px, py, pz = p.reshape(3).tolist()
    dq = fk.passive_jacobian.reshape(-1, n_a).tolist()
    passive_pos = {name: k for k, name in enumerate(fk.passive_names)}
    J = [[0.0] * n_a for _ in range(6)]
    for i in desc.chain:
        lk = desc.links[i]
        if lk.is_fixed:
            continue
        parent = desc.parent_indices[i]
        if parent < 0:
            zx, zy, zz, ox, oy, oz = 0.0, 0.0, 1.0, 0.0, 0.0, 0.0
        else:
            (r0, r1, r2, _) = frames[parent]
            zx, zy, zz, ox, oy, oz = r0[2], r1[2], r2[2], r0[3], r1[3], r2[3]
        if lk.is_prismatic:
            col = (zx, zy, zz, 0.0, 0.0, 0.0)
        else:
            dx, dy, dz = px - ox, py - oy, pz - oz
            col = (zy * dz - zz * dy, zz * dx - zx * dz, zx * dy - zy * dx, zx, zy, zz)
        if lk.is_actuated:
            j = desc.actuated_index(lk.name)
            for r in range(6):
                J[r][j] += col[r]
        else:
            row = dq[passive_pos[lk.name]]
            for r in range(6):
                Jr, c = J[r], col[r]
                for m in range(n_a):
                    Jr[m] += c * row[m]
    return np.array(J)


def manipulator_jacobian(
    desc: RobotDescription,
    params: GeometricParameters | None,
    q: ArrayLike,
    point: str = "flange",
    closure: str = "fourbar",
) -> Array:
    """Manipulator Jacobian w.r.t. the joint readings, thesis eq. (6.37).

    For a revolute joint i with axis ``z_i`` through ``p_i`` (base frame), column i
    is ``[z_i × (p − p_i); z_i]``, for a prismatic one ``[z_i; 0]``, ``p`` being the
    point's position; a loop's passive joints add their derivatives w.r.t. the
    driven ones (eq. 6.39 for ``closure="nominal"``, the exact four-bar derivatives
    for ``"fourbar"``); a coupled description multiplies by the reading map:
    ``J = J_θkin · M``.

    Parameters
    ----------
    desc
        The robot.
    params
        Geometric parameters; ``None``: the nominal ones.
    q
        Joint readings, shape ``(..., n_readings)``, radians.
    point
        ``"flange"`` (its origin) or ``"tcp"`` (flange · tool).
    closure
        ``"fourbar"`` (exact, default) or ``"nominal"``.

    Returns
    -------
    ndarray, shape (..., 6, n_readings)
        Rows 0–2: the point's linear velocity (m/s per rad/s of reading rate);
        rows 3–5: the angular velocity (rad/s per rad/s); both in the base frame.
    """
    return jacobian_from_fk(desc, forward(desc, params, q, closure), point)
