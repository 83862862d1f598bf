"""The campaign's own learned stage of a short campaign in a new set-up (issue 36).

After the prior-regularised physical fit (:mod:`.prior`), what is left of a short
campaign's residual is partly the new set-up's own systematic error — a function of the
joints the earlier set-up's layer does not know (docs/results/ur10-residual.md (c), (g)).
A small stage learns it, on top of the earlier layer's transferable arm-shape stage::

    e_c(q) = R_Bᵀ (p_M − p_MAP(q)) − c_shape,A(q)          (the stage's targets)
    p_hybrid = p_MAP + R_B (c_shape,A(q) + ê_c(q))         (:func:`.residual_model.hybrid_poses`)

``ê_c`` gradient-boosted trees on ``(sin q, cos q)`` (a
:class:`~.residual_model.ResidualLearner`: position only, no shape stage of its own,
≥ max(5, n/10) poses a leaf, 25 or 100 trees at learning rate 0.1 — fewer trees, a
stronger shrinkage toward zero), chosen by grouped K-fold cross-validation over the
campaign's workspace cells (``K = min(5, cells)``).  Its correction enters with a
**weight** chosen by that same CV on a grid fixed in advance (``stage_weights``,
``--prior-stage-weights``: a one-weight stacking of the stage, Breiman 1996; default
:data:`STAGE_WEIGHTS` = {1}, the stage whole or not at all; :data:`STAGE_WEIGHT_GRID` =
{0, ¼, ½, ¾, 1} the grid measured), and the weighted stage is **adopted only
when it beats the physical fit with the earlier layer by more than k standard errors** on
the campaign's held-out cells — the k-standard-error rule of the candidate choice
(:func:`.se_rule.beats`) with its own ``k`` (``--prior-stage-se``, default
:data:`STAGE_SE_K` = 0)::

    m(w) = (1/N) Σ_i ‖e_i − w ê_i‖                  (ê_i: the stage's out-of-fold prediction)
    w̃ = argmin_{w ∈ W, w > 0} m(w)                  (ties: the smaller w)
    d_i = ‖e_i − w̃ ê_i‖ − ‖e_i‖,     adopted ⇔ m(w̃) < m(0)  and  d̄ + k·SE < 0,
    p_hybrid = p_MAP + R_B (c_shape,A(q) + w̃ ê_c(q))          (adopted; else w = 0)

``SE`` the standard error of ``d̄`` clustered by the CV's folds (the stage's grouped
folds, the independent units); ``k = 0`` is the plain comparison of the means.  ``w = 0``
(the fit without the stage) is always the reference, so 0 in the grid changes nothing;
``W = {0}`` is no stage, ``W = {1}`` the stage adopted or not as a whole (the rule before
the weight; ``m(1) < m(0)`` is ``LearnedResidual.useful``).  Otherwise the earlier layer
stays as it was.  Where a pose lies outside the stage's trained region (its in-domain
test) the stage adds nothing there.

Measured on the IPA UR10 (docs/results/short-campaign-ur10.md): the stage pays on
campaigns drawn at random over the new set-up's region and is (correctly) rejected by
its CV on I-optimal ones, whose few extreme poses say little about the cells between.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from plugcell.calibration.data import CalibrationData
from plugcell.calibration.identify import CalibrationError
from plugcell.calibration.model import ErrorModel
from plugcell.calibration.residual_model import (
    CrossValidation,
    LearnedResidual,
    ResidualLearner,
    ResidualModelError,
    check_weight,
    residual_targets,
    workspace_cells,
)
from plugcell.calibration.se_rule import beats, check_k

Array = NDArray[np.float64]

#: Fewest campaign poses the stage is learned from (below: not tried).
MIN_STAGE_POSES = 20
#: Boosting iterations the stage's CV chooses among (learning rate 0.1).
STAGE_TREES: tuple[int, ...] = (25, 100)
#: Default k of the stage's k-standard-error rule: 0, the plain comparison of the CV means.
#: Its own knob, not the candidate choice's k (:data:`.se_rule.SE_RULE_K` = 1): the stage's
#: SE comes from at most 5 grouped folds (4 degrees of freedom) and k = 1 refused stages
#: that helped on held-out cells (IPA C, n = 100: −12 % → −2 %,
#: docs/results/short-campaign-bounds.md).
STAGE_SE_K = 0.0
#: Default grid of the stage's weight ``w`` (module docstring): {1}, the stage whole or not at
#: all, the rule before the weight.
STAGE_WEIGHTS: tuple[float, ...] = (1.0,)
#: The grid measured on the IPA UR10 (fixed before it was; docs/results/short-campaign-bounds.md
#: §7, §8): better than {1} on every series at n ≤ 100 poses, worse on 3 of 6 at n = 200,
#: 400, where the whole stage helps most and its CV's weight (fitted on 4/5 of the
#: campaign) shrinks it too far — hence an option (``--prior-stage-weights
#: 0,0.25,0.5,0.75,1``), not the default.
STAGE_WEIGHT_GRID: tuple[float, ...] = (0.0, 0.25, 0.5, 0.75, 1.0)

__all__ = ["MIN_STAGE_POSES", "STAGE_SE_K", "STAGE_TREES", "STAGE_WEIGHTS", "STAGE_WEIGHT_GRID",
           "CampaignStage",
           "check_weights", "fit_campaign_stage", "judge_stage", "stage_grid", "weighted_cv"]


@dataclass(frozen=True, eq=False)
class CampaignStage:
    """The outcome of :func:`fit_campaign_stage`.

    Attributes
    ----------
    layer : LearnedResidual or None
        The fitted stage (its ``prior`` the earlier arm-shape stage; when adopted its
        ``weight`` the chosen ``w̃``), ``None`` when not tried.
    adopted : bool
        The stage is used: its weighted grouped CV beat the physical fit with the
        earlier layer by more than ``se_k`` standard errors.
    reason : str
        Why it was not tried or not adopted ("" when adopted).
    gain_mm, se_mm : float or None, mm
        When tried: the mean paired CV difference ``d̄`` (stage minus fit; negative: the
        stage helps) and its standard error clustered by fold.
    se_k : float
        The k of the rule.
    weights : tuple of float
        The grid ``W`` of the weight.
    weight : float
        The weight applied: ``w̃`` when adopted, else 0.
    cv_mm : dict or None, mm
        When tried: ``m(w)`` for 0 and each ``w`` of ``W``.
    """

    layer: LearnedResidual | None
    adopted: bool
    reason: str
    gain_mm: float | None = None
    se_mm: float | None = None
    se_k: float = STAGE_SE_K
    weights: tuple[float, ...] = STAGE_WEIGHTS
    weight: float = 0.0
    cv_mm: dict[float, float] | None = None

    def summary(self) -> dict[str, Any]:
        """What PARAMS.json records (``settings.prior.stage``): ``adopted``, ``reason``,
        the weight applied (``weight``, 0 when not adopted) and the grid (``weights``)
        and, when tried, the CV's physical and hybrid (``w = 1``) mean held-out errors
        (mm), ``m(w)`` per weight (``cv_by_weight_mm``, keys ``"0"``, ``"0.25"``, …), the
        paired difference of the weight the rule judged and its standard error
        (``gain_mm``, ``se_mm``, mm), ``se_k``, the cells and the chosen
        hyper-parameters."""
        out: dict[str, Any] = {"adopted": self.adopted, "reason": self.reason,
                               "weight": self.weight, "weights": list(self.weights)}
        if self.layer is not None:
            cv = self.layer.cv
            out.update(physical_mm=cv.physical_mm, hybrid_mm=cv.hybrid_mm,
                       cv_by_weight_mm=None if self.cv_mm is None
                       else {f"{w:g}": v for w, v in self.cv_mm.items()},
                       gain_mm=self.gain_mm, se_mm=self.se_mm, se_k=self.se_k,
                       cells=cv.cells, folds=cv.folds, params=dict(self.layer.params))
        return out


def stage_grid(n: int) -> list[dict[str, Any]]:
    """The stage's hyper-parameter candidates for a campaign of ``n`` poses.

    Parameters
    ----------
    n : int
        Campaign poses.

    Returns
    -------
    list of dict
        ``HistGradientBoostingRegressor`` settings: 15 leaves, ``max(5, min(20, n // 10))``
        poses a leaf, each of :data:`STAGE_TREES` iterations.
    """
    leaf = max(5, min(20, n // 10))
    return [{"max_leaf_nodes": 15, "min_samples_leaf": leaf, "max_iter": t} for t in STAGE_TREES]


def check_weights(weights: Any) -> tuple[float, ...]:
    """The campaign stage's weight grid ``W``, checked, in increasing order.

    Parameters
    ----------
    weights : sequence of float
        The weights ``w ∈ [0, 1]`` the stage's CV chooses among (module docstring).

    Returns
    -------
    tuple of float
        The weights, sorted.

    Raises
    ------
    CalibrationError
        Not a sequence of numbers, empty, a weight not a number in [0, 1] (a bool
        included), or a weight listed twice.
    """
    if isinstance(weights, (str, bytes)) or not isinstance(weights, Iterable):
        raise CalibrationError(f"prior: the campaign stage's weights must be a sequence of "
                               f"numbers in [0, 1], got {weights!r}")
    out = []
    for w in weights:
        try:
            out.append(check_weight(w, "prior: each campaign stage weight"))
        except ResidualModelError as exc:
            raise CalibrationError(str(exc)) from None
    if not out:
        raise CalibrationError("prior: the campaign stage's weights are empty (give 0 for "
                               "no stage)")
    if len(set(out)) < len(out):
        twice = sorted({w for w in out if out.count(w) > 1})
        raise CalibrationError(f"prior: the campaign stage's weights list "
                               f"{', '.join(f'{w:g}' for w in twice)} twice")
    return tuple(sorted(out))


def weighted_cv(cv: CrossValidation, weights: Sequence[float]) -> dict[float, Array]:
    """The stage's held-out error of each pose at each weight, ``‖e_i − w ê_i‖``.

    Parameters
    ----------
    cv : CrossValidation
        The stage's grouped CV, with its ``targets`` ``e`` and out-of-fold
        ``predictions`` ``ê`` (a layer just fitted, not one read from a file).
    weights : sequence of float
        The weights ``w``.

    Returns
    -------
    dict
        ``w`` → (N,) array, m; ``w = 1`` gives ``cv.hybrid_errors`` and ``w = 0``
        ``cv.physical_errors`` exactly.

    Raises
    ------
    CalibrationError
        The CV carries no targets or predictions.
    """
    if cv.targets is None or cv.predictions is None:
        raise CalibrationError("prior: the stage's CV has no out-of-fold predictions (a "
                               "layer read from a file cannot be re-weighted)")
    return {w: np.linalg.norm(cv.targets - w * cv.predictions, axis=1) for w in weights}


def fit_campaign_stage(model: ErrorModel, data: CalibrationData, earlier: LearnedResidual | None,
                       *, robot: str, cell_size_m: float = 0.4, seed: int = 0,
                       min_poses: int = MIN_STAGE_POSES, se_k: float = STAGE_SE_K,
                       weights: Sequence[float] = STAGE_WEIGHTS) -> CampaignStage:
    """Learn the campaign's own stage on the residual of ``model`` (module docstring).

    Parameters
    ----------
    model : ErrorModel
        The prior-regularised physical fit of the campaign (its BASE gives ``R_B``).
    data : CalibrationData
        The campaign (raw measurements, ``N`` poses).
    earlier : LearnedResidual or None
        The earlier calibration's layer: its arm-shape stage (if any) is the stage's
        ``prior`` (subtracted from the targets, added to every prediction).
    robot : str
        The robot's name (recorded in the layer).
    cell_size_m : float, m
        Workspace cell edge of the grouped CV.
    seed : int
        Seed of the trees.
    min_poses : int
        Fewest poses tried.
    se_k : float
        k ≥ 0 of the adoption's k-standard-error rule (module docstring; default
        :data:`STAGE_SE_K` = 0: the plain comparison of the CV means).
    weights : sequence of float
        The grid ``W`` of the stage's weight (:func:`check_weights`; default
        :data:`STAGE_WEIGHTS` = ``(1,)``: the stage whole or not at all;
        :data:`STAGE_WEIGHT_GRID` the grid measured; ``(0,)``: no stage, nothing fitted).

    Returns
    -------
    CampaignStage
        The stage, whether it is adopted and with which weight.

    Raises
    ------
    CalibrationError
        ``se_k`` negative or not finite, a bad weight grid.
    """
    se_k = check_k(se_k)
    weights = check_weights(weights)
    n = len(data)
    if max(weights) == 0.0:
        return CampaignStage(None, False, "its weight grid is {0}: no stage", se_k=se_k,
                             weights=weights)
    if n < min_poses:
        return CampaignStage(None, False, f"{n} poses, the campaign stage needs {min_poses}",
                             se_k=se_k, weights=weights)
    _, p_b = residual_targets(model, data)
    cells = int(workspace_cells(p_b, cell_size_m).max()) + 1
    if cells < 2:
        return CampaignStage(None, False, f"the poses lie in 1 workspace cell of "
                                          f"{cell_size_m:g} m: no cross-validation possible",
                             se_k=se_k, weights=weights)
    shape = None if earlier is None else earlier.shape
    learner = ResidualLearner(cell_size_m=cell_size_m, n_splits=min(5, cells),
                              grid=stage_grid(n), orientation=False, trees=max(STAGE_TREES),
                              min_poses=min_poses, seed=seed, shape_joints=())
    return judge_stage(learner.fit(model, data, robot=robot, prior=shape), weights, se_k)


def judge_stage(layer: LearnedResidual, weights: tuple[float, ...], se_k: float
                ) -> CampaignStage:
    """The weight ``w̃`` of a fitted stage and whether it is adopted (module docstring).

    Parameters
    ----------
    layer : LearnedResidual
        The stage as fitted (weight 1), its CV with targets and predictions.
    weights : tuple of float
        The checked grid ``W`` (:func:`check_weights`) with a weight > 0.
    se_k : float
        The checked k of the rule.

    Returns
    -------
    CampaignStage
        Adopted: the layer with ``weight = w̃`` (and ``useful``: the weighted stage beat
        the fit); not adopted: the layer as fitted and the reason.
    """
    cv = layer.cv
    errors = weighted_cv(cv, (0.0, *(w for w in weights if w > 0)))
    means = {w: float(e.mean()) for w, e in errors.items()}
    best = min((w for w in means if w > 0), key=lambda w: (means[w], w))
    better, mean, se = beats(errors[best], cv.physical_errors, cv.fold, se_k)
    stats = {"gain_mm": mean * 1e3, "se_mm": se * 1e3, "se_k": se_k, "weights": weights,
             "cv_mm": {w: m * 1e3 for w, m in means.items()}}
    at = "" if weights == (1.0,) else f" at weight {best:g}, the grid's best"
    cmp = f"{means[0.0] * 1e3:.3f} -> {means[best] * 1e3:.3f} mm{at}"
    if not means[best] < means[0.0]:
        return CampaignStage(layer, False, f"its grouped CV did not beat the physical fit "
                                           f"({cmp})", **stats)
    if not better:
        return CampaignStage(layer, False, f"its grouped CV gain {-mean * 1e3:.3f} mm "
                                           f"({cmp}) is within {se_k:g} standard error"
                                           f"{'' if se_k == 1 else 's'} ({se * 1e3:.3f} mm) "
                                           f"of the paired difference", **stats)
    adopted = layer if best == 1.0 else replace(layer, weight=best, useful=True)
    return CampaignStage(adopted, True, "", weight=best, **stats)
