"""PARAMS.json and the per-pose residual file: a calibration's documents.

``plugcell calibrate --out PARAMS.json`` writes :func:`params_json` of the
:class:`~plugcell.calibration.result.CalibrationResult` (plus the robot's source and
description, added by the command); :func:`result_from_params` rebuilds a result that
predicts (and compensates) from that document and the robot's description;
:func:`rebase_document` re-registers its BASE (the drift watch).
``plugcell calibrate --residuals RES.json`` writes :func:`residuals_json`: every pose's
measured position and its error vector before and after calibration, for the 3-D view
of the controller UI.

The documents hold SI values with their units (m, rad) for the model and millimetres /
degrees for the statistics, frames and the validity region; NaN and infinities are
written as ``null`` (strict JSON).  A document that cannot be read raises
:class:`ParamsError` (a ``ValueError``) naming the key that is missing or wrong.
The calibration itself (:mod:`plugcell.calibration`) never sees a file or a document.
"""

from __future__ import annotations

import copy
import json
import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from plugcell.calibration.configs import model_config
from plugcell.calibration.determinacy import COMPONENTS, Undetermined
from plugcell.calibration.model import MIN_PAYLOAD_REF_KG, THERMAL_KEY, ErrorModel
from plugcell.calibration.result import CalibrationResult, IterationRecord, harmonic_order
from plugcell.calibration.statistics import PoseResiduals
from plugcell.calibration.validity import ValidityRegion
from plugcell.io.json_fields import (
    DocumentError,
    at,
    flag,
    integer,
    number,
    strict,
    typename,
)
from plugcell.kinematics import RobotDescription
from plugcell.kinematics.rotations import matrix_to_rpy
from plugcell.metrology import AccuracyStats

Array = NDArray[np.float64]

#: ``format`` of PARAMS.json (:func:`params_document`).
FORMAT = "plugcell-calibration"
FORMAT_VERSION = 1
#: ``format`` of the per-pose residual file (:func:`residuals_document`).
RESIDUALS_FORMAT = "plugcell-residuals"
RESIDUALS_FORMAT_VERSION = 1

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "RESIDUALS_FORMAT",
    "RESIDUALS_FORMAT_VERSION",
    "ParamsError",
    "accuracy_summary",
    "params_document",
    "params_json",
    "pose_records",
    "rebase_document",
    "residuals_document",
    "residuals_json",
    "result_from_params",
    "undetermined_document",
    "undetermined_from_document",
    "validity_document",
    "validity_from_document",
]


#: A PARAMS.json document that cannot be used; the message names the key (the error of
#: the document readers of :mod:`plugcell.io.json_fields`, which this module uses).
ParamsError = DocumentError


# ---------------------------------------------------------------------- pieces


def accuracy_summary(stats: AccuracyStats) -> dict[str, Any]:
    """The accuracy figures (8.1–8.2) as a document entry, millimetres and degrees.

    Parameters
    ----------
    stats : AccuracyStats
        Statistics of the position (m) and, when measured, orientation (rad) errors.

    Returns
    -------
    dict
        ``poses``, ``mean_mm``, ``std_mm``, ``max_mm``, ``rms_mm``, ``components_mm``
        {mean, std} (3 each), and ``orientation`` {mean_deg, std_deg, max_deg,
        components_deg, convention} when orientations were measured.
    """
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


