"""The functions Evaluate may call: the thesis's Matlab functions, registered by name.

Thesis 7.3: "the error identification and compensation algorithms presented in
sections 6.4, 6.5.1 are programmed in separate Matlab functions that will be called
by the robot".  These are those functions, on plugcell's engines:

=====================================================  ================================
function                                               thesis
=====================================================  ================================
``calibrate(mJ, mT, model=5, payload=0, …)``            H4Calibration (8.2.2, Fig. 8-4)
``validate(params, vJ, vT, payload=0, …)``              accuracy on other poses (8.2.3)
``residuals(params, mJ, mT, payload=0, …)``             each pose's residual (3-D view, 7.5)
``summary(params)``                                     the figures H4Calibration shows
``save_params(params, 'name')``, ``load_params('name')``  saving; LoadParams (8.3.2)
``frame(params, 'base'|'probe', angles='zyz')``       BASE/PROBE for Set Base/Set Probe
``compensate(params, targets, payload=0, …)``           model-based compensation (6.5.1)
``compensate_joints(params, joints, payload=0, …)``     H4Compensation (8.3.2)
``calc_targets(holes, corners, base, per_bar=6, …)``    CalcTarget (8.4.1)
``probe_from_features(…)``, ``base_from_features(…)``   appendix D (the wizards of 7.5)
``append(a, b)``, ``row(a, i)``, ``size(a)``, ``clear(…)``  workspace housekeeping
=====================================================  ================================

Robot units throughout, converted to SI by :mod:`plugcell.io.units`: lengths in mm,
angles in degrees, joint readings in degrees (a prismatic joint: mm; what ARM_JNTP
gives); a pose 6-vector is ``x, y, z, a, b, c`` with the angles in the
``angles`` convention: ``'zyz'`` (Comau Z-Y-Z, the default), ``'rpy'``, ``'xyz'`` or ``'prj'``
(:mod:`plugcell.io.units`; ``'euler'``, the old name of ``'zyz'``, still works).
Parameters are saved as PARAMS.json (docs/calibration.md) under the service's data
directory, by bare name only.
"""

from __future__ import annotations

import functools
import json
import os
import tempfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from plugcell.devices.compute.expr import EvaluationError
from plugcell.devices.compute.workspace import Workspace, WorkspaceError, as_matrix
from plugcell.framework.keys import check_name as _check_file_name
from plugcell.io.robots import available_robots, load_robot
from plugcell.io.units import (
    M_PER_MM,
    MM_PER_M,
    UnitsError,
    convention_name,
    joints_from_si,
    joints_to_si,
    pose_from_robot,
    robot_from_pose,
)
from plugcell.kinematics import RobotDescription
from plugcell.kinematics.rotations import angles_to_matrix

if TYPE_CHECKING:
    from plugcell.calibration import CalibrationData, CalibrationResult

__all__ = ["FUNCTIONS", "FunctionContext", "Parameters", "register"]


class FunctionError(EvaluationError):
    """A registered function refused its arguments or failed; the message says why."""


@dataclass
class FunctionContext:
    """What a function may use besides its arguments."""

    workspace: Workspace
    robot: str = "smart_h4"
    params_dir: Path = field(default_factory=lambda: Path("."))
    #: Warnings of the functions evaluated (the compute service notes them on the
    #: process: the reason of its Completed update).
    warnings: list[str] = field(default_factory=list)


@dataclass(frozen=True, eq=False)
class Parameters:
    """Identified parameters in a workspace: the result and its PARAMS.json document."""

    result: CalibrationResult
    description: RobotDescription
    document: dict[str, Any]
    kind: str = "identified parameters"


FUNCTIONS: dict[str, Callable[..., Any]] = {}


def register(fn: Callable[..., Any]) -> Callable[..., Any]:
    """Make ``fn`` callable from Evaluate under its own name."""
    FUNCTIONS[fn.__name__] = fn
    return fn


# -- argument checks -------------------------------------------------------------------------


