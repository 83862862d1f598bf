"""The outcome of an identification: predicts, evaluates, reports.

:class:`CalibrationResult` is immutable: the calibrated :class:`ErrorModel`, the nominal
robot with fitted BASE/PROBE, the parameter statistics (8.3–8.5), the accuracy before and
after (8.1–8.2) and the residual of every pose.  Objects and arrays only: its files —
``PARAMS.json`` (``plugcell calibrate --out``) and the per-pose residual file
(``--residuals``) — are written and read by :mod:`plugcell.io.params`
(:func:`~plugcell.io.params.params_document`,
:func:`~plugcell.io.params.result_from_params`,
:func:`~plugcell.io.params.residuals_document`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from plugcell.calibration.configs import ModelConfig
from plugcell.calibration.data import CalibrationData
from plugcell.calibration.determinacy import Undetermined
from plugcell.calibration.identifiability import Identifiability
from plugcell.calibration.model import ErrorModel
from plugcell.calibration.residual_model import (
    LearnedResidual,
    calibration_fingerprint,
    hybrid_poses,
    hybrid_residuals,
)
from plugcell.calibration.statistics import ParameterStatistics, PoseResiduals, pose_residuals
from plugcell.calibration.validity import RegionCheck, ValidityRegion
from plugcell.metrology import AccuracyStats

Array = NDArray[np.float64]

__all__ = [
    "CalibrationResult",
    "IterationRecord",
    "harmonic_order",
]


@dataclass(frozen=True)
class IterationRecord:
    """One Gauss–Newton iteration: residual before the step and the step size.

    Attributes
    ----------
    iteration : int
        Iteration number.
    step_norm : float
        ‖Δg‖ of the step, in the parameters' own units (m, rad, …).
    cost : float
        ``Σ_i w_i ‖W Δx_i‖²`` before the step (m²; ``w_i`` the robust-loss weights).
    mean_position_mm, rms_position_mm : float, mm
        Mean and rms position residual before the step.
    damping : float
        Levenberg–Marquardt damping λ (0 for Gauss–Newton).
    """

    iteration: int
    step_norm: float
    cost: float
    mean_position_mm: float
    rms_position_mm: float
    damping: float = 0.0


@dataclass(frozen=True, eq=False)
class CalibrationResult:
    """An identified model with its statistics (see module docstring).

    Attributes
    ----------
    config : ModelConfig
        Which of the five models.
    robot : str
        Robot name.
    model : ErrorModel
        The calibrated model, ``T = BASE · T_n^0(θ + Δθ) · PROBE`` (6.23).
    nominal : ErrorModel
        The nominal robot with BASE/PROBE fitted (the "before" reference).
    keys : tuple of str
        The identified parameters.
    identifiability : Identifiability or None
        The structural analysis (what each kept parameter stands for).
    data_identifiability : Identifiability or None
        The same analysis on the calibration poses.
    iterations : int
        Iterations of the final stage.
    converged : bool
        Whether ‖Δg‖ < tol was reached.
    history : tuple of IterationRecord
        Per-iteration record.
    statistics : ParameterStatistics or None
        σ̂² (8.3), σ per parameter (8.5), covariance (8.4), κ.
    calibration, calibration_before : AccuracyStats or None
        Accuracy (8.1–8.2, m and rad) on the calibration poses after/before.
    six_dof : bool
        Orientations were measured.
    n_poses : int
        Calibration poses.
    pose_weights : (N,) array or None
        Final robust-loss weights of the poses.
    warnings : tuple of str
        Warnings raised during the fit.
    elapsed_s : float, s
        Wall time of the fit.
    settings : dict
        The calibrator's settings.
    validation, validation_before : AccuracyStats or None
        Accuracy on independent poses after/before.
    n_validation : int
        Validation poses.
    calibration_residuals, validation_residuals : PoseResiduals or None
        The residual of every pose those figures are the statistics of (``None`` in a
        result rebuilt from PARAMS.json by
        :func:`plugcell.io.params.result_from_params`).
    validity : ValidityRegion or None
        The region the calibration poses covered (``None`` for a PARAMS.json written
        before it was recorded).
    validation_region : RegionCheck or None
        The validation poses checked against it.
    residual_model : LearnedResidual or None
        A learned residual layer on top (hybrid model,
        :mod:`~plugcell.calibration.residual_model`), set by :meth:`with_residual_model`.
    hybrid_validation_residuals : PoseResiduals or None
        Physical (``before``) vs hybrid (``after``) on the validation poses.
    hybrid_fallbacks : int
        Validation poses outside the layer's trained region (physical model used).
    undetermined : Undetermined or None
        What the calibration poses did not determine (kept at the initial values,
        :mod:`~plugcell.calibration.determinacy`); ``None``: everything determined (or a
        PARAMS.json written before it was recorded).
    """

    config: ModelConfig
    robot: str
    model: ErrorModel
    nominal: ErrorModel
    keys: tuple[str, ...]
    identifiability: Identifiability | None
    data_identifiability: Identifiability | None
    iterations: int
    converged: bool
    history: tuple[IterationRecord, ...]
    statistics: ParameterStatistics | None
    calibration: AccuracyStats | None
    calibration_before: AccuracyStats | None
    six_dof: bool
    n_poses: int
    pose_weights: Array | None = None
    warnings: tuple[str, ...] = ()
    elapsed_s: float = 0.0
    settings: dict[str, Any] = field(default_factory=dict)
    validation: AccuracyStats | None = None
    validation_before: AccuracyStats | None = None
    n_validation: int = 0
    calibration_residuals: PoseResiduals | None = None
    validation_residuals: PoseResiduals | None = None
    validity: ValidityRegion | None = None
    validation_region: RegionCheck | None = None
    residual_model: LearnedResidual | None = None
    hybrid_validation_residuals: PoseResiduals | None = None
    hybrid_fallbacks: int = 0
    undetermined: Undetermined | None = None

    # ------------------------------------------------------------------ prediction
    def predict(self, q: ArrayLike, payload_kg: ArrayLike | float | None = None,
                temperature_c: ArrayLike | float | None = None) -> Array:
        """Calibrated target poses, ``T = BASE · T_n^0(θ(q) + Δθ(q, m)) · PROBE`` (6.23).

        Parameters
        ----------
        q : (N, n) array_like, rad
            Joint readings.
        payload_kg : float or (N,) array_like, kg, optional
            Payloads (default 0).
        temperature_c : float or (N,) array_like, °C, optional
            Temperatures (default: the model's reference).

        Returns
        -------
        (N, 4, 4) array, m
            Target poses in the measurement frame.
        """
        return self.model.predict(q, payload_kg, temperature_c)

    def predict_nominal(self, q: ArrayLike, payload_kg: ArrayLike | float | None = None,
                        temperature_c: ArrayLike | float | None = None) -> Array:
        """Poses of the nominal robot with the fitted BASE/PROBE (the "before" model).

        Parameters
        ----------
        q : (N, n) array_like, rad
            Joint readings.
        payload_kg : float or (N,) array_like, kg, optional
            Payloads (default 0).
        temperature_c : float or (N,) array_like, °C, optional
            Temperatures (default: the model's reference).

        Returns
        -------
        (N, 4, 4) array, m
            Target poses in the measurement frame.
        """
        return self.nominal.predict(q, payload_kg, temperature_c)

    def residuals(self, data: CalibrationData) -> Array:
        """Residuals measured − calibrated, ``Δx_i = [p_M − p; log(R_M Rᵀ)∨]``.

        Parameters
        ----------
        data : CalibrationData
            Measured poses.

        Returns
        -------
        (N, 6) or (N, 3) array
            Metres and radians (3 columns for position-only data).
        """
        return pose_residuals(data, self.predict(data.q, data.payload_kg, data.temperature_c))

    def evaluate_poses(self, data: CalibrationData, *, refit_base: bool = False,
                       refit_probe: bool = False, rotation_weight: float | None = None,
                       refit_positions_only: bool = False) -> PoseResiduals:
        """The residual of every pose of ``data``, nominal and calibrated.

        ``refit_base``: the data were measured with the tracker elsewhere — BASE is
        re-identified on them for both models (robot geometry kept), see
        :func:`plugcell.calibration.identify.refit_base`; ``refit_probe``: the
        target was remounted too — PROBE re-identified as well.  The refit weighs
        orientation rows by ``rotation_weight`` (m/rad; default: the weight of the fit,
        ``settings["rotation_weight"]``) or, with ``refit_positions_only``, uses the
        positions alone.

        Parameters
        ----------
        data : CalibrationData
            Measured poses.
        refit_base, refit_probe : bool
            Re-identify BASE (and PROBE) on ``data``.
        rotation_weight : float, m/rad, optional
            Weight of the orientation rows of the refit.
        refit_positions_only : bool
            Refit on the positions alone.

        Returns
        -------
        PoseResiduals
            ``before`` (nominal) and ``after`` (calibrated) errors, m and rad.
        """
        nominal, model = self.nominal, self.model
        if refit_base:
            # identify builds results (it imports this module): the one import circle
            # of the calibration package, broken here where the refit is needed
            from plugcell.calibration.identify import refit_base as _refit

            w = self.settings.get("rotation_weight", 1.0) if rotation_weight is None \
                else rotation_weight
            opts = {"probe": refit_probe, "rotation_weight": w,
                    "positions_only": refit_positions_only}
            nominal = _refit(nominal, data, **opts)
            model = _refit(model, data, **opts)
        t = data.temperature_c
        return PoseResiduals.from_poses(data, nominal.predict(data.q, data.payload_kg, t),
                                        model.predict(data.q, data.payload_kg, t))

    def evaluate(self, data: CalibrationData, *, refit_base: bool = False,
                 refit_probe: bool = False, rotation_weight: float | None = None,
                 refit_positions_only: bool = False) -> tuple[AccuracyStats, AccuracyStats]:
        """Accuracy (8.1–8.2) on ``data``: the statistics of :meth:`evaluate_poses`.

        Parameters
        ----------
        data : CalibrationData
            Measured poses (at least 2).
        refit_base, refit_probe, rotation_weight, refit_positions_only
            As :meth:`evaluate_poses`.

        Returns
        -------
        nominal, calibrated : AccuracyStats
            Mean, σ (m − 1), max … of the errors, m and rad.
        """
        r = self.evaluate_poses(data, refit_base=refit_base, refit_probe=refit_probe,
                                rotation_weight=rotation_weight,
                                refit_positions_only=refit_positions_only)
        return r.accuracy("before"), r.accuracy("after")

    def with_validation(self, data: CalibrationData, *, refit_base: bool = False,
                        refit_probe: bool = False, rotation_weight: float | None = None,
                        refit_positions_only: bool = False) -> CalibrationResult:
        """This result with the accuracy and residuals on independent poses ``data``
        (with a residual model also physical vs hybrid on them).

        Parameters
        ----------
        data : CalibrationData
            Validation poses (at least 2).
        refit_base, refit_probe, rotation_weight, refit_positions_only
            As :meth:`evaluate_poses`.

        Returns
        -------
        CalibrationResult
            A copy with ``validation``, ``validation_before``, ``validation_residuals`` and
            ``validation_region`` set (and a warning for poses outside the region).
        """
        r = self.evaluate_poses(data, refit_base=refit_base, refit_probe=refit_probe,
                                rotation_weight=rotation_weight,
                                refit_positions_only=refit_positions_only)
        check = self.check_region(data.q, data.payload_kg)
        warnings = self.warnings
        if check is not None and check.count:
            warnings = (*warnings, "validation: " + check.message("validation poses"))
        out = replace(self, validation=r.accuracy("after"),
                      validation_before=r.accuracy("before"), n_validation=len(data),
                      validation_residuals=r, validation_region=check, warnings=warnings)
        if self.residual_model is not None:
            w = self.settings.get("rotation_weight", 1.0) if rotation_weight is None \
                else rotation_weight
            h, pred = hybrid_residuals(self.model, self.residual_model, data,
                                       refit_base=refit_base, refit_probe=refit_probe,
                                       rotation_weight=w,
                                       refit_positions_only=refit_positions_only)
            out = replace(out, hybrid_validation_residuals=h, hybrid_fallbacks=pred.fallback_count)
        return out

    def check_region(self, q: ArrayLike, payload_kg: ArrayLike | float | None = None,
                     targets: ArrayLike | None = None) -> RegionCheck | None:
        """Configurations checked against the calibrated region (:meth:`ValidityRegion.check`).

        Parameters
        ----------
        q : (N, n) array_like, rad
            Configurations.
        payload_kg : float or (N,) array_like, kg, optional
            Payloads.
        targets : (N, 3) array_like, m, optional
            Target positions, robot base frame.

        Returns
        -------
        RegionCheck or None
            ``None`` when the result has no region (a PARAMS.json from before it was
            recorded).
        """
        if self.validity is None:
            return None
        return self.validity.check(q, payload_kg, targets)

    def with_residual_model(self, layer: LearnedResidual) -> CalibrationResult:
        """This result with a learned residual layer.

        Parameters
        ----------
        layer : LearnedResidual
            A layer trained on this calibration's model
            (:func:`~plugcell.calibration.residual_model.calibration_fingerprint`).

        Returns
        -------
        CalibrationResult
            A copy with ``residual_model`` set (hybrid validation cleared).

        Raises
        ------
        ValueError
            The layer was trained on another calibration.
        """
        if layer.fingerprint != calibration_fingerprint(self.model):
            raise ValueError("the residual model was trained on top of another calibration")
        return replace(self, residual_model=layer, hybrid_validation_residuals=None,
                       hybrid_fallbacks=0)

    def predict_hybrid(self, q: ArrayLike, payload_kg: ArrayLike | float | None = None,
                       temperature_c: ArrayLike | float | None = None
                       ) -> tuple[Array, Array]:
        """Hybrid target poses: the calibrated poses with the learned layer's correction.

        Parameters
        ----------
        q : (N, n) array_like, rad
            Joint readings.
        payload_kg : float or (N,) array_like, kg, optional
            Payloads (default 0).
        temperature_c : float or (N,) array_like, °C, optional
            Temperatures (default: the model's reference).

        Returns
        -------
        T : (N, 4, 4) array, m
            Target poses in the measurement frame (the physical ones without a layer).
        in_domain : (N,) bool array
            False where the physical model's pose was used.
        """
        P = self.predict(q, payload_kg, temperature_c)
        if self.residual_model is None:
            return P, np.ones(len(P), dtype=bool)
        m = np.zeros(len(P)) if payload_kg is None else payload_kg
        pred = self.residual_model.predict(q, m, temperature_c)
        return hybrid_poses(P, self.model.base()[:3, :3], pred.correction), pred.in_domain

    # ------------------------------------------------------------------ parameters
    def value(self, key: str) -> float:
        """Identified value Δĝ of parameter ``key`` (in its unit, :class:`ErrorParameter`).

        Parameters
        ----------
        key : str
            Parameter key.

        Returns
        -------
        float
            The value.
        """
        return self.model.value(key)

    def sigma(self, key: str) -> float:
        """Standard deviation ``σ_Δg = σ̂ √C_jj`` (8.5) of identified parameter ``key``.

        Parameters
        ----------
        key : str
            Parameter key.

        Returns
        -------
        float
            σ in the parameter's unit; NaN if not identified or without statistics.
        """
        if self.statistics is None or key not in self.keys:
            return float("nan")
        return float(self.statistics.sigma[self.keys.index(key)])

    def stands_for(self, key: str) -> str:
        """The combination ``Δg_k + Σ_j c_jk Δg_j`` kept parameter ``key`` stands for.

        Parameters
        ----------
        key : str
            Parameter key.

        Returns
        -------
        str
            E.g. ``"Δa2' − Δa4'"`` (the parameter's own name without an analysis).
        """
        names = dict(zip(self.model.space.keys, self.model.space.names, strict=True))
        if self.identifiability is None:
            return names[key]
        return self.identifiability.stands_for(key, names)

    def parameter_table(self) -> list[dict[str, Any]]:
        """One dict per identified parameter: key, name, kind, value, sigma, unit, stands_for.

        Returns
        -------
        list of dict
            Values and σ in SI units.
        """
        out = []
        for k in self.keys:
            p = self.model.space[k]
            out.append({"key": k, "name": p.name, "kind": p.kind, "value": self.value(k),
                        "sigma": self.sigma(k), "unit": p.unit, "stands_for": self.stands_for(k)})
        return out


def harmonic_order(model: ErrorModel) -> int:
    """The highest joint-angle harmonic order K among the model's parameters.

    Parameters
    ----------
    model : ErrorModel
        The model.

    Returns
    -------
    int
        K (0: no harmonics).
    """
    return max((int(p.key[1]) for p in model.space if p.kind == "harmonic"), default=0)