def pose_records(residuals: PoseResiduals, set_name: str,
                 weights: ArrayLike | None = None) -> list[dict[str, Any]]:
    """One residual-file entry per pose, millimetres and degrees.

    Parameters
    ----------
    residuals : PoseResiduals
        The residuals of N poses (m, rad).
    set_name : str
        ``"calibration"`` or ``"validation"``, recorded as ``set``.
    weights : array_like, shape (N,), optional
        The robust-loss weight of each pose, recorded as ``weight``.

    Returns
    -------
    list of dict
        ``set``, ``index`` (1-based), ``measured_mm``, ``before_mm``, ``after_mm`` (3
        each), ``before_norm_mm``, ``after_norm_mm``; ``orientation_before_deg`` and
        ``orientation_after_deg`` (3 each) for 6-DOF data; ``weight`` when given.
    """
    out = []
    nb, na = residuals.norms("before"), residuals.norms("after")
    w = None if weights is None else np.asarray(weights, dtype=float)
    ob, oa = residuals.orientation_before, residuals.orientation_after
    for i in range(len(residuals)):
        r: dict[str, Any] = {
            "set": set_name, "index": i + 1,
            "measured_mm": (residuals.positions[i] * 1e3).tolist(),
            "before_mm": (residuals.before[i] * 1e3).tolist(),
            "after_mm": (residuals.after[i] * 1e3).tolist(),
            "before_norm_mm": float(nb[i] * 1e3), "after_norm_mm": float(na[i] * 1e3),
        }
        if ob is not None and oa is not None:
            r["orientation_before_deg"] = np.degrees(ob[i]).tolist()
            r["orientation_after_deg"] = np.degrees(oa[i]).tolist()
        if w is not None:
            r["weight"] = float(w[i])
        out.append(r)
    return out


def _iteration_dict(h: IterationRecord) -> dict[str, float]:
    return {"iteration": h.iteration, "step_norm": h.step_norm, "cost": h.cost,
            "mean_position_mm": h.mean_position_mm, "rms_position_mm": h.rms_position_mm,
            "damping": h.damping}


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


def _summaries(result: CalibrationResult) -> dict[str, dict[str, Any]]:
    """The accuracy summaries (mm, deg) of the calibration and validation sets, each
    with its ``before``."""
    out: dict[str, dict[str, Any]] = {}
    for name, after, before in (
            ("calibration", result.calibration, result.calibration_before),
            ("validation", result.validation, result.validation_before)):
        if after is not None:
            out[name] = accuracy_summary(after)
            if before is not None:
                out[name]["before"] = accuracy_summary(before)
    if "validation" in out and result.validation_region is not None:
        out["validation"]["region"] = result.validation_region.summary()
    return out


def _hybrid_summary(result: CalibrationResult) -> dict[str, Any] | None:
    """Physical vs hybrid accuracy on the validation poses (mm, deg)."""
    h = result.hybrid_validation_residuals
    if h is None:
        return None
    return {"physical": accuracy_summary(h.accuracy("before")),
            "hybrid": accuracy_summary(h.accuracy("after")),
            "poses": len(h), "fallbacks": result.hybrid_fallbacks}


# ---------------------------------------------------------------------- validity


def validity_document(region: ValidityRegion) -> dict[str, Any]:
    """PARAMS.json's ``validity``: the region a calibration's poses covered.

    Parameters
    ----------
    region : ValidityRegion
        Joint ranges (rad), lever arms (m/rad), kept poses ``(P, n)`` (rad), threshold
        and cover (m), payload range (kg), target box (m).

    Returns
    -------
    dict
        ``measure`` (what the distance is), ``poses`` (calibration poses the region was
        built from), ``joint_lower_deg``/``joint_upper_deg`` (n each),
        ``lever_mm_per_rad`` (n), ``threshold_mm``, ``cover_mm``, ``payload_kg``
        [min, max], ``target_lower_mm``/``target_upper_mm`` (3 each), ``poses_deg``
        (P × n, rounded to 1e-6°).
    """
    return {
        "measure": "joint ranges + distance to the nearest calibration pose in joint space "
                   "scaled by each joint's lever arm at the target (mm of target motion)",
        "poses": region.n_poses,
        "joint_lower_deg": np.degrees(region.joint_lower).tolist(),
        "joint_upper_deg": np.degrees(region.joint_upper).tolist(),
        "lever_mm_per_rad": (region.lever_m * 1e3).tolist(),
        "threshold_mm": region.threshold_m * 1e3,
        "cover_mm": region.cover_m * 1e3,
        "payload_kg": list(region.payload_kg),
        "target_lower_mm": (region.target_lower * 1e3).tolist(),
        "target_upper_mm": (region.target_upper * 1e3).tolist(),
        "poses_deg": np.round(np.degrees(region.poses), 6).tolist(),
    }


