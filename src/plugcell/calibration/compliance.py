"""Joint deflections: gravity (G1–G3, eq. 6.31) and payload (A, B, C, D, eq. 6.40).

A deflection is added to the joint *readings* before forward kinematics (eq.
4.16): ``q_link = q_reading + Δq(q)`` with ``Δq(q) = R(q) · c``, linear in the
compliance constants ``c``.  With a joint ``coupling`` (vendor convention) the
deflection is that of the kinematic joints θ_kin = M·q + offset — the joint, not
the motor, deflects — and every "reading" below means θ_kin (the readings
themselves without a coupling).  The regressor ``R(q)`` (``(N, n_actuated, n_c)``) is
evaluated on a fixed *reference* geometry — the nominal description — not on
the parameters being identified: the torque arms enter the deflection, a
~1 mm-sized effect, so a 1 mm error in an arm changes it by ~1e-6 mm; fixing
them keeps the model an exact function whose analytic Jacobian is exact
(tested against finite differences).

Gravity (link masses), thesis 6.3.1, per parallelogram loop (arm = joint 2,
crank = joint 2')::

    Δθ_arm   = G1 cos θ_arm                      (6.31)
    Δθ_crank = G2 cos θ_crank + G3 sin θ_crank

with θ the DH angles (reading + nominal offset) in the loop plane (z0 vertical,
the loop plane vertical, θ = 0 horizontal).  A serial robot without loops whose
description gives link masses gets one compliance ``c_j`` (rad/(N·m)) per
actuated joint instead: ``Δθ_j = c_j τ_j(q)`` with ``τ_j`` the gravity torque of
the described masses (eq. 4.15).

Payload, thesis 6.3.2, for every actuated joint *i* (eqs. 6.34–6.41)::

    Δθ_i = (m / m_ref) · [K_i3, K_i4 n_y − K_i5 n_x, K_i4 s_y − K_i5 s_x, K_i4 a_y − K_i5 a_x]
                          · (A_i, B_i, C_i, D_i)

with ``K = Jᵀ`` the manipulator Jacobian at the flange (eq. 6.37; loop joints by
the closure derivatives, which at the nominal parallelogram are eq. 6.39), ``n,
s, a`` the columns of the flange rotation R_n^0 and the thesis's ``P = (0, 0,
mg)`` (so A_i = c_i m g etc.; a physical compliance comes out negative, as in
Table 8-4).  ``m_ref`` is the payload the constants refer to (the heaviest of
the calibration set), so one model predicts every payload on the same mount.

Joint-angle harmonics (issue 19, not in the thesis), for every actuated joint *j*
and order *k* ≤ K (K = 1 or 2)::

    Δθ_j = Σ_k  s_jk sin(k q_j) + c_jk cos(k q_j)

with ``q_j`` the joint reading: the transmission error of a reducer (first order:
eccentricity of a gear or of the encoder; second order: ovality, the harmonic
drive's two-lobe wave generator).  Parameters ``h{k}s_{j}``, ``h{k}c_{j}`` (rad).
A constant term is the joint offset Δθ_j already in the geometric model; whether a
harmonic is separable from it (and from the rest) on given poses is decided by the
identifiability analysis like every other parameter.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from plugcell.calibration.parameters import ErrorParameter
from plugcell.calibration.structure import CLASS_GRAVITY, CLASS_HARMONIC, CLASS_PAYLOAD
from plugcell.kinematics import GeometricParameters, RobotDescription, forward, jacobian_from_fk
from plugcell.kinematics.transforms import cross

Array = NDArray[np.float64]

GRAVITY = 9.81
PAYLOAD_FIELDS: tuple[str, ...] = ("A", "B", "C", "D")

__all__ = [
    "GRAVITY",
    "PAYLOAD_FIELDS",
    "compliance_regressors",
    "gravity_parameters",
    "harmonic_parameters",
    "has_masses",
    "payload_parameters",
]


def has_masses(desc: RobotDescription) -> bool:
    """Whether the description gives any link or point mass (``m > 0``).

    Parameters
    ----------
    desc : RobotDescription
        The robot.

    Returns
    -------
    bool
        True when a serial robot can get the gravity compliances ``c_j`` (eq. 4.15).
    """
    return any(lk.mass > 0 for lk in desc.links) or any(pm.mass > 0 for pm in desc.point_masses)


def gravity_parameters(desc: RobotDescription) -> tuple[ErrorParameter, ...]:
    """Gravity-compliance parameters: G1–G3 per loop (eq. 6.31) or c_j per joint (eq. 4.15).

    Loop *k*: ``Δθ_arm = G_{3k+1} cos θ_arm``, ``Δθ_crank = G_{3k+2} cos θ_crank +
    G_{3k+3} sin θ_crank`` (G in rad); serial robot with masses: ``Δθ_j = c_j τ_j(q)``
    (c_j in rad/(N·m)).

    Parameters
    ----------
    desc : RobotDescription
        The robot.

    Returns
    -------
    tuple of ErrorParameter
        Empty for a serial robot without masses.
    """
    out: list[ErrorParameter] = []
    if desc.loops:
        for k, loop in enumerate(desc.loops):
            for m, joint in enumerate((loop.arm, loop.crank, loop.crank)):
                g = 3 * k + m + 1
                out.append(
                    ErrorParameter(
                        key=f"G{g}", name=f"G{g}", kind="gravity", unit="rad", joint=joint,
                        priority=(CLASS_GRAVITY, g, 0),
                    )
                )
        return tuple(out)
    if not has_masses(desc):
        return ()
    for j, name in enumerate(desc.actuated):
        out.append(
            ErrorParameter(
                key=f"c{name}", name=f"c{name}", kind="gravity", unit="rad/(N·m)", joint=name,
                priority=(CLASS_GRAVITY, j, 0),
            )
        )
    return tuple(out)


def payload_parameters(desc: RobotDescription) -> tuple[ErrorParameter, ...]:
    """Payload-compliance parameters A_i, B_i, C_i, D_i of every actuated joint *i* (eq. 6.40).

    ``Δθ_i = (m/m_ref) · [K_i3, K_i4 n_y − K_i5 n_x, K_i4 s_y − K_i5 s_x, K_i4 a_y − K_i5 a_x]
    · (A_i, B_i, C_i, D_i)`` (module docstring).

    Parameters
    ----------
    desc : RobotDescription
        The robot.

    Returns
    -------
    tuple of ErrorParameter
        ``4 · n_actuated`` parameters; A in rad/m, B–D in rad.
    """
    out: list[ErrorParameter] = []
    for j, name in enumerate(desc.actuated):
        for m, f in enumerate(PAYLOAD_FIELDS):
            out.append(
                ErrorParameter(
                    key=f"{f}{name}", name=f"{f}{name}", kind="payload",
                    unit="rad/m" if f == "A" else "rad", joint=name,
                    priority=(CLASS_PAYLOAD, j, m),
                )
            )
    return tuple(out)


def harmonic_parameters(desc: RobotDescription, order: int) -> tuple[ErrorParameter, ...]:
    """Joint-angle harmonics ``h{k}s_{j}``, ``h{k}c_{j}`` for every actuated joint *j*.

    ``Δθ_j = Σ_{k=1..order} s_jk sin(k q_j) + c_jk cos(k q_j)`` (module docstring).

    Parameters
    ----------
    desc : RobotDescription
        The robot.
    order : {0, 1, 2}
        Highest harmonic order K.

    Returns
    -------
    tuple of ErrorParameter
        ``2 · order · n_actuated`` parameters, rad.

    Raises
    ------
    ValueError
        ``order`` not 0, 1 or 2.
    """
    if order not in (0, 1, 2):
        raise ValueError(f"harmonics: order 0, 1 or 2, got {order}")
    out: list[ErrorParameter] = []
    for j, name in enumerate(desc.actuated):
        for k in range(1, order + 1):
            for m, (f, fn) in enumerate((("s", "sin"), ("c", "cos"))):
                arg = f"q{name}" if k == 1 else f"{k}q{name}"
                out.append(ErrorParameter(
                    key=f"h{k}{f}_{name}", name=f"Δθ{name}·{fn} {arg}", kind="harmonic",
                    unit="rad", joint=name, priority=(CLASS_HARMONIC, j, 2 * (k - 1) + m)))
    return tuple(out)


def _gravity_torques(desc: RobotDescription, ref: GeometricParameters, q: Array) -> Array:
    """Gravity torques ``(N, n)`` of the described masses on a serial robot (z0 up);
    for a prismatic joint the force along its axis (``Σ m g·z``, N)."""
    fk = forward(desc, ref, q)
    frames = fk.frames
    g = np.array([0.0, 0.0, -GRAVITY])
    masses: list[tuple[int, float, Array]] = []
    for i, lk in enumerate(desc.links):
        if lk.mass > 0:
            masses.append((i, lk.mass, np.asarray(lk.com, float)))
    for pm in desc.point_masses:
        if pm.mass > 0:
            masses.append((desc.index(pm.link), pm.mass, np.asarray(pm.com, float)))
    ancestors: list[set[int]] = []
    for lk in desc.links:
        s = set()
        name = lk.name
        while name != "base":
            s.add(desc.index(name))
            name = desc.link(name).parent
        ancestors.append(s)
    tau = np.zeros((*q.shape[:-1], desc.n_actuated))
    for j, name in enumerate(desc.actuated):
        lj = desc.index(name)
        parent = desc.links[lj].parent
        if parent == "base":
            z = np.broadcast_to([0.0, 0.0, 1.0], (*q.shape[:-1], 3))
            o = np.zeros((*q.shape[:-1], 3))
        else:
            P = frames[..., desc.index(parent), :, :]
            z, o = P[..., :3, 2], P[..., :3, 3]
        for i, m, com in masses:
            if lj not in ancestors[i]:
                continue
            F = frames[..., i, :, :]
            if desc.links[lj].is_prismatic:  # a force along the axis, N
                tau[..., j] += np.sum(m * g * z, axis=-1)
                continue
            c = np.einsum("...ij,j->...i", F[..., :3, :3], com) + F[..., :3, 3]
            tau[..., j] += np.sum(cross(c - o, m * g) * z, axis=-1)
    return tau


def _loop_gravity_regressors(desc: RobotDescription, jidx: dict[str, int],
                             theta: Array) -> dict[str, tuple[int, Array]]:
    """The regressors of each parallelogram loop's gravity constants G1–G3 (eq. 6.31).

    For loop ``k`` (arm ``a``, crank ``c``): ``G{3k+1}`` deflects the arm by
    ``cos θ_a``, ``G{3k+2}`` and ``G{3k+3}`` the crank by ``cos θ_c`` and ``sin θ_c``.

    Parameters
    ----------
    desc : RobotDescription
        The robot, uncoupled.
    jidx : dict
        Actuated joint name → its column in ``theta``.
    theta : (N, n_actuated) array, rad
        Kinematic joints plus the nominal offsets.

    Returns
    -------
    dict
        ``"G…"`` → (the joint it deflects, its regressor ``(N,)``).
    """
    loop_g = {}
    for k, loop in enumerate(desc.loops):
        ja, jc = jidx[loop.arm], jidx[loop.crank]
        loop_g[f"G{3 * k + 1}"] = (ja, np.cos(theta[:, ja]))
        loop_g[f"G{3 * k + 2}"] = (jc, np.cos(theta[:, jc]))
        loop_g[f"G{3 * k + 3}"] = (jc, np.sin(theta[:, jc]))
    return loop_g


def compliance_regressors(
    desc: RobotDescription,
    ref: GeometricParameters,
    parameters: Sequence[ErrorParameter],
    q: ArrayLike,
    payload_kg: ArrayLike | None = None,
    payload_ref_kg: float = 0.0,
) -> Array:
    """Compliance regressor ``R(q)`` with ``Δθ = R(q) · c`` (eqs. 6.31, 6.40, 4.15).

    Column of each parameter (module docstring): ``cos θ_arm`` / ``cos θ_crank`` /
    ``sin θ_crank`` for G1–G3 (θ = θ_kin + nominal offset), the gravity torque
    ``τ_j(q)`` for a serial ``c_j``, ``sin(k q_j)`` / ``cos(k q_j)`` for harmonics and the
    row of eq. (6.41) times ``m / m_ref`` for payload constants — all evaluated on the
    reference geometry ``ref``.

    Parameters
    ----------
    desc : RobotDescription
        The robot as described.
    ref : GeometricParameters
        Its reference (nominal) geometry, m and rad.
    parameters : sequence of ErrorParameter
        Gravity, payload and harmonic parameters (the columns, in this order).
    q : (N, n_readings) array_like, rad
        Joint readings (mapped to the kinematic joints θ_kin by a coupling).
    payload_kg : (N,) array_like, kg, optional
        Payload masses (``None``: no payload, zero payload columns).
    payload_ref_kg : float, kg
        The mass the payload constants refer to (≤ 0: zero payload columns).

    Returns
    -------
    R : (N, n_actuated, n_c) array
        Deflection of each kinematic joint per unit of each constant (rad per the
        constant's unit).

    Raises
    ------
    ValueError
        A parameter that is not a compliance parameter.
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    q = desc.kinematic_joints(q)  # the deflections are those of the kinematic joints
    desc = desc.uncoupled()
    N, n = q.shape
    R = np.zeros((N, n, len(parameters)))
    if not parameters:
        return R
    jidx = {name: j for j, name in enumerate(desc.actuated)}
    theta = q + np.array([ref.theta[desc.index(nm)] for nm in desc.actuated])
    loop_g = _loop_gravity_regressors(desc, jidx, theta)
    tau = None
    payload_reg = None
    for c, p in enumerate(parameters):
        if p.kind == "gravity":
            if p.key in loop_g:
                j, reg = loop_g[p.key]
                R[:, j, c] = reg
            else:
                if tau is None:
                    tau = _gravity_torques(desc, ref, q)
                j = jidx[p.joint]  # type: ignore[index]
                R[:, j, c] = tau[:, j]
        elif p.kind == "harmonic":
            j = jidx[p.joint]  # type: ignore[index]
            k = int(p.key[1])
            R[:, j, c] = np.sin(k * q[:, j]) if p.key[2] == "s" else np.cos(k * q[:, j])
        elif p.kind == "payload":
            if payload_reg is None:
                payload_reg = _payload_regressors(desc, ref, q, payload_kg, payload_ref_kg)
            j = jidx[p.joint]  # type: ignore[index]
            R[:, j, c] = payload_reg[:, j, PAYLOAD_FIELDS.index(p.key[0])]
        else:
            raise ValueError(f"{p.key!r} is not a compliance parameter")
    return R


def _payload_regressors(
    desc: RobotDescription,
    ref: GeometricParameters,
    q: Array,
    payload_kg: ArrayLike | None,
    payload_ref_kg: float,
) -> Array:
    """``(N, n, 4)``: the row vector of eq. (6.41) per joint, scaled by m / m_ref."""
    N = q.shape[0]
    if payload_kg is None or payload_ref_kg <= 0:
        return np.zeros((N, desc.n_actuated, 4))
    scale = np.broadcast_to(np.asarray(payload_kg, dtype=float), (N,)) / payload_ref_kg
    fk = forward(desc, ref, q, closure="fourbar")
    K = np.swapaxes(jacobian_from_fk(desc, fk, "flange"), -1, -2)  # (N, n, 6)
    Rn = fk.flange[:, :3, :3]
    out = np.empty((N, desc.n_actuated, 4))
    out[..., 0] = K[..., 2]
    for m in range(3):  # n, s, a columns of R_n^0
        col = Rn[:, :, m]
        out[..., m + 1] = K[..., 3] * col[:, None, 1] - K[..., 4] * col[:, None, 0]
    return out * scale[:, None, None]
