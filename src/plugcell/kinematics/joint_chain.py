"""A serial chain of joints with general origins (URDF style) → DH/Hayati description.

A URDF (or any joint-origin model) places joint *k* at a rigid ``origin`` in the
frame of its parent link and turns (about the unit ``axis``, in the joint frame)
the child link by the joint variable:
``T_child = T_parent · origin · Rot(axis, q)``.  Fixed joints have no variable.
:func:`description_from_chain` converts such a chain **exactly** into the DH +
Hayati rows of :class:`~plugcell.kinematics.description.RobotDescription`
(thesis eq. B.1, ``F_i = F_{i-1} Rz(θ_i) Tz(d_i) Tx(a_i) Rx(α_i) Ry(β_i)``):

* only the joint *axis lines* at q = 0 matter, so fixed joints between moving ones
  fold into the neighbouring rows;
* frame F_{i−1} has its z axis on joint *i*'s axis line; the row of link *i* takes
  it to joint *i+1*'s line — along the common normal (β = 0) when the axes are not
  parallel, and with Hayati's β when they are (d_i = 0 there, which fixes the
  otherwise free position along the parallel axes; the row is then marked
  ``hayati``, as the calibrator needs);
* the first row takes the chain's base frame to joint 1's line (a ``fixed`` link
  ``mount``, omitted when the base frame's z axis already is that line);
* the last row (the flange) only turns about and moves along the last axis
  (``θ_n, d_n``) towards the tip frame; the remaining constant transform is the
  description's ``tool``, so ``forward(...).tcp`` is the tip frame.

Masses of the bodies that move with joint *i* are lumped into link *i* (mass and
centre of mass in F_i).  Pure math: no files; :mod:`plugcell.io.urdf` reads URDFs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from plugcell.kinematics.description import JointCoupling, Link, RobotDescription
from plugcell.kinematics.errors import DescriptionError
from plugcell.kinematics.parameters import GeometricParameters
from plugcell.kinematics.transforms import cross, dh_hayati, rot_z

Array = NDArray[np.float64]

__all__ = [
    "JOINT_KINDS",
    "CalibratedOrigins",
    "ChainJoint",
    "JointChain",
    "calibrated_origins",
    "chain_forward",
    "description_from_chain",
]

#: Joint kinds of a chain: ``revolute`` (also URDF ``continuous``), ``prismatic``
#: (moves the child along the axis) and ``fixed``.
JOINT_KINDS: tuple[str, ...] = ("revolute", "prismatic", "fixed")
#: Name of the fixed link from the chain's base frame to joint 1's axis line.
MOUNT = "mount"
#: Below this |sin| of the angle between two axes (0.57°) they count as parallel and
#: get a Hayati row: the common normal of nearly parallel axes is ill-conditioned
#: (its position error grows like ε/sin²), the Hayati row is exact for any angle.
PARALLEL_SIN = 1e-2
#: Lengths (m) and angles (rad) below this are rounded to 0 in the DH rows.
_ZERO = 1e-14


@dataclass(frozen=True, eq=False)
class ChainJoint:
    """One joint of a serial chain: ``T_child = T_parent · origin · Rot(axis, q)``.

    Attributes
    ----------
    name : str
        Joint name (becomes the link name in the description).
    kind : str
        One of :data:`JOINT_KINDS`: ``revolute``, ``prismatic`` (``Trans(axis · q)``)
        or ``fixed``.
    origin : (4, 4) array, m
        Pose of the joint frame in the parent link's frame at q = 0.
    axis : (3,) array
        Unit axis in the joint frame (ignored for ``fixed``).
    limits : (float, float) or None
        ``(lower, upper)``, rad (m for prismatic), or ``None`` (unlimited, e.g. URDF
        continuous).
    mass : float, kg
        The child body's mass (with whatever is rigidly attached to it off the chain).
    com : (float, float, float), m
        Its centre of mass in the child link frame.
    mimic : (str, float, float) or None
        ``(joint, multiplier, offset)``: this joint's value is
        ``q = multiplier · q_joint + offset`` (URDF ``<mimic>``, offset in rad), so it
        is no reading of its own.
    """

    name: str
    kind: str
    origin: Array
    axis: Array = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))
    limits: tuple[float, float] | None = None
    mass: float = 0.0
    com: tuple[float, float, float] = (0.0, 0.0, 0.0)
    mimic: tuple[str, float, float] | None = None


@dataclass(frozen=True, eq=False)
class JointChain:
    """Joints from a base link to a tip link, in order; the base frame is the root.

    ``T_tip = Π_k origin_k · Rot(axis_k, q_k)`` (:func:`chain_forward`).

    Attributes
    ----------
    name : str
        Robot name.
    joints : tuple of ChainJoint
        The joints, base to tip.
    notes : str
        Free text carried into the description.
    """

    name: str
    joints: tuple[ChainJoint, ...]
    notes: str = ""

    @property
    def moving(self) -> tuple[ChainJoint, ...]:
        """The non-fixed joints, in chain order (the joint-reading order)."""
        return tuple(j for j in self.joints if j.kind != "fixed")


@dataclass(frozen=True)
class _Row:
    theta: float
    d: float
    a: float
    alpha: float
    beta: float
    hayati: bool


def _clean(x: float) -> float:
    return 0.0 if abs(x) < _ZERO else float(x)


def line_step(frame: Array, point: Array, direction: Array) -> _Row:
    """The DH + Hayati row taking ``frame``'s z axis onto the line ``point + s·direction``.

    Not parallel: x_new = z × w / |z × w| on the common normal, d and a the offsets
    along z and x_new, α the angle about x_new from z to w, β = 0.  Parallel or nearly
    (|z × w| below :data:`PARALLEL_SIN`): d = 0 (the new origin is the point of the line
    in the plane of ``frame``'s x and y axes), x_new towards it (or ``frame``'s x if the lines
    coincide), then Rx(α) Ry(β) with w = (sin β, −sin α cos β, cos α cos β) in the new
    x, y, z axes — exact also for nearly parallel lines.  In both cases θ is the angle
    about z from ``frame``'s x to x_new.

    Parameters
    ----------
    frame : (4, 4) array, m
        The current frame F_{i−1} (its z axis is the current joint axis line).
    point : (3,) array, m
        A point of the next axis line, in the same frame as ``frame``.
    direction : (3,) array
        Direction of the next axis line (need not be unit).

    Returns
    -------
    _Row
        ``(θ, d, a, α, β, hayati)`` with θ, α, β in rad and d, a in m.
    """
    R, o = frame[:3, :3], frame[:3, 3]
    x, z = R[:, 0], R[:, 2]
    w = direction / np.linalg.norm(direction)
    c = cross(z, w)
    s = float(np.linalg.norm(c))
    r = point - o
    if s > PARALLEL_SIN:
        xn = c / s
        zw = float(z @ w)
        A = np.array([[1.0, -zw], [zw, -1.0]])
        t, u = np.linalg.solve(A, [r @ z, r @ w])
        foot = point + u * w
        d = float(t)
        a = float((foot - (o + t * z)) @ xn)
        theta = math.atan2(float(cross(x, xn) @ z), float(x @ xn))
        alpha = math.atan2(float(cross(z, w) @ xn), zw)
        return _Row(_clean(theta), _clean(d), _clean(a), _clean(alpha), 0.0, False)
    u = -float(r @ z) / float(w @ z)
    v = r + u * w  # new origin − o, in the x-y plane of frame
    v = v - float(v @ z) * z  # exactly in it (v·z is round-off of 0.5-sized numbers)
    a = float(np.linalg.norm(v))
    xn = v / a if a > _ZERO else x  # below _ZERO the lines coincide (a rounds to 0)
    if a <= _ZERO:
        a = 0.0
    yn = cross(z, xn)
    wx, wy, wz = float(w @ xn), float(w @ yn), float(w @ z)
    beta = math.asin(max(-1.0, min(1.0, wx)))
    alpha = math.atan2(-wy, wz)
    theta = math.atan2(float(cross(x, xn) @ z), float(x @ xn))
    return _Row(_clean(theta), 0.0, _clean(a), _clean(alpha), _clean(beta), True)


def _row_transform(row: _Row) -> Array:
    return dh_hayati(
        np.array(row.theta), np.array(row.d), np.array(row.a), np.array(row.alpha),
        np.array(row.beta),
    )


def _axis_rotation(axis: Array, q: float) -> Array:
    """Rodrigues rotation (4, 4) about unit ``axis`` by ``q``."""
    k = axis / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    T = np.eye(4)
    T[:3, :3] = np.eye(3) + math.sin(q) * K + (1 - math.cos(q)) * (K @ K)
    return T


def chain_forward(chain: JointChain, q: Array) -> Array:
    """Tip frame of the chain for moving-joint values ``q`` (reference FK).

    ``T = Π_k origin_k · Rot(axis_k, q_k)`` (prismatic: ``Trans(axis_k · q_k)``) over the
    joints in order (fixed: nothing) — the URDF definition.

    Parameters
    ----------
    chain : JointChain
        The chain.
    q : (n_moving,) array, rad (m for prismatic)
        Values of the moving joints in chain order (mimic joints included; their
        ``mimic`` relation is not applied here).

    Returns
    -------
    T : (4, 4) array, m
        The tip frame in the chain's base frame.
    """
    T = np.eye(4)
    j = 0
    for jt in chain.joints:
        T = T @ jt.origin
        if jt.kind == "revolute":
            T = T @ _axis_rotation(jt.axis, float(q[j]))
        elif jt.kind == "prismatic":
            S = np.eye(4)
            S[:3, 3] = np.asarray(jt.axis) / np.linalg.norm(jt.axis) * float(q[j])
            T = T @ S
        if jt.kind != "fixed":
            j += 1
    return T


def description_from_chain(chain: JointChain, unlimited: float = 2 * math.pi) -> RobotDescription:
    """The exact DH/Hayati :class:`RobotDescription` of a serial chain (module docstring).

    Parameters
    ----------
    chain : JointChain
        Joints from the base link (the description's base frame F0's parent, i.e.
        the robot base frame) to the tip (the TCP: ``tool`` in the flange frame).
    unlimited : float
        Limit (± rad) given to joints without limits (URDF ``continuous``).

    Returns
    -------
    RobotDescription
        One actuated (revolute) or prismatic link per moving joint, named after the
        joint, in chain order (which is the joint-reading order); joint reading = URDF
        joint position (rad or m).  A prismatic joint's row turns its axis line like a
        revolute one; its reading moves ``d`` along it.

    Raises
    ------
    DescriptionError
        No moving joint, an unsupported joint kind or a zero axis (location
        ``joints[k]``).
    """
    frames, axes, bodies, tip = _joint_lines(chain)
    moving = chain.moving
    mount, rows, dh_frames = _dh_rows(frames, axes, tip)
    links: list[Link] = []
    parent = "base"
    if mount is not None:
        links.append(Link(MOUNT, parent, "fixed", mount.theta, mount.d, mount.a, mount.alpha,
                          mount.beta, mount.hayati))
        parent = MOUNT
    for i, (jt, row) in enumerate(zip(moving, rows, strict=True)):
        mass, com = _lumped_body([b[1:] for b in bodies if b[0] == i], dh_frames[i])
        kind = "prismatic" if jt.kind == "prismatic" else "actuated"
        links.append(Link(jt.name, parent, kind, row.theta, row.d, row.a, row.alpha,
                          row.beta, row.hayati, mass, com))
        parent = jt.name
    tool = np.linalg.inv(dh_frames[-1]) @ tip
    tool[3] = [0.0, 0.0, 0.0, 1.0]
    readings = [jt for jt in moving if jt.mimic is None]
    limits = np.array([jt.limits if jt.limits is not None else (-unlimited, unlimited)
                       for jt in readings], dtype=float)
    return RobotDescription(
        name=chain.name,
        links=tuple(links),
        actuated=tuple(jt.name for jt in moving),
        flange=moving[-1].name,
        loops=(),
        base=np.eye(4),
        tool=tool,
        joint_limits=limits,
        notes=chain.notes,
        home=np.clip(np.zeros(len(readings)), limits[:, 0], limits[:, 1]),
        coupling=_mimic_coupling(chain),
    )


def _joint_lines(chain: JointChain
                 ) -> tuple[list[Array], list[Array], list[tuple[int, float, Array]], Array]:
    """Walk the chain at q = 0: ``T ← T · origin_k``.

    Returns
    -------
    frames : list of (4, 4) array
        The frame of each moving joint, in the base frame.
    axes : list of (3,) array
        Its unit axis in the base frame, ``R · a/‖a‖``.
    bodies : list of (int, float, (3,) array)
        Each mass: the moving joint whose link carries it, kg, centre of mass in the
        base frame.
    tip : (4, 4) array
        The tip frame (the TCP).
    """
    T = np.eye(4)
    frames: list[Array] = []
    axes: list[Array] = []
    bodies: list[tuple[int, float, Array]] = []
    m = -1
    for k, jt in enumerate(chain.joints):
        if jt.kind not in JOINT_KINDS:
            raise DescriptionError(
                f"joints[{k}] ({jt.name})",
                f"joint kind {jt.kind!r} is not supported (supported: {', '.join(JOINT_KINDS)})",
            )
        T = T @ np.asarray(jt.origin, dtype=float)
        if jt.kind != "fixed":
            ax = np.asarray(jt.axis, dtype=float)
            n = float(np.linalg.norm(ax))
            if not (np.all(np.isfinite(ax)) and n > 1e-12):
                raise DescriptionError(f"joints[{k}] ({jt.name}).axis", "must be a non-zero vector")
            frames.append(T.copy())
            axes.append(T[:3, :3] @ (ax / n))
            m += 1
        if jt.mass > 0 and m >= 0:
            bodies.append((m, jt.mass, T[:3, :3] @ np.asarray(jt.com) + T[:3, 3]))
    if not frames:
        raise DescriptionError("joints", "the chain has no moving joint")
    return frames, axes, bodies, T


def _dh_rows(frames: list[Array], axes: list[Array], tip: Array
             ) -> tuple[_Row | None, list[_Row], list[Array]]:
    """The DH/Hayati rows that put each joint's z on the next joint's axis line
    (:func:`line_step`), the last one's on the tip (its ``θ`` turns x towards the tip's
    x, its ``d`` reaches the tip's plane).

    Returns
    -------
    mount : _Row or None
        The fixed row from the base frame to the first joint's line (None: none needed).
    rows : list of _Row
        One per moving joint.
    dh_frames : list of (4, 4) array
        The frame after each row, in the base frame.
    """
    F = np.eye(4)
    mount: _Row | None = line_step(F, frames[0][:3, 3], axes[0])
    if any((mount.theta, mount.d, mount.a, mount.alpha, mount.beta)):
        F = F @ _row_transform(mount)
    else:
        mount = None
    dh_frames: list[Array] = []
    rows: list[_Row] = []
    n = len(frames)
    for i in range(n):
        if i + 1 < n:
            row = line_step(F, frames[i + 1][:3, 3], axes[i + 1])
        else:
            z, x, o = F[:3, 2], F[:3, 0], F[:3, 3]
            xt = tip[:3, 0] - (tip[:3, 0] @ z) * z
            th = math.atan2(float(cross(x, xt) @ z), float(x @ xt)) if np.linalg.norm(
                xt) > 1e-9 else 0.0
            row = _Row(_clean(th), _clean(float((tip[:3, 3] - o) @ z)), 0.0, 0.0, 0.0, False)
        F = F @ _row_transform(row)
        dh_frames.append(F.copy())
        rows.append(row)
    return mount, rows, dh_frames


def _lumped_body(bodies: list[tuple[float, Array]], frame: Array
                 ) -> tuple[float, tuple[float, float, float]]:
    """The masses a link carries as one: ``m = Σ mᵢ``, centre of mass ``Σ mᵢ pᵢ / m``
    (base frame) expressed in the link's DH ``frame``, ``Rᵀ (p − o)``."""
    mass = sum(b[0] for b in bodies)
    com = np.zeros(3)
    if mass > 0:
        pw = sum(b[0] * b[1] for b in bodies) / mass
        com = frame[:3, :3].T @ (pw - frame[:3, 3])
    return float(mass), (float(com[0]), float(com[1]), float(com[2]))


