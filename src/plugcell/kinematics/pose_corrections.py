"""A Cartesian correction of a pose as a controller applies it: KUKA RSI's ``RKorr``.

A correction ``o = (x, y, z, A, B, C)`` (m and rad) moves a path pose
``T_p = (R_p, p_p)`` to ``T_c`` in one of two frames (RSI's ``RefCorrSys``), with
``R_o = Rz(A)·Ry(B)·Rx(C)`` (KUKA's A, B, C: Z-Y'-X'')::

    base:  p_c = p_p + o_xyz,         R_c = R_o · R_p
    tool:  p_c = p_p + R_p · o_xyz,   R_c = R_p · R_o

— along and about the base frame's axes, or the TCP's; either way the rotation turns
the tool about the TCP point.  :func:`correct_pose` applies ``o``;
:func:`pose_correction` is its inverse, the correction that takes ``T_p`` to a given
``T_c``, and :func:`uncorrect_pose` the path pose a corrected one came from::

    base:  o_xyz = p_c − p_p,          R_o = R_c · R_pᵀ
    tool:  o_xyz = R_pᵀ (p_c − p_p),   R_o = R_pᵀ · R_c

with ``(A, B, C)`` of ``R_o`` (``B`` in ``[−π/2, π/2]``).  For a small correction
``A, B, C`` are the rotation vector's z, y and x to first order, so the correction
of a joint step ``δθ`` is ``o ≈ P · J(θ) · δθ`` (``P`` the swap of the rotation's
x and z; base frame) — checked against finite differences in the tests.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .rotations import matrix_to_rpy, rpy_to_matrix

__all__ = ["CORRECTION_FRAMES", "correct_pose", "pose_correction", "uncorrect_pose"]

Array = NDArray[np.float64]

#: The frames a Cartesian correction may be given in.
CORRECTION_FRAMES = ("base", "tool")


def _frame(frame: str) -> bool:
    if frame not in CORRECTION_FRAMES:
        raise ValueError(f"unknown correction frame {frame!r}: one of "
                         f"{', '.join(CORRECTION_FRAMES)}")
    return frame == "tool"


def correct_pose(T_path: ArrayLike, correction: ArrayLike, frame: str) -> Array:
    """``T_c``: the path pose with the correction applied (module docstring).

    Parameters
    ----------
    T_path : (4, 4) array_like
        ``T_p``, the pose without correction (m).
    correction : (6,) array_like
        ``o = (x, y, z, A, B, C)``: m and rad.
    frame : {"base", "tool"}
        Along the base frame's axes or the TCP's.

    Returns
    -------
    (4, 4) ndarray
        ``T_c``.
    """
    tool = _frame(frame)
    Tp = np.asarray(T_path, dtype=float)
    o = np.asarray(correction, dtype=float).reshape(6)
    Ro = rpy_to_matrix(o[5], o[4], o[3])
    T = Tp.copy()
    if tool:
        T[:3, 3] += Tp[:3, :3] @ o[:3]
        T[:3, :3] = Tp[:3, :3] @ Ro
    else:
        T[:3, 3] += o[:3]
        T[:3, :3] = Ro @ Tp[:3, :3]
    return T


def pose_correction(T_path: ArrayLike, T_corrected: ArrayLike, frame: str) -> Array:
    """``o``: the correction that takes ``T_p`` to ``T_c`` (the inverse of
    :func:`correct_pose`, module docstring).

    Parameters
    ----------
    T_path, T_corrected : (4, 4) array_like
        ``T_p`` and ``T_c`` (m).
    frame : {"base", "tool"}
        Along the base frame's axes or the TCP's.

    Returns
    -------
    (6,) ndarray
        ``(x, y, z, A, B, C)``: m and rad.
    """
    tool = _frame(frame)
    Tp = np.asarray(T_path, dtype=float)
    Tc = np.asarray(T_corrected, dtype=float)
    Rp, dp = Tp[:3, :3], Tc[:3, 3] - Tp[:3, 3]
    if tool:
        xyz, Ro = Rp.T @ dp, Rp.T @ Tc[:3, :3]
    else:
        xyz, Ro = dp, Tc[:3, :3] @ Rp.T
    roll, pitch, yaw = matrix_to_rpy(Ro)
    return np.array([*xyz, yaw, pitch, roll], dtype=float)


def uncorrect_pose(T_corrected: ArrayLike, correction: ArrayLike, frame: str) -> Array:
    """``T_p``: the path pose that ``correction`` took to ``T_c`` (the inverse of
    :func:`correct_pose` in its pose)::

        base:  R_p = R_oᵀ · R_c,   p_p = p_c − o_xyz
        tool:  R_p = R_c · R_oᵀ,   p_p = p_c − R_p · o_xyz

    Parameters
    ----------
    T_corrected : (4, 4) array_like
        ``T_c`` (m).
    correction : (6,) array_like
        ``o = (x, y, z, A, B, C)``: m and rad.
    frame : {"base", "tool"}
        Along the base frame's axes or the TCP's.

    Returns
    -------
    (4, 4) ndarray
        ``T_p``.
    """
    tool = _frame(frame)
    Tc = np.asarray(T_corrected, dtype=float)
    o = np.asarray(correction, dtype=float).reshape(6)
    Ro = rpy_to_matrix(o[5], o[4], o[3])
    T = Tc.copy()
    if tool:
        T[:3, :3] = Tc[:3, :3] @ Ro.T
        T[:3, 3] = Tc[:3, 3] - T[:3, :3] @ o[:3]
    else:
        T[:3, :3] = Ro.T @ Tc[:3, :3]
        T[:3, 3] = Tc[:3, 3] - o[:3]
    return T