def _matrix(x: Any, what: str, cols: tuple[int, ...] | None = None) -> np.ndarray:
    if isinstance(x, Parameters | str):
        raise FunctionError(f"{what}: a matrix expected, got {_kind(x)}")
    try:
        m = as_matrix(x, what)
    except WorkspaceError as exc:
        raise FunctionError(str(exc)) from None
    if cols is not None and m.shape[1] not in cols:
        want = " or ".join(str(c) for c in cols)
        raise FunctionError(f"{what}: {want} columns expected, got {m.shape[0]}×{m.shape[1]}")
    return m


def _kind(x: Any) -> str:
    if isinstance(x, str):
        return f"the string {x!r}"
    return getattr(x, "kind", type(x).__name__)


def _params(x: Any, what: str = "params") -> Parameters:
    if not isinstance(x, Parameters):
        raise FunctionError(f"{what}: identified parameters expected (from calibrate or "
                            f"load_params), got {_kind(x)}")
    return x


def _text(x: Any, what: str) -> str:
    if not isinstance(x, str):
        raise FunctionError(f"{what}: a 'string' expected, got {_kind(x)}")
    return x


def _number(x: Any, what: str) -> float:
    if isinstance(x, np.ndarray) and x.size == 1:
        x = float(x.reshape(-1)[0])
    if not isinstance(x, float | int) or not np.isfinite(x):
        raise FunctionError(f"{what}: a number expected, got {_kind(x)}")
    return float(x)


def _integer(x: Any, what: str) -> int:
    v = _number(x, what)
    if v != int(v):
        raise FunctionError(f"{what}: a whole number expected, got {v:g}")
    return int(v)


def _convention(angles: Any) -> str:
    """The convention ``angles`` names (io.units; ``'euler'``: the old name of ``'zyz'``)."""
    try:
        return convention_name(_text(angles, "angles"))
    except UnitsError as exc:
        raise FunctionError(f"angles: {exc}") from None


def _payload(x: Any, n: int) -> np.ndarray:
    if isinstance(x, float | int):
        m = np.full(n, float(x))
    else:
        m = _matrix(x, "payload").reshape(-1)
        if m.size == 1:
            m = np.full(n, m[0])
    if m.shape != (n,) or np.any(m < 0):
        raise FunctionError(f"payload: one mass ≥ 0 kg or one per pose ({n}) expected")
    return m


@functools.lru_cache(maxsize=8)
def _robot(name: str) -> RobotDescription:
    return load_robot(name)


def _description(ctx: FunctionContext, robot: Any) -> RobotDescription:
    if robot is None:
        return _robot(ctx.robot)
    name = _text(robot, "robot")
    if name not in available_robots():  # bare names only: never a path from a program
        raise FunctionError(f"robot {name!r} unknown; shipped robots: "
                            f"{', '.join(available_robots())}")
    return _robot(name)


def _poses(rows: np.ndarray, convention: str) -> np.ndarray:
    """N×6 rows (mm, deg) → (N, 4, 4) in metres."""
    return np.stack([pose_from_robot(r, convention) for r in rows]) if len(rows) else (
        np.empty((0, 4, 4)))


def _data(desc: RobotDescription, mJ: Any, mT: Any, payload: Any, angles: Any,
          names: tuple[str, str]) -> CalibrationData:
    from plugcell.calibration import CalibrationData

    J = _matrix(mJ, names[0], (desc.n_readings,))
    T = _matrix(mT, names[1], (3, 6))
    if len(J) != len(T):
        raise FunctionError(f"{names[0]} has {len(J)} rows but {names[1]} has {len(T)}")
    m = _payload(payload, len(J))
    rotations = None
    if T.shape[1] == 6:
        rotations = angles_to_matrix(np.deg2rad(T[:, 3:]), _convention(angles))
    try:
        return CalibrationData(q=joints_to_si(J, desc.reading_scale()),
                               positions=T[:, :3] * M_PER_MM,
                               rotations=rotations, payload_kg=m)
    except ValueError as exc:
        raise FunctionError(str(exc)) from None


