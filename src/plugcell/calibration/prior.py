"""A robot moved to a new set-up: a short campaign identified with the earlier calibration as
a prior (maximum a posteriori, Tikhonov regularisation toward the prior).

The earlier calibration (set-up A: geometry, compliance, its learned layer) is a prior for
the robot in the new set-up.  A short campaign there identifies what it can determine:

* BASE and PROBE (the tracker and the target moved): free, no prior;
* every other parameter the earlier calibration identified, pulled toward its earlier
  value by its earlier uncertainty;
* the learned layer: the earlier layer is kept and its correction taken out of the new
  measurements *before* the physical fit (an offset), so the physical parameters absorb
  what differs in the new set-up and the layer what the physics cannot express — or,
  when the CV prefers it, left out (the candidates ``"τ/physical"``,
  :data:`PHYSICAL_SCALES`: the same MAP on the raw campaign; the earlier layer can be
  wrong for the new set-up);
* the campaign's own stage (:mod:`.campaign_stage`, ``stage=True``): small trees on what
  the fit leaves, on top of the earlier layer's arm-shape stage, weighted by their
  grouped CV over the campaign's cells (``w`` from a grid fixed in advance, default {1}:
  whole or not at all; e.g. {0, ¼, ½, ¾, 1}) and adopted only when the weighted stage
  beats the fit without it by more than k standard errors of the paired difference
  (:func:`.se_rule.beats`; its own k, default 0).

The problem (MAP with Gaussian measurement noise ``σ_y`` per residual row and a Gaussian
prior ``N(x_p, (τ σ_k)²)`` on each regularised parameter)::

    x̂ = argmin_x  ‖W (y − f(x))‖² + ‖Λ (x − x_p)‖²,    Λ = diag(λ_k),
    λ_k = σ_y / (τ σ_k)   for the regularised parameters,   λ_k = 0 for BASE and PROBE,

``y − f(x)`` the pose residuals (eq. 6.23; metres and radians, orientation rows weighed
by ``W = diag(1, 1, 1, w, w, w)``), ``σ_k`` the earlier calibration's standard deviation
of parameter ``k`` (eq. 8.5), ``σ_y = √σ̂²`` its residual standard deviation (eq. 8.3),
and ``τ ≥ 1`` an inflation: eq. 8.5 assumes independent pose errors, which the residuals
of a real robot are not (the σ are optimistic), and a robot moved to another set-up
differs from the earlier one by more than the earlier fit's noise.  ``τ`` is chosen by
cross-validation over the campaign's own poses (a seeded random K-fold, or grouped over
its workspace cells; never a pose outside the campaign) among :data:`SCALES`, or given.
``τ = 0`` (:data:`FRAMES_ONLY`) is the prior held exactly — only BASE and PROBE
re-identified, the earlier model moved; as the first candidate it makes the choice a
shrinkage estimator: where the campaign cannot show a gain, the CV keeps it.  The two
baselines (the earlier physical model moved, the campaign alone) are candidates too, and
any other candidate is adopted only when it beats the better of them by more than k
standard errors of the paired CV difference (:func:`pick_significant`).

Gauss–Newton on the augmented system: with the stacked residual
``F(x) = [W (y − f(x)); Λ (x_p − x)]`` and its Jacobian ``∂F/∂x = −[W H; Λ]``
(``H = ∂f/∂x``, the analytic identification Jacobian), each step is
``Δx = argmin ‖[W H; Λ] Δx − F(x)‖`` (eq. 4.8 on the augmented rows), halved while it
raises the cost.  The posterior covariance reported is ``σ̂² (HᵀWᵀWH + ΛᵀΛ)⁻¹``.

Limits: without the earlier layer the result is the physical MAP alone; directions of
the frames the campaign does not determine stay where the re-registration left them
(:mod:`.determinacy`).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from plugcell.calibration.campaign_stage import (
    STAGE_SE_K,
    STAGE_WEIGHTS,
    CampaignStage,
    check_weights,
    fit_campaign_stage,
)
from plugcell.calibration.configs import ModelConfig
from plugcell.calibration.data import CalibrationData
from plugcell.calibration.identifiability import analyse
from plugcell.calibration.identify import (
    BACKTRACK_STEPS,
    CalibrationError,
    Calibrator,
    DivergenceError,
    _jacobian_rows,
    _Problem,
    _residual_rows,
    refit_base,
)
from plugcell.calibration.jacobian import identification_jacobian
from plugcell.calibration.linalg import least_squares
from plugcell.calibration.model import ErrorModel
from plugcell.calibration.residual_model import (
    LearnedResidual,
    _remove_correction,
    calibration_fingerprint,
    fold_labels,
    workspace_cells,
)
from plugcell.calibration.result import CalibrationResult, IterationRecord
from plugcell.calibration.se_rule import SE_RULE_K, beats, check_k, paired_difference
from plugcell.calibration.statistics import PoseResiduals, parameter_statistics
from plugcell.calibration.validity import ValidityRegion

Array = NDArray[np.float64]

#: τ = 0: the prior held exactly — only BASE and PROBE re-identified (the earlier model moved).
FRAMES_ONLY = 0.0
#: Candidate inflations τ of the prior's σ, chosen by CV over the campaign
#: (:data:`FRAMES_ONLY` first: the shrinkage to the earlier model when the CV cannot tell).
SCALES: tuple[float, ...] = (FRAMES_ONLY, 1.0, 3.0, 10.0, 30.0, 100.0, 300.0, 1000.0)
#: τ used when the campaign covers fewer than 2 workspace cells (no CV possible).
DEFAULT_SCALE = 10.0
#: Workspace cell edge (m) grouping the campaign's poses for the choice of τ.
CELL_SIZE_M = 0.4
#: The CV splits of the choice: ``"cells"`` (grouped K-fold over the campaign's workspace
#: cells, K = min(5, cells)) or ``"kfold"`` (seeded random K-fold over the poses,
#: K = min(:data:`KFOLD_SPLITS`, N); the default).
CV_SPLITS: tuple[str, ...] = ("cells", "kfold")
#: K of the random split ``cv_split="kfold"``.
KFOLD_SPLITS = 10
#: Baseline (ii) among the CV's candidates: the earlier physical model with BASE + PROBE
#: re-identified on the raw campaign, without its learned layer.
MOVED = "moved"
#: Baseline (i) among the CV's candidates: the earlier calibration's model calibrated on the
#: campaign alone (no prior, no layer).
ALONE = "alone"
#: Suffix of a MAP candidate *without* the earlier layer (``"10/physical"``: τ = 10 on the
#: raw campaign, no layer offset, no layer in the result).
PHYSICAL = "/physical"
#: The τ of the MAP candidates without the earlier layer: the CV also decides whether the
#: earlier layer helps in the new set-up (:data:`MOVED` is τ = 0 without it).
PHYSICAL_SCALES: tuple[float, ...] = (1.0, 3.0, 10.0, 30.0, 100.0)
#: A candidate of the CV: a τ of :data:`SCALES`, ``f"{τ:g}/physical"`` for a τ of
#: :data:`PHYSICAL_SCALES`, :data:`MOVED` or :data:`ALONE`.
Choice = float | str
#: The CV's candidates in order of preference (the first within 1 % of the best wins): the
#: MAP with the earlier layer, the MAP without it, then the baselines.
CANDIDATES: tuple[Choice, ...] = (*SCALES, *(f"{t:g}{PHYSICAL}" for t in PHYSICAL_SCALES),
                                  MOVED, ALONE)


__all__ = ["ALONE", "CANDIDATES", "CELL_SIZE_M", "CV_SPLITS", "DEFAULT_SCALE", "FRAMES_ONLY",
           "KFOLD_SPLITS", "MOVED", "PHYSICAL", "PHYSICAL_SCALES", "SCALES", "SE_RULE_K",
           "Choice", "Prior", "PriorCalibrator", "augmented_residual", "frame_keys",
           "paired_difference", "parse_choice", "pick", "pick_significant"]


def parse_choice(choice: Choice) -> tuple[float | None, bool]:
    """What a candidate fits: ``(τ, with the earlier layer)``.

    Parameters
    ----------
    choice : float or str
        A τ (with the earlier layer; also as its CV key, ``f"{τ:g}"``), ``"τ/physical"``
        (without it), :data:`MOVED` (τ = 0 without it) or :data:`ALONE` (no prior: ``τ``
        is ``None``).

    Returns
    -------
    tau : float or None
        The inflation τ of the prior's σ (:data:`FRAMES_ONLY` for :data:`MOVED`).
    layer : bool
        Whether the earlier layer's correction is an offset of the fit and part of the
        result.

    Raises
    ------
    CalibrationError
        A string that is none of these (τ neither 0 nor a finite number ≥ 1).
    """
    if not isinstance(choice, str):
        return float(choice), True
    if choice == MOVED:
        return FRAMES_ONLY, False
    if choice == ALONE:
        return None, False
    text, layer = ((choice[:-len(PHYSICAL)], False) if choice.endswith(PHYSICAL)
                   else (choice, True))
    try:
        tau = float(text)
    except ValueError:
        tau = math.nan
    if not (tau == FRAMES_ONLY or (math.isfinite(tau) and tau >= 1.0)):
        raise CalibrationError(f"prior: unknown candidate {choice!r} (a τ = 0 or ≥ 1, "
                               f"'τ{PHYSICAL}', {MOVED!r} or {ALONE!r})")
    return tau, layer


def _label(choice: Choice) -> str:
    """A candidate's key in the CV scores: ``f"{τ:g}"``, ``"τ/physical"``, ``"moved"`` or
    ``"alone"``."""
    return choice if isinstance(choice, str) else f"{choice:g}"


def pick(scores: Mapping[str, float]) -> Choice:
    """The CV's choice among the scored candidates (keys as :func:`_label`).

    Eligible: ``s_c ≤ min(1.01 s*, s_alone, s_moved)`` (``s*`` the best score; a baseline
    not scored counts as ∞) — within 1 % of the best and never above either baseline —
    and of those the first of :data:`CANDIDATES` (the strongest prior the data do not
    reject).  So ``s_choice ≤ s_alone`` and ``s_choice ≤ s_moved`` whatever the scores.

    Parameters
    ----------
    scores : mapping of str to float
        CV score (any unit, e.g. m) of each candidate tried.

    Returns
    -------
    float or str
        The chosen candidate.

    Raises
    ------
    CalibrationError
        No candidate of :data:`CANDIDATES` was scored.
    """
    known = [c for c in CANDIDATES if _label(c) in scores]
    if not known:
        raise CalibrationError(f"prior: no known candidate among the CV scores {list(scores)}")
    best = min(scores[_label(c)] for c in known)
    bound = min(best * 1.01, scores.get(ALONE, math.inf), scores.get(MOVED, math.inf))
    return next((c for c in known if scores[_label(c)] <= bound), known[0])


def pick_significant(errors: Mapping[str, Array], fold: Array,
                     k: float = SE_RULE_K) -> Choice:
    """The CV's choice with a k-standard-error rule: a candidate other than the baselines
    only when its CV shows it better than the better baseline beyond noise.

    ``b`` is the baseline (:data:`ALONE`, :data:`MOVED`) with the lower CV score.  A
    candidate ``c`` is eligible when its mean paired difference to ``b`` over the
    campaign's poses (:func:`paired_difference`, SE clustered by fold) satisfies
    ``d̄_c + k·SE_c < 0``; among the eligible and the baselines :func:`pick` chooses (the
    first of :data:`CANDIDATES` within 1 % of the best, never above either baseline).  No
    candidate eligible: ``b``.  Under the null that ``c`` is no better than ``b`` the CV
    difference is ≥ 0 in expectation, so a candidate is adopted by chance with
    probability ≈ Φ(−k) (16 % at k = 1) and then is, in truth, no worse than ``b`` beyond
    the CV's noise; a candidate truly worse than ``b`` is adopted with a probability that
    falls with its CV deficit.  ``k = 0``: the plain sign of the difference.

    Parameters
    ----------
    errors : mapping of str to (N,) array
        Each candidate's held-out CV errors (keys as :func:`_label`), one per pose, in
        one unit; the baselines among them.
    fold : (N,) int array
        The fold that held each pose out.
    k : float
        The number of standard errors (≥ 0).

    Returns
    -------
    float or str
        The chosen candidate.

    Raises
    ------
    CalibrationError
        ``k`` negative or not finite, no candidate of :data:`CANDIDATES` among ``errors``.
    """
    k = check_k(k)
    scores = {c: float(np.mean(v)) for c, v in errors.items()}
    bases = [b for b in (MOVED, ALONE) if b in scores and math.isfinite(scores[b])]
    if not bases:
        return pick(scores)
    base = min(bases, key=lambda b: scores[b])
    keep = {}
    for c, s in scores.items():
        if c in (MOVED, ALONE):
            keep[c] = s
            continue
        if beats(errors[c], errors[base], fold, k)[0]:
            keep[c] = s
    return pick(keep)


@dataclass(frozen=True, eq=False)
class Prior:
    """The earlier calibration used as a prior.

    Attributes
    ----------
    robot : str
        Robot name of the earlier calibration.
    config : ModelConfig
        Its model (one of the five, :mod:`.configs`).
    model : ErrorModel
        Its identified model (values in each parameter's unit, frames in m).
    keys : tuple of str
        The parameters it identified.
    sigma : (k,) array
        Their standard deviations σ_k (eq. 8.5), in each parameter's unit, ``keys`` order.
    sigma_y : float, m
        Its residual standard deviation per residual row, ``√σ̂²`` (eq. 8.3).
    layer : LearnedResidual or None
        Its learned residual layer, if any.
    """

    robot: str
    config: ModelConfig
    model: ErrorModel
    keys: tuple[str, ...]
    sigma: Array
    sigma_y: float
    layer: LearnedResidual | None = None

    def __post_init__(self) -> None:
        s = np.asarray(self.sigma, float)
        if s.shape != (len(self.keys),):
            raise CalibrationError(f"prior: {s.size} σ for {len(self.keys)} parameters")
        if not (math.isfinite(self.sigma_y) and self.sigma_y > 0):
            raise CalibrationError(f"prior: the residual σ̂ must be a number > 0, got "
                                   f"{self.sigma_y!r} (a PARAMS.json without 'sigma2'?)")

    @classmethod
    def from_result(cls, result: CalibrationResult,
                    layer: LearnedResidual | None = None) -> Prior:
        """The prior of a calibration result that carries its statistics.

        Parameters
        ----------
        result : CalibrationResult
            The earlier calibration (with ``statistics``).
        layer : LearnedResidual, optional
            Its learned layer (default: ``result.residual_model``).

        Returns
        -------
        Prior
            The prior.

        Raises
        ------
        CalibrationError
            The result has no statistics (σ).
        """
        if result.statistics is None:
            raise CalibrationError("prior: the earlier calibration has no statistics (σ)")
        return cls(result.robot, result.config, result.model, tuple(result.keys),
                   np.asarray(result.statistics.sigma, float),
                   float(np.sqrt(result.statistics.sigma2)),
                   result.residual_model if layer is None else layer)


def frame_keys(model: ErrorModel) -> list[str]:
    """The keys of BASE and PROBE (with the flange link's, which PROBE absorbs): the
    parameters a new set-up re-identifies freely (as :func:`~.identify.refit_base`).

    Parameters
    ----------
    model : ErrorModel
        The model.

    Returns
    -------
    list of str
        Its frame keys (a0, b0, α0, β0, θ0, d0; the flange's θ, d, a, α; PROBE's θ, d).
    """
    s = model.structure
    fl = s.desc.flange
    keys = [f"{f}{s.base_name}" for f in ("a", "b", "alpha", "beta", "theta", "d")]
    keys += [f"theta{fl}", f"d{fl}", f"a{fl}", f"alpha{fl}", f"theta{s.probe_name}",
             f"d{s.probe_name}"]
    return [k for k in keys if k in model.space]


def augmented_residual(model: ErrorModel, problem: _Problem, keys: Sequence[str],
                       x_prior: Array, lam: Array) -> tuple[Array, Array]:
    """The stacked residual ``F = [W (y − f(x)); Λ (x_p − x)]`` and its Jacobian
    ``∂F/∂x = −[W H; Λ]`` at ``model`` (module docstring).

    Parameters
    ----------
    model : ErrorModel
        The model at ``x`` (the values of ``keys``).
    problem : _Problem
        The campaign (data, pose batch, rotation weight ``w``).
    keys : sequence of str
        The unknowns ``x`` (k).
    x_prior : (k,) array
        ``x_p`` (each in its parameter's unit; any value where ``λ = 0``).
    lam : (k,) array
        ``λ_k`` (1 / parameter unit × m).

    Returns
    -------
    F : (N·rows + k,) array
        Residuals: m and (weighted) rad, then the prior rows (m).
    J : (N·rows + k, k) array
        ``∂F/∂x``.
    """
    jac = identification_jacobian(model, problem.batch, keys)
    x = np.array([model.value(k) for k in keys])
    r = _residual_rows(problem, jac.poses).reshape(-1)
    H = _jacobian_rows(problem, jac.H).reshape(-1, len(keys))
    F = np.concatenate([r, lam * (x_prior - x)])
    J = -np.vstack([H, np.diag(lam)])
    return F, J


class PriorCalibrator:
    """Identify a short campaign in a new set-up with an earlier calibration as prior
    (module docstring: the equation, the choice of τ, the layer as an offset).

    Parameters
    ----------
    prior : Prior
        The earlier calibration.
    scale : float, optional
        The inflation τ ≥ 1 of the prior's σ, or 0 (:data:`FRAMES_ONLY`: the prior held
        exactly, BASE and PROBE alone re-identified); default: chosen by CV over the
        campaign among :data:`CANDIDATES` (:meth:`choose`).
    stage : bool
        Learn the campaign's own stage on what the physical fit leaves, weight it by its
        grouped CV (``stage_weights``) and adopt it when the weighted stage beats the fit
        without it by more than ``stage_se_k`` standard errors (:mod:`.campaign_stage`);
        default True.
    rotation_weight : float, m/rad
        Weight ``w`` of the orientation rows.
    tol : float
        Stop when ‖Δx‖ < tol.
    max_iterations : int
        Iteration bound.
    cell_size_m : float, m
        Workspace cell edge of the CV's groups.
    cv_split : str
        The CV splits of the choice (:data:`CV_SPLITS`): ``"kfold"`` (default), a seeded
        random :data:`KFOLD_SPLITS`-fold over the poses, or ``"cells"``, grouped over the
        campaign's workspace cells — on I-optimal campaigns, whose few
        extreme poses a held-out cell takes away, the grouped split penalises the weakly
        regularised candidates (the campaign alone, large τ) more than the fit on the
        whole campaign deserves (docs/results/short-campaign-bounds.md).  The campaign
        stage keeps its grouped CV.
    se_k : float
        k ≥ 0 of the choice's k-standard-error rule (:func:`pick_significant`; default
        :data:`SE_RULE_K`).
    stage_se_k : float
        k ≥ 0 of the campaign stage's adoption, the same rule on its grouped CV
        (:func:`.campaign_stage.fit_campaign_stage`; default
        :data:`~.campaign_stage.STAGE_SE_K` = 0, the plain comparison).
    stage_weights : sequence of float
        The grid ``W ⊂ [0, 1]`` of the campaign stage's weight: with
        ``m(w) = mean_i ‖e_i − w ê_i‖`` over the stage's grouped CV (``ê`` its
        out-of-fold predictions), ``w̃ = argmin_{w ∈ W, w > 0} m(w)``, adopted when
        ``m(w̃) < m(0)`` and ``d̄ + k·SE < 0`` for ``d_i = ‖e_i − w̃ ê_i‖ − ‖e_i‖``, then
        ``p = p_MAP + R_B (c_shape + w̃ ê_c(q))`` (:func:`.campaign_stage.judge_stage`;
        default :data:`~.campaign_stage.STAGE_WEIGHTS` = ``(1,)``, the stage whole or not
        at all; :data:`~.campaign_stage.STAGE_WEIGHT_GRID` = (0, ¼, ½, ¾, 1) the grid
        measured; ``(0,)``: no stage).
    progress : callable, optional
        ``(stage, i, n, message)``.

    Raises
    ------
    CalibrationError
        τ neither 0 nor a number ≥ 1, non-positive tolerances or weights, an unknown
        ``cv_split``, a bad k, a bad stage weight grid (:func:`.campaign_stage.check_weights`).
    """

    def __init__(self, prior: Prior, *, scale: float | None = None, stage: bool = True,
                 rotation_weight: float = 1.0, tol: float = 1e-7, max_iterations: int = 30,
                 cell_size_m: float = CELL_SIZE_M, cv_split: str = "kfold",
                 se_k: float = SE_RULE_K, stage_se_k: float = STAGE_SE_K,
                 stage_weights: Sequence[float] = STAGE_WEIGHTS,
                 progress: Callable[[str, int, int, str], None] | None = None) -> None:
        if scale is not None and not (scale == FRAMES_ONLY
                                      or (math.isfinite(scale) and scale >= 1.0)):
            raise CalibrationError(f"the prior's σ inflation τ must be 0 (BASE + PROBE only) "
                                   f"or a number ≥ 1, got {scale}")
        if not (tol > 0 and max_iterations >= 1 and rotation_weight > 0 and cell_size_m > 0):
            raise CalibrationError("tol, max_iterations, rotation_weight, cell_size_m must be > 0")
        if cv_split not in CV_SPLITS:
            raise CalibrationError(f"prior: unknown CV split {cv_split!r} (one of "
                                   f"{', '.join(CV_SPLITS)})")
        self.prior = prior
        self.scale = scale
        self.stage = bool(stage)
        self.rotation_weight = float(rotation_weight)
        self.tol = float(tol)
        self.max_iterations = int(max_iterations)
        self.cell_size_m = float(cell_size_m)
        self.cv_split = cv_split
        self.se_k = check_k(se_k)
        self.stage_se_k = check_k(stage_se_k)
        self.stage_weights = check_weights(stage_weights)
        self.progress = progress

    def _say(self, stage: str, i: int, n: int, msg: str) -> None:
        if self.progress is not None:
            self.progress(stage, i, n, msg)

    # ------------------------------------------------------------------ pieces
    def _check(self, data: CalibrationData) -> None:
        desc = self.prior.model.structure.desc
        if data.q.shape[1] != desc.n_readings:
            raise CalibrationError(
                f"the data have {data.q.shape[1]} joint columns, the prior's robot "
                f"{self.prior.robot!r} has {desc.n_readings}")

    def offset_data(self, data: CalibrationData) -> tuple[CalibrationData, Array | None]:
        """The campaign with the prior layer's correction taken out (``p_M − R_B e``,
        ``Exp(−R_B φ) R_M``; ``R_B`` of the prior re-registered on the raw campaign), and
        the layer's in-domain mask (``None`` without a layer)."""
        layer = self.prior.layer
        if layer is None:
            return data, None
        pred = layer.predict(data.q, data.payload_kg, data.temperature_c)
        if not pred.in_domain.any():
            return data, pred.in_domain
        moved = refit_base(self.prior.model, data, probe=True,
                           rotation_weight=self.rotation_weight)
        return _remove_correction(data, moved.base()[:3, :3], pred.correction), pred.in_domain

    def _start(self, data: CalibrationData) -> tuple[ErrorModel, list[str], list[str]]:
        """The prior re-registered on ``data`` (BASE + PROBE), the frame keys these poses
        determine and the regularised keys."""
        start = refit_base(self.prior.model, data, probe=True,
                           rotation_weight=self.rotation_weight)
        frames = frame_keys(start)
        problem = _Problem(start, data, start.batch(data.q, data.payload_kg, data.temperature_c),
                           self.rotation_weight)
        jac = identification_jacobian(start, problem.batch, frames)
        kept = list(analyse(_jacobian_rows(problem, jac.H).reshape(-1, len(frames)),
                            frames).kept)
        regular = [k for k in self.prior.keys if k not in frames and k in start.space]
        return start, kept, regular

    def _lambda(self, keys: Sequence[str], regular: Sequence[str], tau: float) -> Array:
        sig = dict(zip(self.prior.keys, np.asarray(self.prior.sigma, float), strict=True))
        lam = np.zeros(len(keys))
        for i, k in enumerate(keys):
            if k in regular:
                s = sig[k]
                if not (math.isfinite(s) and s > 0):
                    raise CalibrationError(f"prior: parameter {k} has no usable σ ({s})")
                lam[i] = self.prior.sigma_y / (tau * s)
        return lam

    def solve(self, data: CalibrationData, tau: float
              ) -> tuple[ErrorModel, ErrorModel, list[str], Array, list[IterationRecord], bool]:
        """Gauss–Newton on the augmented problem (module docstring) for one ``τ``.

        Parameters
        ----------
        data : CalibrationData
            The campaign (already offset by the prior layer, :meth:`offset_data`).
        tau : float
            The inflation τ of the prior's σ (:data:`FRAMES_ONLY`: no regularised key).

        Returns
        -------
        model : ErrorModel
            The MAP estimate.
        start : ErrorModel
            The prior re-registered on the campaign (BASE + PROBE only).
        keys : list of str
            The unknowns (determined frame keys, then the regularised keys).
        lam : (k,) array
            ``λ_k``.
        history : list of IterationRecord
            One per iteration.
        converged : bool
            ‖Δx‖ < tol reached.
        """
        start, frames, regular = self._start(data)
        if tau == FRAMES_ONLY:  # the prior held exactly: the earlier model moved
            regular = []
        keys = frames + regular
        lam = self._lambda(keys, regular, tau)
        x_prior = np.array([start.value(k) for k in keys])
        problem = _Problem(start, data, start.batch(data.q, data.payload_kg, data.temperature_c),
                           self.rotation_weight)
        model = start
        history: list[IterationRecord] = []
        converged = False
        F, J = augmented_residual(model, problem, keys, x_prior, lam)
        for it in range(1, self.max_iterations + 1):
            cost = float(F @ F)
            s = np.linalg.norm(J, axis=0)
            s = np.where(s > 0, s, 1.0)
            step = least_squares(-J / s, F) / s
            for _ in range(BACKTRACK_STEPS):
                new = model.updated(keys=keys, step=step)
                Fn, Jn = augmented_residual(new, problem, keys, x_prior, lam)
                if float(Fn @ Fn) <= cost * (1.0 + 1e-12) + 1e-30:
                    break
                step = 0.5 * step
            if not np.all(np.isfinite(Fn)):
                raise DivergenceError("the prior fit diverged: non-finite residuals")
            n_rows = len(data) * data.rows
            pos = np.linalg.norm(Fn[:n_rows].reshape(len(data), data.rows)[:, :3], axis=1)
            step_norm = float(np.linalg.norm(step))
            history.append(IterationRecord(it, step_norm, float(Fn @ Fn),
                                           float(pos.mean() * 1e3),
                                           float(np.sqrt(np.mean(pos**2)) * 1e3)))
            model, F, J = new, Fn, Jn
            if step_norm < self.tol:
                converged = True
                break
        return model, start, keys, lam, history, converged

    def _cv_errors(self, raw: CalibrationData, offset: CalibrationData,
                   folds: Sequence[tuple[Array, Array]], choice: Choice) -> Array:
        """The held-out position errors (m, one a campaign pose) of candidate ``choice``
        fitted on the other cells of each fold: a τ on the offset campaign (the hybrid's
        error: the prior layer's correction is in the offset), the candidates without the
        earlier layer (``"τ/physical"``, :data:`MOVED`, :data:`ALONE`) on the raw one.  A
        candidate that cannot be fitted on a fold (too few poses for the plain calibration)
        scores ``inf``."""
        err = np.empty(len(raw))
        tau, layer = parse_choice(choice)
        data = offset if layer else raw
        for tr, te in folds:
            test = data.subset(te)
            try:
                if tau is None:
                    model = self._alone(data.subset(tr)).model
                else:
                    model, *_ = self.solve(data.subset(tr), tau)
            except CalibrationError:
                err[te] = np.inf
                continue
            P = model.predict(test.q, test.payload_kg, test.temperature_c)
            err[te] = np.linalg.norm(test.positions - P[:, :3, 3], axis=1)
        return err

    def _alone(self, data: CalibrationData) -> CalibrationResult:
        """Baseline (i): the prior's model calibrated on ``data`` alone (no prior)."""
        return Calibrator(self.prior.model.structure.desc, self.prior.config.number,
                          rotation_weight=self.rotation_weight).fit(data)

    def choose(self, data: CalibrationData, offset: CalibrationData | None = None
               ) -> tuple[Choice, dict[str, float]]:
        """The candidate of :data:`CANDIDATES` by K-fold CV over the campaign (default
        ``cv_split="kfold"``: a seeded random K-fold over the poses, K =
        min(:data:`KFOLD_SPLITS`, N); ``"cells"``: grouped over its workspace cells, K =
        min(5, cells)): each candidate's held-out position error per pose (m), fitted on
        the other folds, and :func:`pick_significant` — a candidate other than the
        baselines (:data:`ALONE`, :data:`MOVED`) only when it beats the better of them by
        more than ``se_k`` standard errors of the paired difference (clustered by fold);
        among those and the baselines the first of :data:`CANDIDATES` within 1 % of the
        best and no worse than either baseline, so the choice's CV error is never above
        the campaign alone's nor the earlier model moved's.  Fewer than 2 poses
        (``"cells"``: 2 cells): :data:`DEFAULT_SCALE`.

        Parameters
        ----------
        data : CalibrationData
            The raw campaign.
        offset : CalibrationData, optional
            The campaign offset by the prior layer (:meth:`offset_data`; default: computed).

        Returns
        -------
        choice : float or str
            A τ, ``"τ/physical"``, :data:`MOVED` or :data:`ALONE` (:func:`parse_choice`).
        scores : dict of str to float
            The CV score (m) of each candidate, keyed ``f"{τ:g}"``, ``"τ/physical"``,
            ``"moved"``, ``"alone"`` (empty without CV).
        """
        from sklearn.model_selection import GroupKFold, KFold

        if offset is None:
            offset, _ = self.offset_data(data)
        start = refit_base(self.prior.model, data, probe=True,
                           rotation_weight=self.rotation_weight)
        targets = (np.linalg.inv(start.base()) @ start.predict(
            data.q, data.payload_kg, data.temperature_c))[:, :3, 3]
        if self.cv_split == "kfold":
            if len(data) < 2:
                return DEFAULT_SCALE, {}
            folds = list(KFold(n_splits=min(KFOLD_SPLITS, len(data)), shuffle=True,
                               random_state=0).split(targets))
        else:
            groups = workspace_cells(targets, self.cell_size_m)
            cells = int(groups.max()) + 1
            if cells < 2:
                return DEFAULT_SCALE, {}
            folds = list(GroupKFold(n_splits=min(5, cells)).split(targets, groups=groups))
        fold = fold_labels(folds, len(data))
        errors: dict[str, Array] = {}
        for c in CANDIDATES:
            errors[_label(c)] = self._cv_errors(data, offset, folds, c)
            self._say("prior", 0, 0, f"{_label(c)}: held-out "
                      f"{errors[_label(c)].mean() * 1e3:.4f} mm")
        scores = {c: float(e.mean()) for c, e in errors.items()}
        return pick_significant(errors, fold, self.se_k), scores

    # ------------------------------------------------------------------ fit
    def fit(self, data: CalibrationData) -> CalibrationResult:
        """Identify the campaign ``data`` with the prior (module docstring).

        Parameters
        ----------
        data : CalibrationData
            The short campaign in the new set-up: readings ``(N, n)`` rad, measured
            positions ``(N, 3)`` or poses, m.

        Returns
        -------
        CalibrationResult
            The MAP model; ``nominal`` is the prior re-registered on the campaign (BASE +
            PROBE: the "before"); its learned layer: the campaign's own stage (with its
            weight) on top of the prior layer's arm-shape stage when adopted
            (:mod:`.campaign_stage`), else the prior's layer (rebound to the new model: its
            correction was the offset the physical fit saw); ``settings["prior"]`` records
            τ, its CV scores, the regularised keys and the stage.

        Raises
        ------
        CalibrationError
            Data of another robot (joint count), a prior without usable σ.
        """
        t0 = time.perf_counter()
        self._check(data)
        offset, in_domain = self.offset_data(data)
        scores: dict[str, float] = {}
        choice: Choice | None = self.scale
        if choice is None:
            choice, scores = self.choose(data, offset)
        if choice == ALONE:
            return self._fit_alone(data, scores, t0)
        earlier = self.prior.layer
        tau, with_layer = parse_choice(choice)
        assert tau is not None  # ALONE returned above
        if not with_layer:  # the MAP (or the earlier model moved) without the earlier layer
            offset, in_domain, earlier = data, None, None
        final, start, keys, lam, history, converged = self.solve(offset, tau)
        self._say("prior", 1, 1, f"{_label(choice)}: mean residual "
                  f"{history[-1].mean_position_mm if history else float('nan'):.4f} mm")
        stage = self._stage(final, data, earlier)
        layer = earlier
        if stage is not None and stage.adopted:
            layer = stage.layer
        elif layer is not None:
            layer = replace(layer, fingerprint=calibration_fingerprint(final))
        warnings: list[str] = []
        if in_domain is not None and not in_domain.all():
            warnings.append(f"{int((~in_domain).sum())} of {len(data)} campaign poses lie "
                            "outside the prior layer's region: its correction is not applied "
                            "there")
        settings = self._settings(choice, scores, [k for k, v in zip(keys, lam, strict=True)
                                                   if v > 0], earlier is not None, stage)
        return self._result(data, offset, final, start, keys, lam, history, converged,
                            layer, warnings, settings, t0)

    def _stage(self, model: ErrorModel, data: CalibrationData,
               earlier: LearnedResidual | None) -> CampaignStage | None:
        """The campaign's own stage on what ``model`` leaves of ``data`` (``None`` when
        ``stage=False``), on top of ``earlier``'s arm-shape stage."""
        if not self.stage:
            return None
        stage = fit_campaign_stage(model, data, earlier, robot=self.prior.robot,
                                   cell_size_m=self.cell_size_m, se_k=self.stage_se_k,
                                   weights=self.stage_weights)
        self._say("prior", 1, 1, "campaign stage: " + (
            f"adopted, weight {stage.weight:g}" if stage.adopted else "not used") + (
            f" ({stage.reason})" if stage.reason else ""))
        return stage

    def _settings(self, choice: Choice, scores: Mapping[str, float], regularised: list[str],
                  layer_offset: bool, stage: CampaignStage | None) -> dict[str, object]:
        """``settings["prior"]`` of a result: the candidate chosen (``choice``: ``"map"``
        (with the earlier layer), ``"τ/physical"`` (without it), ``"moved"`` or ``"alone"``;
        ``scale``: its τ, ``None`` for the campaign alone), how,
        the CV scores (mm), the k of the k-standard-error rule (``se_k``), the regularised
        keys, whether the prior layer's correction was an offset, whether the earlier
        calibration had a layer (``earlier_layer``), the campaign stage."""
        return {"robot": self.prior.robot,
                "choice": choice if isinstance(choice, str) else "map",
                "scale": parse_choice(choice)[0],
                "scale_chosen_by": "given" if self.scale is not None
                else (("grouped CV" if self.cv_split == "cells" else f"random "
                       f"{KFOLD_SPLITS}-fold CV") if scores else "default"),
                "cv_mm": {k: v * 1e3 for k, v in scores.items()},
                "se_k": self.se_k if scores else None,
                "regularised": regularised,
                "sigma_y_m": self.prior.sigma_y,
                "layer_offset": layer_offset,
                "earlier_layer": self.prior.layer is not None,
                "stage": None if stage is None else stage.summary()}

    def _fit_alone(self, data: CalibrationData, scores: Mapping[str, float],
                   t0: float) -> CalibrationResult:
        """The CV chose the campaign alone (:data:`ALONE`): the plain calibration of
        ``data`` with the campaign's own stage when its CV adopts it (no earlier layer)."""
        res = self._alone(data)
        stage = self._stage(res.model, data, None)
        if stage is not None and stage.adopted and stage.layer is not None:
            res = res.with_residual_model(stage.layer)
        settings = self._settings(ALONE, scores, [], False, stage)
        return replace(res, settings={**res.settings, "prior": settings},
                       warnings=(*res.warnings, "the short campaign's cross-validation preferred "
                                 "the campaign alone to the earlier calibration: the prior is "
                                 "not used"),
                       elapsed_s=time.perf_counter() - t0)

    def _result(self, data: CalibrationData, offset: CalibrationData, final: ErrorModel,
                start: ErrorModel, keys: list[str], lam: Array,
                history: list[IterationRecord], converged: bool,
                layer: LearnedResidual | None, warnings: list[str],
                prior_settings: dict[str, object], t0: float) -> CalibrationResult:
        """The :class:`CalibrationResult` of a fit: posterior statistics
        ``σ̂² (HᵀWᵀWH + ΛᵀΛ)⁻¹`` at the MAP, residuals before (the prior moved) and after
        on the offset campaign, the validity region of the campaign's poses."""
        problem = _Problem(final, offset,
                           final.batch(offset.q, offset.payload_kg, offset.temperature_c),
                           self.rotation_weight)
        x_prior = np.array([start.value(k) for k in keys])
        F, J = augmented_residual(final, problem, keys, x_prior, lam)
        stats = parameter_statistics(-J, F)
        P_start = start.predict(offset.q, offset.payload_kg, offset.temperature_c)
        P_final = final.predict(offset.q, offset.payload_kg, offset.temperature_c)
        residuals = PoseResiduals.from_poses(offset, P_start, P_final)
        targets = (np.linalg.inv(final.base()) @ P_final)[:, :3, 3]
        return CalibrationResult(
            config=self.prior.config, robot=self.prior.robot, model=final,
            nominal=start, keys=tuple(keys), identifiability=None,
            data_identifiability=None, iterations=len(history), converged=converged,
            history=tuple(history), statistics=stats,
            calibration=residuals.accuracy("after"),
            calibration_before=residuals.accuracy("before"),
            six_dof=data.six_dof, n_poses=len(data), warnings=tuple(warnings),
            elapsed_s=time.perf_counter() - t0, calibration_residuals=residuals,
            validity=ValidityRegion.from_poses(final, data.q, data.payload_kg,
                                               targets=targets),
            residual_model=layer,
            settings={"method": "gauss-newton", "loss": "linear",
                      "rotation_weight": self.rotation_weight, "tol": self.tol,
                      "max_iterations": self.max_iterations, "prior": prior_settings})
