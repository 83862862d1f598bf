"""Central differences: what every analytic derivative of plugcell is checked against."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np


def central_differences(f: Callable[[np.ndarray], np.ndarray], x: np.ndarray,
                        eps: float = 1e-6) -> np.ndarray:
    """``∂f/∂x_j ≈ (f(x + ε e_j) − f(x − ε e_j)) / 2ε`` for every component ``j`` of ``x``.

    Parameters
    ----------
    f : callable
        ``f(x)`` for points ``x`` of shape ``(..., n)``, batched over the leading axes;
        values of shape ``(..., m)``.
    x : (..., n) array
        The points.
    eps : float
        The step ``ε``.

    Returns
    -------
    (..., m, n) array
        The Jacobian estimate, column ``j`` the derivative along ``x_j``.
    """
    x = np.asarray(x, dtype=float)
    cols = []
    for j in range(x.shape[-1]):
        dx = np.zeros(x.shape[-1])
        dx[j] = eps
        cols.append((np.asarray(f(x + dx)) - np.asarray(f(x - dx))) / (2 * eps))
    return np.stack(cols, axis=-1)