# -- calibration (8.2) ----------------------------------------------------------------------


@register
def calibrate(ctx: FunctionContext, mJ: Any, mT: Any, model: Any = 5.0, payload: Any = 0.0,
              angles: Any = "zyz", robot: Any = None) -> Parameters:
    """Identify the error parameters from joint readings ``mJ`` (N×n, deg) and tracker
    measurements ``mT`` (N×6 poses mm/deg, or N×3 positions mm) — H4Calibration."""
    from plugcell.calibration import CalibrationError, Calibrator
    from plugcell.io.params import params_json

    desc = _description(ctx, robot)
    data = _data(desc, mJ, mT, payload, angles, ("mJ", "mT"))
    spec: int | str = model if isinstance(model, str) else _integer(model, "model")
    try:
        result = Calibrator(desc, model=spec).fit(data)
    except (CalibrationError, ValueError) as exc:
        raise FunctionError(str(exc)) from None
    return Parameters(result, desc, json.loads(params_json(result)))


def _stats_row(before: Any, after: Any, poses: int) -> np.ndarray:
    orientation = after.orientation.norm.mean if after.orientation is not None else 0.0
    return np.array([[poses, before.position.norm.mean * MM_PER_M,
                      after.position.norm.mean * MM_PER_M, after.position.norm.std * MM_PER_M,
                      after.position.norm.max * MM_PER_M,
                      np.rad2deg(orientation)]])


@register
def validate(ctx: FunctionContext, params: Any, vJ: Any, vT: Any, payload: Any = 0.0,
             angles: Any = "zyz") -> np.ndarray:
    """Accuracy on other poses: 1×6 ``[poses, mean before, mean after, σ after, max after
    (mm), mean orientation after (deg)]`` (eqs. 8.1–8.2)."""
    p = _params(params)
    data = _data(p.description, vJ, vT, payload, angles, ("vJ", "vT"))
    before, after = p.result.evaluate(data)
    return _stats_row(before, after, len(data))


@register
def residuals(ctx: FunctionContext, params: Any, mJ: Any, mT: Any, payload: Any = 0.0,
              angles: Any = "zyz") -> np.ndarray:
    """The residual of every pose: N×6 ``[x, y, z, dx, dy, dz]`` (mm) — the measured
    position and measured − calibrated model, in the tracker frame (what the 3-D view of
    the visualisation service shows, 7.5)."""
    p = _params(params)
    data = _data(p.description, mJ, mT, payload, angles, ("mJ", "mT"))
    try:
        res = p.result.evaluate_poses(data)
    except ValueError as exc:
        raise FunctionError(str(exc)) from None
    return np.hstack([res.positions, res.after]) * MM_PER_M


@register
def summary(ctx: FunctionContext, params: Any) -> np.ndarray:
    """The calibration figures (Fig. 8-8): 1×6 as :func:`validate`, on the calibration
    poses."""
    doc = _params(params).document.get("calibration")
    if not doc:
        raise FunctionError("these parameters carry no calibration statistics")
    before = doc.get("before") or {}
    orientation = (doc.get("orientation") or {}).get("mean_deg", 0.0)
    return np.array([[doc["poses"], before.get("mean_mm", np.nan), doc["mean_mm"],
                      doc["std_mm"], doc["max_mm"], orientation]], dtype=float)


def _params_path(ctx: FunctionContext, name: Any) -> Path:
    text = _text(name, "name")
    try:
        _check_file_name(text, "parameter set name")
    except ValueError as exc:
        raise FunctionError(str(exc)) from None
    if text.startswith(".") or ".." in text:
        raise FunctionError(f"parameter set name {text!r}: no dots at the start, no '..'")
    return ctx.params_dir / f"{text}.json"


