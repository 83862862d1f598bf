"""Following a Cartesian path in joint space: Newton steps from a nearby solution.

Along a path the joint solution of the next pose is a small step from the previous
one, so instead of the global search of :func:`plugcell.kinematics.inverse` (seeds,
restarts, ~4 ms) a few Newton steps from that solution suffice, and they stay on its
branch (configuration)::

    e = pose_error_exact(T_target, T(q))        (position, rotation vector)
    q ← q + Jᵀ (J Jᵀ + λI)⁻¹ e,   λ = 10⁻¹² · tr(J Jᵀ)/6

with ``J`` the manipulator Jacobian of the TCP w.r.t. the readings
(:func:`plugcell.kinematics.jacobian_from_fk`, loops through their closure) — the same
update as ``inverse``'s iterations, with a vanishing damping: Newton's method, which
converges quadratically from a close seed.  The joint rates follow from the TCP's
twist: ``q̇ = J⁺·[v; ω]`` and ``q̈ = J⁺·([a; α] − J̇q̇)``, ``J̇q̇`` by a central
difference of ``J`` along ``q̇``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from plugcell.kinematics.description import RobotDescription
from plugcell.kinematics.forward import forward
from plugcell.kinematics.jacobian import jacobian_from_fk
from plugcell.kinematics.parameters import GeometricParameters
from plugcell.kinematics.pose_error import pose_error_exact

Array = NDArray[np.float64]

__all__ = ["joint_rates", "tcp_jacobian", "track"]

#: Largest joint step (rad) of one Newton step.
MAX_STEP = 0.5
#: Relative damping of the steps (numerical safety only).
DAMPING = 1e-12


def tcp_jacobian(desc: RobotDescription, params: GeometricParameters, q: Array,
                 closure: str) -> tuple[Array, Array]:
    """TCP poses and Jacobians at readings ``q`` (forward kinematics, eq. 6.37).

    Parameters
    ----------
    desc, params, closure
        The robot model (as :func:`plugcell.kinematics.forward`).
    q : (B, n) array, rad

    Returns
    -------
    T : (B, 4, 4) array, m
        TCP poses (NaN where a loop cannot close).
    J : (B, 6, n) array
        Manipulator Jacobians of the TCP w.r.t. the readings.
    """
    fk = forward(desc, params, q, closure, raise_errors=False)
    return fk.tcp, jacobian_from_fk(desc, fk, "tcp")


def _step(J: Array, e: Array) -> Array:
    JJt = J @ np.swapaxes(J, -1, -2)
    lam = DAMPING * np.trace(JJt, axis1=-2, axis2=-1)[..., None, None] / 6.0 + 1e-300
    y = np.linalg.solve(JJt + lam * np.eye(6), e[..., None])[..., 0]
    dq = np.einsum("bji,bj->bi", J, y)
    big = np.max(np.abs(dq), axis=-1)
    return dq * np.minimum(1.0, MAX_STEP / np.maximum(big, 1e-300))[:, None]


def track(
    desc: RobotDescription,
    params: GeometricParameters,
    T: Array,
    seed: Array,
    closure: str,
    tol: float = 1e-11,
    max_iterations: int = 12,
) -> tuple[Array, NDArray[np.bool_]]:
    """Newton steps (module docstring) from ``seed`` (B, n) towards TCP poses ``T`` (B, 4, 4).

    Parameters
    ----------
    desc, params, closure
        The robot model (as :func:`plugcell.kinematics.forward`).
    T : (B, 4, 4) array, m
        TCP poses in the robot base frame.
    seed : (B, n) array, rad
        Nearby solutions.
    tol : float
        Convergence: ``‖Δp‖ < tol`` m and ``‖φ‖ < tol`` rad.
    max_iterations : int

    Returns
    -------
    q : (B, n) array, rad
    converged : (B,) bool array
    """
    q = np.array(seed, dtype=float)
    B = q.shape[0]
    done = np.zeros(B, dtype=bool)
    active = np.arange(B)
    for _ in range(max_iterations + 1):
        fk = forward(desc, params, q[active], closure, raise_errors=False)
        e = pose_error_exact(T[active], fk.tcp)
        ok = np.isfinite(e).all(axis=-1)
        conv = ok & (np.linalg.norm(e[:, :3], axis=-1) < tol) & \
            (np.linalg.norm(e[:, 3:], axis=-1) < tol)
        done[active[conv]] = True
        keep = ok & ~conv
        if not np.any(keep):
            break
        J = jacobian_from_fk(desc, fk, "tcp")  # only when a step is needed
        active, J, e = active[keep], J[keep], e[keep]
        q[active] += _step(J, e)
    return q, done


def joint_rates(
    desc: RobotDescription,
    params: GeometricParameters,
    q: Array,
    twist: Array,
    twist_rate: Array | None,
    closure: str,
) -> tuple[Array, Array | None, Array]:
    """Joint velocities (and accelerations) that give the TCP twist (and its rate).

    ``q̇ = J⁺·[v; ω]``; ``q̈ = J⁺·([a; α] − J̇q̇)`` with
    ``J̇q̇ ≈ (J(q + εq̇) − J(q − εq̇))/(2ε) · q̇``, ``ε = 10⁻⁶/max(‖q̇‖∞, 1)``.

    Parameters
    ----------
    q : (B, n) array, rad
    twist : (B, 6) array
        ``[v (m/s); ω (rad/s)]`` of the TCP, base frame.
    twist_rate : (B, 6) array or None
        ``[a (m/s²); α (rad/s²)]``; None: no accelerations.

    Returns
    -------
    qd : (B, n) array, rad/s
    qdd : (B, n) array or None, rad/s²
    J : (B, 6, n) array
        The Jacobian at ``q``.
    """
    _, J = tcp_jacobian(desc, params, q, closure)
    Jp = np.linalg.pinv(J)
    qd = np.einsum("bij,bj->bi", Jp, twist)
    if twist_rate is None:
        return qd, None, J
    eps = 1e-6 / np.maximum(np.max(np.abs(qd), axis=-1), 1.0)[:, None]
    _, Jplus = tcp_jacobian(desc, params, q + eps * qd, closure)
    _, Jminus = tcp_jacobian(desc, params, q - eps * qd, closure)
    Jdot_qd = np.einsum("bij,bj->bi", (Jplus - Jminus) / (2.0 * eps[:, :, None]), qd)
    qdd = np.einsum("bij,bj->bi", Jp, twist_rate - Jdot_qd)
    return qd, qdd, J