def validity_from_document(d: dict[str, Any]) -> ValidityRegion:
    """The region of a :func:`validity_document` (inverse; ``cover_mm`` optional).

    Parameters
    ----------
    d : dict
        PARAMS.json's ``validity``.

    Returns
    -------
    ValidityRegion
        In SI units.

    Raises
    ------
    ParamsError
        ``"validity: missing key 'threshold_mm'"`` and the like for a bad entry.
    """
    try:
        return ValidityRegion(joint_lower=np.radians(d["joint_lower_deg"]),
                              joint_upper=np.radians(d["joint_upper_deg"]),
                              lever_m=np.asarray(d["lever_mm_per_rad"], float) / 1e3,
                              poses=np.radians(np.asarray(d["poses_deg"], float)),
                              threshold_m=float(d["threshold_mm"]) / 1e3,
                              cover_m=float(d.get("cover_mm", 0.0)) / 1e3,
                              payload_kg=(float(d["payload_kg"][0]), float(d["payload_kg"][1])),
                              target_lower=np.asarray(d["target_lower_mm"], float) / 1e3,
                              target_upper=np.asarray(d["target_upper_mm"], float) / 1e3,
                              n_poses=int(d["poses"]))
    except KeyError as exc:
        raise ParamsError(f"validity: missing key {exc}") from None
    except (TypeError, IndexError, ValueError, OverflowError) as exc:
        raise ParamsError(f"validity: {exc}") from None


# ---------------------------------------------------------------------- undetermined


def undetermined_document(u: Undetermined) -> dict[str, Any]:
    """PARAMS.json's ``undetermined``: what the calibration poses did not determine.

    Parameters
    ----------
    u : Undetermined
        From the calibration (:mod:`plugcell.calibration.determinacy`).

    Returns
    -------
    dict
        ``components`` (of ``probe_position``, ``probe_orientation``, ``base_position``,
        ``base_orientation``), ``probe_axes`` (flange-frame axes), ``parameters`` (keys),
        ``given`` (frames the user gave), ``orientation_spread_deg``,
        ``required_spread_deg``, ``flange_orientation`` (3 × 3, robot base frame),
        ``poses``, ``directions``, ``tolerance``, ``messages``.
    """
    return {
        "components": list(u.components), "probe_axes": list(u.probe_axes),
        "parameters": list(u.parameters), "given": list(u.given),
        "orientation_spread_deg": math.degrees(u.orientation_spread_rad),
        "required_spread_deg": math.degrees(u.required_spread_rad),
        "flange_orientation": np.asarray(u.flange_orientation).tolist(),
        "poses": u.n_poses, "directions": u.n_directions, "tolerance": u.tolerance,
        "messages": list(u.messages),
    }


def undetermined_from_document(d: dict[str, Any]) -> Undetermined:
    """The record of an :func:`undetermined_document` (inverse).

    Parameters
    ----------
    d : dict
        PARAMS.json's ``undetermined``.

    Returns
    -------
    Undetermined
        The record.

    Raises
    ------
    ParamsError
        A missing key or a value of the wrong type, e.g. ``"undetermined.components:
        unknown 'probe'"``.
    """
    doc = {"undetermined": d}

    def names(key: str, allowed: tuple[str, ...] | None = None) -> tuple[str, ...]:
        v = at(doc, "undetermined", key, default=[])
        if not isinstance(v, list) or not all(isinstance(x, str) for x in v):
            raise ParamsError(f"undetermined.{key}: expected a list of names")
        bad = [x for x in v if allowed is not None and x not in allowed]
        if bad:
            raise ParamsError(f"undetermined.{key}: unknown {', '.join(map(repr, bad))}; "
                              f"known: {', '.join(allowed or ())}")
        return tuple(v)

    try:
        R = np.asarray(at(doc, "undetermined", "flange_orientation"), dtype=float)
    except (TypeError, ValueError):
        raise ParamsError("undetermined.flange_orientation: expected a 3x3 matrix") from None
    if R.shape != (3, 3) or not np.all(np.isfinite(R)):
        raise ParamsError("undetermined.flange_orientation: expected a finite 3x3 matrix")
    return Undetermined(
        components=names("components", COMPONENTS), probe_axes=names("probe_axes",
                                                                     ("x", "y", "z")),
        parameters=names("parameters"), given=names("given", ("base", "probe")),
        orientation_spread_rad=math.radians(number(doc, "undetermined", "orientation_spread_deg")),
        required_spread_rad=math.radians(number(doc, "undetermined", "required_spread_deg")),
        flange_orientation=R, n_poses=integer(doc, "undetermined", "poses"),
        n_directions=integer(doc, "undetermined", "directions"),
        tolerance=number(doc, "undetermined", "tolerance"),
        messages=names("messages"))