@register
def save_params(ctx: FunctionContext, params: Any, name: Any) -> None:
    """Save identified parameters as PARAMS.json under the service's data directory
    (with a learned residual layer, its side file ``NAME.residual.skops`` beside it)."""
    p = _params(params)
    path = _params_path(ctx, name)
    path.parent.mkdir(parents=True, exist_ok=True)
    layer = p.result.residual_model
    if layer is not None:
        from plugcell.io.residual_models import ResidualFileError, residual_path, save_residual

        try:
            entry = save_residual(layer, residual_path(path))
        except ResidualFileError as exc:
            raise FunctionError(str(exc)) from None
        p.document["residual_model"] = {**(p.document.get("residual_model") or {}), **entry}
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".params-", suffix=".json")
    with os.fdopen(fd, "w", encoding="utf-8") as fh:
        json.dump(p.document, fh, indent=2, allow_nan=False)
    os.replace(tmp, path)


@register
def load_params(ctx: FunctionContext, name: Any) -> Parameters:
    """Load parameters saved by :func:`save_params` (or written by ``plugcell calibrate``)
    — LoadParams of 8.3.2."""
    from plugcell.io.params import result_from_params

    path = _params_path(ctx, name)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
        desc = _description(ctx, doc.get("robot"))
        result = result_from_params(doc, desc)
    except FileNotFoundError:
        raise FunctionError(f"no parameter set {path.stem!r} in {path.parent}") from None
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise FunctionError(f"{path.name}: cannot read: {exc}") from None
    entry = doc.get("residual_model")
    if entry:  # a learned residual layer: the hybrid model (docs/calibration.md)
        from plugcell.io.residual_models import ResidualFileError, load_residual

        try:
            layer = load_residual(entry, path, robot=result.robot, model=result.model)
        except ResidualFileError as exc:
            raise FunctionError(str(exc)) from None
        result = result.with_residual_model(layer)
    return Parameters(result, desc, doc)


@register
def frame(ctx: FunctionContext, params: Any, which: Any, angles: Any = "zyz") -> np.ndarray:
    """The identified BASE or PROBE as a 1×6 row (mm, deg) for Set Base / Set Probe."""
    p = _params(params)
    name = _text(which, "which")
    if name not in ("base", "probe"):
        raise FunctionError(f"which: 'base' or 'probe', got {name!r}")
    T = p.result.model.base() if name == "base" else p.result.model.probe()
    return robot_from_pose(T, _convention(angles)).reshape(1, 6)


# -- drift watch (issue 19) -------------------------------------------------------------------


@register
def base_drift(ctx: FunctionContext, params: Any, nests: Any, measured: Any,
               threshold: Any = 0.05) -> np.ndarray:
    """The drift of BASE from re-measured reference nests (docs/metrology.md): ``nests``
    K×3 or K×6, the registered nest positions in the robot base frame (mm); ``measured``
    K×3 or K×6, the same nests measured now with the tracker's BASE set to the identified
    one (robot base frame, mm); ``threshold`` mm.  → 1×9 ``[displacement mm, alarm 0|1,
    consistent 0|1, tx, ty, tz (mm), rx, ry, rz (deg)]``: the drift ``D`` in the tracker
    frame (``BASE' = D · BASE``) and its largest displacement at the nests."""
    from plugcell.metrology.drift import estimate_base_drift

    p = _params(params)
    n = _matrix(nests, "nests")
    m = _matrix(measured, "measured")
    if n.shape[1] not in (3, 6) or m.shape[1] not in (3, 6):
        raise FunctionError("nests and measured: K×3 or K×6 rows (mm[, deg])")
    B = p.result.model.base()
    m_tracker = m[:, :3] / MM_PER_M @ B[:3, :3].T + B[:3, 3]
    try:
        est = estimate_base_drift(B, n[:, :3] / MM_PER_M, m_tracker,
                                  threshold_m=_number(threshold, "threshold") * M_PER_MM)
    except ValueError as exc:
        raise FunctionError(str(exc)) from None
    return np.r_[est.displacement_m * MM_PER_M, float(est.alarm), float(est.consistent),
                 est.translation_m * MM_PER_M, np.degrees(est.rotation_rad)].reshape(1, 9)