def _mimic_coupling(chain: JointChain) -> JointCoupling | None:
    """The reading → joint map of the chain's mimic joints (``None`` without any).

    Readings are the moving joints that mimic none, in chain order; a mimic joint's
    row is ``multiplier`` at the column of the reading it follows (through other mimic
    joints, multipliers multiplied and offsets carried), with its ``offset``.
    """
    moving = chain.moving
    if all(jt.mimic is None for jt in moving):
        return None
    by_name = {jt.name: (k, jt) for k, jt in enumerate(chain.joints)}
    readings = [jt.name for jt in moving if jt.mimic is None]
    col = {nm: c for c, nm in enumerate(readings)}
    M = np.zeros((len(moving), len(readings)))
    off = np.zeros(len(moving))
    for i, jt in enumerate(moving):
        # θ_jt = mult·θ_cur + offset; cur mimics target: θ_cur = m·θ_target + o
        mult, offset, cur, seen = 1.0, 0.0, jt, {jt.name}
        while cur.mimic is not None:
            target, m, o = cur.mimic
            mult, offset = mult * m, offset + mult * o
            if target not in by_name or by_name[target][1].kind == "fixed":
                loc = f"joints[{by_name[cur.name][0]}] ({cur.name}).mimic"
                raise DescriptionError(
                    loc, f"mimics {target!r}, which is not a moving joint of the chain")
            if target in seen:
                raise DescriptionError(f"joints[{by_name[cur.name][0]}] ({cur.name}).mimic",
                                       "mimic joints follow each other in a circle")
            seen.add(target)
            cur = by_name[target][1]
        M[i, col[cur.name]] = mult
        off[i] = offset
    return JointCoupling(tuple(readings), M, off)