# ---------------------------------------------------------------------- PARAMS.json


def params_document(result: CalibrationResult,
                    residual_file: dict[str, Any] | None = None) -> dict[str, Any]:
    """The PARAMS.json content of ``result`` (before the NaN → null of :func:`params_json`).

    Parameters
    ----------
    result : CalibrationResult
        The identified model and its statistics.
    residual_file : dict, optional
        What :func:`plugcell.io.residual_models.save_residual` returned (side-file name,
        SHA-256), recorded under ``residual_model`` beside the layer's summary.

    Returns
    -------
    dict
        ``format``, ``format_version``, ``robot``, ``model`` (number, name, family,
        gravity, payload, title, harmonics, thermal, temperature_ref_c), ``data``
        (poses, six_dof, payload_ref_kg), ``parameters`` (one row per identified
        parameter: key, name, kind, value, sigma, unit, stands_for), ``dependent``,
        ``unidentifiable``, ``values`` (every parameter of the model, SI),
        ``base``/``probe`` (matrix, xyz_mm, rpy_deg; BASE also as eq. 6.24),
        ``references``, ``nominal_frames``, ``iterations``, ``converged``,
        ``condition_number``, ``sigma2``, ``dof``, ``history``, ``calibration``,
        ``validation`` (accuracy summaries, mm/deg), ``warnings``, ``residual_model``,
        ``validation_hybrid``, ``elapsed_s``, ``settings``, ``validity``,
        ``undetermined`` (:func:`undetermined_document`; ``null``: everything determined).
    """
    model = result.model
    space = model.space
    ident = result.identifiability
    dependent = []
    if ident is not None:
        for k in ident.dropped:
            dependent.append({"key": k, "name": space[k].name,
                              "identified_via": [space[v].name for v in ident.via.get(k, ())]})
    summaries = _summaries(result)
    cal, val = summaries.get("calibration"), summaries.get("validation")
    st = result.statistics
    return {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "robot": result.robot,
        "model": {**result.config.as_dict(), "harmonics": harmonic_order(model),
                  "thermal": THERMAL_KEY in space,
                  "temperature_ref_c": model.temperature_ref_c},
        "data": {"poses": result.n_poses, "six_dof": result.six_dof,
                 "payload_ref_kg": model.payload_ref_kg},
        "parameters": result.parameter_table(),
        "dependent": dependent,
        "unidentifiable": [] if ident is None else [space[k].name for k in ident.zero],
        "values": model.as_dict(),
        "base": {**_frame_dict(model.base()), "thesis_6_24": _thesis_base(model.base())},
        "probe": _frame_dict(model.probe()),
        "references": {"base": model.base_ref.tolist(), "probe": model.probe_ref.tolist()},
        "nominal_frames": {"base": _frame_dict(result.nominal.base()),
                           "probe": _frame_dict(result.nominal.probe()),
                           "values": result.nominal.as_dict()},
        "iterations": result.iterations,
        "converged": result.converged,
        "condition_number": None if st is None else st.condition_number,
        "sigma2": None if st is None else st.sigma2,
        "dof": None if st is None else st.dof,
        "history": [_iteration_dict(h) for h in result.history],
        "calibration": cal,
        "validation": val,
        "warnings": list(result.warnings),
        "residual_model": None if result.residual_model is None
        else {**result.residual_model.summary(), **(residual_file or {})},
        "validation_hybrid": _hybrid_summary(result),
        "elapsed_s": result.elapsed_s,
        "settings": dict(result.settings),
        "validity": None if result.validity is None else validity_document(result.validity),
        "undetermined": None if result.undetermined is None
        else undetermined_document(result.undetermined),
    }