@register
def rebase(ctx: FunctionContext, params: Any, drift: Any) -> Parameters:
    """Parameters with BASE re-registered by a :func:`base_drift` row: ``BASE' = D·BASE``
    (the robot's parameters and a learned residual layer unchanged)."""
    from plugcell.io.params import rebase_document, result_from_params
    from plugcell.kinematics.transforms import so3_exp

    p = _params(params)
    row = _matrix(drift, "drift", (9,))[0]
    D = np.eye(4)
    D[:3, :3] = so3_exp(np.radians(row[6:9]))
    D[:3, 3] = row[3:6] / MM_PER_M
    doc = rebase_document(p.document, p.result, D @ p.result.model.base(),
                          {"displacement_mm": float(row[0]), "alarm": bool(row[1] > 0.5),
                           "translation_mm": row[3:6].tolist(),
                           "rotation_deg": row[6:9].tolist()})
    result = result_from_params(doc, p.description)
    if p.result.residual_model is not None:
        result = result.with_residual_model(p.result.residual_model)
    return Parameters(result, p.description, doc)


# -- compensation (6.5.1, 8.3.2) ------------------------------------------------------------


def _tool(p: Parameters, tool: Any, convention: str) -> np.ndarray | None:
    if tool is None:
        return None
    return pose_from_robot(_matrix(tool, "tool", (6,)).reshape(-1), convention)


def _note_region(ctx: FunctionContext, p: Parameters, function: str, q: np.ndarray,
                 payload: np.ndarray) -> None:
    """Warn (``ctx.warnings``) about compensated joints ``q`` (rad) outside the region the
    parameters were identified on: how many, and the first three with how far."""
    check = p.result.check_region(q, payload)
    if check is None or not check.count:
        return
    names = p.description.actuated
    first = [f"target {int(k) + 1}: {check.reasons(int(k), names)}"
             for k in np.flatnonzero(check.outside)[:3]]
    more = f"; … and {check.count - 3} more" if check.count > 3 else ""
    ctx.warnings.append(f"{function}: {check.message('targets')} — " + "; ".join(first) + more)


def _joints_or_fail(result: Any, desc: RobotDescription) -> np.ndarray:
    if not np.all(result.ok):
        k = int(np.flatnonzero(~result.ok)[0])
        raise FunctionError(f"target {k + 1}: {result.reason[k]}")
    return joints_from_si(result.q, desc.reading_scale())


@register
def compensate(ctx: FunctionContext, params: Any, targets: Any, payload: Any = 0.0,
               angles: Any = "zyz", tool: Any = None) -> np.ndarray:
    """Model-based compensation (6.5.1): target poses N×6 (robot base frame, mm/deg) →
    the joints (N×n, deg) that reach them on the identified model.  ``tool``: the
    compensated point in the flange frame (6-vector; default the identified PROBE)."""
    from plugcell.compensation import IdentifiedModel
    from plugcell.compensation import compensate as _compensate

    p = _params(params)
    convention = _convention(angles)
    T = _poses(_matrix(targets, "targets", (6,)), convention)
    model = IdentifiedModel(p.result.model, tool=_tool(p, tool, convention),
                            residual=p.result.residual_model)
    m = _payload(payload, len(T))
    try:
        res = _compensate(model, T, m, raise_errors=False)
    except ValueError as exc:
        raise FunctionError(str(exc)) from None
    q = _joints_or_fail(res, p.description)
    _note_region(ctx, p, "compensate", res.q, m)
    return q


