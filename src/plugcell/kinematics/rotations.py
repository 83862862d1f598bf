"""Orientation conventions: Euler ZYZ (Comau), roll-pitch-yaw, intrinsic XYZ, projective.

All functions are vectorised over leading axes and work in radians.  Each
``*_to_matrix`` returns ``(..., 3, 3)`` rotation matrices; each ``matrix_to_*``
returns ``(..., 3)`` angle triples.

Conventions (R maps frame coordinates to reference coordinates):

``zyz``
    Comau Euler angles (A, B, C), thesis eq. (A.4): ``R = Rz(A)·Ry(B)·Rz(C)``,
    B ∈ [0, π], A, C ∈ (−π, π].  Gimbal lock (sin B ≈ 0): C := 0.
``rpy``
    Roll-pitch-yaw about the *fixed* X, Y, Z axes (r, p, y):
    ``R = Rz(y)·Ry(p)·Rx(r)``, p ∈ [−π/2, π/2].  Gimbal lock (cos p ≈ 0): r := 0.
``xyz``
    Intrinsic (moving-axes) X-Y-Z (a, b, c): ``R = Rx(a)·Ry(b)·Rz(c)``,
    b ∈ [−π/2, π/2].  Gimbal lock (cos b ≈ 0): c := 0.
``prj``
    Projective (projection) angles (u, v, w) of the tracker service (thesis
    Table 7-3 names ``prj2tr``/``tr2prj`` but never defines them; this is our
    definition).  Each angle is the angle of the projection of one frame axis on
    one coordinate plane of the reference frame:

    * u = atan2(y_z, y_y): the frame's y axis projected on the reference YZ plane,
      measured from Y towards Z (a rotation about X);
    * v = atan2(z_x, z_z): the z axis projected on the ZX plane, from Z towards X
      (about Y);
    * w = atan2(x_y, x_x): the x axis projected on the XY plane, from X towards Y
      (about Z).

    To first order (u, v, w) equals the rotation vector, which makes them handy
    for small corrections.  The map is invertible in closed form: the three axes
    are ``x ∝ (cos w, sin w, ξ)``, ``y ∝ (η, cos u, sin u)``, ``z ∝ (sin v, ζ, cos v)``
    and orthogonality is *linear* in (ξ, η, ζ).  Domain: no frame axis may be
    perpendicular to its projection plane (|angle| < 90° is always safe) and
    ``sin u sin v sin w + cos u cos v cos w ≠ 0``; outside it :func:`prj_to_matrix`
    raises ``ValueError``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from plugcell.kinematics.transforms import _matrix_to_quat, _rot, identity, so3_log

Array = NDArray[np.float64]

CONVENTIONS: tuple[str, ...] = ("zyz", "rpy", "xyz", "prj")

#: Below this value of sin(B) (zyz) or cos(p) (rpy, xyz) the middle angle is treated
#: as a gimbal lock and the last (first for rpy) angle is set to zero.
GIMBAL_EPS = 1e-9

__all__ = [
    "CONVENTIONS",
    "angles_to_matrix",
    "matrix_to_angles",
    "matrix_to_pose",
    "matrix_to_prj",
    "matrix_to_quat",
    "matrix_to_rpy",
    "matrix_to_xyz",
    "matrix_to_zyz",
    "nearest_angles",
    "nearest_quat",
    "nearest_rotvec",
    "pose_to_matrix",
    "prj_to_matrix",
    "quat_to_matrix",
    "rpy_to_matrix",
    "xyz_to_matrix",
    "zyz_to_matrix",
]


def _f(x: ArrayLike) -> Array:
    return np.asarray(x, dtype=float)


def _rx(t: Array) -> Array:
    """``Rx(t)``: the rotation block of :func:`~plugcell.kinematics.transforms.rot_x`."""
    return _rot(t, 0)[..., :3, :3]


def _ry(t: Array) -> Array:
    """``Ry(t)``: the rotation block of :func:`~plugcell.kinematics.transforms.rot_y`."""
    return _rot(t, 1)[..., :3, :3]


def _rz(t: Array) -> Array:
    """``Rz(t)``: the rotation block of :func:`~plugcell.kinematics.transforms.rot_z`."""
    return _rot(t, 2)[..., :3, :3]


def _bcast(*xs: ArrayLike) -> list[Array]:
    return list(np.broadcast_arrays(*(_f(x) for x in xs)))


# --------------------------------------------------------------------------- ZYZ (A.4)
def zyz_to_matrix(A: ArrayLike, B: ArrayLike, C: ArrayLike) -> Array:
    """Comau Euler ZYZ angles → rotation matrix, ``R = Rz(A) · Ry(B) · Rz(C)`` (thesis A.4).

    Parameters
    ----------
    A, B, C : (...) array_like, rad
        The three Euler angles; they broadcast together.

    Returns
    -------
    R : (..., 3, 3) array
        Rotation matrices (frame coordinates → reference coordinates).
    """
    A, B, C = _bcast(A, B, C)
    return _rz(A) @ _ry(B) @ _rz(C)


def matrix_to_zyz(R: ArrayLike) -> Array:
    """Rotation matrix → Comau Euler angles (A, B, C), thesis eq. (A.4); B ∈ [0, π].

    ``A = atan2(R23, R13)``, ``B = atan2(√(R13² + R23²), R33)``, ``C = atan2(R32, −R31)``
    (1-based indices as in the thesis).  Gimbal lock (sin B < 1e-9): C = 0 and A
    carries the whole rotation about z, ``A = atan2(R21, R11)`` for B = 0,
    ``A = atan2(−R21, −R11)`` for B = π.

    Parameters
    ----------
    R : (..., 3, 3) array_like
        Rotation matrices.

    Returns
    -------
    angles : (..., 3) array, rad
        ``(A, B, C)`` with A, C ∈ (−π, π], B ∈ [0, π].
    """
    R = _f(R)
    sB = np.hypot(R[..., 0, 2], R[..., 1, 2])
    B = np.arctan2(sB, R[..., 2, 2])
    A = np.arctan2(R[..., 1, 2], R[..., 0, 2])
    C = np.arctan2(R[..., 2, 1], -R[..., 2, 0])
    lock = sB < GIMBAL_EPS
    up = R[..., 2, 2] > 0
    # B = 0:  R = Rz(A + C);  B = π:  R[:2,:2] = Rz(A − C)·diag(−1, 1)
    A_lock = np.where(
        up,
        np.arctan2(R[..., 1, 0], R[..., 0, 0]),
        np.arctan2(-R[..., 1, 0], -R[..., 0, 0]),
    )
    A = np.where(lock, A_lock, A)
    C = np.where(lock, 0.0, C)
    return np.stack([A, B, C], axis=-1)


# --------------------------------------------------------------------------- RPY
def rpy_to_matrix(r: ArrayLike, p: ArrayLike, y: ArrayLike) -> Array:
    """Roll-pitch-yaw about the fixed X, Y, Z axes → ``R = Rz(y) · Ry(p) · Rx(r)``.

    Parameters
    ----------
    r, p, y : (...) array_like, rad
        Roll (about X), pitch (about Y), yaw (about Z); they broadcast together.

    Returns
    -------
    R : (..., 3, 3) array
        Rotation matrices.
    """
    r, p, y = _bcast(r, p, y)
    return _rz(y) @ _ry(p) @ _rx(r)


def matrix_to_rpy(R: ArrayLike) -> Array:
    """Rotation matrix → (roll, pitch, yaw) about fixed X-Y-Z; pitch ∈ [−π/2, π/2].

    Inverts ``R = Rz(y) Ry(p) Rx(r)``: ``p = atan2(−R31, √(R11² + R21²))``,
    ``r = atan2(R32, R33)``, ``y = atan2(R21, R11)`` (1-based).  Gimbal lock
    (cos p < 1e-9): roll = 0, yaw = atan2(−R12, R22).

    Parameters
    ----------
    R : (..., 3, 3) array_like
        Rotation matrices.

    Returns
    -------
    angles : (..., 3) array, rad
        ``(r, p, y)``.
    """
    R = _f(R)
    cp = np.hypot(R[..., 0, 0], R[..., 1, 0])
    p = np.arctan2(-R[..., 2, 0], cp)
    r = np.arctan2(R[..., 2, 1], R[..., 2, 2])
    y = np.arctan2(R[..., 1, 0], R[..., 0, 0])
    lock = cp < GIMBAL_EPS
    r = np.where(lock, 0.0, r)
    y = np.where(lock, np.arctan2(-R[..., 0, 1], R[..., 1, 1]), y)
    return np.stack([r, p, y], axis=-1)


# --------------------------------------------------------------------------- intrinsic XYZ
def xyz_to_matrix(a: ArrayLike, b: ArrayLike, c: ArrayLike) -> Array:
    """Intrinsic (moving-axes) X-Y-Z angles → ``R = Rx(a) · Ry(b) · Rz(c)``.

    Parameters
    ----------
    a, b, c : (...) array_like, rad
        Angles about the moving X, Y, Z axes; they broadcast together.

    Returns
    -------
    R : (..., 3, 3) array
        Rotation matrices.
    """
    a, b, c = _bcast(a, b, c)
    return _rx(a) @ _ry(b) @ _rz(c)


def matrix_to_xyz(R: ArrayLike) -> Array:
    """Rotation matrix → intrinsic X-Y-Z angles (a, b, c); b ∈ [−π/2, π/2].

    Inverts ``R = Rx(a) Ry(b) Rz(c)``: ``b = atan2(R13, √(R11² + R12²))``,
    ``a = atan2(−R23, R33)``, ``c = atan2(−R12, R11)`` (1-based).  Gimbal lock
    (cos b < 1e-9): c = 0, a = atan2(R32, R22).

    Parameters
    ----------
    R : (..., 3, 3) array_like
        Rotation matrices.

    Returns
    -------
    angles : (..., 3) array, rad
        ``(a, b, c)``.
    """
    R = _f(R)
    cb = np.hypot(R[..., 0, 0], R[..., 0, 1])
    b = np.arctan2(R[..., 0, 2], cb)
    a = np.arctan2(-R[..., 1, 2], R[..., 2, 2])
    c = np.arctan2(-R[..., 0, 1], R[..., 0, 0])
    lock = cb < GIMBAL_EPS
    a = np.where(lock, np.arctan2(R[..., 2, 1], R[..., 1, 1]), a)
    c = np.where(lock, 0.0, c)
    return np.stack([a, b, c], axis=-1)


# --------------------------------------------------------------------------- projective
def matrix_to_prj(R: ArrayLike) -> Array:
    """Rotation matrix → projective angles (u, v, w) (see the module docstring).

    ``u = atan2(R32, R22)``, ``v = atan2(R13, R33)``, ``w = atan2(R21, R11)``
    (1-based).  A degenerate projection (axis perpendicular to its plane) gives
    ``atan2(0, 0) = 0`` deterministically; such a triple does not round-trip.

    Parameters
    ----------
    R : (..., 3, 3) array_like
        Rotation matrices.

    Returns
    -------
    angles : (..., 3) array, rad
        ``(u, v, w)``.
    """
    R = _f(R)
    u = np.arctan2(R[..., 2, 1], R[..., 1, 1])
    v = np.arctan2(R[..., 0, 2], R[..., 2, 2])
    w = np.arctan2(R[..., 1, 0], R[..., 0, 0])
    return np.stack([u, v, w], axis=-1)


def prj_to_matrix(u: ArrayLike, v: ArrayLike, w: ArrayLike) -> Array:
    """Projective angles (u, v, w) → rotation matrix (see the module docstring).

    Solves the 3×3 linear system that makes ``x ∝ (cw, sw, ξ)``, ``y ∝ (η, cu, su)``,
    ``z ∝ (sv, ζ, cv)`` mutually orthogonal::

        su·ξ + cw·η        = −sw·cu      (x·y = 0)
               sv·η + cu·ζ = −su·cv      (y·z = 0)
        cv·ξ        + sw·ζ = −sv·cw      (z·x = 0)

    then normalises the columns ``R = [x/‖x‖, y/‖y‖, z/‖z‖]`` and checks the frame is
    right-handed.

    Parameters
    ----------
    u, v, w : (...) array_like, rad
        Projective angles about X, Y, Z; they broadcast together.

    Returns
    -------
    R : (..., 3, 3) array
        Rotation matrices.

    Raises
    ------
    ValueError
        If the angles are outside the domain: the system is singular
        (``|su·sv·sw + cu·cv·cw| < 1e-12``) or no proper rotation has these
        projections (det R < 0.5).
    """
    u, v, w = _bcast(u, v, w)
    cu, su, cv, sv, cw, sw = np.cos(u), np.sin(u), np.cos(v), np.sin(v), np.cos(w), np.sin(w)
    # x·y = 0:  cw·η + sw·cu + ξ·su = 0
    # y·z = 0:  η·sv + cu·ζ + su·cv = 0
    # z·x = 0:  sv·cw + ζ·sw + cv·ξ = 0
    M = np.zeros((*u.shape, 3, 3))
    rhs = np.zeros((*u.shape, 3))
    M[..., 0, 0], M[..., 0, 1] = su, cw
    rhs[..., 0] = -sw * cu
    M[..., 1, 1], M[..., 1, 2] = sv, cu
    rhs[..., 1] = -su * cv
    M[..., 2, 0], M[..., 2, 2] = cv, sw
    rhs[..., 2] = -sv * cw
    det = su * sv * sw + cu * cv * cw
    if np.any(np.abs(det) < 1e-12):
        raise ValueError("prj_to_matrix: angles outside the domain (singular projection system)")
    sol = np.linalg.solve(M, rhs[..., None])[..., 0]
    xi, eta, zeta = sol[..., 0], sol[..., 1], sol[..., 2]
    x = np.stack([cw, sw, xi], -1)
    y = np.stack([eta, cu, su], -1)
    z = np.stack([sv, zeta, cv], -1)
    x = x / np.linalg.norm(x, axis=-1, keepdims=True)
    y = y / np.linalg.norm(y, axis=-1, keepdims=True)
    z = z / np.linalg.norm(z, axis=-1, keepdims=True)
    R = np.stack([x, y, z], axis=-1)
    if np.any(np.linalg.det(R) < 0.5):
        raise ValueError("prj_to_matrix: no proper rotation has these projective angles")
    return R


# --------------------------------------------------------------------------- dispatch
_TO = {"zyz": zyz_to_matrix, "rpy": rpy_to_matrix, "xyz": xyz_to_matrix, "prj": prj_to_matrix}
_FROM = {"zyz": matrix_to_zyz, "rpy": matrix_to_rpy, "xyz": matrix_to_xyz, "prj": matrix_to_prj}


def _check(convention: str) -> str:
    if convention not in _TO:
        raise ValueError(f"unknown angle convention {convention!r}; expected one of {CONVENTIONS}")
    return convention


def angles_to_matrix(angles: ArrayLike, convention: str) -> Array:
    """Angle triples → rotation matrices, ``R = R_convention(θ₁, θ₂, θ₃)``.

    Dispatches to :func:`zyz_to_matrix`, :func:`rpy_to_matrix`, :func:`xyz_to_matrix`
    or :func:`prj_to_matrix`.

    Parameters
    ----------
    angles : (..., 3) array_like, rad
        Angle triples in the order of ``convention``.
    convention : str
        One of :data:`CONVENTIONS` (``"zyz"``, ``"rpy"``, ``"xyz"``, ``"prj"``).

    Returns
    -------
    R : (..., 3, 3) array
        Rotation matrices.

    Raises
    ------
    ValueError
        Unknown convention, last axis not 3, or ``prj`` angles outside the domain.
    """
    angles = _f(angles)
    if angles.shape[-1:] != (3,):
        raise ValueError(f"expected angles of shape (..., 3), got {angles.shape}")
    return _TO[_check(convention)](angles[..., 0], angles[..., 1], angles[..., 2])


def matrix_to_angles(R: ArrayLike, convention: str) -> Array:
    """Rotation matrices → angle triples, the inverse of :func:`angles_to_matrix`.

    Parameters
    ----------
    R : (..., 3, 3) array_like
        Rotation matrices.
    convention : str
        One of :data:`CONVENTIONS`.

    Returns
    -------
    angles : (..., 3) array, rad
        Angle triples (gimbal-lock rules of the per-convention functions).

    Raises
    ------
    ValueError
        Unknown convention.
    """
    return _FROM[_check(convention)](_f(R))


def pose_to_matrix(xyz: ArrayLike, angles: ArrayLike, convention: str = "zyz") -> Array:
    """Position + orientation angles → homogeneous transform, ``T = [R(angles) xyz; 0 1]``.

    Parameters
    ----------
    xyz : (..., 3) array_like, m
        Positions.
    angles : (..., 3) array_like, rad
        Angle triples in ``convention``; broadcast with ``xyz``.
    convention : str, default ``"zyz"``
        One of :data:`CONVENTIONS`.

    Returns
    -------
    T : (..., 4, 4) array, m
        Homogeneous transforms.

    Raises
    ------
    ValueError
        Unknown convention or malformed angles (see :func:`angles_to_matrix`).
    """
    xyz = _f(xyz)
    R = angles_to_matrix(angles, convention)
    shape = np.broadcast_shapes(xyz.shape[:-1], R.shape[:-2])
    T = identity(shape)
    T[..., :3, :3] = R
    T[..., :3, 3] = xyz
    return T


def matrix_to_pose(T: ArrayLike, convention: str = "zyz") -> tuple[Array, Array]:
    """Homogeneous transform → position and orientation angles, the inverse of
    :func:`pose_to_matrix`.

    Parameters
    ----------
    T : (..., 4, 4) array_like, m
        Homogeneous transforms.
    convention : str, default ``"zyz"``
        One of :data:`CONVENTIONS`.

    Returns
    -------
    xyz : (..., 3) array, m
        Translations (a copy).
    angles : (..., 3) array, rad
        Angle triples in ``convention``.

    Raises
    ------
    ValueError
        Unknown convention.
    """
    T = _f(T)
    return T[..., :3, 3].copy(), matrix_to_angles(T[..., :3, :3], convention)


# --------------------------------------------------------------------------- quaternions
def quat_to_matrix(q: ArrayLike) -> Array:
    """Unit quaternions ``(w, x, y, z)`` (ABB's q1..q4) → rotation matrices.

    ``R = I + 2w[v]× + 2[v]×²`` for the normalised ``q = (w, v)`` (a quaternion read
    from a file, rounded to a few digits, is normalised first).

    Parameters
    ----------
    q : (..., 4) array_like
        Quaternions, scalar first; any non-zero norm.

    Returns
    -------
    R : (..., 3, 3) array
        Rotation matrices.

    Raises
    ------
    ValueError
        Last axis not 4, or a quaternion of (near) zero norm.
    """
    q = _f(q)
    if q.shape[-1:] != (4,):
        raise ValueError(f"expected quaternions of shape (..., 4), got {q.shape}")
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    if np.any(n < 1e-6):
        raise ValueError("a quaternion of zero norm is no rotation")
    w, x, y, z = np.moveaxis(q / n, -1, 0)
    R = np.empty((*q.shape[:-1], 3, 3))
    R[..., 0, 0] = 1 - 2 * (y * y + z * z)
    R[..., 0, 1] = 2 * (x * y - w * z)
    R[..., 0, 2] = 2 * (x * z + w * y)
    R[..., 1, 0] = 2 * (x * y + w * z)
    R[..., 1, 1] = 1 - 2 * (x * x + z * z)
    R[..., 1, 2] = 2 * (y * z - w * x)
    R[..., 2, 0] = 2 * (x * z - w * y)
    R[..., 2, 1] = 2 * (y * z + w * x)
    R[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return R


def matrix_to_quat(R: ArrayLike) -> Array:
    """Rotation matrices → unit quaternions ``(w, x, y, z)`` with ``w ≥ 0`` (Shepperd).

    Parameters
    ----------
    R : (..., 3, 3) array_like
        Rotation matrices.

    Returns
    -------
    q : (..., 4) array
        Unit quaternions, scalar first; the inverse of :func:`quat_to_matrix`.
    """
    return _matrix_to_quat(_f(R))


# --------------------------------------------------------------------------- continuity
#: Per convention: which angle of the triple turns about the first, middle and last axis
#: applied, ``R = R_a(θ[i0]) · R_b(θ[i1]) · R_c(θ[i2])`` (``zyz``: z, y, z; ``rpy``: z, y, x
#: with ``(r, p, y)`` stored; ``xyz``: x, y, z); and the other triple of the same rotation
#: ``θ[i0] + π, s·θ[i1] + c, θ[i2] + π``.
_SEQUENCES = {
    "zyz": ((0, 1, 2), (-1.0, 0.0)),
    "rpy": ((2, 1, 0), (-1.0, np.pi)),
    "xyz": ((0, 1, 2), (-1.0, np.pi)),
}
#: Below this distance of the middle angle from its singular value, only the sum (or
#: difference) of the outer angles is defined: it is shared out as in the reference.
GIMBAL_NEAR = 1e-9


def _wrap_to(theta: Array, ref: Array) -> Array:
    """``θ + 2πk`` nearest ``ref`` (elementwise), then back into (−π − ε, π + ε]."""
    t = theta + 2 * np.pi * np.round((ref - theta) / (2 * np.pi))
    t = np.where(t > np.pi + 1e-12, t - 2 * np.pi, t)
    return np.where(t < -np.pi - 1e-12, t + 2 * np.pi, t)


def _angle_diff(theta: Array, ref: Array) -> Array:
    """``θ − ref`` wrapped into (−π, π]."""
    return np.angle(np.exp(1j * (theta - ref)))


def nearest_angles(R: ArrayLike, convention: str, reference: ArrayLike) -> Array:
    """The angle triple of ``R`` nearest a reference triple (a program's angles stay
    continuous).

    Every rotation has two triples in a three-angle convention (``(θ0, θ1, θ2)`` and
    ``(θ0 + π, −θ1 (+π), θ2 + π)``, module table) and each angle is defined modulo 2π;
    of these the one nearest ``reference`` (max-norm of the differences wrapped into
    (−π, π]) is returned, each angle within [−π, π] (to 1e-12).  At gimbal lock (the
    middle angle within :data:`GIMBAL_NEAR` of its singular value) only ``θ0 ± θ2`` is
    defined: the change of it from the reference's is shared equally between θ0 and θ2.
    So a rotation equal to the reference's gives back the reference's angles (to
    rounding), the triple a controller interpolates from does not jump, and ``C −180°``
    does not become ``C +180°``.

    Parameters
    ----------
    R : (..., 3, 3) array_like
        Rotation matrices.
    convention : {"zyz", "rpy", "xyz"}
        Angle convention (module docstring).
    reference : (..., 3) array_like, rad
        Triples to stay near (broadcast with ``R``).

    Returns
    -------
    (..., 3) array, rad
        ``θ`` with ``angles_to_matrix(θ, convention) = R``.

    Raises
    ------
    ValueError
        A convention without the two-triple structure (``prj``).
    """
    if convention not in _SEQUENCES:
        raise ValueError(f"nearest_angles: convention {convention!r} not in {tuple(_SEQUENCES)}")
    R = _f(R)
    (i0, i1, i2), (s, c) = _SEQUENCES[convention]
    ref = np.broadcast_to(_f(reference), (*R.shape[:-2], 3))
    a = matrix_to_angles(R, convention)
    b = a.copy()
    b[..., i0] = a[..., i0] + np.pi
    b[..., i1] = s * a[..., i1] + c
    b[..., i2] = a[..., i2] + np.pi
    a, b = _wrap_to(a, ref), _wrap_to(b, ref)
    # distance on the circle: a reference of 179.9° is 0.2° from −179.9°, which is
    # written as such (angles stay within [−π, π]) rather than as the other triple
    da = np.max(np.abs(_angle_diff(a, ref)), axis=-1)
    db = np.max(np.abs(_angle_diff(b, ref)), axis=-1)
    out = np.where((db < da)[..., None], b, a)
    # gimbal lock: middle angle at its singular value, only θ0 + σ θ2 is defined
    mid = out[..., i1]
    if convention == "zyz":
        lock_plus = np.abs(np.sin(mid)) < GIMBAL_NEAR
        sigma = np.where(np.cos(mid) > 0, 1.0, -1.0)  # B = 0: A + C; B = π: A − C
    else:
        lock_plus = np.abs(np.cos(mid)) < GIMBAL_NEAR
        # rpy p = +π/2: y − r; p = −π/2: y + r.  xyz b = ±π/2: a ± c (same algebra)
        sigma = np.where(np.sin(mid) > 0, -1.0, 1.0)
        if convention == "xyz":
            sigma = -sigma
    if np.any(lock_plus):
        comb_new = out[..., i0] + sigma * out[..., i2]
        comb_ref = ref[..., i0] + sigma * ref[..., i2]
        d = _angle_diff(comb_new, comb_ref)
        locked = out.copy()
        locked[..., i0] = ref[..., i0] + d / 2
        locked[..., i2] = ref[..., i2] + sigma * d / 2
        locked[..., i1] = mid
        out = np.where(lock_plus[..., None], locked, out)
    return out


def nearest_rotvec(R: ArrayLike, reference: ArrayLike) -> Array:
    """The rotation vector of ``R`` nearest a reference one (Universal Robots' rx, ry, rz).

    ``log R = θu`` with θ ∈ [0, π]; ``(θ − 2π)u`` is the same rotation; the one
    nearer ``reference`` (Euclidean) is returned — a pose written as ``[…, 0, 3.1416, 0]``
    keeps that sign rather than flipping to ``−3.1416``.

    Parameters
    ----------
    R : (..., 3, 3) array_like
        Rotation matrices.
    reference : (..., 3) array_like, rad
        Rotation vectors to stay near.

    Returns
    -------
    (..., 3) array, rad
        Rotation vectors ``w`` with ``so3_exp(w) = R``.
    """
    w = so3_log(_f(R))
    ref = np.broadcast_to(_f(reference), w.shape)
    th = np.linalg.norm(w, axis=-1, keepdims=True)
    u = w / np.where(th > 0, th, 1.0)
    alt = w - 2 * np.pi * u
    pick = np.linalg.norm(alt - ref, axis=-1) < np.linalg.norm(w - ref, axis=-1)
    return np.where((pick & (th[..., 0] > 0))[..., None], alt, w)


def nearest_quat(R: ArrayLike, reference: ArrayLike) -> Array:
    """The unit quaternion of ``R`` with the sign of a reference one (``q`` and ``−q`` are
    the same rotation): ``q · sign(q·q_ref)``.

    Parameters
    ----------
    R : (..., 3, 3) array_like
        Rotation matrices.
    reference : (..., 4) array_like
        Quaternions ``(w, x, y, z)`` to stay near.

    Returns
    -------
    (..., 4) array
        Unit quaternions ``(w, x, y, z)``.
    """
    q = matrix_to_quat(R)
    ref = np.broadcast_to(_f(reference), q.shape)
    flip = np.sum(q * ref, axis=-1) < 0
    return np.where(flip[..., None], -q, q)
