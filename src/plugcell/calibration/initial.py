"""Initial BASE and PROBE from the measurements themselves (no appendix-D procedure needed).

The tracker measures ``T_i = BASE · F_i · PROBE`` (eq. 6.23) with ``F_i`` the flange
pose the nominal model gives for the joint readings of pose *i*.  Before the
identification can linearise, BASE and PROBE must be known roughly — with the
tracker anywhere in the cell and the target mounted at any angle:

* **6-DOF data: closed-form AX = YB.**  With ``A_ij = F_i⁻¹F_j`` and
  ``B_ij = T_i⁻¹T_j`` the PROBE ``X`` solves the hand-eye equation ``A X = X B``:
  the rotation axes satisfy ``log R_A = R_X log R_B``, so ``R_X`` is the
  orthogonal Procrustes (Kabsch) fit of the rotation vectors (Park & Martin 1994),
  and ``(R_A − I) t_X = R_X t_B − t_A`` gives ``t_X`` by linear least squares.
  Then ``BASE = T_i X⁻¹ F_i⁻¹``, averaged over the poses (rotation projected
  back onto SO(3)).
* **6-DOF, robust variant**: the rigid registration below for BASE and the target
  offset, then ``R_X`` as the rotation average of ``(R_BASE R_F,i)ᵀ R_i`` — it needs
  no rotation between poses, so it also serves poses that all share one
  orientation (e.g. ISO 9283 cubes), where AX = YB is degenerate.
  :func:`estimate_base_probe_poses` tries both and keeps the better.
* **Positions only: rigid registration.**  The unknowns are ``R_Y, t_Y`` (BASE) and
  the target offset ``t_X`` in the flange frame: alternate a Kabsch registration
  of the predicted target points onto the measured ones
  (:func:`plugcell.metrology.fit_rigid_transform`)
  with the linear least-squares solution for ``t_X, t_Y`` given ``R_Y``.  The
  target's orientation is not observed; PROBE's rotation is set to identity.

Both are vectorised over poses and exact for noise-free data of a nominal robot.

**Poses that hardly turn the flange** (a surface scan at constant tool orientation)
do not determine the target offset ``t_X``: ``R_F,i t_X`` is then nearly the same for
every pose and trades against ``t_Y``.  The linear solve for ``(t_X, t_Y)`` is then
truncated — directions whose singular value is below ``rel_tol`` of the largest (the
columns all have norm √N) keep ``t_X`` at ``prior_offset`` (minimum-norm deviation from
it) — and the hand-eye estimate refuses (its ``(R_A − I)`` has singular values of the
order of the pair rotations, below ``rel_tol·√pairs``), instead of returning an offset
that wandered by metres along the undetermined direction (:mod:`.determinacy`).
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from plugcell.calibration.linalg import least_squares, null_space, restricted_basis
from plugcell.kinematics.transforms import invert, so3_log
from plugcell.metrology import fit_rigid_transform

Array = NDArray[np.float64]

__all__ = [
    "FrameEstimate",
    "estimate_base_probe",
    "estimate_base_probe_poses",
    "estimate_base_probe_positions",
]


class InitialEstimateError(ValueError):
    """The data do not determine BASE and PROBE (too few or degenerate poses)."""


@dataclass(frozen=True)
class FrameEstimate:
    """Initial BASE and PROBE and the rms position misfit they leave.

    Attributes
    ----------
    base : (4, 4) array, m
        BASE (robot base frame in the measurement frame).
    probe : (4, 4) array, m
        PROBE (target in the flange frame).
    rms : float, m
        ``√(Σ_i ‖p(BASE F_i PROBE) − p_i‖² / N)``.
    """

    base: Array
    probe: Array
    rms: float


def _project_rotation(M: Array) -> Array:
    U, _, Vt = np.linalg.svd(M)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt)) or 1.0])
    return U @ D @ Vt


def _pairs(n: int) -> tuple[Array, Array]:
    i = np.arange(n)
    a = np.concatenate([i, i])
    b = np.concatenate([(i + 1) % n, (i + n // 2) % n])
    keep = a != b
    return a[keep], b[keep]


def estimate_base_probe(flange: ArrayLike, measured: ArrayLike, *,
                        rel_tol: float = 0.0) -> FrameEstimate:
    """Closed-form BASE and PROBE from 6-DOF data (hand-eye ``A X = X B``, module docstring).

    With ``A_ij = F_i⁻¹F_j``, ``B_ij = T_i⁻¹T_j``: ``R_X = argmin Σ ‖log R_A − R_X log R_B‖²``
    (Kabsch), ``(R_A − I) t_X = R_X t_B − t_A`` (least squares), then
    ``BASE = proj_SO(3)(Σ_i R(T_i X⁻¹ F_i⁻¹))`` with the mean translation.

    Parameters
    ----------
    flange : (N, 4, 4) array_like, m
        Nominal flange poses in the robot base frame, ``N ≥ 3``.
    measured : (N, 4, 4) array_like, m
        Measured target poses in the tracker frame.
    rel_tol : float
        Refuse when the smallest singular value of the stacked ``(R_A − I)`` is below
        ``rel_tol · √pairs`` (the pair rotations do not determine ``t_X``; default 0:
        never).

    Returns
    -------
    FrameEstimate
        BASE, PROBE (m) and the rms position misfit (m).

    Raises
    ------
    InitialEstimateError
        Shape mismatch, fewer than 3 poses, fewer than 2 pose pairs that rotate
        the flange by more than 1e-3 rad, or pair rotations that do not determine the
        PROBE position (``rel_tol``).
    """
    F = np.asarray(flange, dtype=float)
    T = np.asarray(measured, dtype=float)
    if F.shape != T.shape or F.ndim != 3 or F.shape[1:] != (4, 4):
        raise InitialEstimateError(f"flange {F.shape} and measured {T.shape} must be (N, 4, 4)")
    N = len(F)
    if N < 3:
        raise InitialEstimateError(f"need at least 3 poses to estimate BASE and PROBE, got {N}")
    i, j = _pairs(N)
    A = invert(F[i]) @ F[j]
    B = invert(T[i]) @ T[j]
    alpha = so3_log(A[:, :3, :3])
    beta = so3_log(B[:, :3, :3])
    w = np.linalg.norm(alpha, axis=1)
    ok = w > 1e-3
    if np.count_nonzero(ok) < 2:
        raise InitialEstimateError("the poses hardly rotate the flange: PROBE is undetermined")
    # Kabsch: alpha ≈ R_X beta
    Hm = beta[ok].T @ alpha[ok]
    U, _, Vt = np.linalg.svd(Hm)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0])
    RX = Vt.T @ D @ U.T
    # (R_A − I) t_X = R_X t_B − t_A
    lhs = (A[:, :3, :3] - np.eye(3)).reshape(-1, 3)
    rhs = (B[:, :3, 3] @ RX.T - A[:, :3, 3]).reshape(-1)
    if rel_tol > 0 and np.linalg.svd(lhs, compute_uv=False)[-1] < rel_tol * np.sqrt(len(A)):
        raise InitialEstimateError("the poses hardly rotate the flange: the PROBE position "
                                   "is undetermined")
    tX, *_ = np.linalg.lstsq(lhs, rhs, rcond=None)
    X = np.eye(4)
    X[:3, :3], X[:3, 3] = RX, tX
    Y = T @ invert(X) @ invert(F)
    RY = _project_rotation(Y[:, :3, :3].sum(axis=0))
    tY = Y[:, :3, 3].mean(axis=0)
    base = np.eye(4)
    base[:3, :3], base[:3, 3] = RY, tY
    pred = base @ F @ X
    rms = float(np.sqrt(np.mean(np.sum((pred[:, :3, 3] - T[:, :3, 3]) ** 2, axis=1))))
    return FrameEstimate(base=base, probe=X, rms=rms)


def estimate_base_probe_positions(
    flange: ArrayLike, positions: ArrayLike, *, probe_offset: ArrayLike | None = None,
    iterations: int = 20, prior_offset: ArrayLike | None = None, rel_tol: float = 0.0,
) -> FrameEstimate:
    """BASE and the target offset from target positions by alternating registration.

    Model ``p_i = R_Y (p_F,i + R_F,i t_X) + t_Y``: alternate ``R_Y`` from a Kabsch
    registration of the predicted points onto the measured ones with the linear
    least-squares ``(t_X, t_Y)`` of ``p_i − R_Y p_F,i = R_Y R_F,i t_X + t_Y``, until the
    offset moves less than 1e-12 m.  PROBE's rotation is the identity.

    Parameters
    ----------
    flange : (N, 4, 4) array_like, m
        Nominal flange poses, ``N ≥ 4`` (not coplanar with a single orientation).
    positions : (N, 3) array_like, m
        Measured target positions, tracker frame.
    probe_offset : (3,) array_like, m, optional
        Starting target offset ``t_X`` in the flange frame (default 0).
    iterations : int
        Most alternations (must be ≥ 1).
    prior_offset : (3,) array_like, m, optional
        The offset kept along directions the poses do not determine (default: the
        starting offset).
    rel_tol : float
        Relative singular value of ``[R_Y R_F,i  I]`` (columns of norm √N) below which a
        direction is undetermined (module docstring; default 0: plain least squares).

    Returns
    -------
    FrameEstimate
        BASE, PROBE ``[I t_X; 0 1]`` (m) and the rms position misfit (m).

    Raises
    ------
    InitialEstimateError
        Malformed shapes or fewer than 4 poses.
    ValueError
        ``iterations < 1``.
    """
    if iterations < 1:
        raise ValueError(f"iterations must be ≥ 1, got {iterations}")
    F = np.asarray(flange, dtype=float)
    P = np.asarray(positions, dtype=float)
    N = len(F)
    if F.shape != (N, 4, 4) or P.shape != (N, 3):
        raise InitialEstimateError(
            f"flange {F.shape} must be (N, 4, 4), positions {P.shape} (N, 3)")
    if N < 4:
        raise InitialEstimateError(
            f"need at least 4 poses to estimate BASE and the target, got {N}")
    tX = np.zeros(3) if probe_offset is None else np.asarray(probe_offset, dtype=float)
    prior = tX.copy() if prior_offset is None else np.asarray(prior_offset, dtype=float)
    RF, pF = F[:, :3, :3], F[:, :3, 3]
    for _ in range(iterations):
        pts = pF + RF @ tX
        fit = fit_rigid_transform(pts, P)
        RY = fit.rotation
        sol = _translations(RY, RF, pF, P, prior, rel_tol)
        step = np.linalg.norm(sol[:3] - tX)
        tX = sol[:3]
        tY = sol[3:]
        if step < 1e-12:
            break
    base = np.eye(4)
    base[:3, :3], base[:3, 3] = RY, tY
    X = np.eye(4)
    X[:3, 3] = tX
    return FrameEstimate(base=base, probe=X, rms=_rms(base, F, X, P))


def _translations(RY: Array, RF: Array, pF: Array, P: Array, prior: Array,
                  rel_tol: float) -> Array:
    """``(t_X, t_Y)`` (6,) m for a fixed BASE rotation ``R_Y``: least squares of the
    linear ``P_i − R_Y p_F,i = R_Y R_F,i t_X + t_Y``; directions the poses do not see
    (relative singular value below ``rel_tol``) keep ``t_X`` at ``prior``, ``t_Y`` its
    best match."""
    N = len(P)
    M = np.concatenate([RY @ RF, np.broadcast_to(np.eye(3), (N, 3, 3))], axis=2)
    rhs = P - pF @ RY.T
    M2, b = M.reshape(-1, 6), rhs.reshape(-1)
    _, V0 = null_space(M2, rel_tol) if rel_tol > 0 else (None, np.zeros((6, 0)))
    if V0.shape[1] == 0:
        sol, *_ = np.linalg.lstsq(M2, b, rcond=None)
        return sol
    x0 = np.concatenate([prior, np.mean(rhs - (RY @ RF) @ prior, axis=0)])
    Z = restricted_basis(V0, np.ones(6))
    return x0 + Z @ least_squares(M2 @ Z, b - M2 @ x0)


def _rms(base: Array, F: Array, X: Array, P: Array) -> float:
    pred = (base @ F @ X)[:, :3, 3]
    return float(np.sqrt(np.mean(np.sum((pred - P) ** 2, axis=1))))


def estimate_base_probe_poses(flange: ArrayLike, measured: ArrayLike, *,
                              prior_offset: ArrayLike | None = None,
                              rel_tol: float = 0.0) -> FrameEstimate:
    """6-DOF initial BASE/PROBE: the better of the hand-eye and registration estimates.

    Candidates: :func:`estimate_base_probe` (if the poses rotate enough) and
    :func:`estimate_base_probe_positions` with ``R_X = proj_SO(3)(Σ_i (R_BASE R_F,i)ᵀ R_i)``;
    the one with the smaller rms position misfit is returned.

    Parameters
    ----------
    flange : (N, 4, 4) array_like, m
        Nominal flange poses in the robot base frame, ``N ≥ 4``.
    measured : (N, 4, 4) array_like, m
        Measured target poses in the tracker frame.
    prior_offset : (3,) array_like, m, optional
        Target offset kept along directions the poses do not determine (default 0).
    rel_tol : float
        The relative singular value threshold of both estimates (default 0: none).

    Returns
    -------
    FrameEstimate
        BASE, PROBE (m) and the rms position misfit (m).

    Raises
    ------
    InitialEstimateError
        Malformed shapes or fewer than 4 poses.
    """
    F = np.asarray(flange, dtype=float)
    T = np.asarray(measured, dtype=float)
    candidates = []
    with contextlib.suppress(InitialEstimateError):
        candidates.append(estimate_base_probe(F, T, rel_tol=rel_tol))
    reg = estimate_base_probe_positions(F, T[:, :3, 3], prior_offset=prior_offset,
                                        rel_tol=rel_tol)
    RX = _project_rotation(np.sum(
        np.swapaxes(reg.base[:3, :3] @ F[:, :3, :3], -1, -2) @ T[:, :3, :3], axis=0))
    X = reg.probe.copy()
    X[:3, :3] = RX
    candidates.append(FrameEstimate(base=reg.base, probe=X, rms=_rms(reg.base, F, X, T[:, :3, 3])))
    return min(candidates, key=lambda e: e.rms)
