"""Robot units ↔ SI: the one boundary between the two.

Robot controllers, their programs, tracker software and people speak millimetres and
degrees, and write a pose as six numbers — ``x, y, z`` in mm and three angles in degrees
in a named convention.  Inside plugcell everything is metres, radians and 4×4
homogeneous transforms.  This module turns one into the other::

    T(x, y, z, a, b, c) = | R(a°, b°, c°)   10⁻³·(x, y, z)ᵀ |
                          | 0   0   0       1               |

with the rotation ``R`` of the convention (:mod:`plugcell.kinematics.rotations`):

=========  ==================================================  ===========================
name       R(a, b, c)                                          used by
=========  ==================================================  ===========================
``zyz``    Z-Y-Z Euler angles: Rz(a)·Ry(b)·Rz(c)               Comau PDL POSITION (A.4),
                                                               the tracker's ``euler2tr``
``rpy``    roll-pitch-yaw about fixed X, Y, Z: Rz(c)·Ry(b)·Rx(a)  the tracker's ``rpy2tr``
``xyz``    intrinsic X-Y-Z: Rx(a)·Ry(b)·Rz(c)
``prj``    projective angles (rotations.py)                    the tracker's ``prj2tr``
=========  ==================================================  ===========================

The names are those of :data:`plugcell.kinematics.rotations.CONVENTIONS`, which
implements each convention once.  ``"euler"``, the name this module used for ``zyz``
before issue #33, is still accepted with a :class:`DeprecationWarning`
(:func:`convention_name`); the tracker's option words ``euler2tr``/``tr2euler``
(thesis Table 7-3, on the wire) are unchanged.

Robot *programs* (``plugcell compensate --program``, :mod:`plugcell.io.programs`) write a
pose in their vendor's own notation — :data:`NOTATIONS`, converted by
:func:`pose_from_notation` and :func:`notation_from_pose`:

=============  =========================================  =================================
notation       numbers                                    R
=============  =========================================  =================================
``kuka``       X, Y, Z mm; A, B, C deg                    Rz(A)·Ry(B)·Rx(C) (ZYX intrinsic)
``abb``        x, y, z mm; q1, q2, q3, q4                 unit quaternion q1 + q2 i + q3 j + q4 k
``ur``         x, y, z **m**; rx, ry, rz **rad**          rotation vector: exp([r]×)
``fanuc``      X, Y, Z mm; W, P, R deg                    Rz(R)·Ry(P)·Rx(W) (XYZ fixed)
``comau``      X, Y, Z mm; A, B, C deg                    Rz(A)·Ry(B)·Rz(C) (ZYZ Euler)
=============  =========================================  =================================

The robot service, the simulated controller, the tracker service, the compute service
and the web UI all convert here (``devices/robot/poses.py``, ``devices/tracker/frames.py``
and ``pdl/conversion.py`` only add their own checks and errors).
"""

from __future__ import annotations

import warnings

import numpy as np
from numpy.typing import ArrayLike, NDArray

from plugcell.kinematics.rotations import (
    CONVENTIONS,
    angles_to_matrix,
    matrix_to_pose,
    nearest_angles,
    nearest_quat,
    nearest_rotvec,
    pose_to_matrix,
    quat_to_matrix,
)
from plugcell.kinematics.transforms import so3_exp

Array = NDArray[np.float64]

#: Metres per millimetre, and millimetres per metre.
M_PER_MM = 1e-3
MM_PER_M = 1e3
#: Radians per degree: a revolute joint's reading scale.
DEG = np.pi / 180.0
#: A Comau robot's convention: PDL's POSITION (thesis A.4).
ROBOT_CONVENTION = "zyz"
#: Old convention names still accepted (with a DeprecationWarning) → the name to use.
DEPRECATED_CONVENTIONS = {"euler": "zyz"}

#: A vendor's pose notation (module table): (numbers, metres per length unit, angle
#: convention of rotations.py or ``"quat"``/``"rotvec"``, order of the angles in R's
#: convention's triple, radians per angle unit).
NOTATIONS: dict[str, tuple[int, float, str, tuple[int, ...], float]] = {
    "kuka": (6, M_PER_MM, "rpy", (2, 1, 0), DEG),  # (A, B, C) = (yaw, pitch, roll)
    "abb": (7, M_PER_MM, "quat", (0, 1, 2, 3), 1.0),
    "ur": (6, 1.0, "rotvec", (0, 1, 2), 1.0),
    "fanuc": (6, M_PER_MM, "rpy", (0, 1, 2), DEG),
    "comau": (6, M_PER_MM, "zyz", (0, 1, 2), DEG),
}