def params_json(result: CalibrationResult, indent: int | None = 2,
                residual_file: dict[str, Any] | None = None) -> str:
    """:func:`params_document` as strict JSON (NaN and infinities → ``null``).

    Parameters
    ----------
    result : CalibrationResult
        The calibration.
    indent : int or None, default 2
        JSON indentation (``None``: one line).
    residual_file : dict, optional
        As in :func:`params_document`.

    Returns
    -------
    str
        The JSON text (no trailing newline).
    """
    return json.dumps(strict(params_document(result, residual_file)), indent=indent,
                      allow_nan=False)


def _values(document: dict[str, Any], *path: str) -> dict[str, float]:
    x = at(document, *path)
    if not isinstance(x, dict):
        raise ParamsError(f"{'.'.join(path)}: expected an object, got {typename(x)}")
    for k in x:
        number(document, *path, k)  # names the dotted key of a bad value
    return x


def _transform(document: dict[str, Any], *path: str) -> Array:
    x = at(document, *path)
    try:
        T = np.array(x, dtype=float)
    except (TypeError, ValueError, OverflowError):
        T = np.zeros(0)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise ParamsError(f"{'.'.join(path)}: expected a finite 4x4 matrix")
    return T


def result_from_params(document: dict[str, Any], description: RobotDescription, *,
                       check_robot: bool = True) -> CalibrationResult:
    """A result that predicts, rebuilt from a PARAMS.json document and its robot.

    The model and the nominal robot (values, BASE/PROBE references, payload and
    temperature references, harmonics, thermal expansion), the identified keys, the
    iteration count, the warnings and the validity region come back; the statistics,
    the per-pose residuals and the learned residual layer do not (the caller loads the
    layer's side file: :func:`plugcell.io.residual_models.load_residual`).

    Parameters
    ----------
    document : dict
        What :func:`params_document` wrote (as read from JSON).  ``model.harmonics``,
        ``model.thermal``, ``model.temperature_ref_c``, ``warnings``, ``validity`` and
        ``undetermined`` may be absent (files written before they were recorded).
    description : RobotDescription
        The robot the calibration was identified on (its ``name`` is the document's
        ``robot``).
    check_robot : bool, default True
        Refuse a document whose ``robot`` is not ``description.name`` (a calibration of
        another robot).  ``False`` when ``description`` was taken from the document
        itself (its ``description`` or ``robot_source``), which then names the robot.

    Returns
    -------
    CalibrationResult
        Without statistics, history or residuals.

    Raises
    ------
    ParamsError
        Not a plugcell calibration (``format``), a newer ``format_version``, a missing
        key or a value of the wrong type (the message names the dotted key), a
        calibration of another robot (``check_robot``), or identified parameters the
        model does not have.
    """
    robot = _robot_of(document, description, check_robot)
    cfg, options = _model_options(document)
    values = _values(document, "values")
    nominal_values = _values(document, "nominal_frames", "values")
    keys = _parameter_keys(document)
    iterations = integer(document, "iterations")
    converged = flag(document, "converged")
    six_dof = flag(document, "data", "six_dof")
    n_poses = integer(document, "data", "poses")
    warnings = at(document, "warnings", default=[])
    if not isinstance(warnings, list) or not all(isinstance(w, str) for w in warnings):
        raise ParamsError("warnings: expected a list of strings")
    try:
        model = _model(description, cfg, options, values)
        nominal = _model(description, cfg, options, nominal_values)
    except ValueError as exc:  # the model cannot be built on this robot
        raise ParamsError(f"model {cfg.number} ({cfg.name}) on {description.name!r}: "
                          f"{exc}") from None
    unknown = [k for k in keys if k not in model.space.keys]
    if unknown:
        raise ParamsError(f"parameters: {', '.join(map(repr, unknown))} not in model "
                          f"{cfg.number} ({cfg.name}) of {description.name!r}")
    return CalibrationResult(
        config=cfg, robot=robot, model=model, nominal=nominal, keys=tuple(keys),
        identifiability=None, data_identifiability=None, iterations=iterations,
        converged=converged, history=(), statistics=None, calibration=None,
        calibration_before=None, six_dof=six_dof, n_poses=n_poses,
        warnings=tuple(warnings), validity=_section(document, "validity",
                                                    validity_from_document),
        undetermined=_section(document, "undetermined", undetermined_from_document))


