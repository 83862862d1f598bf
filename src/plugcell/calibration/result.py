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
    """One Gauss–Newton iteration: residual before the step and the step size."""

    iteration: int
    step_norm: float
    cost: float
    mean_position_mm: float
    rms_position_mm: float
    damping: float = 0.0


@dataclass(frozen=True, eq=False)
class CalibrationResult:
    """An identified model with its statistics (see module docstring).

    ``model``: the calibrated :class:`ErrorModel`; ``nominal``: the nominal robot
    with BASE/PROBE fitted (the "before" reference); ``keys``: the identified
    parameters; ``identifiability``: the structural analysis (what each kept
    parameter stands for); ``statistics``: σ², σ per parameter, κ;
    ``calibration``/``calibration_before``: accuracy on the calibration poses
    after/before; ``validation``/``validation_before``: on independent poses;
    ``calibration_residuals``/``validation_residuals``: the residual of every pose
    (:class:`~plugcell.calibration.statistics.PoseResiduals`) those figures are the
    statistics of (``None`` in a result rebuilt from PARAMS.json by
    :func:`plugcell.io.params.result_from_params`);
    ``validity``: the region the calibration poses covered
    (:class:`~plugcell.calibration.validity.ValidityRegion`; ``None`` for a PARAMS.json
    written before it was recorded); ``validation_region``: the validation poses checked
    against it.
    ``residual_model``: a learned residual layer on top (hybrid model,
    :mod:`~plugcell.calibration.residual_model`), set by :meth:`with_residual_model`;
    ``hybrid_validation_residuals``: physical (``before``) vs hybrid (``after``) on the
    validation poses, ``hybrid_fallbacks``: validation poses outside the layer's
    trained region (physical model used).
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

    # ------------------------------------------------------------------ prediction
    def predict(self, q: ArrayLike, payload_kg: ArrayLike | float | None = None,
                temperature_c: ArrayLike | float | None = None) -> Array:
        """Calibrated target poses ``(N, 4, 4)`` in the measurement frame."""
        return self.model.predict(q, payload_kg, temperature_c)

    def predict_nominal(self, q: ArrayLike, payload_kg: ArrayLike | float | None = None,
                        temperature_c: ArrayLike | float | None = None) -> Array:
        """Poses of the nominal robot with the fitted BASE/PROBE."""
        return self.nominal.predict(q, payload_kg, temperature_c)

    def residuals(self, data: CalibrationData) -> Array:
        """``(N, 6)`` (or ``(N, 3)``) measured − calibrated, metres and radians."""
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
        """Accuracy (8.1–8.2) on ``data``: (nominal, calibrated); the statistics of
        :meth:`evaluate_poses` (same options)."""
        r = self.evaluate_poses(data, refit_base=refit_base, refit_probe=refit_probe,
                                rotation_weight=rotation_weight,
                                refit_positions_only=refit_positions_only)
        return r.accuracy("before"), r.accuracy("after")

    def with_validation(self, data: CalibrationData, *, refit_base: bool = False,
                        refit_probe: bool = False, rotation_weight: float | None = None,
                        refit_positions_only: bool = False) -> CalibrationResult:
        """This result with the accuracy and residuals on independent poses ``data``
        (options of :meth:`evaluate_poses`; with a residual model also physical vs hybrid
        on them)."""
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
        """Configurations ``q`` (rad) checked against the calibrated region (``None`` when
        the result has no region: a PARAMS.json from before it was recorded)."""
        if self.validity is None:
            return None
        return self.validity.check(q, payload_kg, targets)

    def with_residual_model(self, layer: LearnedResidual) -> CalibrationResult:
        """This result with a learned residual layer (trained on this calibration's
        model: :func:`~plugcell.calibration.residual_model.calibration_fingerprint`)."""
        if layer.fingerprint != calibration_fingerprint(self.model):
            raise ValueError("the residual model was trained on top of another calibration")
        return replace(self, residual_model=layer, hybrid_validation_residuals=None,
                       hybrid_fallbacks=0)

    def predict_hybrid(self, q: ArrayLike, payload_kg: ArrayLike | float | None = None,
                       temperature_c: ArrayLike | float | None = None
                       ) -> tuple[Array, Array]:
        """Hybrid target poses ``(N, 4, 4)`` (measurement frame) and ``(N,)`` in-domain
        flags (False: the physical model's pose); the physical ones without a layer."""
        P = self.predict(q, payload_kg, temperature_c)
        if self.residual_model is None:
            return P, np.ones(len(P), dtype=bool)
        m = np.zeros(len(P)) if payload_kg is None else payload_kg
        pred = self.residual_model.predict(q, m, temperature_c)
        return hybrid_poses(P, self.model.base()[:3, :3], pred.correction), pred.in_domain

    # ------------------------------------------------------------------ parameters
    def value(self, key: str) -> float:
        return self.model.value(key)

    def sigma(self, key: str) -> float:
        if self.statistics is None or key not in self.keys:
            return float("nan")
        return float(self.statistics.sigma[self.keys.index(key)])

    def stands_for(self, key: str) -> str:
        names = dict(zip(self.model.space.keys, self.model.space.names, strict=True))
        if self.identifiability is None:
            return names[key]
        return self.identifiability.stands_for(key, names)

    def parameter_table(self) -> list[dict[str, Any]]:
        """One dict per identified parameter: key, name, value, sigma, unit, stands_for."""
        out = []
        for k in self.keys:
            p = self.model.space[k]
            out.append({"key": k, "name": p.name, "kind": p.kind, "value": self.value(k),
                        "sigma": self.sigma(k), "unit": p.unit, "stands_for": self.stands_for(k)})
        return out


def harmonic_order(model: ErrorModel) -> int:
    """The highest joint-angle harmonic order among the model's parameters (0: none)."""
    return max((int(p.key[1]) for p in model.space if p.kind == "harmonic"), default=0)