__all__ = [
    "CONVENTIONS",
    "DEG",
    "DEPRECATED_CONVENTIONS",
    "MM_PER_M",
    "M_PER_MM",
    "NOTATIONS",
    "ROBOT_CONVENTION",
    "UnitsError",
    "convention_name",
    "joints_from_si",
    "joints_to_si",
    "notation_from_pose",
    "pose_from_notation",
    "pose_from_robot",
    "robot_from_pose",
]


class UnitsError(ValueError):
    """Six numbers that are no pose (the message says why)."""


def convention_name(name: str) -> str:
    """The name of an angle convention in :data:`CONVENTIONS`, from what a user wrote.

    Parameters
    ----------
    name : str
        ``"zyz"``, ``"rpy"``, ``"xyz"``, ``"prj"``, or an old name of
        :data:`DEPRECATED_CONVENTIONS` (``"euler"``: ``"zyz"``, with a
        :class:`DeprecationWarning`).

    Returns
    -------
    str
        The name rotations.py knows.

    Raises
    ------
    UnitsError
        An unknown name (the known ones listed).
    """
    if name in CONVENTIONS:
        return name
    if name in DEPRECATED_CONVENTIONS:
        new = DEPRECATED_CONVENTIONS[name]
        warnings.warn(f"angle convention {name!r} is deprecated: use {new!r}",
                      DeprecationWarning, stacklevel=3)
        return new
    raise UnitsError(f"unknown angle convention {name!r}; expected one of "
                     f"{', '.join(CONVENTIONS)}")


def pose_from_robot(values: ArrayLike, convention: str = ROBOT_CONVENTION) -> Array:
    """``x, y, z`` (mm), three angles (deg) in ``convention`` → 4×4 transform (m).

    Parameters
    ----------
    values
        Six numbers, shape ``(6,)`` (any shape of six elements is flattened).
    convention
        ``"zyz"``, ``"rpy"``, ``"xyz"`` or ``"prj"`` (module doc; :func:`convention_name`).

    Returns
    -------
    ndarray, shape (4, 4)
        The homogeneous transform, translation in metres.

    Raises
    ------
    UnitsError
        Not six finite numbers, or angles outside the convention's domain.
    """
    name = convention_name(convention)
    a = np.asarray(values, dtype=float).reshape(-1)
    if a.shape != (6,):
        raise UnitsError(f"expected 6 numbers (x, y, z mm, 3 angles deg), got {a.size}")
    if not np.all(np.isfinite(a)):
        raise UnitsError("values must be finite")
    try:
        return pose_to_matrix(a[:3] * M_PER_MM, np.deg2rad(a[3:]), name)
    except ValueError as exc:  # projective angles outside their domain
        raise UnitsError(str(exc)) from None


def robot_from_pose(T: ArrayLike, convention: str = ROBOT_CONVENTION) -> Array:
    """4×4 transform (m) → ``x, y, z`` (mm), three angles (deg) in ``convention``.

    Parameters
    ----------
    T
        Homogeneous transform, shape ``(4, 4)``, translation in metres.
    convention
        ``"zyz"``, ``"rpy"``, ``"xyz"`` or ``"prj"`` (module doc; :func:`convention_name`).

    Returns
    -------
    ndarray, shape (6,)
        ``x, y, z`` in millimetres, then the three angles in degrees.

    Raises
    ------
    UnitsError
        An unknown convention.
    """
    xyz, angles = matrix_to_pose(np.asarray(T, dtype=float), convention_name(convention))
    return np.concatenate([np.asarray(xyz) * MM_PER_M, np.rad2deg(angles)])



def pose_from_notation(values: ArrayLike, notation: str) -> Array:
    """Poses written in a vendor's notation (module table) → 4×4 transforms (m).

    ``T = [R(angles) s·(x, y, z); 0 0 0 1]`` with the notation's length scale ``s`` and
    rotation ``R``; a quaternion is normalised first (files round it).

    Parameters
    ----------
    values : (..., k) array_like
        ``k`` = 6 (7 for ``abb``) numbers per pose, in the notation's units.
    notation : str
        A key of :data:`NOTATIONS`.

    Returns
    -------
    (..., 4, 4) ndarray
        Homogeneous transforms, translation in metres.

    Raises
    ------
    UnitsError
        Unknown notation, the wrong count of numbers, non-finite values or a zero
        quaternion.
    """
    k, length, conv, order, angle = _notation(notation)
    v = np.asarray(values, dtype=float)
    if v.shape[-1:] != (k,):
        raise UnitsError(f"{notation}: expected {k} numbers a pose, got shape {v.shape}")
    if not np.all(np.isfinite(v)):
        raise UnitsError("values must be finite")
    rot = v[..., 3:][..., list(order)] * angle
    if conv == "quat":
        try:
            R = quat_to_matrix(rot)
        except ValueError as exc:
            raise UnitsError(str(exc)) from None
    elif conv == "rotvec":
        R = so3_exp(rot)
    else:
        R = angles_to_matrix(rot, conv)
    T = np.zeros((*v.shape[:-1], 4, 4))
    T[..., :3, :3] = R
    T[..., :3, 3] = v[..., :3] * length
    T[..., 3, 3] = 1.0
    return T