def _robot_of(document: Any, description: RobotDescription, check_robot: bool) -> str:
    """The document's robot, once it is a plugcell calibration this plugcell reads."""
    if not isinstance(document, dict) or document.get("format") != FORMAT:
        raise ParamsError("not a plugcell calibration (missing 'format')")
    version = document.get("format_version", FORMAT_VERSION)
    if isinstance(version, bool) or not isinstance(version, int) or version > FORMAT_VERSION:
        raise ParamsError(f"format_version {version!r}: this plugcell reads up to "
                          f"{FORMAT_VERSION} (written by a newer plugcell?)")
    robot = at(document, "robot")
    if not isinstance(robot, str):
        raise ParamsError(f"robot: expected a name, got {typename(robot)}")
    if check_robot and robot != description.name:
        raise ParamsError(f"a calibration of robot {robot!r}, not of {description.name!r}")
    return robot


def _model_options(document: dict[str, Any]) -> tuple[Any, dict[str, Any]]:
    """The model's configuration and the options of :meth:`ErrorModel.create` it was
    identified with: BASE/PROBE references, payload and temperature references,
    harmonics, thermal expansion (absent ones: their defaults of older files)."""
    model_number = at(document, "model", "number")
    try:
        cfg = model_config(model_number)
    except ValueError as exc:
        raise ParamsError(f"model.number: {exc}") from None
    base_ref = _transform(document, "references", "base")
    probe_ref = _transform(document, "references", "probe")
    m_ref = number(document, "data", "payload_ref_kg")
    if m_ref != 0.0 and m_ref < MIN_PAYLOAD_REF_KG:  # compliance scales with m / m_ref
        raise ParamsError(f"data.payload_ref_kg: 0 (no payload) or at least "
                          f"{MIN_PAYLOAD_REF_KG:g} kg, got {m_ref:g}")
    harmonics = integer(document, "model", "harmonics", default=0)
    if harmonics not in (0, 1, 2):
        raise ParamsError(f"model.harmonics: 0, 1 or 2, got {harmonics}")
    thermal = flag(document, "model", "thermal", default=False)
    t_ref = number(document, "model", "temperature_ref_c", default=0.0)
    return cfg, {"gravity": cfg.gravity, "payload": cfg.payload, "base": base_ref,
                 "probe": probe_ref, "payload_ref_kg": m_ref, "harmonics": harmonics,
                 "thermal": thermal, "temperature_ref_c": t_ref}


def _model(description: RobotDescription, cfg: Any, options: dict[str, Any],
           values: dict[str, float]) -> ErrorModel:
    """The model of ``cfg`` on ``description`` with ``values`` (absent keys: 0)."""
    m = ErrorModel.create(description, cfg.family, **options)
    return m.with_values([float(values.get(k, 0.0)) for k in m.space.keys])


