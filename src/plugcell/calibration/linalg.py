"""Dense least squares for tall Jacobians (many poses, few parameters).

The identification Jacobian has ``6N`` rows and ``k ≤ ~80`` columns.  Up to
``GRAM_ROWS`` rows the Householder QR is used (most accurate); beyond that the
``k × k`` Gram matrix ``HᵀH`` (one BLAS pass over the rows, linear in N) and its
Cholesky factor — the normal equations of eq. (4.8), accurate enough for the
column-scaled Jacobians of calibration (κ ≲ 1e4, so κ² ≲ 1e8 ≪ 1/ε).

SciPy's triangular and Cholesky solvers are imported where they are called: a process
that reads a calibration (the robot's link process, a service) without solving one does
not import SciPy (0.4 s of start-up).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]

#: Row count above which the Gram matrix replaces the QR factorisation.
GRAM_ROWS = 20_000

__all__ = ["GRAM_ROWS", "least_squares", "null_space", "r_factor", "restricted_basis"]


def r_factor(H: Array) -> Array:
    """An upper-triangular ``R`` with ``RᵀR = HᵀH``: the same column geometry (norms,
    angles, singular values, linear relations) in a small matrix.

    QR (``H = QR``) up to :data:`GRAM_ROWS` rows, the Cholesky factor of ``HᵀH`` beyond
    (QR again if that fails).

    Parameters
    ----------
    H : (n, k) array
        A tall matrix.

    Returns
    -------
    R : (k, k) array
        Upper triangular (``(n, k)`` if ``n < k``).
    """
    H = np.asarray(H, dtype=float)
    if H.shape[0] <= max(GRAM_ROWS, 2 * H.shape[1]):
        return np.asarray(np.linalg.qr(H, mode="r"))
    from scipy.linalg import cho_factor

    G = H.T @ H
    try:
        c, _ = cho_factor(G, lower=False)
        return np.triu(c)
    except np.linalg.LinAlgError:
        return np.asarray(np.linalg.qr(H, mode="r"))


def least_squares(A: Array, b: Array) -> Array:
    """``x = argmin ‖A x − b‖`` (eq. 4.8).

    ``x = R⁻¹ Qᵀ b`` by QR; by the normal equations ``AᵀA x = Aᵀb`` (Cholesky) above
    :data:`GRAM_ROWS` rows; the SVD-based minimum-norm solution if ``A`` is rank
    deficient (or the Cholesky fails).

    Parameters
    ----------
    A : (n, k) array
        Design matrix.
    b : (n,) array
        Right-hand side.

    Returns
    -------
    x : (k,) array
        The least-squares solution.
    """
    from scipy.linalg import cho_factor, cho_solve, solve_triangular

    A = np.asarray(A, dtype=float)
    if A.shape[0] > GRAM_ROWS:
        try:
            c = cho_factor(A.T @ A, lower=False)
            return np.asarray(cho_solve(c, A.T @ b), dtype=float)
        except np.linalg.LinAlgError:
            return np.linalg.lstsq(A, b, rcond=None)[0]
    Q, R = np.linalg.qr(A, mode="reduced")
    d = np.abs(np.diag(R))
    if d.size and d.min() > 1e-12 * d.max():
        return np.asarray(solve_triangular(R, Q.T @ b), dtype=float)
    return np.linalg.lstsq(A, b, rcond=None)[0]


def null_space(A: Array, rel_tol: float) -> tuple[Array, Array]:
    """The numerical null space of ``A``: right singular vectors whose singular value is
    below ``rel_tol · σ₁``.

    ``A = U Σ Vᵀ`` (from the small factor ``R`` of :func:`r_factor`, ``RᵀR = AᵀA``, so a
    tall ``A`` costs one QR); the returned basis spans ``{v : ‖A v‖ < rel_tol · σ₁ ‖v‖}``
    in the sense of the truncated SVD.

    Parameters
    ----------
    A : (n, k) array
        A matrix (e.g. a column-scaled identification Jacobian).
    rel_tol : float
        Relative singular value threshold.

    Returns
    -------
    s : (k,) array
        ``σ₁ ≥ … ≥ σ_k`` (zeros appended when ``n < k``).
    V0 : (k, m) array
        Orthonormal basis of the null space (``m = 0``: none).
    """
    A = np.asarray(A, dtype=float)
    k = A.shape[1]
    if k == 0:
        return np.zeros(0), np.zeros((0, 0))
    R = r_factor(A) if A.shape[0] > k else A
    _, s, Vt = np.linalg.svd(R, full_matrices=True)
    s = np.concatenate([s, np.zeros(k - len(s))])
    small = s < rel_tol * s[0] if s[0] > 0 else np.ones(k, dtype=bool)
    return s, Vt[small].T.copy()


def restricted_basis(C: Array, scale: Array) -> Array:
    """An orthonormal basis ``Z`` of the scaled steps ``x`` that leave the combinations
    ``Cᵀ g`` unchanged, where ``g = x / scale`` (column scaling).

    ``Cᵀ (x / scale) = 0`` ⇔ ``x ⊥ span(C / scale)``; ``Z`` spans the orthogonal
    complement (by a full QR of ``C / scale``).  A least-squares step taken as ``x = Z y``
    keeps every ``Cᵀ g`` at its value (the undetermined combinations stay where they
    started) and is the minimum-norm step in those directions.

    Parameters
    ----------
    C : (k, m) array
        The combinations to keep, one column each (parameter units).
    scale : (k,) array
        Column scales of the current Jacobian (``x = scale · g``).

    Returns
    -------
    Z : (k, k − m) array
        Orthonormal basis of the allowed scaled steps.
    """
    k, m = C.shape
    if m == 0:
        return np.eye(k)
    Q, _ = np.linalg.qr(C / scale[:, None], mode="complete")
    return Q[:, m:]
