"""The one differential pose error convention used everywhere in plugcell.

``pose_error(T_target, T_actual)`` returns ``Δx = [Δp; φ]`` (shape ``(..., 6)``):

* ``Δp = p_target − p_actual`` — the displacement of the *point* (TCP/flange
  origin), expressed in the common reference (base) frame;
* ``φ = vee(skew(R_target·R_actualᵀ − I))`` — the rotational part of thesis eq.
  (B.15): to first order ``R_target = exp([φ]×)·R_actual``, i.e. φ is the small
  rotation, about base-frame axes, that takes the actual orientation to the
  target one.

Why not B.15's translational part: ``(T_M − T_N)·T_N⁻¹`` has translation
``p_M − R_M R_Nᵀ p_N ≈ Δp − φ × p_N``, the displacement of the point that sits at
the *base origin* (a spatial twist).  Referencing the translation at the TCP
instead makes ``Δp`` the quantity a metrology system measures and a user reads,
and the matching Jacobian columns are the geometric-Jacobian form
``[z_{i−1} × (p_tcp − p_{i−1}); z_{i−1}]`` of thesis eq. (6.37): for a small joint
motion ``dq``, ``pose_error(T(q + dq), T(q)) ≈ J(q)·dq`` with the manipulator
Jacobian of :mod:`plugcell.kinematics.jacobian`.

``pose_error_exact`` replaces φ by the exact log map ``so3_log(R_target·R_actualᵀ)``
(same first-order value, exact for large rotations).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from plugcell.kinematics.transforms import so3_log, vee

Array = NDArray[np.float64]

__all__ = ["pose_error", "pose_error_exact", "rotation_error"]


def _rel(T_target: ArrayLike, T_actual: ArrayLike) -> tuple[Array, Array]:
    Tt = np.asarray(T_target, dtype=float)
    Ta = np.asarray(T_actual, dtype=float)
    dp = Tt[..., :3, 3] - Ta[..., :3, 3]
    Rrel = Tt[..., :3, :3] @ np.swapaxes(Ta[..., :3, :3], -1, -2)
    return dp, Rrel


def pose_error(T_target: ArrayLike, T_actual: ArrayLike) -> Array:
    """First-order pose error ``Δx = [p_t − p_a; vee(R_t R_aᵀ − I)]``.

    Rotational part as in thesis eq. (B.15), ``φ = vee(R_t R_aᵀ − I)`` (so
    ``R_t ≈ exp([φ]×) R_a``); translational part referenced at the point, not at the
    base origin (see the module docstring).  Both parts in the base frame.

    Parameters
    ----------
    T_target : (..., 4, 4) array_like, m
        Target poses ``[R_t p_t; 0 1]``.
    T_actual : (..., 4, 4) array_like, m
        Actual poses ``[R_a p_a; 0 1]``; broadcast with ``T_target``.

    Returns
    -------
    dx : (..., 6) array
        ``[Δp (m); φ (rad)]``.
    """
    dp, Rrel = _rel(T_target, T_actual)
    return np.concatenate([dp, vee(Rrel)], axis=-1)


def pose_error_exact(T_target: ArrayLike, T_actual: ArrayLike) -> Array:
    """Exact pose error ``Δx = [p_t − p_a; log(R_t R_aᵀ)∨]``.

    As :func:`pose_error` with the exact rotation vector ``φ = so3_log(R_t·R_aᵀ)``
    (equal to first order, exact for large rotations).

    Parameters
    ----------
    T_target : (..., 4, 4) array_like, m
        Target poses.
    T_actual : (..., 4, 4) array_like, m
        Actual poses; broadcast with ``T_target``.

    Returns
    -------
    dx : (..., 6) array
        ``[Δp (m); φ (rad)]``, ``‖φ‖ ≤ π``.
    """
    dp, Rrel = _rel(T_target, T_actual)
    return np.concatenate([dp, so3_log(Rrel)], axis=-1)


def rotation_error(T_target: ArrayLike, T_actual: ArrayLike) -> Array:
    """Angle of the rotation between two orientations, ``Δφ = ‖log(R_t R_aᵀ)∨‖``.

    Parameters
    ----------
    T_target : (..., 4, 4) array_like
        Target poses (only the rotation block is read).
    T_actual : (..., 4, 4) array_like
        Actual poses; broadcast with ``T_target``.

    Returns
    -------
    angle : (...) array, rad
        Rotation angles in [0, π].
    """
    _, Rrel = _rel(T_target, T_actual)
    return np.linalg.norm(so3_log(Rrel), axis=-1)
