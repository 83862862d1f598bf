"""Identification of the error parameters: the iterative algorithm of Fig. 6-9.

:class:`Calibrator` reads like a scikit-learn estimator::

    result = Calibrator(desc, model="full").fit(data)     # -> CalibrationResult
    result.predict(q, payload_kg)                          # calibrated T-MAC poses
    plugcell.io.params.params_document(result)             # PARAMS.json content

``fit`` does what an engineer does with a file of joint readings and tracker
measurements, and nothing else is needed:

1. **Initial BASE and PROBE** from the data (:mod:`.initial`: AX = YB for 6-DOF,
   rigid registration for positions), unless the user gives them (appendix D).
2. **Nominal frames fit**: BASE and PROBE refined by least squares on the nominal
   robot — the "nominal" accuracy every model is compared with (Table 8-2) — and
   folded into the references, so the identification starts from the nominal
   geometry (skipped when the user gives BASE and PROBE: then "nominal" is the
   nominal robot with them, as with the appendix-D procedure in the thesis).
3. **Identifiability** (:mod:`.identifiability`): the model's structurally
   identifiable parameters, checked again on these poses.
4. **Gauss–Newton** with the exact forward model and the analytic Jacobian:
   ``Δg = argmin ‖Δx − H Δg‖`` (4.8), ``g ← g + Δg`` until ``‖Δg‖ < tol`` (1e-6,
   thesis 8.1).  Options: Levenberg–Marquardt (``method="lm"``) and a robust
   loss (``loss="huber"`` or ``"cauchy"``, iteratively reweighted per pose).
5. **Statistics** (8.1–8.5) and warnings (ill-conditioning, outliers, few poses).

Residual rows are metres and radians; ``rotation_weight`` (m/rad, default 1 as
in the thesis) scales the orientation rows of 6-DOF data.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from plugcell.calibration.configs import ModelConfig, model_config
from plugcell.calibration.data import CalibrationData
from plugcell.calibration.determinacy import (
    NULL_TOL,
    Undetermined,
    analyse_determinacy,
    orientation_spread,
)
from plugcell.calibration.identifiability import (
    Identifiability,
    analyse,
    structural_identifiability,
)
from plugcell.calibration.initial import (
    InitialEstimateError,
    estimate_base_probe_poses,
    estimate_base_probe_positions,
)
from plugcell.calibration.jacobian import JacobianResult, identification_jacobian
from plugcell.calibration.linalg import least_squares, null_space, restricted_basis
from plugcell.calibration.model import MIN_PAYLOAD_REF_KG, ErrorModel, PoseBatch, fold_frames
from plugcell.calibration.result import CalibrationResult, IterationRecord
from plugcell.calibration.statistics import (
    AccuracyStats,
    ParameterStatistics,
    PoseResiduals,
    accuracy,
    parameter_statistics,
    pose_residuals,
)
from plugcell.calibration.validity import ValidityRegion
from plugcell.kinematics import RobotDescription, forward
from plugcell.kinematics.errors import KinematicsError
from plugcell.metrology import fit_rigid_transform

Array = NDArray[np.float64]

METHODS: tuple[str, ...] = ("gauss-newton", "lm", "least-squares")
#: Halvings of a Gauss-Newton step that would increase the cost (a safeguard: the
#: full step is taken whenever it descends, as in the thesis's algorithm).
BACKTRACK_STEPS = 8
#: Default relative rank tolerance on the data: a scaled column closer than this to the
#: span of the kept ones is not identifiable from measured (noisy) poses.
DATA_RANK_TOL = 1e-3
#: Pose residuals below this (m) are never called outliers (tracker noise level).
#: Mean position error (m) of the nominal robot with fitted BASE/PROBE above which the
#: data cannot belong to the robot (a real robot's nominal error is a few mm).
MISMATCH_M = 0.05
#: ‖Δg‖ of the last iteration above which a non-converged fit counts as diverged.
UNSETTLED_STEP = 1e-3
OUTLIER_FLOOR_M = 0.05e-3
#: Equations per identified parameter below which a fit is flagged (noise is not averaged).
EQUATIONS_PER_PARAMETER = 3
_HINT = "check the units (joints in degrees, positions in mm), the joint order and --rot"
LOSSES: tuple[str, ...] = ("linear", "huber", "cauchy")
#: Default threshold of the Huber/Cauchy loss, × the median pose residual.
DEFAULT_LOSS_SCALE = 3.0

#: Progress callback: ``(stage, iteration, max_iterations, message)``.
Progress = Callable[[str, int, int, str], None]

__all__ = [
    "DEFAULT_LOSS_SCALE",
    "LOSSES",
    "METHODS",
    "CalibrationError",
    "Calibrator",
    "DivergenceError",
    "refit_base",
]


def few_equations(poses: int, rows: int, parameters: int) -> str:
    """The warning for ``poses × rows`` equations fewer than
    :data:`EQUATIONS_PER_PARAMETER` per parameter, with the poses that would do."""
    what = "poses" if rows == 6 else "positions"
    need = -(-EQUATIONS_PER_PARAMETER * parameters // rows)
    return (f"few equations: {poses} {what} × {rows} = {poses * rows} equations for "
            f"{parameters} parameters, fewer than {EQUATIONS_PER_PARAMETER} per parameter; "
            f"measure at least {need} {what} (the thesis used 90–150 poses)")


class CalibrationError(ValueError):
    """A calibration that cannot be carried out (bad data, too few poses, …)."""


class DivergenceError(CalibrationError):
    """The iteration diverged (cost exploded, the loop could not close, NaN)."""


@dataclass(frozen=True)
class _Problem:
    model: ErrorModel
    data: CalibrationData
    batch: PoseBatch
    rotation_weight: float


def _residual_rows(p: _Problem, poses: Array) -> Array:
    r = pose_residuals(p.data, poses)
    if p.data.six_dof:
        r = r.copy()
        r[:, 3:] *= p.rotation_weight
    return r


def _jacobian_rows(p: _Problem, H: Array) -> Array:
    if p.data.six_dof:
        H = H.copy()
        H[:, 3:] *= p.rotation_weight
        return H
    return H[:, :3]


def _robust_weights(r: Array, loss: str, scale: float) -> Array:
    """Per-pose IRLS weights from the pose residual norms."""
    e = np.linalg.norm(r, axis=1)
    if loss == "linear":
        return np.ones(len(e))
    s = scale * max(float(np.median(e)), 1e-15)
    u = e / s
    if loss == "huber":
        return np.where(u <= 1.0, 1.0, 1.0 / np.maximum(u, 1e-300))
    return 1.0 / (1.0 + u * u)


class Calibrator:
    """Identify the error parameters of one of the five models (module docstring).

    Minimises ``Σ_i w_i ‖W Δx_i‖²`` with ``Δx_i = [p_M − p; φ]`` of eq. 6.23 over the kept
    parameters (``w_i`` the IRLS weights of the robust loss, 1 for ``"linear"``), each
    Gauss–Newton step ``Δg = argmin ‖√w W (H Δg − Δx)‖`` (eq. 4.8) — see :meth:`fit`.

    Parameters
    ----------
    desc : RobotDescription
        The robot.
    model : int or str
        1–5 or a name (:mod:`.configs`).
    base, probe : (4, 4) array_like, m, optional
        Initial BASE/PROBE, estimated from the data when omitted.
    method : {"gauss-newton", "lm", "least-squares"}
        Iteration (``"least-squares"``: SciPy's).
    loss : {"linear", "huber", "cauchy"}
        Robust loss ρ.
    loss_scale : float
        Scale of the robust loss, × the median pose residual.
    tol : float
        Stop when ‖Δg‖ < tol (the step in the parameters' own units, m, rad, …).
    max_iterations : int
        Iteration bound.
    rotation_weight : float, m/rad
        Weight w of the orientation rows, ``W = diag(1, 1, 1, w, w, w)``.
    condition_limit : float, optional
        Apply the rule of eq. (4.10) on the data (``None``: only report κ).
    payload_ref_kg : float, kg, optional
        The mass the payload constants refer to (default: the heaviest payload of the
        data).
    parameters : sequence of str, optional
        Identify exactly these keys instead of the analysis' choice.
    rank_tol : float
        Relative distance of a scaled column from the span of the others below which a
        parameter is not identified from these poses (default 1e-3).
    progress : callable, optional
        Callback ``(stage, i, n, message)``.
    harmonics : {0, 1, 2}
        Add the joint-angle harmonics up to this order to the model (transmission
        error, :mod:`.compliance`).
    thermal : bool
        Add the thermal expansion κT of the chain's lengths about the calibration data's
        mean temperature (needs their ``temperature_c``).
    null_tol : float
        Relative singular value of the scaled Jacobian below which a direction (a
        combination of parameters, e.g. PROBE position with BASE position) is not
        determined by the poses and kept at its initial value (:mod:`.determinacy`;
        default 1e-4).

    Raises
    ------
    CalibrationError
        Unknown model, method or loss, non-positive tolerances or weights, a bad
        harmonic order.
    """

    def __init__(
        self,
        desc: RobotDescription,
        model: int | str = 5,
        *,
        base: ArrayLike | None = None,
        probe: ArrayLike | None = None,
        method: str = "gauss-newton",
        loss: str = "linear",
        loss_scale: float = DEFAULT_LOSS_SCALE,
        tol: float = 1e-6,
        max_iterations: int = 50,
        rotation_weight: float = 1.0,
        condition_limit: float | None = None,
        payload_ref_kg: float | None = None,
        parameters: Sequence[str] | None = None,
        rank_tol: float = DATA_RANK_TOL,
        progress: Progress | None = None,
        harmonics: int = 0,
        thermal: bool = False,
        null_tol: float = NULL_TOL,
    ) -> None:
        try:
            self.config: ModelConfig = model_config(model)
        except ValueError as exc:
            raise CalibrationError(str(exc)) from None
        if method not in METHODS:
            raise CalibrationError(f"method must be one of {METHODS}, got {method!r}")
        if loss not in LOSSES:
            raise CalibrationError(f"loss must be one of {LOSSES}, got {loss!r}")
        if not (tol > 0 and max_iterations >= 1 and rotation_weight > 0 and loss_scale > 0):
            raise CalibrationError("tol, max_iterations, rotation_weight, loss_scale must be > 0")
        if not 0 <= null_tol < 1:
            raise CalibrationError(f"null_tol must be in [0, 1), got {null_tol!r}")
        if harmonics not in (0, 1, 2):
            raise CalibrationError(f"harmonics: order 0, 1 or 2, got {harmonics!r}")
        self.harmonics = int(harmonics)
        self.thermal = bool(thermal)
        self.desc = desc
        self.base = None if base is None else np.asarray(base, dtype=float)
        self.probe = None if probe is None else np.asarray(probe, dtype=float)
        self.method = method
        self.loss = loss
        self.loss_scale = float(loss_scale)
        self.tol = float(tol)
        self.max_iterations = int(max_iterations)
        self.rotation_weight = float(rotation_weight)
        self.condition_limit = condition_limit
        self.payload_ref_kg = payload_ref_kg
        self.parameters = None if parameters is None else tuple(parameters)
        self.rank_tol = float(rank_tol)
        self.null_tol = float(null_tol)
        self.progress = progress
        self._cache: dict[Any, Identifiability] = {}

    # ------------------------------------------------------------------ helpers
    def _say(self, stage: str, i: int, n: int, msg: str) -> None:
        if self.progress is not None:
            self.progress(stage, i, n, msg)

    def _coerce(self, data: Any) -> CalibrationData:
        if not isinstance(data, CalibrationData):
            try:
                data = CalibrationData.from_measurements(data)
            except (AttributeError, ValueError) as exc:
                raise CalibrationError(f"cannot use the data: {exc}") from None
        n = self.desc.n_readings
        if data.q.shape[1] != n:
            raise CalibrationError(
                f"the data have {data.q.shape[1]} joint columns, robot {self.desc.name!r} has {n}"
            )
        return data

    def initial_frames(self, data: CalibrationData) -> tuple[Array, Array, float]:
        """Initial BASE, PROBE and the rms position misfit they leave.

        The nominal flange poses ``F_i = T_n^0(q_i; g_nom)`` (exact four-bar closure) are
        registered onto the measurements, ``T_i ≈ BASE · F_i · PROBE``: with both frames
        given to the calibrator they are returned as they are; otherwise they are
        estimated — from 6-DOF poses by :func:`estimate_base_probe_poses`, from positions
        ``p_i ≈ R_BASE (p_F,i + R_F,i t_PROBE) + t_BASE`` by
        :func:`estimate_base_probe_positions` (a given PROBE's offset as the start) — and
        a frame given to the calibrator replaces its estimate.

        Parameters
        ----------
        data : CalibrationData
            The calibration poses: readings ``q`` ``(N, n_readings)``, rad; measured
            positions ``(N, 3)`` or poses ``(N, 4, 4)``, m.

        Returns
        -------
        base : (4, 4) array, m
            BASE, the robot base frame in the measurement frame.
        probe : (4, 4) array, m
            PROBE, the target in the flange frame.
        rms : float, m
            ``sqrt(mean_i ‖p_i − p̂_i‖²)`` of the position misfit — of the returned
            frames when both were given, else of the estimated pair (before a given
            frame replaces its estimate).

        Raises
        ------
        CalibrationError
            The nominal kinematics fail on the readings, or the data do not determine
            BASE and PROBE (too few or degenerate poses).
        """
        ref = self.desc.nominal_parameters()
        try:
            flange = forward(self.desc, ref, data.q, closure="fourbar").flange
        except KinematicsError as exc:
            raise CalibrationError(f"nominal kinematics fail on the data: {exc}") from None
        if self.base is not None and self.probe is not None:
            pred = self.base @ flange @ self.probe
            rms = float(np.sqrt(np.mean(np.sum((pred[:, :3, 3] - data.positions) ** 2, 1))))
            return self.base, self.probe, rms
        # where the target sits on the flange when the poses cannot tell (its offset along
        # directions they do not determine, :mod:`.determinacy`): the given PROBE, else
        # the description's tool point
        prior = (self.desc.tool if self.probe is None else self.probe)[:3, 3]
        try:
            if data.six_dof:
                est = estimate_base_probe_poses(flange, data.poses, prior_offset=prior,
                                                rel_tol=self.null_tol)
            else:
                off = None if self.probe is None else self.probe[:3, 3]
                est = estimate_base_probe_positions(flange, data.positions, probe_offset=off,
                                                    prior_offset=prior, rel_tol=self.null_tol)
        except (InitialEstimateError, ValueError) as exc:
            raise CalibrationError(f"cannot estimate BASE and PROBE from the data: {exc}") from None
        base = est.base if self.base is None else self.base
        probe = est.probe if self.probe is None else self.probe
        return base, probe, est.rms

    # ------------------------------------------------------------------ fit
    def fit(self, data: Any, *, validation: Any | None = None) -> CalibrationResult:
        """Identify the parameters from ``data`` (a MeasurementSet or CalibrationData).

        The stages, each a method below: the references the model needs (payload,
        temperature) → initial BASE/PROBE (:meth:`initial_frames`) → the error model
        (:meth:`_error_model`) → BASE/PROBE fitted on the nominal robot
        (:meth:`_nominal_fit`) → which parameters these poses identify
        (:meth:`_identifiable`) → the iterations (:meth:`_iterate`) → diagnostics of
        the fit (:meth:`_diagnose`).

        Parameters
        ----------
        data
            The calibration poses: joint readings ``q`` (n, n_readings), rad; measured
            positions (n, 3) or poses (n, 4, 4), m; payload (n,), kg.
        validation
            Optional independent poses of the same form, evaluated with the result.

        Returns
        -------
        CalibrationResult
            The identified model, its statistics, residuals and warnings.
        """
        t0 = time.perf_counter()
        data = self._coerce(data)
        warnings: list[str] = []
        m_ref, t_ref = self._references(data, warnings)
        base0, probe0, rms0 = self.initial_frames(data)
        self._say("frames", 0, 1, f"initial BASE/PROBE: rms misfit {rms0 * 1e3:.3f} mm")
        model = self._error_model(base0, probe0, m_ref, t_ref)
        batch = model.batch(data.q, data.payload_kg, data.temperature_c)
        problem = _Problem(model, data, batch, self.rotation_weight)
        nominal = self._nominal_fit(problem, model, warnings)
        nominal_poses = nominal.predict_batch(batch)
        before = self._check_nominal(data, nominal_poses)
        structural, on_data, jac0, undetermined = self._identifiable(problem, nominal, warnings)
        keys = list(jac0.keys)
        final, history, converged, weights, jac = self._iterate(
            problem, nominal, keys, "identify", warnings, loss=self.loss, jac=jac0
        )
        if jac is None:
            jac = identification_jacobian(final, batch, keys)
        stats, residuals = self._diagnose(problem, nominal_poses, jac, weights, history,
                                          converged, warnings)
        if undetermined is not None:  # the campaign's orientation of the calibrated flange
            flange = np.linalg.inv(final.base()) @ jac.poses @ np.linalg.inv(final.probe())
            undetermined = replace(undetermined,
                                   flange_orientation=orientation_spread(flange[:, :3, :3])[0])
        result = CalibrationResult(
            config=self.config,
            robot=self.desc.name,
            model=final,
            nominal=nominal,
            keys=tuple(keys),
            identifiability=structural,
            data_identifiability=on_data,
            iterations=len(history),
            converged=converged,
            history=tuple(history),
            statistics=stats,
            calibration=residuals.accuracy("after"),
            calibration_before=before,
            calibration_residuals=residuals,
            six_dof=data.six_dof,
            n_poses=len(data),
            pose_weights=weights,
            warnings=tuple(warnings),
            elapsed_s=time.perf_counter() - t0,
            validity=self._region(final, data, jac, undetermined),
            undetermined=undetermined,
            settings={"method": self.method, "loss": self.loss, "loss_scale": self.loss_scale,
                      "tol": self.tol,
                      "rotation_weight": self.rotation_weight,
                      "condition_limit": self.condition_limit,
                      "max_iterations": self.max_iterations, "harmonics": self.harmonics,
                      "thermal": self.thermal},
        )
        if validation is not None:
            result = result.with_validation(self._coerce(validation))
        return result

    def _region(self, final: ErrorModel, data: CalibrationData, jac: JacobianResult,
                undetermined: Undetermined | None) -> ValidityRegion:
        """The region of the calibration poses (:class:`ValidityRegion`): lever arms and
        targets at the identified PROBE — or, when the poses did not determine its
        position (and it was not given), at the robot description's tool point: an
        undetermined PROBE is no measured lever."""
        if undetermined is not None and undetermined.unknown("probe_position"):
            tool = fold_frames(final).with_references(probe=self.desc.tool)
            return ValidityRegion.from_poses(tool, data.q, data.payload_kg)
        return ValidityRegion.from_poses(
            final, data.q, data.payload_kg,
            targets=(np.linalg.inv(final.base()) @ jac.poses)[:, :3, 3])

    def _references(self, data: CalibrationData, warnings: list[str]) -> tuple[float, float]:
        """The payload m_ref (kg) the payload constants refer to — the given one, else
        the heaviest of the data — and the temperature T_ref (°C) the thermal term
        expands about, the mean of the data's (0 without the term); refuses a model
        that needs what the data lack."""
        cfg = self.config
        m_ref = float(self.payload_ref_kg if self.payload_ref_kg is not None
                      else data.payload_kg.max())
        if cfg.payload and m_ref < MIN_PAYLOAD_REF_KG:
            raise CalibrationError(
                f"model {cfg.number} ({cfg.name}) identifies payload compliance but the data "
                "carry no payload (payload_kg column missing, zero or under 1 g); use model 4 "
                "or add --payload-kg"
            )
        if not data.six_dof and self.rotation_weight != 1.0:
            warnings.append("rotation_weight ignored: the data are positions only")
        t_ref = 0.0
        if self.thermal:
            if data.temperature_c is None:
                raise CalibrationError("the thermal term needs a temperature per pose: the "
                                       "measurement file has no temperature_c column")
            t_ref = float(np.mean(data.temperature_c))
            if np.ptp(data.temperature_c) < 0.1:
                warnings.append(f"thermal term: the temperatures span only "
                                f"{np.ptp(data.temperature_c):.2f} K")
        return m_ref, t_ref

    def _error_model(self, base0: Array, probe0: Array, m_ref: float,
                     t_ref: float) -> ErrorModel:
        """The error model of the configuration (:mod:`.configs`) at the nominal robot,
        with the initial BASE (4×4, m) and PROBE (4×4, m)."""
        cfg = self.config
        try:
            model = ErrorModel.create(self.desc, cfg.family, gravity=cfg.gravity,
                                      payload=cfg.payload, base=base0, probe=probe0,
                                      payload_ref_kg=m_ref if cfg.payload else 0.0,
                                      harmonics=self.harmonics, thermal=self.thermal,
                                      temperature_ref_c=t_ref)
        except ValueError as exc:
            raise CalibrationError(str(exc)) from None
        if cfg.gravity and not model.space.of_kind("gravity"):
            raise CalibrationError(
                f"model {cfg.number} ({cfg.name}) needs gravity deflection, but robot "
                f"{self.desc.name!r} has neither a parallelogram nor link masses in its "
                "description"
            )
        return model

    def _nominal_fit(self, problem: _Problem, model: ErrorModel,
                     warnings: list[str]) -> ErrorModel:
        """BASE and PROBE fitted on the nominal robot, unless both were given: the
        least-squares fit min Σᵢ ‖r_i(g)‖² over the frame parameters g that these poses
        identify (the base link's and flange's DH/Hayati parameters, the probe's
        θ, d), folded back into the two frames (:func:`~.model.fold_frames`)."""
        if self.base is not None and self.probe is not None:
            return model
        s = model.structure
        fl = s.desc.flange
        frame_keys = [k for k in (
            f"a{s.base_name}", f"b{s.base_name}", f"alpha{s.base_name}",
            f"beta{s.base_name}", f"theta{s.base_name}", f"d{s.base_name}", f"theta{fl}",
            f"d{fl}", f"a{fl}", f"alpha{fl}", f"theta{s.probe_name}", f"d{s.probe_name}")
            if k in model.space]
        jac = identification_jacobian(model, problem.batch, frame_keys)
        fa = analyse(_jacobian_rows(problem, jac.H).reshape(-1, len(frame_keys)), frame_keys)
        fitted, *_ = self._iterate(problem, model, list(fa.kept), "nominal", warnings,
                                   loss="linear")
        return fold_frames(fitted)

    def _check_nominal(self, data: CalibrationData, nominal_poses: Array) -> AccuracyStats:
        """The accuracy of the nominal robot in its fitted frames; refuses measurements
        that cannot be of this robot (mean position error > :data:`MISMATCH_M`)."""
        before = accuracy(data, nominal_poses)
        if before.position.norm.mean > MISMATCH_M:
            raise DivergenceError(
                f"the measurements do not match robot {self.desc.name!r}: even with BASE and "
                f"PROBE fitted the mean position error is {before.position.norm.mean * 1e3:.1f} "
                f"mm (> {MISMATCH_M * 1e3:.0f} mm); {_HINT}"
            )
        self._say("frames", 1, 1,
                  f"nominal: mean position error {before.position.norm.mean * 1e3:.3f} mm")
        return before

    def _identifiable(
        self, problem: _Problem, nominal: ErrorModel, warnings: list[str]
    ) -> tuple[Identifiability, Identifiability, JacobianResult, Undetermined | None]:
        """Which parameters to identify: the structural analysis of the model (or the
        ``parameters`` asked for), then the analysis on these poses' weighted
        identification Jacobian H (rows: poses × 3 or 6, columns: parameters) — a column
        within ``rank_tol`` of the span of the others, or removed by the condition rule
        κ(H) ≤ limit (eq. 4.10), is dropped with a warning.  Then the directions of H
        (all its columns) the poses do not determine, in words
        (:func:`~.determinacy.analyse_determinacy`): one warning per undetermined frame
        quantity or group of parameters, instead of the column warnings of the
        parameters they explain.  Refuses fewer equations than parameters.  Returns both
        analyses, the Jacobian of the kept columns at the nominal model and what is
        undetermined (``None``: nothing)."""
        data, model = problem.data, problem.model
        cfg = self.config
        structural = self._structural(nominal, data, len(np.unique(data.payload_kg)) > 1)
        if self.parameters is not None:
            unknown = [k for k in self.parameters if k not in model.space]
            if unknown:
                raise CalibrationError(
                    f"unknown parameters {unknown}; known: {list(model.space.keys)}")
            keys = list(self.parameters)
        else:
            keys = list(structural.kept)
        jac = identification_jacobian(nominal, problem.batch, keys)
        Hd = _jacobian_rows(problem, jac.H).reshape(-1, len(keys))
        on_data = analyse(Hd, keys, rank_tol=self.rank_tol,
                          condition_limit=self.condition_limit)
        flange = np.linalg.inv(nominal.base()) @ jac.poses @ np.linalg.inv(nominal.probe())
        given = tuple(n for n, f in (("base", self.base), ("probe", self.probe)) if f is not None)
        undetermined = None
        if self.null_tol > 0:
            undetermined = analyse_determinacy(nominal, Hd, keys, flange[:, :3, :3],
                                               given=given, kept=on_data.kept,
                                               tol=self.null_tol)
        explained: set[str] = set()
        if undetermined is not None:
            warnings.extend(undetermined.messages)
            explained = set(undetermined.parameters)
            if undetermined.components:
                fl = model.structure.desc.flange
                explained |= {k for k in keys if model.space[k].kind in ("base", "probe")
                              or model.space[k].link == fl}
        for k in keys:
            if k not in on_data.kept and k not in explained:
                how = "removed by the condition-number rule (4.10)" if k in on_data.eliminated \
                    else "these poses do not separate it from the others"
                warnings.append(f"parameter {model.space[k].name} not identified: {how}")
        keys = list(on_data.kept)
        n_eq = len(data) * data.rows
        if n_eq <= len(keys):
            need = len(keys) // data.rows + 1
            raise CalibrationError(
                f"too few poses: model {cfg.number} ({cfg.name}) identifies {len(keys)} "
                f"parameters, {len(data)} {'poses' if data.six_dof else 'positions'} give only "
                f"{n_eq} equations; measure at least {need} (better {3 * need})"
            )
        if n_eq < EQUATIONS_PER_PARAMETER * len(keys):
            warnings.append(few_equations(len(data), data.rows, len(keys)))
        cols = [jac.keys.index(k) for k in keys]  # the kept columns of the data check
        return structural, on_data, JacobianResult(poses=jac.poses, H=jac.H[:, :, cols],
                                                   keys=tuple(keys)), undetermined

    def _diagnose(
        self, problem: _Problem, nominal_poses: Array, jac: JacobianResult, weights: Array,
        history: list[IterationRecord], converged: bool, warnings: list[str],
    ) -> tuple[ParameterStatistics, PoseResiduals]:
        """The statistics of the identified parameters from the weighted residuals
        r_w = √w·r and Jacobian H_w = √w·H at the solution (σ̂² = ‖r_w‖²/(m − p),
        cov = σ̂²·(H_wᵀH_w)⁻¹, :func:`~.statistics.parameter_statistics`), the pose
        residuals before and after, and the warnings: κ > 100 (eq. 4.10), poses whose
        residual exceeds max(median + 5·MAD, 3·median) (outliers or unmodelled
        effects), no convergence — or a :class:`DivergenceError` if still moving."""
        data = problem.data
        keys = list(jac.keys)
        r = _residual_rows(problem, jac.poses) * np.sqrt(weights)[:, None]
        H = _jacobian_rows(problem, jac.H) * np.sqrt(weights)[:, None, None]
        stats = parameter_statistics(H.reshape(-1, len(keys)), r.reshape(-1))
        residuals = PoseResiduals.from_poses(data, nominal_poses, jac.poses)
        if stats.condition_number > 100:
            warnings.append(
                f"ill-conditioned: κ = {stats.condition_number:.0f} > 100 (eq. 4.10); "
                "spread the poses wider or use a smaller model"
            )
        e = residuals.norms("after")
        med = float(np.median(e))
        mad = float(np.median(np.abs(e - med))) * 1.4826
        limit = max(med + 5.0 * mad, 3.0 * med, OUTLIER_FLOOR_M)
        out = np.flatnonzero(e > limit)
        if out.size:
            listed = ", ".join(f"#{i + 1} ({e[i] * 1e3:.3f} mm)" for i in out[:8])
            warnings.append(
                f"{out.size} pose(s) with a large residual (> {limit * 1e3:.3f} mm: median + "
                f"5·MAD, at least 3× the median) — outliers or unmodelled effects: {listed}"
            )
        if not converged and history and history[-1].step_norm > UNSETTLED_STEP:
            raise DivergenceError(
                f"the fit diverged: still moving after {self.max_iterations} iterations "
                f"(‖Δg‖ = {history[-1].step_norm:.3g}, mean residual "
                f"{history[-1].mean_position_mm:.3f} mm); {_HINT}, or try --method lm"
            )
        if not converged:
            warnings.append(
                f"not converged in {self.max_iterations} iterations (‖Δg‖ ≥ {self.tol:g})")
        return stats, residuals

    def _structural(self, model: ErrorModel, data: CalibrationData, mixed: bool) -> Identifiability:
        pos_only = not data.six_dof
        key = (pos_only, tuple(np.unique(data.payload_kg)) if mixed else None,
               np.round(model.probe_ref, 4).tobytes(), np.round(model.base_ref, 4).tobytes())
        if key not in self._cache:
            self._cache[key] = self._structural_analysis(model, data, mixed)
        return self._cache[key]

    def _structural_analysis(self, model: ErrorModel, data: CalibrationData, mixed: bool
                             ) -> Identifiability:
        pos_only = not data.six_dof
        if not mixed:
            return structural_identifiability(model, position_only=pos_only)
        # payloads that vary separate payload constants from gravity ones (A2 vs G1)
        from plugcell.calibration.identifiability import random_batch, random_configurations

        keys = model.space.by_priority()
        q = random_configurations(model, 60, 0)
        m = np.resize(np.unique(data.payload_kg), len(q))
        jac = identification_jacobian(model, random_batch(model, q, m), keys)
        H = jac.H[:, :3] if pos_only else jac.H
        return analyse(H.reshape(-1, len(keys)), keys)

    def _iterate(
        self, p: _Problem, model: ErrorModel, keys: list[str], stage: str, warnings: list[str],
        *, loss: str, jac: JacobianResult | None = None,
    ) -> tuple[ErrorModel, list[IterationRecord], bool, Array, JacobianResult | None]:
        """Gauss–Newton / LM iterations on ``keys`` (Fig. 6-9); ``jac``: the Jacobian at
        ``model`` if already known.  Returns the Jacobian at the final model too.

        Each iteration solves, on the column-scaled Jacobian H_s = H_w·S⁻¹ (S: the
        column norms), Gauss–Newton's Δg = S⁻¹·argmin ‖H_s·x − r_w‖ (halved while it
        raises the cost) or Levenberg–Marquardt's
        Δg = S⁻¹·(H_sᵀH_s + λ·diag(H_sᵀH_s))⁻¹·H_sᵀ·r_w, where r_w = √w·r and
        H_w = √w·H carry the robust per-pose weights w (:func:`_robust_weights`);
        it stops when ‖Δg‖ < ``tol``.  Directions the poses do not determine
        (:meth:`_undetermined`, found at the first iteration) are kept where they start:
        each step is solved on ``H_s Z`` and taken as ``x = Z y``, ``Z`` the orthonormal
        basis of the scaled steps that leave them unchanged
        (:func:`~.linalg.restricted_basis`) — the truncated-SVD (minimum-norm) step.
        ``method="least-squares"`` hands the same problem to SciPy
        (:meth:`_iterate_scipy`)."""
        weights = np.ones(len(p.data))
        history: list[IterationRecord] = []
        if not keys:
            return model, history, True, weights, None
        if self.method == "least-squares":
            return self._iterate_scipy(p, model, keys, stage, loss=loss)
        lam = 1e-3
        best_cost = None
        converged = False
        C: Array | None = None  # the undetermined combinations, fixed at the first iteration
        if jac is None or jac.keys != tuple(keys):
            jac = self._jac(model, p, keys)
        for it in range(1, self.max_iterations + 1):
            r = _residual_rows(p, jac.poses)
            weights = _robust_weights(r, loss, self.loss_scale)
            sw = np.sqrt(weights)
            rw = (r * sw[:, None]).reshape(-1)
            Hw = (_jacobian_rows(p, jac.H) * sw[:, None, None]).reshape(-1, len(keys))
            cost = float(rw @ rw)
            if not np.isfinite(cost):
                raise DivergenceError(f"{stage}: the residuals became NaN/inf at iteration {it}")
            if best_cost is None:
                best_cost = cost
            elif cost > 1e4 * best_cost + 1e-18:
                raise DivergenceError(
                    f"{stage}: the fit diverged (cost grew from {best_cost:.3g} to {cost:.3g}); "
                    f"{_HINT}"
                )
            best_cost = min(best_cost, cost)
            scale = np.linalg.norm(Hw, axis=0)
            scale = np.where(scale > 0, scale, 1.0)
            Hs = Hw / scale
            if C is None:
                C = self._undetermined(Hs, scale)
            Z = restricted_basis(C, scale) if C.shape[1] else None
            if self.method == "gauss-newton":
                new, jac_new, step = self._gauss_newton_step(p, model, keys, Hs, rw, Z, scale,
                                                             sw, cost)
            else:
                new, jac_new, step, lam = self._lm_step(p, model, keys, Hs, rw, Z, scale, sw,
                                                        cost, lam, stage)
            step_norm = float(np.linalg.norm(step))
            pos = np.linalg.norm(r[:, :3], axis=1)
            history.append(IterationRecord(it, step_norm, cost, float(pos.mean() * 1e3),
                                           float(np.sqrt(np.mean(pos**2)) * 1e3),
                                           lam if self.method == "lm" else 0.0))
            self._say(stage, it, self.max_iterations,
                      f"iteration {it}: mean position residual {pos.mean() * 1e3:.4f} mm, "
                      f"|Δg| = {step_norm:.3g}")
            model, jac = new, jac_new
            if step_norm < self.tol:
                converged = True
                break
        return model, history, converged, weights, jac

    def _weighted_cost(self, p: _Problem, model: ErrorModel, keys: list[str], sw: Array
                       ) -> tuple[float, JacobianResult]:
        """The weighted cost ``‖√w · r‖²`` at ``model`` and its Jacobian (DivergenceError
        when the model cannot be evaluated)."""
        jac = self._jac(model, p, keys)
        rn = (_residual_rows(p, jac.poses) * sw[:, None]).reshape(-1)
        return float(rn @ rn), jac

    def _gauss_newton_step(
        self, p: _Problem, model: ErrorModel, keys: list[str], Hs: Array, rw: Array,
        Z: Array | None, scale: Array, sw: Array, cost: float,
    ) -> tuple[ErrorModel, JacobianResult, Array]:
        """Gauss–Newton's step (Fig. 6-9), ``Δg = S⁻¹·argmin ‖H_s·x − r_w‖`` (``x = Z y``
        with undetermined directions), halved up to ``BACKTRACK_STEPS`` times while it
        raises the cost; returns the new model, its Jacobian and the step taken."""
        step = (least_squares(Hs, rw) if Z is None else Z @ least_squares(Hs @ Z, rw)) / scale
        for _ in range(BACKTRACK_STEPS):
            new = model.updated(keys=keys, step=step)
            try:
                new_cost, jac_new = self._weighted_cost(p, new, keys, sw)
                if new_cost <= cost * (1.0 + 1e-9) + 1e-30:
                    return new, jac_new, step
            except DivergenceError:
                pass
            step = 0.5 * step
        new = model.updated(keys=keys, step=step)
        return new, self._jac(new, p, keys), step

    def _lm_step(
        self, p: _Problem, model: ErrorModel, keys: list[str], Hs: Array, rw: Array,
        Z: Array | None, scale: Array, sw: Array, cost: float, lam: float, stage: str,
    ) -> tuple[ErrorModel, JacobianResult, Array, float]:
        """Levenberg–Marquardt's step ``Δg = S⁻¹·(H_rᵀH_r + λ·diag(H_rᵀH_r))⁻¹·H_rᵀ·r_w``
        (``H_r = H_s Z``, ``Δg = S⁻¹ Z y`` with undetermined directions): λ ×10 until the
        cost does not rise, then ÷10 for the next; returns the new model, its Jacobian,
        the step and λ.  DivergenceError after 30 tries."""
        Hr = Hs if Z is None else Hs @ Z
        A = Hr.T @ Hr
        g = Hr.T @ rw
        for _ in range(30):
            y = np.linalg.solve(A + lam * np.diag(np.diag(A) + 1e-12), g)
            step = (y if Z is None else Z @ y) / scale
            new = model.updated(keys=keys, step=step)
            try:
                new_cost, jac_new = self._weighted_cost(p, new, keys, sw)
                ok = new_cost <= cost
            except DivergenceError:
                ok = False
            if ok:
                return new, jac_new, step, max(lam / 10.0, 1e-12)
            lam *= 10.0
        raise DivergenceError(f"{stage}: Levenberg–Marquardt found no descent step")

    def _iterate_scipy(
        self, p: _Problem, model: ErrorModel, keys: list[str], stage: str, *, loss: str,
    ) -> tuple[ErrorModel, list[IterationRecord], bool, Array, JacobianResult | None]:
        """The same least-squares problem solved by :func:`scipy.optimize.least_squares`
        (trust-region reflective, ``x_scale="jac"``) with the analytic Jacobian.

        Unknowns x (the increments of ``keys`` from ``model``'s values), residuals
        f(x) = r(g₀ + x) stacked (n·rows,), Jacobian ∂f/∂x = −H(g₀ + x).  A robust
        ``loss`` is SciPy's of the same name, applied to each residual component with
        ``f_scale`` = ``loss_scale`` × the median pose residual of a first, plain fit
        (then the robust fit starts from it) — per component, where the Gauss–Newton
        path re-weights whole poses at every iteration.  Stops when SciPy's
        relative step test ‖Δx‖ < ``tol``·(``tol`` + ‖x‖) holds (``xtol``) or
        ``max_iterations`` Jacobians were evaluated.  The per-pose weights returned are
        those of :func:`_robust_weights` at the solution (ones for ``"linear"``).
        """
        from scipy.optimize import least_squares as scipy_least_squares

        history: list[IterationRecord] = []
        cache: dict[bytes, JacobianResult] = {}
        # the undetermined combinations are kept: unknowns y, increments Δg = Zg·y
        H0 = _jacobian_rows(p, self._jac(model, p, keys).H).reshape(-1, len(keys))
        s0 = np.linalg.norm(H0, axis=0)
        s0 = np.where(s0 > 0, s0, 1.0)
        C = self._undetermined(H0 / s0, s0)
        Zg = restricted_basis(C, np.ones(len(keys))) if C.shape[1] else np.eye(len(keys))

        def at(y: Array) -> JacobianResult:
            key = y.tobytes()
            if key not in cache:
                cache.clear()
                cache[key] = self._jac(model.updated(keys=keys, step=Zg @ y), p, keys)
            return cache[key]

        def fun(x: Array) -> Array:
            return _residual_rows(p, at(x).poses).reshape(-1)

        def jac(x: Array) -> Array:
            j = at(x)
            H = _jacobian_rows(p, j.H).reshape(-1, len(keys))
            r = _residual_rows(p, j.poses)
            pos = np.linalg.norm(r[:, :3], axis=1)
            # the step since the previous Jacobian (an accepted iteration of SciPy's)
            step_norm = float(np.linalg.norm(Zg @ (x - history_x[-1]))) if history_x else 0.0
            history_x.append(x.copy())
            history.append(IterationRecord(len(history) + 1, step_norm, float(np.sum(r * r)),
                                           float(pos.mean() * 1e3),
                                           float(np.sqrt(np.mean(pos**2)) * 1e3), 0.0))
            self._say(stage, len(history), self.max_iterations,
                      f"iteration {len(history)}: mean position residual "
                      f"{pos.mean() * 1e3:.4f} mm")
            return -H @ Zg

        history_x: list[Array] = []

        def solve(x0: Array, loss_name: str, f_scale: float) -> Any:
            try:
                return scipy_least_squares(
                    fun, x0, jac=jac, method="trf", x_scale="jac", loss=loss_name,
                    f_scale=f_scale, xtol=self.tol, ftol=1e-15, gtol=1e-15,
                    max_nfev=self.max_iterations * 4)
            except (ValueError, np.linalg.LinAlgError) as exc:
                raise DivergenceError(f"{stage}: SciPy's least_squares failed: {exc}") from None

        solution = solve(np.zeros(Zg.shape[1]), "linear", 1.0)
        if loss != "linear":  # the scale from the residuals at the plain solution
            r1 = _residual_rows(p, at(solution.x).poses)
            f_scale = self.loss_scale * max(float(np.median(np.linalg.norm(r1, axis=1))), 1e-15)
            solution = solve(solution.x, loss, f_scale)
        final = model.updated(keys=keys, step=Zg @ solution.x)
        jac_final = self._jac(final, p, keys)
        weights = _robust_weights(_residual_rows(p, jac_final.poses), loss, self.loss_scale)
        return final, history, bool(solution.status > 0), weights, jac_final

    def _undetermined(self, Hs: Array, scale: Array) -> Array:
        """The combinations ``Cᵀ g`` the poses do not determine: ``C = S V₀``, ``V₀`` the
        right singular vectors of the column-scaled Jacobian ``H_s`` (scales ``S``) with
        ``σ < null_tol · σ₁`` (:mod:`.determinacy`); ``(k, 0)`` when there are none."""
        _, V0 = null_space(Hs, self.null_tol)
        return V0 * scale[:, None]

    @staticmethod
    def _jac(model: ErrorModel, p: _Problem, keys: Sequence[str]):
        try:
            jac = identification_jacobian(model, p.batch, keys)
        except KinematicsError as exc:
            raise DivergenceError(f"the fit diverged: {exc}; {_HINT}") from None
        if not np.all(np.isfinite(jac.H)) or not np.all(np.isfinite(jac.poses)):
            raise DivergenceError(f"the fit diverged: non-finite Jacobian; {_HINT}")
        return jac


def refit_base(model: ErrorModel, data: CalibrationData, *, probe: bool = False,
               rotation_weight: float = 1.0, positions_only: bool = False) -> ErrorModel:
    """``model`` with its BASE (and, with ``probe=True``, its PROBE) re-identified on ``data``,
    the robot's geometry and compliance kept: for poses measured after the tracker
    (or the target) moved — the situation of appendix D's closing note.

    Starts from a rigid registration of the model's predicted target points onto the
    measured ones, then Gauss–Newton on a0, b0, α0, β0, θ0, d0 (and the PROBE frame)
    minimising ``Σ ‖Δp‖² + w² ‖Δφ‖²`` over the poses, ``w = rotation_weight`` (m/rad, as
    in :class:`Calibrator`).

    Parameters
    ----------
    model : ErrorModel
        The calibrated model.
    data : CalibrationData
        Poses measured in the new setup.
    probe : bool
        Also re-identify the PROBE frame (and the flange link's θ, d, a, α).
    rotation_weight : float, m/rad
        Weight ``w`` of the orientation rows.
    positions_only : bool
        Register 6-DOF data on their positions alone (``Σ ‖Δp‖²``), e.g. when the
        measured orientations are less trusted.

    Returns
    -------
    ErrorModel
        ``model`` with the new BASE (and PROBE), geometry and compliance unchanged.

    Raises
    ------
    CalibrationError
        ``rotation_weight`` not a finite number > 0.
    """
    if not (np.isfinite(rotation_weight) and rotation_weight > 0):
        raise CalibrationError(f"rotation_weight must be a finite number > 0, got "
                               f"{rotation_weight}")
    if positions_only:
        data = data.positions_only()
    m = fold_frames(model)
    robot = np.linalg.inv(m.base()) @ m.predict(data.q, data.payload_kg, data.temperature_c)
    fit = fit_rigid_transform(robot[:, :3, 3], data.positions)
    m = m.with_references(base=fit.transform)
    s = m.structure
    keys = [f"{f}{s.base_name}" for f in ("a", "b", "alpha", "beta", "theta", "d")]
    if probe:
        fl = s.desc.flange
        keys += [f"theta{fl}", f"d{fl}", f"a{fl}", f"alpha{fl}", f"theta{s.probe_name}",
                 f"d{s.probe_name}"]
    keys = [k for k in keys if k in m.space]
    cal = Calibrator(s.source, 1)
    problem = _Problem(m, data, m.batch(data.q, data.payload_kg, data.temperature_c),
                       float(rotation_weight))
    jac = identification_jacobian(m, problem.batch, keys)
    fa = analyse(_jacobian_rows(problem, jac.H).reshape(-1, len(keys)), keys)
    fitted, *_ = cal._iterate(problem, m, list(fa.kept), "base", [], loss="linear")
    return fitted