def notation_from_pose(T: ArrayLike, notation: str, reference: ArrayLike) -> Array:
    """4×4 transforms (m) → a vendor's notation, the representation nearest ``reference``.

    The inverse of :func:`pose_from_notation`.  A rotation has several triples (and a
    quaternion two signs): the one nearest the pose's previous numbers is written
    (:func:`~plugcell.kinematics.rotations.nearest_angles`, ``nearest_quat``,
    ``nearest_rotvec``), so a program's angles change only as much as its rotation does.

    Parameters
    ----------
    T : (..., 4, 4) array_like, m
        Poses.
    notation : str
        A key of :data:`NOTATIONS`.
    reference : (..., k) array_like
        The previous numbers of each pose, in the notation (only the angles are used).

    Returns
    -------
    (..., k) ndarray
        The numbers, in the notation's units.

    Raises
    ------
    UnitsError
        Unknown notation.
    """
    k, length, conv, order, angle = _notation(notation)
    T = np.asarray(T, dtype=float)
    ref = np.asarray(reference, dtype=float)[..., 3:][..., list(order)] * angle
    R = T[..., :3, :3]
    if conv == "quat":
        rot = nearest_quat(R, ref)
    elif conv == "rotvec":
        rot = nearest_rotvec(R, ref)
    else:
        rot = nearest_angles(R, conv, ref)
    out = np.empty((*T.shape[:-2], k))
    out[..., :3] = T[..., :3, 3] / length
    out[..., 3:][..., list(order)] = rot / angle
    return out


def _notation(notation: str) -> tuple[int, float, str, tuple[int, ...], float]:
    try:
        return NOTATIONS[notation]
    except KeyError:
        raise UnitsError(f"unknown pose notation {notation!r}; expected one of "
                         f"{sorted(NOTATIONS)}") from None


def _scale(joint_scale: np.ndarray | None, n: int) -> float | np.ndarray:
    if joint_scale is None:
        return DEG
    scale = np.asarray(joint_scale, dtype=float)
    if scale.shape not in ((), (n,)):  # one scale for all columns, or one a column
        raise ValueError(f"joint_scale has {scale.size} entries for {n} joint columns")
    if not np.all(np.isfinite(scale) & (scale != 0)):
        raise ValueError(f"joint_scale must be finite and non-zero, got {scale.tolist()}")
    return scale


def joints_to_si(values: np.ndarray, joint_scale: np.ndarray | None = None) -> np.ndarray:
    """Joint readings in robot units (degrees; a prismatic joint: mm) → SI: ``q = s · v``.

    The one conversion of joint readings: measurement files, plan files and the compute
    service's functions use it.

    Parameters
    ----------
    values : (N, n) ndarray
        The joint readings ``j1..jn``, in robot units.
    joint_scale : (n,) array_like, optional
        SI per file unit of each column (``desc.reading_scale()``: π/180 for degrees,
        1e-3 for the mm of a prismatic joint); default π/180 for all.

    Returns
    -------
    (N, n) ndarray
        The joints in rad (a prismatic joint: m).

    Raises
    ------
    ValueError
        ``joint_scale`` neither a scalar nor of shape ``(n,)``, or not finite and
        non-zero.
    """
    return values * _scale(joint_scale, values.shape[-1])


def joints_from_si(joints: np.ndarray, joint_scale: np.ndarray | None = None) -> np.ndarray:
    """Joints in SI → robot units (degrees; a prismatic joint: mm): ``v = q / s``.

    Parameters
    ----------
    joints : (N, n) ndarray
        Joints in rad (a prismatic joint: m).
    joint_scale : (n,) array_like, optional
        SI per file unit of each column; default π/180 (degrees) for all.

    Returns
    -------
    (N, n) ndarray
        The joint readings ``j1..jn`` in robot units.

    Raises
    ------
    ValueError
        ``joint_scale`` neither a scalar nor of shape ``(n,)``, or not finite and
        non-zero.
    """
    return joints / _scale(joint_scale, joints.shape[-1])