@register
def compensate_joints(ctx: FunctionContext, params: Any, joints: Any, payload: Any = 0.0,
                      angles: Any = "zyz", tool: Any = None) -> np.ndarray:
    """H4Compensation (8.3.2): the nominal joints of a target (POS_TO_JNTP, N×n deg) →
    the compensated joints (N×n, deg) that put the tool where the nominal robot would."""
    from plugcell.compensation import IdentifiedModel, NominalModel
    from plugcell.compensation import compensate_joints as _compensate_joints

    p = _params(params)
    desc = p.description
    q = joints_to_si(_matrix(joints, "joints", (desc.n_readings,)), desc.reading_scale())
    model = IdentifiedModel(p.result.model, tool=_tool(p, tool, _convention(angles)),
                            residual=p.result.residual_model)
    T = NominalModel(desc, tool=model.tool).pose(q)
    m = _payload(payload, len(q))
    try:
        res = _compensate_joints(model, T, q, m, raise_errors=False)
    except ValueError as exc:
        raise FunctionError(str(exc)) from None
    out = _joints_or_fail(res, desc)
    _note_region(ctx, p, "compensate_joints", res.q, m)
    return out


@register
def region(ctx: FunctionContext, params: Any, joints: Any, payload: Any = 0.0) -> np.ndarray:
    """Joints (N×n, deg; e.g. what :func:`compensate` returned) checked against the region
    the parameters were identified on: N×3 ``[outside (1/0), distance to the nearest
    calibration pose (mm), worst joint beyond its calibrated range (deg)]``
    (docs/planning.md).  Fails for parameters saved before the region was recorded."""
    p = _params(params)
    q = joints_to_si(_matrix(joints, "joints", (p.description.n_readings,)),
                     p.description.reading_scale())
    check = p.result.check_region(q, _payload(payload, len(q)))
    if check is None:
        raise FunctionError("these parameters record no calibrated region (saved by an older "
                            "plugcell): calibrate again to have one")
    return np.column_stack([check.outside.astype(float), check.distance_m * MM_PER_M,
                            np.degrees(check.joint_excess_rad)])


# -- part localisation (8.4.1) ---------------------------------------------------------------


@register
def calc_targets(ctx: FunctionContext, holes: Any, corners: Any, base: Any,
                 per_bar: Any = 6.0, angles: Any = "zyz", normal: Any = None) -> np.ndarray:
    """CalcTarget (8.4.1): target frames from holes measured with an SMR (tracker frame).

    ``holes``: (k·per_bar)×3 (or ×6: the first three columns) positions in mm, bar by
    bar; each hole is the origin of a target frame.  ``corners``: ≥ 3 holes (the four
    at the corners of the bars) whose best-fit plane's normal is the common z axis —
    signed towards ``normal`` (3 numbers, tracker frame), by default towards the
    tracker.  Each bar's best-fit line through its holes (first to last) is its y
    axis; x = y × z.  The frames are transformed into the robot base frame with
    ``base`` (a 1×6 BASE in mm/deg, or identified parameters) and returned as
    (k·per_bar)×6 poses (mm, deg in ``angles``).
    """
    from plugcell.metrology import MetrologyError, fit_line, fit_plane, frame_from_axes
    from plugcell.metrology import invert_transform as _inv

    convention = _convention(angles)
    H = _matrix(holes, "holes", (3, 6))[:, :3] * M_PER_MM
    C = _matrix(corners, "corners", (3, 6))[:, :3] * M_PER_MM
    n = _integer(per_bar, "per_bar")
    if n < 2 or len(H) % n:
        raise FunctionError(f"holes: {len(H)} rows is not a whole number of bars of {n} holes "
                            "(per_bar ≥ 2)")
    if isinstance(base, Parameters):
        B = base.result.model.base()
    else:
        B = pose_from_robot(_matrix(base, "base", (6,)).reshape(-1), convention)
    hint = (-C.mean(axis=0) if normal is None
            else _matrix(normal, "normal", (3,)).reshape(-1))
    try:
        z = fit_plane(C, normal_hint=hint).normal
        frames = []
        for k in range(0, len(H), n):
            bar = H[k:k + n]
            y = fit_line(bar).direction
            for origin in bar:
                frames.append(_inv(B) @ frame_from_axes(origin, z=z, y=y))
    except MetrologyError as exc:
        raise FunctionError(str(exc)) from None
    return np.stack([robot_from_pose(T, convention) for T in frames])


