"""Dense least squares for tall Jacobians (many poses, few parameters).

The identification Jacobian has ``6N`` rows and ``k ≤ ~80`` columns.  Up to
``GRAM_ROWS`` rows the Householder QR is used (most accurate); beyond that the
``k × k`` Gram matrix ``HᵀH`` (one BLAS pass over the rows, linear in N) and its
Cholesky factor — the normal equations of eq. (4.8), accurate enough for the
column-scaled Jacobians of calibration (κ ≲ 1e4, so κ² ≲ 1e8 ≪ 1/ε).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import LinAlgError, cho_factor, cho_solve, solve_triangular

Array = NDArray[np.float64]

#: Row count above which the Gram matrix replaces the QR factorisation.
GRAM_ROWS = 20_000

__all__ = ["GRAM_ROWS", "least_squares", "r_factor"]


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
    G = H.T @ H
    try:
        c, _ = cho_factor(G, lower=False)
        return np.triu(c)
    except LinAlgError:
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
    A = np.asarray(A, dtype=float)
    if A.shape[0] > GRAM_ROWS:
        try:
            c = cho_factor(A.T @ A, lower=False)
            return np.asarray(cho_solve(c, A.T @ b), dtype=float)
        except LinAlgError:
            return np.linalg.lstsq(A, b, rcond=None)[0]
    Q, R = np.linalg.qr(A, mode="reduced")
    d = np.abs(np.diag(R))
    if d.size and d.min() > 1e-12 * d.max():
        return np.asarray(solve_triangular(R, Q.T @ b), dtype=float)
    return np.linalg.lstsq(A, b, rcond=None)[0]