def _parameter_keys(document: dict[str, Any]) -> list[str]:
    """The keys of the identified parameters (``parameters[i].key``)."""
    rows = at(document, "parameters")
    if not isinstance(rows, list):
        raise ParamsError(f"parameters: expected a list, got {typename(rows)}")
    keys = []
    for i, row in enumerate(rows):
        key = row.get("key") if isinstance(row, dict) else None
        if not isinstance(key, str):
            raise ParamsError(f"parameters[{i}]: expected an object with a 'key' name")
        keys.append(key)
    return keys


def _section(document: dict[str, Any], name: str, read: Any) -> Any:
    """``read(document[name])`` — None when the section is absent or empty (files written
    before it was recorded); ParamsError when it is not an object."""
    v = document.get(name)
    if not v:
        return None
    if not isinstance(v, dict):
        raise ParamsError(f"{name}: expected an object, got {typename(v)}")
    return read(v)


def rebase_document(document: dict[str, Any], result: CalibrationResult, base: ArrayLike,
                    event: dict[str, Any] | None = None) -> dict[str, Any]:
    """A copy of PARAMS.json ``document`` with BASE re-registered (the drift watch).

    The reference becomes the new BASE, the BASE parameters' values zero, ``event`` is
    appended to ``drift_history``; ``parameters`` stays the record of the
    identification.

    Parameters
    ----------
    document : dict
        The PARAMS.json document of ``result``.
    result : CalibrationResult
        The calibration ``document`` describes (which of its parameters are BASE's).
    base : array_like, shape (4, 4)
        The new BASE (robot base in the measurement frame, m).
    event : dict, optional
        What happened (time, displacement…), appended to ``drift_history``.

    Returns
    -------
    dict
        The new document (``document`` is not changed).

    Raises
    ------
    ValueError
        ``base`` is not a finite 4×4 transform.
    """
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


# ---------------------------------------------------------------------- residual file


def residuals_document(result: CalibrationResult) -> dict[str, Any]:
    """The per-pose residual file (``plugcell calibrate --residuals``), mm and degrees.

    Parameters
    ----------
    result : CalibrationResult
        A result with per-pose residuals (one from a fit, not from PARAMS.json).

    Returns
    -------
    dict
        ``format``, ``format_version``, ``robot``, ``model`` {number, name},
        ``six_dof``, ``units``, ``convention``; ``sets`` {calibration, validation}: the
        accuracy summaries of PARAMS.json; ``poses``: one entry per pose
        (:func:`pose_records`), calibration poses first, each calibration pose with its
        robust-loss ``weight`` when known.

    Raises
    ------
    ValueError
        ``result`` carries no per-pose residuals (rebuilt from PARAMS.json).
    """
    if result.calibration_residuals is None:
        raise ValueError("this result carries no per-pose residuals (rebuilt from "
                         "PARAMS.json?): evaluate_poses(data) computes them")
    poses = pose_records(result.calibration_residuals, "calibration", result.pose_weights)
    if result.validation_residuals is not None:
        poses += pose_records(result.validation_residuals, "validation")
    return {
        "format": RESIDUALS_FORMAT,
        "format_version": RESIDUALS_FORMAT_VERSION,
        "robot": result.robot,
        "model": {"number": result.config.number, "name": result.config.name},
        "six_dof": result.six_dof,
        "units": {"length": "mm", "angle": "deg"},
        "convention": "residual = measured - predicted, measurement (tracker) frame; "
                      "before: nominal robot with BASE/PROBE fitted; after: calibrated",
        "sets": _summaries(result),
        "poses": poses,
    }


def residuals_json(result: CalibrationResult, indent: int | None = 2) -> str:
    """:func:`residuals_document` as strict JSON (NaN and infinities → ``null``).

    Parameters
    ----------
    result : CalibrationResult
        A result with per-pose residuals.
    indent : int or None, default 2
        JSON indentation.

    Returns
    -------
    str
        The JSON text (no trailing newline).
    """
    return json.dumps(strict(residuals_document(result)), indent=indent, allow_nan=False)
