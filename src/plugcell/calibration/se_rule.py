"""The k-standard-error rule of a cross-validation: is a CV gain beyond the CV's noise?

Used by both choices a short campaign makes (issue 36): which candidate fit
(:func:`.prior.pick_significant`) and whether the campaign's own learned stage is adopted
(:func:`.campaign_stage.fit_campaign_stage`).  Both compare the held-out errors of two
fits pose by pose on the same CV folds; the gain counts only when

    d̄ + k·SE < 0,     d_i = e_i − e_ref,i,

``SE`` the standard error of the mean paired difference clustered by fold
(:func:`paired_difference`).  ``k = 0``: the plain sign of the difference.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from plugcell.calibration.identify import CalibrationError

Array = NDArray[np.float64]

#: k of the k-standard-error rule: a fit other than the reference is adopted only when its CV
#: error is below the reference's by more than k standard errors of the paired difference
#: (k = 1: the one-standard-error rule).
SE_RULE_K = 1.0

__all__ = ["SE_RULE_K", "beats", "check_k", "paired_difference"]


def check_k(k: float) -> float:
    """``k`` as a float, checked.

    Parameters
    ----------
    k : float
        The number of standard errors.

    Returns
    -------
    float
        ``k``.

    Raises
    ------
    CalibrationError
        ``k`` negative, not finite or not a number.
    """
    try:
        ok = math.isfinite(k) and k >= 0
    except TypeError:
        ok = False
    if not ok:
        raise CalibrationError(f"prior: the standard-error factor k must be a number ≥ 0, "
                               f"got {k!r}")
    return float(k)


def paired_difference(e: Array, e_ref: Array, fold: Array) -> tuple[float, float]:
    """The mean paired CV difference of a candidate to a reference and its standard error,
    clustered by CV fold.

    With ``d_i = e_i − e_ref,i`` over the ``N`` poses and ``G`` folds (the poses a fold
    holds out share the fit made without them, so their errors are correlated; the folds
    are the independent units)::

        d̄ = (1/N) Σ_i d_i,     SE² = G / (G − 1) · Σ_g (Σ_{i∈g} (d_i − d̄))² / N²

    (the cluster-robust variance of a mean; with equal folds ``SE = sd_g(d̄_g) / √G``,
    the standard error over folds of the one-standard-error rule).

    Parameters
    ----------
    e, e_ref : (N,) array
        Held-out errors of the candidate and of the reference, one per pose (any unit).
    fold : (N,) int array
        The CV fold that held each pose out.

    Returns
    -------
    mean : float
        ``d̄`` (the unit of ``e``); ``inf`` when ``e`` has a non-finite error, ``nan`` when
        ``e_ref`` has one.
    se : float
        ``SE`` (``inf`` with fewer than 2 folds).
    """
    e = np.asarray(e, float)
    e_ref = np.asarray(e_ref, float)
    if not np.all(np.isfinite(e_ref)):
        return math.nan, math.inf
    if not np.all(np.isfinite(e)):
        return math.inf, math.inf
    d = e - e_ref
    mean = float(d.mean())
    _, g = np.unique(np.asarray(fold), return_inverse=True)
    n_g = int(g.max()) + 1 if g.size else 0
    if n_g < 2:
        return mean, math.inf
    sums = np.bincount(g, weights=d - mean, minlength=n_g)
    return mean, float(np.sqrt(n_g / (n_g - 1) * np.sum(sums**2)) / d.size)


def beats(e: Array, e_ref: Array, fold: Array, k: float = SE_RULE_K
          ) -> tuple[bool, float, float]:
    """Whether a fit's CV beats a reference's by more than ``k`` standard errors.

    ``d̄ + k·SE < 0`` with ``d̄``, ``SE`` of :func:`paired_difference` (module docstring).
    Under the null that the fit is no better than the reference, the rule adopts it by
    chance with probability ≈ Φ(−k) (16 % at k = 1).

    Parameters
    ----------
    e, e_ref : (N,) array
        Held-out errors of the fit and of the reference, one per pose (any one unit).
    fold : (N,) int array
        The CV fold that held each pose out.
    k : float
        The number of standard errors (≥ 0).

    Returns
    -------
    better : bool
        ``d̄ + k·SE < 0`` (``False`` when either has a non-finite error or, the SE being
        infinite, fewer than 2 folds).
    mean, se : float
        ``d̄`` and ``SE`` (the unit of ``e``).

    Raises
    ------
    CalibrationError
        ``k`` negative or not finite.
    """
    k = check_k(k)
    mean, se = paired_difference(e, e_ref, fold)
    return bool(mean + k * se < 0), mean, se