# -- appendix D: initial BASE and PROBE (the visualisation service's wizards, 7.5) -----------


def _points(x: Any, what: str) -> np.ndarray:
    return _matrix(x, what, (3, 6))[:, :3] * M_PER_MM


@register
def probe_from_features(ctx: FunctionContext, circle: Any, holes: Any, tmac: Any,
                        angles: Any = "zyz", smr_offset: Any = 6.35) -> np.ndarray:
    """App. D.1: PROBE (1×6, mm/deg) from SMR positions while the last joint turns
    (``circle``, N×3 mm), the two dowel holes from −y to +y (``holes``), and the T-MAC
    pose measured without moving (``tmac``, 1×6); ``smr_offset``: SMR centre height (mm)."""
    from plugcell.metrology import MetrologyError, probe_from_flange_features

    convention = _convention(angles)
    T = pose_from_robot(_matrix(tmac, "tmac", (6,)).reshape(-1), convention)
    try:
        est = probe_from_flange_features(_points(circle, "circle"), _points(holes, "holes"), T,
                                         smr_offset=_number(smr_offset, "smr_offset") * M_PER_MM)
    except MetrologyError as exc:
        raise FunctionError(str(exc)) from None
    return robot_from_pose(est.probe, convention).reshape(1, 6)


@register
def base_from_features(ctx: FunctionContext, circle: Any, plane: Any, line: Any,
                        angles: Any = "zyz", smr_offset: Any = 6.35) -> np.ndarray:
    """App. D.2: BASE (1×6, mm/deg) from SMR positions on joint 1 while it turns
    (``circle``), on the base surface (``plane``), and T-MAC positions while the robot
    moves along its +x (``line``), all N×3 mm in the tracker frame."""
    from plugcell.metrology import MetrologyError
    from plugcell.metrology import base_from_features as _base_from_features

    try:
        est = _base_from_features(_points(circle, "circle"), _points(plane, "plane"),
                                 _points(line, "line"),
                                 smr_offset=_number(smr_offset, "smr_offset") * M_PER_MM)
    except MetrologyError as exc:
        raise FunctionError(str(exc)) from None
    return robot_from_pose(est.base, _convention(angles)).reshape(1, 6)


# -- housekeeping ---------------------------------------------------------------------------


@register
def append(ctx: FunctionContext, a: Any, b: Any) -> np.ndarray:
    """``[a; b]``: the rows of b below those of a (equal numbers of columns)."""
    A, B = _matrix(a, "a"), _matrix(b, "b")
    if A.size and A.shape[1] != B.shape[1]:
        raise FunctionError(f"append: {A.shape[1]} and {B.shape[1]} columns")
    return np.vstack([A, B]) if A.size else B


@register
def row(ctx: FunctionContext, a: Any, i: Any) -> np.ndarray:
    """Row ``i`` (1-based, as in the robot language) of ``a``, as a 1×n matrix."""
    A = _matrix(a, "a")
    k = _integer(i, "i")
    if not 1 <= k <= len(A):
        raise FunctionError(f"row {k} of a matrix with {len(A)} rows")
    return A[k - 1 : k].copy()


@register
def size(ctx: FunctionContext, a: Any) -> np.ndarray:
    """``[rows, columns]`` of a matrix."""
    A = _matrix(a, "a")
    return np.array([[A.shape[0], A.shape[1]]], dtype=float)


@register
def clear(ctx: FunctionContext, *names: Any) -> None:
    """Remove the named values (``clear('mJ', 'mT')``), or everything (``clear()``)."""
    texts = [_text(n, "name") for n in names]
    try:
        ctx.workspace.clear(texts or None)
    except WorkspaceError as exc:
        raise FunctionError(str(exc)) from None
