"""The outcome of an identification: predicts, evaluates, reports, serialises.

:class:`CalibrationResult` is immutable.  ``to_dict()`` is the content of
``PARAMS.json`` (``plugcell calibrate --out``); :meth:`CalibrationResult.from_dict`
rebuilds a working result from it together with the robot description, so a
saved calibration can predict (and compensate) later.  ``residuals_dict()`` is the
per-pose residual file (``plugcell calibrate --residuals``): every pose's measured
position and its error vector before and after calibration, for the 3-D view of the
controller UI.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from plugcell.calibration.configs import ModelConfig, model_config
from plugcell.calibration.data import CalibrationData
from plugcell.calibration.identifiability import Identifiability
from plugcell.calibration.model import THERMAL_KEY, ErrorModel
from plugcell.calibration.residual_model import (
    LearnedResidual,
    calibration_fingerprint,
    hybrid_poses,
    hybrid_residuals,
)
from plugcell.calibration.statistics import (
    ParameterStatistics,
    PoseResiduals,
    accuracy_summary,
    pose_residuals,
)
from plugcell.calibration.validity import RegionCheck, ValidityRegion
from plugcell.kinematics import RobotDescription
from plugcell.kinematics.rotations import matrix_to_rpy
from plugcell.metrology import AccuracyStats

Array = NDArray[np.float64]

FORMAT = "plugcell-calibration"
FORMAT_VERSION = 1
#: ``format`` of the per-pose residual file (:meth:`CalibrationResult.residuals_dict`).
RESIDUALS_FORMAT = "plugcell-residuals"
RESIDUALS_FORMAT_VERSION = 1

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "RESIDUALS_FORMAT",
    "RESIDUALS_FORMAT_VERSION",
    "CalibrationResult",
    "IterationRecord",
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

    def as_dict(self) -> dict[str, float]:
        """The fields as a JSON-ready dict."""
        return {"iteration": self.iteration, "step_norm": self.step_norm, "cost": self.cost,
                "mean_position_mm": self.mean_position_mm,
                "rms_position_mm": self.rms_position_mm, "damping": self.damping}


def _frame_dict(T: Array) -> dict[str, Any]:
    return {
        "matrix": np.asarray(T).tolist(),
        "xyz_mm": (np.asarray(T)[:3, 3] * 1e3).tolist(),
        "rpy_deg": np.degrees(matrix_to_rpy(np.asarray(T)[:3, :3])).tolist(),
    }


def _thesis_base(T: Array) -> dict[str, float] | None:
    """The BASE as the six parameters of eq. (6.24) (via D.6), when regular."""
    from plugcell.metrology import MetrologyError, base_parameters_from_matrix

    try:
        bp = base_parameters_from_matrix(T)
    except (MetrologyError, ValueError):
        return None
    return {"a0_mm": bp.a0 * 1e3, "b0_mm": bp.b0 * 1e3, "alpha0_deg": math.degrees(bp.alpha0),
            "beta0_deg": math.degrees(bp.beta0), "theta0_deg": math.degrees(bp.theta0),
            "d0_mm": bp.d0 * 1e3}


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
        result rebuilt by :meth:`from_dict`).
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

    # ------------------------------------------------------------------ serialisation
    def _summaries(self) -> dict[str, dict[str, Any]]:
        """The accuracy summaries (mm, deg) of the calibration and validation sets, each
        with its ``before``."""
        out: dict[str, dict[str, Any]] = {}
        for name, after, before in (("calibration", self.calibration, self.calibration_before),
                                    ("validation", self.validation, self.validation_before)):
            if after is not None:
                out[name] = accuracy_summary(after)
                if before is not None:
                    out[name]["before"] = accuracy_summary(before)
        if "validation" in out and self.validation_region is not None:
            out["validation"]["region"] = self.validation_region.summary()
        return out

    def to_dict(self, residual_file: dict[str, Any] | None = None) -> dict[str, Any]:
        """The PARAMS.json content (SI values with units; statistics in mm / deg).

        ``residual_file``: what :func:`plugcell.io.residual_models.save_residual`
        returned (side-file name, SHA-256), recorded under ``residual_model``."""
        space = self.model.space
        ident = self.identifiability
        dependent = []
        if ident is not None:
            for k in ident.dropped:
                dependent.append({"key": k, "name": space[k].name,
                                  "identified_via": [space[v].name for v in ident.via.get(k, ())]})
        summaries = self._summaries()
        cal, val = summaries.get("calibration"), summaries.get("validation")
        st = self.statistics
        return {
            "format": FORMAT,
            "format_version": FORMAT_VERSION,
            "robot": self.robot,
            "model": {**self.config.as_dict(), "harmonics": harmonic_order(self.model),
                      "thermal": THERMAL_KEY in self.model.space,
                      "temperature_ref_c": self.model.temperature_ref_c},
            "data": {"poses": self.n_poses, "six_dof": self.six_dof,
                     "payload_ref_kg": self.model.payload_ref_kg},
            "parameters": self.parameter_table(),
            "dependent": dependent,
            "unidentifiable": [] if ident is None else [space[k].name for k in ident.zero],
            "values": self.model.as_dict(),
            "base": {**_frame_dict(self.model.base()),
                     "thesis_6_24": _thesis_base(self.model.base())},
            "probe": _frame_dict(self.model.probe()),
            "references": {"base": self.model.base_ref.tolist(),
                           "probe": self.model.probe_ref.tolist()},
            "nominal_frames": {"base": _frame_dict(self.nominal.base()),
                               "probe": _frame_dict(self.nominal.probe()),
                               "values": self.nominal.as_dict()},
            "iterations": self.iterations,
            "converged": self.converged,
            "condition_number": None if st is None else st.condition_number,
            "sigma2": None if st is None else st.sigma2,
            "dof": None if st is None else st.dof,
            "history": [h.as_dict() for h in self.history],
            "calibration": cal,
            "validation": val,
            "warnings": list(self.warnings),
            "residual_model": None if self.residual_model is None
            else {**self.residual_model.summary(), **(residual_file or {})},
            "validation_hybrid": self._hybrid_summary(),
            "elapsed_s": self.elapsed_s,
            "settings": dict(self.settings),
            "validity": None if self.validity is None else self.validity.to_dict(),
        }

    def _hybrid_summary(self) -> dict[str, Any] | None:
        """Physical vs hybrid accuracy on the validation poses (mm, deg)."""
        h = self.hybrid_validation_residuals
        if h is None:
            return None
        return {"physical": accuracy_summary(h.accuracy("before")),
                "hybrid": accuracy_summary(h.accuracy("after")),
                "poses": len(h), "fallbacks": self.hybrid_fallbacks}

    def to_json(self, indent: int | None = 2,
                residual_file: dict[str, Any] | None = None) -> str:
        return json.dumps(_clean(self.to_dict(residual_file)), indent=indent, allow_nan=False)

    def residuals_dict(self) -> dict[str, Any]:
        """The per-pose residual file (``plugcell calibrate --residuals``), mm and degrees.

        ``format``, ``format_version``, ``robot``, ``model`` {number, name}, ``six_dof``,
        ``units``, ``convention``; ``sets`` {calibration, validation}: the accuracy
        summaries of PARAMS.json; ``poses``: one entry per pose, calibration poses
        first — ``set``, ``index``, ``measured_mm``, ``before_mm``, ``after_mm``,
        ``before_norm_mm``, ``after_norm_mm`` (+ orientation errors in degrees for
        6-DOF data, + the robust-loss ``weight`` of a calibration pose).  Raises
        ``ValueError`` for a result without residuals (one rebuilt from PARAMS.json).
        """
        if self.calibration_residuals is None:
            raise ValueError("this result carries no per-pose residuals (rebuilt from "
                             "PARAMS.json?): evaluate_poses(data) computes them")
        poses = self.calibration_residuals.records("calibration", self.pose_weights)
        if self.validation_residuals is not None:
            poses += self.validation_residuals.records("validation")
        return {
            "format": RESIDUALS_FORMAT,
            "format_version": RESIDUALS_FORMAT_VERSION,
            "robot": self.robot,
            "model": {"number": self.config.number, "name": self.config.name},
            "six_dof": self.six_dof,
            "units": {"length": "mm", "angle": "deg"},
            "convention": "residual = measured - predicted, measurement (tracker) frame; "
                          "before: nominal robot with BASE/PROBE fitted; after: calibrated",
            "sets": self._summaries(),
            "poses": poses,
        }

    def residuals_json(self, indent: int | None = 2) -> str:
        """:meth:`residuals_dict` as strict JSON."""
        return json.dumps(_clean(self.residuals_dict()), indent=indent, allow_nan=False)

    @classmethod
    def from_dict(cls, d: dict[str, Any], desc: RobotDescription) -> CalibrationResult:
        """A result that predicts, rebuilt from :meth:`to_dict` output and the robot."""
        if d.get("format") != FORMAT:
            raise ValueError("not a plugcell calibration (missing 'format')")
        cfg = model_config(d["model"]["number"])
        refs = d["references"]
        m_ref = float(d["data"]["payload_ref_kg"])

        def build(values: dict[str, float]) -> ErrorModel:
            m = ErrorModel.create(desc, cfg.family, gravity=cfg.gravity, payload=cfg.payload,
                                  base=np.array(refs["base"]), probe=np.array(refs["probe"]),
                                  payload_ref_kg=m_ref,
                                  harmonics=int(d["model"].get("harmonics", 0)),
                                  thermal=bool(d["model"].get("thermal", False)),
                                  temperature_ref_c=float(d["model"].get("temperature_ref_c",
                                                                         0.0)))
            return m.with_values([float(values.get(k, 0.0)) for k in m.space.keys])

        model = build(d["values"])
        nominal = build(d["nominal_frames"]["values"])
        validity = None
        if d.get("validity"):  # absent in files written before the region was recorded
            validity = ValidityRegion.from_dict(d["validity"])
        return cls(config=cfg, robot=d["robot"], model=model, nominal=nominal,
                   keys=tuple(p["key"] for p in d["parameters"]), identifiability=None,
                   data_identifiability=None, iterations=int(d["iterations"]),
                   converged=bool(d["converged"]), history=(), statistics=None,
                   calibration=None, calibration_before=None, six_dof=bool(d["data"]["six_dof"]),
                   n_poses=int(d["data"]["poses"]), warnings=tuple(d.get("warnings", ())),
                   validity=validity)


def rebase_document(document: dict[str, Any], result: CalibrationResult, base: ArrayLike,
                    event: dict[str, Any] | None = None) -> dict[str, Any]:
    """A copy of the PARAMS.json ``document`` of ``result`` with BASE re-registered to
    ``base`` ``(4, 4)`` (the drift watch): the reference becomes the new BASE, the BASE
    parameters' values zero, ``event`` appended to ``drift_history``; ``parameters``
    stays the record of the identification.

    Parameters
    ----------
    document : dict
        The PARAMS.json document of ``result``.
    result : CalibrationResult
        The calibration.
    base : (4, 4) array_like, m
        The re-registered BASE.
    event : dict, optional
        The drift event to record.

    Returns
    -------
    dict
        The new document (``document`` is not changed).

    Raises
    ------
    ValueError
        ``base`` not a finite 4×4 matrix.
    """
    import copy

    B = np.asarray(base, dtype=float)
    if B.shape != (4, 4) or not np.all(np.isfinite(B)):
        raise ValueError(f"base: expected a finite 4x4 transform, got shape {B.shape}")
    d = copy.deepcopy(document)
    for p in result.model.space:
        if p.kind == "base":
            d["values"][p.key] = 0.0
    d["references"]["base"] = B.tolist()
    d["base"] = {**_frame_dict(B), "thesis_6_24": _thesis_base(B)}
    if event is not None:
        d.setdefault("drift_history", []).append(dict(event))
    return d


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


def _clean(x: Any) -> Any:
    """Replace NaN/inf by None so the JSON is strict."""
    if isinstance(x, dict):
        return {k: _clean(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_clean(v) for v in x]
    if isinstance(x, float | np.floating):
        return float(x) if math.isfinite(x) else None
    if isinstance(x, np.integer):
        return int(x)
    return x
