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
campaign's workspace cells (``K = min(5, cells)``).  The stage is **adopted only when
that CV beats the physical fit with the earlier layer by more than k standard errors** on
the campaign's held-out cells — the k-standard-error rule of the candidate choice
(:func:`.se_rule.beats`) with its own ``k`` (``--prior-stage-se``, default
:data:`STAGE_SE_K` = 0)::

    d_i = ‖e_i − ê_i‖ − ‖e_i‖,     adopted ⇔ d̄ + k·SE < 0,

``SE`` the standard error of ``d̄`` clustered by the CV's folds (the stage's grouped
folds, the independent units); ``k = 0`` is the plain comparison of the means
(``LearnedResidual.useful``).  Otherwise the earlier layer stays as it was.  Where a
pose lies outside the stage's trained region (its in-domain test) the stage adds
nothing there.

Measured on the IPA UR10 (docs/results/short-campaign-ur10.md): the stage pays on
campaigns drawn at random over the new set-up's region and is (correctly) rejected by
its CV on I-optimal ones, whose few extreme poses say little about the cells between.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from plugcell.calibration.data import CalibrationData
from plugcell.calibration.model import ErrorModel
from plugcell.calibration.residual_model import (
    LearnedResidual,
    ResidualLearner,
    residual_targets,
    workspace_cells,
)
from plugcell.calibration.se_rule import beats, check_k

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

__all__ = ["MIN_STAGE_POSES", "STAGE_SE_K", "STAGE_TREES", "CampaignStage", "fit_campaign_stage",
           "stage_grid"]


@dataclass(frozen=True, eq=False)
class CampaignStage:
    """The outcome of :func:`fit_campaign_stage`.

    Attributes
    ----------
    layer : LearnedResidual or None
        The fitted stage (its ``prior`` the earlier arm-shape stage), ``None`` when not
        tried.
    adopted : bool
        The stage is used: its grouped CV beat the physical fit with the earlier layer by
        more than ``se_k`` standard errors.
    reason : str
        Why it was not tried or not adopted ("" when adopted).
    gain_mm, se_mm : float or None, mm
        When tried: the mean paired CV difference ``d̄`` (stage minus fit; negative: the
        stage helps) and its standard error clustered by fold.
    se_k : float
        The k of the rule.
    """

    layer: LearnedResidual | None
    adopted: bool
    reason: str
    gain_mm: float | None = None
    se_mm: float | None = None
    se_k: float = STAGE_SE_K

    def summary(self) -> dict[str, Any]:
        """What PARAMS.json records (``settings.prior.stage``): ``adopted``, ``reason`` and,
        when tried, the CV's physical and hybrid mean held-out errors (mm), the paired
        difference and its standard error (``gain_mm``, ``se_mm``, mm), ``se_k``, the
        cells and the chosen hyper-parameters."""
        out: dict[str, Any] = {"adopted": self.adopted, "reason": self.reason}
        if self.layer is not None:
            cv = self.layer.cv
            out.update(physical_mm=cv.physical_mm, hybrid_mm=cv.hybrid_mm,
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


def fit_campaign_stage(model: ErrorModel, data: CalibrationData, earlier: LearnedResidual | None,
                       *, robot: str, cell_size_m: float = 0.4, seed: int = 0,
                       min_poses: int = MIN_STAGE_POSES, se_k: float = STAGE_SE_K
                       ) -> CampaignStage:
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

    Returns
    -------
    CampaignStage
        The stage and whether it is adopted.

    Raises
    ------
    CalibrationError
        ``se_k`` negative or not finite.
    """
    se_k = check_k(se_k)
    n = len(data)
    if n < min_poses:
        return CampaignStage(None, False, f"{n} poses, the campaign stage needs {min_poses}")
    _, p_b = residual_targets(model, data)
    cells = int(workspace_cells(p_b, cell_size_m).max()) + 1
    if cells < 2:
        return CampaignStage(None, False, f"the poses lie in 1 workspace cell of "
                                          f"{cell_size_m:g} m: no cross-validation possible")
    shape = None if earlier is None else earlier.shape
    learner = ResidualLearner(cell_size_m=cell_size_m, n_splits=min(5, cells),
                              grid=stage_grid(n), orientation=False, trees=max(STAGE_TREES),
                              min_poses=min_poses, seed=seed, shape_joints=())
    layer = learner.fit(model, data, robot=robot, prior=shape)
    cv = layer.cv
    better, mean, se = beats(cv.hybrid_errors, cv.physical_errors, cv.fold, se_k)
    stats = {"gain_mm": mean * 1e3, "se_mm": se * 1e3, "se_k": se_k}
    if not layer.useful:
        return CampaignStage(layer, False, f"its grouped CV did not beat the physical fit "
                                           f"({cv.physical_mm:.3f} -> {cv.hybrid_mm:.3f} mm)",
                             **stats)
    if not better:
        return CampaignStage(layer, False, f"its grouped CV gain {-mean * 1e3:.3f} mm "
                                           f"({cv.physical_mm:.3f} -> {cv.hybrid_mm:.3f} mm) "
                                           f"is within {se_k:g} standard error"
                                           f"{'' if se_k == 1 else 's'} ({se * 1e3:.3f} mm) "
                                           f"of the paired difference", **stats)
    return CampaignStage(layer, True, "", **stats)

