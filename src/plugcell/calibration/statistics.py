"""Residuals and statistics of a calibration (thesis 8.2.1, eqs. 8.1–8.5).

* Residual of pose *i* (our convention, :mod:`plugcell.kinematics.pose_error`):
  ``Δx_i = [p_M − p; log(R_M Rᵀ)]`` — metres and radians in the measurement frame.
* Accuracy (8.1, 8.2): mean, σ (m − 1), max of the error norms and of each
  component, via :func:`plugcell.metrology.accuracy_statistics`.  Orientation
  components are the rotation vector of ``R_model⁻¹ R_measured`` (exact, robust
  at any attitude) rather than the thesis's differences of roll-pitch-yaw angles,
  which are meaningless near pitch ±90° — for small errors away from that
  singularity the two agree to first order up to a change of axes.
* Per-pose residuals (:class:`PoseResiduals`): the error vectors those statistics are
  taken over, before (nominal robot with fitted BASE/PROBE) and after calibration,
  with the measured positions — what a 3-D view of the residuals shows (the file,
  in mm and degrees: :func:`plugcell.io.params.residuals_document`).
* Parameter statistics (8.3–8.5): ``σ² = Σ Δx² / (n − r)``, ``C = (HᵀH)⁻¹``,
  ``σ_Δg_j = σ·sqrt(C_jj)``; computed from the SVD of the column-scaled H.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from plugcell.calibration.data import CalibrationData
from plugcell.calibration.linalg import r_factor
from plugcell.kinematics import pose_error_exact
from plugcell.metrology import AccuracyStats, accuracy_statistics, pose_errors

Array = NDArray[np.float64]

__all__ = [
    "ParameterStatistics",
    "PoseResiduals",
    "accuracy",
    "error_vectors",
    "parameter_statistics",
    "pose_residuals",
]

Which = Literal["before", "after"]


def pose_residuals(measured: CalibrationData, predicted: Array) -> Array:
    """Identification residuals measured − predicted, ``Δx_i = [p_M − p; log(R_M Rᵀ)∨]``.

    Parameters
    ----------
    measured : CalibrationData
        The measurements (6-DOF poses or positions), measurement frame.
    predicted : (N, 4, 4) array, m
        Predicted target poses.

    Returns
    -------
    (N, 6) or (N, 3) array
        ``[Δp (m); φ (rad)]`` per pose (:func:`~plugcell.kinematics.pose_error_exact`,
        rotation about the measurement-frame axes), or ``Δp`` only for positions.
    """
    if measured.six_dof:
        return pose_error_exact(measured.poses, predicted)
    return measured.positions - predicted[:, :3, 3]


def error_vectors(measured: CalibrationData, predicted: Array) -> tuple[Array, Array | None]:
    """Per-pose errors measured − predicted, ``Δp = p_M − p``, ``Δφ = log(Rᵀ R_M)∨``.

    The vectors the accuracy statistics (8.1–8.2) are taken over.  Note that ``Δφ``
    here is about the *predicted* frame's axes (``R_predicted⁻¹ R_measured``), while
    :func:`pose_residuals` gives the rotation about the measurement-frame axes; the
    norms agree.

    Parameters
    ----------
    measured : CalibrationData
        The measurements.
    predicted : (N, 4, 4) array, m
        Predicted target poses.

    Returns
    -------
    dp : (N, 3) array, m
        Position errors.
    dphi : (N, 3) array, rad, or None
        Rotation vectors, ``None`` for position-only data.
    """
    if measured.six_dof:
        return pose_errors(measured.poses, predicted, orientation="rotvec")
    return measured.positions - np.asarray(predicted)[:, :3, 3], None


def accuracy(measured: CalibrationData, predicted: Array) -> AccuracyStats:
    """Accuracy statistics (8.1–8.2) of predicted against measured poses.

    ``Δ̄ = Σ|Δ_i|/m``, ``σ = √(Σ(|Δ_i| − Δ̄)²/(m − 1))`` over the vectors of
    :func:`error_vectors`.

    Parameters
    ----------
    measured : CalibrationData
        The measurements, ``N ≥ 2``.
    predicted : (N, 4, 4) array, m
        Predicted target poses.

    Returns
    -------
    AccuracyStats
        Position (m) and, for 6-DOF data, orientation (rad) statistics.

    Raises
    ------
    ValueError
        Fewer than 2 poses.
    """
    if len(measured) < 2:
        raise ValueError("accuracy statistics need at least 2 poses")
    return accuracy_statistics(*error_vectors(measured, predicted))


def _frozen(x: Any, name: str, n: int | None) -> Array:
    a = np.array(x, dtype=float)
    if a.ndim != 2 or a.shape[1] != 3 or (n is not None and a.shape[0] != n):
        want = "(N, 3)" if n is None else f"({n}, 3)"
        raise ValueError(f"{name} must be {want}, got {a.shape}")
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class PoseResiduals:
    """The residual of every pose of one set, before and after calibration (8.2.1).

    Attributes
    ----------
    positions : (N, 3) array, m
        The measured target positions, measurement frame.
    before, after : (N, 3) array, m
        Position errors ``p_M − p`` by the nominal robot with BASE/PROBE fitted and by
        the calibrated model.
    orientation_before, orientation_after : (N, 3) array, rad, or None
        Orientation errors (rotation vector, see :func:`error_vectors`), ``None`` for
        position-only data.

    Their statistics are the result's accuracy figures:
    ``result.calibration_residuals.accuracy("after")`` is ``result.calibration``.
    Read-only arrays; build one with :meth:`from_poses`.
    """

    positions: Array
    before: Array
    after: Array
    orientation_before: Array | None = None
    orientation_after: Array | None = None

    def __post_init__(self) -> None:
        p = _frozen(self.positions, "positions", None)
        n = len(p)
        object.__setattr__(self, "positions", p)
        for name in ("before", "after"):
            object.__setattr__(self, name, _frozen(getattr(self, name), name, n))
        ob, oa = self.orientation_before, self.orientation_after
        if (ob is None) != (oa is None):
            raise ValueError("orientation_before and orientation_after: both or neither")
        if ob is not None:
            object.__setattr__(self, "orientation_before",
                               _frozen(ob, "orientation_before", n))
            object.__setattr__(self, "orientation_after", _frozen(oa, "orientation_after", n))

    @classmethod
    def from_poses(cls, measured: CalibrationData, nominal: Array,
                   calibrated: Array) -> PoseResiduals:
        """The residuals of ``measured`` against the poses predicted by two models.

        Parameters
        ----------
        measured : CalibrationData
            The measurements.
        nominal : (N, 4, 4) array, m
            Poses predicted by the nominal robot (BASE/PROBE fitted).
        calibrated : (N, 4, 4) array, m
            Poses predicted by the calibrated model.

        Returns
        -------
        PoseResiduals
            Errors of :func:`error_vectors` before and after.
        """
        dp0, dphi0 = error_vectors(measured, nominal)
        dp1, dphi1 = error_vectors(measured, calibrated)
        return cls(measured.positions, dp0, dp1, dphi0, dphi1)

    def __len__(self) -> int:
        return int(self.positions.shape[0])

    @property
    def six_dof(self) -> bool:
        """True when orientation errors are present."""
        return self.orientation_after is not None

    def errors(self, which: Which = "after") -> tuple[Array, Array | None]:
        """``(Δp, Δφ)`` before or after calibration.

        Parameters
        ----------
        which : {"before", "after"}
            Which model's residuals.

        Returns
        -------
        dp : (N, 3) array, m
            Position errors.
        dphi : (N, 3) array, rad, or None
            Orientation errors, ``None`` for positions only.

        Raises
        ------
        ValueError
            Unknown ``which``.
        """
        if which == "before":
            return self.before, self.orientation_before
        if which == "after":
            return self.after, self.orientation_after
        raise ValueError(f"which must be 'before' or 'after', got {which!r}")

    def norms(self, which: Which = "after") -> Array:
        """Position error norms ``|Δp_i|``.

        Parameters
        ----------
        which : {"before", "after"}
            Which model's residuals.

        Returns
        -------
        (N,) array, m
            The norms.
        """
        return np.linalg.norm(self.errors(which)[0], axis=1)

    def accuracy(self, which: Which = "after") -> AccuracyStats:
        """The accuracy statistics (8.1–8.2) of these residuals.

        Parameters
        ----------
        which : {"before", "after"}
            Which model's residuals.

        Returns
        -------
        AccuracyStats
            Mean, σ (m − 1), max … of the norms and components (m, rad).

        Raises
        ------
        ValueError
            Fewer than 2 poses, or unknown ``which``.
        """
        if len(self) < 2:
            raise ValueError("accuracy statistics need at least 2 poses")
        return accuracy_statistics(*self.errors(which))


@dataclass(frozen=True)
class ParameterStatistics:
    """σ² (8.3), parameter σ (8.5), covariance (8.4) and the condition number of the
    column-scaled identification Jacobian.

    Attributes
    ----------
    sigma2 : float
        ``σ̂² = rᵀr / (n − k)`` (8.3), in the squared unit of the (weighted) residuals
        (NaN when ``n ≤ k``).
    sigma : (k,) array
        ``σ_Δg_j = σ̂ √C_jj`` (8.5), in each parameter's unit.
    covariance : (k, k) array
        ``σ̂² C`` with ``C = (HᵀH)⁻¹`` (8.4; pseudo-inverse on a rank-deficient H).
    condition_number : float
        ``σ₁/σ_k`` of the column-scaled H.
    dof : int
        ``n − k``.
    """

    sigma2: float
    sigma: Array
    covariance: Array
    condition_number: float
    dof: int


def parameter_statistics(H: Array, r: Array) -> ParameterStatistics:
    """Parameter statistics of a least-squares fit, eqs. (8.3)–(8.5).

    ``σ̂² = rᵀr / (n − k)``, ``C = (HᵀH)⁻¹``, ``σ_Δg_j = σ̂ √C_jj``; ``C`` from the SVD of the
    column-scaled ``H S⁻¹ = U Σ Vᵀ``: ``C = S⁻¹ V Σ⁻² Vᵀ S⁻¹`` (singular values below
    ``1e-14 σ₁`` are dropped, a pseudo-inverse).

    Parameters
    ----------
    H : (n, k) array
        Stacked (weighted) identification Jacobian.
    r : (n,) array
        Final (weighted) residuals, m and rad.

    Returns
    -------
    ParameterStatistics
        σ̂², per-parameter σ, covariance, condition number and degrees of freedom.
    """
    n, k = H.shape
    dof = n - k
    sigma2 = float(r @ r / dof) if dof > 0 else float("nan")
    s = np.linalg.norm(H, axis=0)
    s = np.where(s > 0, s, 1.0)
    Hs = H / s
    if Hs.shape[0] > 2 * Hs.shape[1]:
        Hs = r_factor(Hs)  # same singular values and right vectors
    _, sv, Vt = np.linalg.svd(Hs, full_matrices=False)
    kappa = float(sv[0] / sv[-1]) if sv.size and sv[-1] > 0 else float("inf")
    inv = np.where(sv > sv[0] * 1e-14, 1.0 / np.maximum(sv, 1e-300) ** 2, 0.0) if sv.size else sv
    Cs = (Vt.T * inv) @ Vt
    C = Cs / np.outer(s, s)
    sigma = np.sqrt(np.maximum(np.diag(C), 0.0) * sigma2)
    return ParameterStatistics(sigma2=sigma2, sigma=sigma, covariance=sigma2 * C,
                               condition_number=kappa, dof=dof)