@dataclass(frozen=True, eq=False)
class CalibratedOrigins:
    """Joint origins of a chain that reproduce a calibrated DH/Hayati geometry.

    Attributes
    ----------
    origins : (n_joints, 4, 4) array, m
        The new ``origin`` of every joint of the chain (fixed joints unchanged except
        ``tip_joint``).
    tip_joint : int or None
        Index of the fixed joint that took up the flange's calibrated offset (``None``
        if none did).
    residual : (4, 4) array, m
        The constant ``E = tip_exported⁻¹ · tip_calibrated`` left when no joint could
        take it up (identity otherwise).
    """

    origins: Array
    tip_joint: int | None
    residual: Array


def calibrated_origins(chain: JointChain, desc: RobotDescription,
                       params: GeometricParameters, *, fixed_tip: bool = True
                       ) -> CalibratedOrigins:
    """New joint origins that give ``chain`` the geometry ``params`` of ``desc``.

    ``desc`` must be :func:`description_from_chain` of ``chain``.  Joint *i*'s frame
    at q = 0 is ``J_i = F_{i−1} Rz(θ_i) K_i`` with ``K_i`` constant (nominal), so the
    calibrated frame is ``J'_i = F'_{i−1} Rz(θ'_i) K_i`` — on the calibrated axis, with
    the URDF axis vector along it — and origin'_i = (previous link frame')⁻¹ J'_i.
    The tip: ``tip' = F'_n · tool``; with ``fixed_tip`` the first fixed joint after the
    last moving joint takes up the difference (exact); otherwise (or without such a
    joint) it is returned as ``residual``.  Link frames stay on their joint axes, so
    meshes and inertias keep their place on the bodies.

    Parameters
    ----------
    chain : JointChain
        The chain ``desc`` was made from.
    desc : RobotDescription
        ``description_from_chain(chain)``.
    params : GeometricParameters
        The calibrated geometry (m, rad).
    fixed_tip : bool, default True
        Let the first fixed joint after the last moving one take up the tip offset.

    Returns
    -------
    CalibratedOrigins
        ``(n_joints, 4, 4)`` new origins (m), the tip joint used and the residual.
    """
    from plugcell.kinematics.forward import forward

    moving = [k for k, j in enumerate(chain.joints) if j.kind != "fixed"]
    desc = desc.uncoupled()  # the chain's q = 0 is θ_kin = 0 (mimic joints included)
    q0 = np.zeros(desc.n_actuated)
    nom = forward(desc, None, q0)
    cal = forward(desc, params, q0)
    p_nom = desc.nominal_parameters()

    def axis_frame(fk: Any, p: GeometricParameters, name: str) -> Array:
        lk = desc.link(name)
        parent = fk.frame(lk.parent) if lk.parent != "base" else np.eye(4)
        return np.asarray(parent @ rot_z(p.theta[desc.index(name)]))

    # nominal joint frames from the chain itself
    T = np.eye(4)
    J_nom: dict[int, Array] = {}
    for k, jt in enumerate(chain.joints):
        T = T @ jt.origin
        if k in moving:
            J_nom[k] = T.copy()
    origins = np.array([np.asarray(j.origin, dtype=float) for j in chain.joints])
    T = np.eye(4)
    for m, k in enumerate(moving):
        name = desc.actuated[m]
        K = np.linalg.inv(axis_frame(nom, p_nom, name)) @ J_nom[k]
        J_cal = axis_frame(cal, params, name) @ K
        # fixed joints before this one keep their origins
        for kk in range(moving[m - 1] + 1 if m else 0, k):
            T = T @ origins[kk]
        origins[k] = np.linalg.inv(T) @ J_cal
        T = J_cal
    tip_cal = cal.flange @ desc.tool
    after = list(range(moving[-1] + 1, len(chain.joints)))
    tip_joint = after[0] if (after and fixed_tip) else None
    if tip_joint is not None:
        rest = np.eye(4)
        for kk in after[1:]:
            rest = rest @ origins[kk]
        origins[tip_joint] = np.linalg.inv(T) @ tip_cal @ np.linalg.inv(rest)
        residual = np.eye(4)
    else:
        tip_exp = T
        for kk in after:
            tip_exp = tip_exp @ origins[kk]
        residual = np.linalg.inv(tip_exp) @ tip_cal
    origins[:, 3] = [0.0, 0.0, 0.0, 1.0]
    return CalibratedOrigins(origins, tip_joint, residual)
