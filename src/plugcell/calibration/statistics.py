"""Residuals and statistics of a calibration (thesis 8.2.1, eqs. 8.1–8.5).

* Residual of pose *i* (our convention, :mod:`plugcell.kinematics.pose_error`):
  ``Δx_i = [p_M − p; log(R_M Rᵀ)]`` — metres and radians in the measurement frame.
* Accuracy (8.1, 8.2): mean, σ (m − 1), max of the error norms and of each
  component, via :func:`plugcell.metrology.accuracy_statistics`.  Orientation
  components are the rotation vector of ``R_model⁻¹ R_measured`` (exact, robust
  at any attitude) rather than the thesis's differences of roll-pitch-yaw angles,
  which are meaningless near pitch ±90° — for small errors away from that
  singularity the two agree to first order up to a change of axes.
* Parameter statistics (8.3–8.5): ``σ² = Σ Δx² / (n − r)``, ``C = (HᵀH)⁻¹``,
  ``σ_Δg_j = σ·sqrt(C_jj)``; computed from the SVD of the column-scaled H.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from plugcell.calibration.data import CalibrationData
from plugcell.calibration.linalg import r_factor
from plugcell.kinematics import pose_error_exact
from plugcell.metrology import AccuracyStats, accuracy_statistics, pose_errors

Array = NDArray[np.float64]

__all__ = [
    "ParameterStatistics",
    "accuracy",
    "accuracy_summary",
    "parameter_statistics",
    "pose_residuals",
]


def pose_residuals(measured: CalibrationData, predicted: Array) -> Array:
    """``(N, rows)`` residuals measured − predicted (6 per pose, or 3 for positions)."""
    if measured.six_dof:
        return pose_error_exact(measured.poses, predicted)
    return measured.positions - predicted[:, :3, 3]


def accuracy(measured: CalibrationData, predicted: Array) -> AccuracyStats:
    """Accuracy statistics (8.1–8.2) of predicted against measured poses."""
    if len(measured) < 2:
        raise ValueError("accuracy statistics need at least 2 poses")
    if measured.six_dof:
        dp, dphi = pose_errors(measured.poses, predicted, orientation="rotvec")
        return accuracy_statistics(dp, dphi)
    return accuracy_statistics(measured.positions - predicted[:, :3, 3])


def accuracy_summary(stats: AccuracyStats) -> dict[str, Any]:
    """JSON-ready summary: ``mean_mm``, ``std_mm``, ``max_mm``, ``rms_mm``, per-component
    means/σ (mm), and the orientation (deg) when measured."""
    d = stats.as_dict(length_unit="mm", angle_unit="deg")
    pos = d["position"]
    out: dict[str, Any] = {
        "poses": stats.count,
        "mean_mm": pos["mean"], "std_mm": pos["std"], "max_mm": pos["max"], "rms_mm": pos["rms"],
        "components_mm": {"mean": pos["components"]["mean"], "std": pos["components"]["std"]},
    }
    if "orientation" in d:
        o = d["orientation"]
        out["orientation"] = {
            "mean_deg": o["mean"], "std_deg": o["std"], "max_deg": o["max"],
            "components_deg": {"mean": o["components"]["mean"], "std": o["components"]["std"]},
            "convention": "rotation vector of R_model^-1 R_measured",
        }
    return out


@dataclass(frozen=True)
class ParameterStatistics:
    """σ² (8.3), parameter σ (8.5), covariance (8.4) and the condition number of the
    column-scaled identification Jacobian."""

    sigma2: float
    sigma: Array
    covariance: Array
    condition_number: float
    dof: int


def parameter_statistics(H: Array, r: Array) -> ParameterStatistics:
    """``H`` ``(n, k)`` stacked (weighted) Jacobian, ``r`` ``(n,)`` final residuals."""
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
