"""A learned residual layer on top of the physical error model (hybrid model).

After the physical identification a real robot keeps an error the model's terms
do not explain (~0.4 mm on the IPA UR10).  :class:`ResidualLearner` fits that rest
as a function of the joint readings (and the temperature and payload when the
data carry them) with scikit-learn's gradient boosting, one
:class:`~sklearn.ensemble.HistGradientBoostingRegressor` per component.  The
hybrid pose is::

    p_hybrid = p_phys + R_B · e(x)          R_hybrid = Exp(R_B · φ(x)) · R_phys

with ``p_phys, R_phys`` the physical model's prediction (measurement frame),
``R_B`` the rotation of its BASE and ``e, φ`` the learned position and
orientation residuals **in the robot base frame** — so the layer transfers when
BASE (and PROBE) are re-identified after the tracker moved.  The features are
``x = (sin q, cos q[, T / 2 K][, m / 10 kg])``.

Where a pose lies outside the region of that layer (another set-up, other joint
combinations) a second, coarser stage may apply — the **arm-shape stage**
(:class:`ShapeStage`)::

    (e, φ) = R_z(q1) · s(sin q2, cos q2, sin q3, cos q3)

the residual expressed in the frame that turns with joint 1, a function of the
shoulder and elbow angles alone.  The arm above joint 1 is the same body wherever
joint 1 points and gravity lies along joint 1's axis, so an error of the arm's shape
is the same vector in that frame for the same ``q2, q3``; these two joints carry
the long levers.  What depends on ``q1`` itself, on the wrist combinations of one
campaign or on where the tracker stood is not in it.  Precedence: the full layer
where it is in domain, else the shape stage where it is in domain, else the physical
model (:attr:`ResidualPrediction.local`, :attr:`ResidualPrediction.in_domain`).

Honest validation is built in:

* hyper-parameters are chosen by **grouped** cross-validation inside the
  calibration set — the groups are contiguous cubic cells (``cell_size_m``) of
  the target position in the robot base frame, never a random split of
  near-identical poses;
* an **in-domain test**: a pose is in the trained region when its nearest
  training pose in feature space is no farther than ``threshold`` — the
  ``domain_quantile`` of the distances from held-out cells to the training poses
  of the cross-validation, i.e. the distances at which the layer was shown to
  work.  Outside, the hybrid model falls back to the physical one (and says so:
  :attr:`ResidualPrediction.in_domain`);
* if the layer does not beat the physical model on the held-out cells it is
  marked not useful and never applied.

Pure math (numpy, scikit-learn), no files: serialisation is
:mod:`plugcell.io.residual_models`.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from plugcell.calibration.data import CalibrationData
from plugcell.calibration.model import ErrorModel
from plugcell.calibration.statistics import PoseResiduals
from plugcell.kinematics.transforms import so3_exp

Array = NDArray[np.float64]

__all__ = [
    "DEFAULT_GRID",
    "MIN_POSES",
    "SHAPE_JOINTS",
    "CrossValidation",
    "LearnedResidual",
    "ResidualLearner",
    "ResidualModelError",
    "ResidualPrediction",
    "ShapeStage",
    "calibration_fingerprint",
    "check_weight",
    "from_joint1_frame",
    "hybrid_poses",
    "hybrid_residuals",
    "joint1_rotation",
    "shape_features",
    "to_joint1_frame",
    "workspace_cells",
]

#: fewest poses the learner accepts (with at least ``n_splits`` workspace cells).
MIN_POSES = 200
#: joints (0-based) of the arm-shape stage: shoulder and elbow (module docstring).
SHAPE_JOINTS = (1, 2)
#: the default hyper-parameter grid (gradient boosting, 300 trees, learning rate 0.1).
DEFAULT_GRID: tuple[dict[str, Any], ...] = (
    {"max_leaf_nodes": 15, "min_samples_leaf": 20},
    {"max_leaf_nodes": 31, "min_samples_leaf": 20},
    {"max_leaf_nodes": 15, "min_samples_leaf": 50},
    {"max_leaf_nodes": 31, "min_samples_leaf": 50},
)
_FIXED = {"max_iter": 300, "learning_rate": 0.1, "early_stopping": False}
#: feature scales: 2 K of temperature or 10 kg of payload count as one unit (≈ one radian).
TEMPERATURE_SCALE_K = 2.0
PAYLOAD_SCALE_KG = 10.0

Progress = Callable[[str], None]


class ResidualModelError(ValueError):
    """Bad input for the learned residual layer (too few poses, mismatched features…)."""


def calibration_fingerprint(model: ErrorModel) -> str:
    """A short hash of the physical model's robot parameters (every kind but BASE and PROBE).

    ``fingerprint = SHA-256(key₁ ‖ round(g₁, 15) ‖ key₂ ‖ round(g₂, 15) ‖ …)[:16 hex]`` over
    the parameters ``g_i`` of ``model.space`` whose kind is neither ``base`` nor
    ``probe``, in the order of the space (each value as its float64 bytes, rounded to 15
    decimals).  The learned layer is valid only on top of the robot model it was trained
    with; re-registering BASE/PROBE (the tracker moved, the drift watch) keeps it valid.

    Parameters
    ----------
    model : ErrorModel
        The identified physical model (its current parameter values, SI units: m, rad,
        and each parameter's own unit).

    Returns
    -------
    str
        16 hexadecimal characters.
    """
    h = hashlib.sha256()
    for p, v in zip(model.space, np.asarray(model.values, float), strict=True):
        if p.kind not in ("base", "probe"):
            h.update(p.key.encode())
            h.update(np.round(np.float64(v), 15).tobytes())
    return h.hexdigest()[:16]


def workspace_cells(points: ArrayLike, cell_size_m: float) -> Array:
    """Group index of each point: the cubic workspace cell of edge ``cell_size_m`` it lies in.

    The cell of point ``p`` is the integer triple ``c = ⌊(p − p_min) / s⌋`` (component-wise),
    ``p_min`` the component-wise minimum of ``points`` (the grid is anchored at their lower
    corner) and ``s = cell_size_m``; the occupied cells are then numbered ``0 … K−1`` in
    lexicographic order of ``c`` (empty cells get no number).

    Parameters
    ----------
    points : (N, 3) array_like, m
        Positions (the learner passes the predicted target positions in the robot base
        frame).
    cell_size_m : float, m
        Edge ``s`` of the cubic cells, > 0.

    Returns
    -------
    (N,) ndarray of int
        The cell number of each point, in ``0 … K−1`` with ``K`` the occupied cells.
    """
    p = np.asarray(points, float)
    cells = np.floor((p - p.min(axis=0)) / cell_size_m).astype(np.int64)
    _, groups = np.unique(cells, axis=0, return_inverse=True)
    return np.asarray(groups).reshape(-1)


def fold_labels(folds: Sequence[tuple[ArrayLike, ArrayLike]], n: int) -> Array:
    """The fold that holds each pose out.

    Parameters
    ----------
    folds : sequence of (train, test) index arrays
        A K-fold split of ``n`` poses (each pose in one test set).
    n : int
        Number of poses.

    Returns
    -------
    (n,) int array
        ``g`` with ``i ∈ test_g``.
    """
    fold = np.empty(n, int)
    for g, (_, te) in enumerate(folds):
        fold[te] = g
    return fold


@dataclass(frozen=True)
class CrossValidation:
    """Grouped cross-validation of the layer on the calibration set (mm, deg).

    The poses are grouped by workspace cell (:func:`workspace_cells` of the predicted
    target positions in the base frame) and split by ``GroupKFold`` into ``folds`` folds,
    so no cell is both trained and tested on.  Every pose is predicted once, by the
    regressors trained on the other folds; the error of pose i is
    ``‖e_i − ê_i‖`` (hybrid) against ``‖e_i‖`` (physical), ``e_i`` the physical residual
    in the base frame.

    Attributes
    ----------
    physical_mm : float, mm
        Mean position error ``mean_i ‖e_i‖`` of the physical model over all poses.
    hybrid_mm : float, mm
        Mean held-out position error ``mean_i ‖e_i − ê_i‖`` of the hybrid model with the
        chosen hyper-parameters (the best of ``scores``).
    physical_orientation_deg, hybrid_orientation_deg : float or None, deg
        The same for the orientation (norm of the rotation-vector residual, converted to
        degrees); ``None`` when the layer learns no orientation (3-DOF data or
        ``orientation=False``).
    folds : int
        Number of folds ``n_splits``.
    cells : int
        Number of occupied workspace cells.
    cell_size_m : float, m
        Edge of the workspace cells.
    scores : tuple of (dict, float)
        ``(hyper-parameters, hybrid_mm)`` for each candidate of the grid, in grid order.
    physical_errors, hybrid_errors : (N,) array or None, m
        Per pose, ``‖e_i‖`` and ``‖e_i − ê_i‖`` with the chosen hyper-parameters (the
        paired difference of :func:`.se_rule.beats`); ``None`` for a layer read from a
        file (not stored there).
    fold : (N,) int array or None
        The fold that held each pose out.
    targets, predictions : (N, 3) array or None, m
        Per pose, the position target ``e_i`` and its out-of-fold prediction ``ê_i``
        with the chosen hyper-parameters (so a weighted layer's CV error
        ``‖e_i − w ê_i‖`` needs no refit: :mod:`.campaign_stage`); ``None`` for a layer
        read from a file.
    """

    physical_mm: float
    hybrid_mm: float
    physical_orientation_deg: float | None
    hybrid_orientation_deg: float | None
    folds: int
    cells: int
    cell_size_m: float
    scores: tuple[tuple[dict[str, Any], float], ...]
    physical_errors: Array | None = field(default=None, compare=False, repr=False)
    hybrid_errors: Array | None = field(default=None, compare=False, repr=False)
    fold: Array | None = field(default=None, compare=False, repr=False)
    targets: Array | None = field(default=None, compare=False, repr=False)
    predictions: Array | None = field(default=None, compare=False, repr=False)

    def as_dict(self) -> dict[str, Any]:
        """The record as PARAMS.json stores it (``residual_model.cross_validation``).

        Returns
        -------
        dict
            The attributes (mm, deg, m) with ``scores`` as ``grid``: a list of
            ``{"params": dict, "hybrid_mm": float}``.
        """
        return {"physical_mm": self.physical_mm, "hybrid_mm": self.hybrid_mm,
                "physical_orientation_deg": self.physical_orientation_deg,
                "hybrid_orientation_deg": self.hybrid_orientation_deg,
                "folds": self.folds, "cells": self.cells, "cell_size_m": self.cell_size_m,
                "grid": [{"params": p, "hybrid_mm": s} for p, s in self.scores]}


@dataclass(frozen=True)
class ResidualPrediction:
    """The learned correction ``(e, φ)`` of ``N`` poses and where it applies.

    In domain means ``d(x) = min_j ‖x − x_j‖ ≤ threshold`` (nearest training pose ``x_j``
    in feature space) and a useful layer.  Precedence per pose: the full layer where
    ``local``, else the arm-shape stage (:class:`ShapeStage`) where its own test passes,
    else no correction (physical model).

    Attributes
    ----------
    correction : (N, 6) array, m and rad
        ``[e; φ]``: position correction (m) then rotation vector (rad), robot base frame;
        zero where ``in_domain`` is False (and the last three zero when the layer learns
        no orientation).  Applied by :func:`hybrid_poses`.
    in_domain : (N,) bool array
        True where the full layer or the shape stage corrects the pose.
    distance : (N,) array, feature units
        ``d(x)`` of the full layer: distance to the nearest training pose over all its
        features (``sin q, cos q[, T/2 K][, m/10 kg]``, dimensionless).
    local : (N,) bool array or None
        True where the full layer of the calibration set-up applies (the shape stage's
        correction is used where ``in_domain & ~local``); without a shape stage it
        equals ``in_domain``.  ``None`` only when built without it.
    """

    correction: Array
    in_domain: Array
    distance: Array
    local: Array | None = None

    @property
    def fallback_count(self) -> int:
        """Poses outside the trained region (physical model used)."""
        return int(np.count_nonzero(~self.in_domain))


def joint1_rotation(q1: ArrayLike) -> Array:
    """Rotations ``R_z(q1)`` about the base z axis (joint 1's axis).

    ``R_z(q) = [[cos q, −sin q, 0], [sin q, cos q, 0], [0, 0, 1]]``.

    Parameters
    ----------
    q1 : (N,) array_like or float, rad
        Joint-1 readings (flattened).

    Returns
    -------
    (N, 3, 3) ndarray
        One rotation matrix per reading.
    """
    a = np.asarray(q1, float).reshape(-1)
    c, s = np.cos(a), np.sin(a)
    R = np.zeros((len(a), 3, 3))
    R[:, 0, 0] = c
    R[:, 0, 1] = -s
    R[:, 1, 0] = s
    R[:, 1, 1] = c
    R[:, 2, 2] = 1.0
    return R


def to_joint1_frame(q1: ArrayLike, vectors: ArrayLike) -> Array:
    """Base-frame vectors expressed in the frame that turns with joint 1.

    ``v₁ = R_z(q1)ᵀ v`` for every consecutive 3-vector ``v`` of a row (position, rotation
    vector…); the inverse of :func:`from_joint1_frame`.

    Parameters
    ----------
    q1 : (N,) array_like, rad
        Joint-1 reading of each row.
    vectors : (N, 3k) array_like
        ``k`` 3-vectors per row in the robot base frame (any unit, e.g. m then rad).

    Returns
    -------
    (N, 3k) ndarray
        The same vectors in the joint-1 frame, same units.
    """
    R = joint1_rotation(q1)
    v = np.asarray(vectors, float)
    return np.hstack([np.einsum("nji,nj->ni", R, v[:, k:k + 3])
                      for k in range(0, v.shape[1], 3)])


def from_joint1_frame(q1: ArrayLike, vectors: ArrayLike) -> Array:
    """Joint-1-frame vectors back in the robot base frame (inverse of :func:`to_joint1_frame`).

    ``v = R_z(q1) v₁`` for every consecutive 3-vector ``v₁`` of a row.

    Parameters
    ----------
    q1 : (N,) array_like, rad
        Joint-1 reading of each row.
    vectors : (N, 3k) array_like
        ``k`` 3-vectors per row in the joint-1 frame (any unit, e.g. m then rad).

    Returns
    -------
    (N, 3k) ndarray
        The same vectors in the robot base frame, same units.
    """
    R = joint1_rotation(q1)
    v = np.asarray(vectors, float)
    return np.hstack([np.einsum("nij,nj->ni", R, v[:, k:k + 3])
                      for k in range(0, v.shape[1], 3)])


def shape_features(q: ArrayLike, joints: Sequence[int]) -> Array:
    """Features of the arm-shape stage: ``x_s = (sin q_J, cos q_J)`` of the joints ``J``.

    Parameters
    ----------
    q : (N, n) or (n,) array_like, rad
        Joint readings.
    joints : sequence of int
        The joints ``J`` (0-based column indices of ``q``), e.g. :data:`SHAPE_JOINTS`.

    Returns
    -------
    (N, 2·len(joints)) ndarray, dimensionless
        The sines of the selected joints, then their cosines.
    """
    qa = np.atleast_2d(np.asarray(q, float))[:, list(joints)]
    return np.hstack([np.sin(qa), np.cos(qa)])


@dataclass(frozen=True, eq=False)
class ShapeStage:
    """The transferable arm-shape stage of a :class:`LearnedResidual` (module docstring).

    The residual **in the frame that turns with joint 1** as a function of the arm's
    shape alone::

        (e, φ) = R_z(q1) · s(x_s),    x_s = (sin q_J, cos q_J)

    with ``J = joints`` (default shoulder and elbow, :data:`SHAPE_JOINTS`) and ``s`` the
    regressors, fitted on the base-frame residuals turned into the joint-1 frame
    (``R_z(q1)ᵀ e``, ``R_z(q1)ᵀ φ``).  In domain: the nearest training pose in the shape
    feature space is no farther than ``threshold``.

    Attributes
    ----------
    joints : tuple of int
        The shape joints ``J`` (0-based; joint 1, index 0, turns about the base z axis).
    estimators : tuple of regressor
        One fitted ``HistGradientBoostingRegressor`` per component of the correction in
        the joint-1 frame: 3 (position, m) or 6 (position m, then rotation vector rad).
    neighbours : sklearn.neighbors.NearestNeighbors
        Index of the training features ``x_s``.
    threshold : float, feature units (dimensionless)
        In-domain distance: the ``domain_quantile`` of the held-out-cell distances to the
        training poses in the grouped cross-validation.
    params : dict
        The chosen hyper-parameters (with the fixed ones: trees, learning rate).
    physical_mm : float, mm
        Mean position error of the physical model on the calibration poses.
    cv_mm : float, mm
        Mean held-out-cell position error with this stage alone.
    useful : bool
        ``cv_mm < physical_mm``: the stage beat the physical model on held-out cells
        (a stage that is not useful is never applied).
    """

    joints: tuple[int, ...]
    estimators: tuple[Any, ...]
    neighbours: Any
    threshold: float
    params: dict[str, Any]
    physical_mm: float
    cv_mm: float
    useful: bool

    def predict(self, q: ArrayLike) -> tuple[Array, Array, Array]:
        """The shape stage's correction ``R_z(q1) · s(sin q_J, cos q_J)`` of each pose.

        Parameters
        ----------
        q : (N, n) or (n,) array_like, rad
            Joint readings (column 0 is joint 1; ``n > max(joints)``).

        Returns
        -------
        correction : (N, k) ndarray, m and rad
            The correction in the robot base frame, ``k = len(estimators)`` (3: position
            m; 6: position m then rotation vector rad); zero outside the domain.
        in_domain : (N,) bool ndarray
            ``distance ≤ threshold`` and the stage is ``useful``.
        distance : (N,) ndarray, dimensionless
            Distance to the nearest training pose in the shape feature space.
        """
        qa = np.atleast_2d(np.asarray(q, float))
        X = shape_features(qa, self.joints)
        dist = self.neighbours.kneighbors(X, n_neighbors=1, return_distance=True)[0][:, 0]
        inside = (dist <= self.threshold) & self.useful
        corr = np.zeros((len(X), len(self.estimators)))
        if inside.any():
            from threadpoolctl import threadpool_limits

            with threadpool_limits(1):
                y = np.column_stack([est.predict(X[inside]) for est in self.estimators])
            corr[inside] = from_joint1_frame(qa[inside, 0], y)
        return corr, inside, dist

    def summary(self) -> dict[str, Any]:
        """What PARAMS.json records about the stage (no estimator state).

        Returns
        -------
        dict
            ``joints`` (1-based), ``frame`` (``"joint 1"``), ``features``, ``params``,
            ``threshold`` (dimensionless), ``physical_mm``, ``cv_mm`` (mm), ``useful``.
        """
        return {"joints": [j + 1 for j in self.joints], "frame": "joint 1",
                "features": [f"sin/cos q{j + 1}" for j in self.joints],
                "params": dict(self.params), "threshold": self.threshold,
                "physical_mm": self.physical_mm, "cv_mm": self.cv_mm, "useful": self.useful}


@dataclass(frozen=True, eq=False)
class LearnedResidual:
    """A fitted residual layer (see module docstring); built by :meth:`ResidualLearner.fit`.

    The hybrid pose (applied by :func:`hybrid_poses`)::

        p_hybrid = p_phys + R_B · e(x)          R_hybrid = Exp(R_B · φ(x)) · R_phys

    with ``(e, φ)`` the regressors' output in the robot base frame and the features
    ``x = (sin q, cos q[, T / 2 K][, m / 10 kg])`` (T the temperature in °C, m the
    payload in kg).

    Attributes
    ----------
    robot : str
        The robot's name.
    fingerprint : str
        :func:`calibration_fingerprint` of the physical model it was trained on.
    estimators : tuple of regressor
        One fitted ``HistGradientBoostingRegressor`` per component, base frame: 3
        position components (m), then 3 rotation-vector components (rad) when
        ``orientation``.
    neighbours : sklearn.neighbors.NearestNeighbors
        Index of the training features ``x``.
    threshold : float, feature units (dimensionless)
        In-domain distance: the ``domain_quantile`` of the distances from held-out cells
        to the training poses in the grouped cross-validation.
    uses_temperature, uses_payload : bool
        Whether ``T / 2 K`` and ``m / 10 kg`` are features.
    orientation : bool
        Whether the orientation residual ``φ`` is learned (6-DOF data).
    params : dict
        The chosen hyper-parameters (with the fixed ones: trees, learning rate).
    cv : CrossValidation
        The grouped cross-validation.
    useful : bool
        False when it did not beat the physical model on held-out cells: then this
        stage is never applied.  The shape stage is judged by its own held-out cells
        (it exists only when it beat the physical model there) and applies either way.
    n_poses : int
        Number of training poses.
    sklearn_version : str
        scikit-learn version that fitted it ("" when unknown).
    shape : ShapeStage or None
        The transferable arm-shape stage, used where a pose is outside this layer's
        region, or ``None``.
    prior : ShapeStage or None
        An arm-shape stage learned in another set-up (another calibration's layer of the
        same robot), applied underneath: this layer's stages were fitted on the residual
        it leaves, and every prediction adds its correction where its own in-domain test
        passes; or ``None``.
    weight : float
        The factor ``w ∈ [0, 1]`` on this layer's own regressors' correction where it
        applies (``local``): ``(e, φ) = w · ê(x)``; the shape and prior stages are not
        scaled.  1 (the default, and every layer written before the weight existed) but
        for a campaign stage shrunk by its own CV (:mod:`.campaign_stage`), whose
        ``useful`` then says that the weighted correction beat the fit on held-out cells.
    """

    robot: str
    fingerprint: str
    estimators: tuple[Any, ...]
    neighbours: Any
    threshold: float
    uses_temperature: bool
    uses_payload: bool
    orientation: bool
    params: dict[str, Any]
    cv: CrossValidation
    useful: bool
    n_poses: int
    sklearn_version: str = field(default="")
    shape: ShapeStage | None = None
    prior: ShapeStage | None = None
    weight: float = 1.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "weight", check_weight(self.weight, "the layer's weight"))

    def features(self, q: ArrayLike, payload_kg: ArrayLike | float | None = None,
                 temperature_c: ArrayLike | float | None = None) -> Array:
        """The feature matrix ``x = (sin q, cos q[, T / 2 K][, m / 10 kg])`` of each pose.

        Parameters
        ----------
        q : (N, n) or (n,) array_like, rad
            Joint readings.
        payload_kg : (N,) array_like or float, kg, optional
            Payload; required when ``uses_payload`` (ignored otherwise).
        temperature_c : (N,) array_like or float, °C, optional
            Temperature; required when ``uses_temperature`` (ignored otherwise).

        Returns
        -------
        (N, f) ndarray, dimensionless
            ``f = 2n`` (+1 with temperature, +1 with payload): sines, cosines, then
            ``T / 2`` and ``m / 10``.

        Raises
        ------
        ResidualModelError
            A feature the layer uses is missing or not finite.
        """
        return _features(q, payload_kg, temperature_c, self.uses_payload, self.uses_temperature)

    def predict(self, q: ArrayLike, payload_kg: ArrayLike | float | None = None,
                temperature_c: ArrayLike | float | None = None) -> ResidualPrediction:
        """The correction ``(e(x), φ(x))`` of each pose in the robot base frame.

        A pose is in the layer's domain when ``min_j ‖x − x_j‖ ≤ threshold`` (nearest
        training pose in feature space) and the layer is ``useful``; there the
        regressors give ``(e, φ)``.  Elsewhere (everywhere when the layer is not
        ``useful``) the shape stage's correction
        ``R_z(q1) · s(sin q_J, cos q_J)`` is used where its own test passes, else zero
        (physical model).  The regressors' ``(e, φ)`` is scaled by ``weight``.  A
        ``prior`` stage's correction is added everywhere its own test passes (the stages
        above were fitted on what it leaves).

        Parameters
        ----------
        q : (N, n) or (n,) array_like, rad
            Joint readings.
        payload_kg : (N,) array_like or float, kg, optional
            Payload; required when the layer uses it as a feature.
        temperature_c : (N,) array_like or float, °C, optional
            Temperature; required when the layer uses it as a feature.

        Returns
        -------
        ResidualPrediction
            ``correction`` (N, 6) m and rad (zero outside the trained region),
            ``in_domain`` (N,), ``distance`` (N,) in feature space, ``local`` (N,).

        Raises
        ------
        ResidualModelError
            A feature the layer uses is missing or not finite.
        """
        X = self.features(q, payload_kg, temperature_c)
        dist = self.neighbours.kneighbors(X, n_neighbors=1, return_distance=True)[0][:, 0]
        local = (dist <= self.threshold) & self.useful
        corr = np.zeros((len(X), 6))
        inside = local.copy()
        if self.shape is not None and not local.all():
            c, shape_in, _ = self.shape.predict(q)
            use = shape_in & ~local            # the set-up's own layer comes first
            corr[use, :c.shape[1]] = c[use]
            inside |= use
        if local.any():
            from threadpoolctl import threadpool_limits

            Xi = X[local]
            with threadpool_limits(1):
                for j, est in enumerate(self.estimators):
                    corr[local, j] = est.predict(Xi)
            if self.weight != 1.0:  # a shrunk campaign stage (1: the prediction untouched)
                corr[local] *= self.weight
        if self.prior is not None:
            c, prior_in, _ = self.prior.predict(q)
            corr[:, :c.shape[1]] += c
            inside |= prior_in
        return ResidualPrediction(corr, inside, dist, local)

    def summary(self) -> dict[str, Any]:
        """What PARAMS.json records about the layer (no estimator state).

        Returns
        -------
        dict
            ``kind``, ``learner``, ``robot``, ``fingerprint``, ``features`` (names),
            ``frame`` (``"robot base"``), ``orientation``, ``params``, ``threshold``
            (dimensionless), ``useful``, ``weight``, ``poses``, ``cross_validation``
            (:meth:`CrossValidation.as_dict`, mm and deg), ``sklearn_version`` and
            ``shape_stage`` and ``prior_stage`` (:meth:`ShapeStage.summary` or ``None``).
        """
        return {"kind": "learned", "learner": "sklearn.HistGradientBoostingRegressor",
                "robot": self.robot, "fingerprint": self.fingerprint,
                "features": feature_names(self.uses_payload, self.uses_temperature),
                "frame": "robot base", "orientation": self.orientation,
                "params": dict(self.params), "threshold": self.threshold,
                "useful": self.useful, "weight": self.weight, "poses": self.n_poses,
                "cross_validation": self.cv.as_dict(), "sklearn_version": self.sklearn_version,
                "shape_stage": None if self.shape is None else self.shape.summary(),
                "prior_stage": None if self.prior is None else self.prior.summary()}


def check_weight(w: Any, what: str = "weight") -> float:
    """A weight ``w ∈ [0, 1]`` of a learned correction, as a float, checked.

    Parameters
    ----------
    w : float
        The weight.
    what : str
        Its name in the error message.

    Returns
    -------
    float
        ``w``.

    Raises
    ------
    ResidualModelError
        ``w`` not a real number (a bool included), not finite, or outside [0, 1].
    """
    ok = isinstance(w, (int, float, np.integer, np.floating)) and not isinstance(w, bool)
    if not (ok and math.isfinite(w) and 0.0 <= w <= 1.0):
        raise ResidualModelError(f"{what} must be a number in [0, 1], got {w!r}")
    return float(w)


def feature_names(payload: bool, temperature: bool) -> list[str]:
    """The names of the feature groups of ``x = (sin q, cos q[, T / 2 K][, m / 10 kg])``.

    Parameters
    ----------
    payload, temperature : bool
        Whether the payload and the temperature are features.

    Returns
    -------
    list of str
        ``["sin q", "cos q"]`` then ``"temperature / 2 K"`` and ``"payload / 10 kg"``
        when used (the names :func:`~plugcell.io.residual_models.load_residual` reads).
    """
    names = ["sin q", "cos q"]
    if temperature:
        names.append(f"temperature / {TEMPERATURE_SCALE_K:g} K")
    if payload:
        names.append(f"payload / {PAYLOAD_SCALE_KG:g} kg")
    return names


def _column(x: ArrayLike | float | None, n: int, what: str) -> Array:
    if x is None:
        raise ResidualModelError(f"the residual model uses the {what}: give it for every pose")
    a = np.broadcast_to(np.asarray(x, float), (n,)).astype(float)
    if not np.all(np.isfinite(a)):
        bad = int(np.flatnonzero(~np.isfinite(a))[0])
        raise ResidualModelError(f"{what}: missing or non-finite value at pose {bad + 1}")
    return a


def _features(q: ArrayLike, payload_kg: ArrayLike | float | None,
              temperature_c: ArrayLike | float | None, payload: bool,
              temperature: bool) -> Array:
    qa = np.atleast_2d(np.asarray(q, float))
    cols = [np.sin(qa), np.cos(qa)]
    if temperature:
        cols.append(_column(temperature_c, len(qa), "temperature")[:, None] / TEMPERATURE_SCALE_K)
    if payload:
        cols.append(_column(payload_kg, len(qa), "payload")[:, None] / PAYLOAD_SCALE_KG)
    return np.hstack(cols)


def residual_targets(model: ErrorModel, data: CalibrationData) -> tuple[Array, Array]:
    """Physical residuals in the robot base frame and the predicted target positions.

    ``e = R_Bᵀ (p_M − p_P)``, ``φ = R_Bᵀ log(R_M R_Pᵀ)`` (the measurement-frame rotation
    vector turned into base-frame axes) and ``p_b = R_Bᵀ (p_P − t_B)``, with ``(R_B, t_B)``
    the model's BASE, ``P`` its prediction and ``M`` the measurement.

    Parameters
    ----------
    model : ErrorModel
        The identified physical model.
    data : CalibrationData
        ``N`` poses: joint readings (rad), measured positions (m) and, for 6-DOF data,
        rotations, payloads (kg), temperatures (°C).

    Returns
    -------
    E : (N, 3) or (N, 6) ndarray, m and rad
        ``[e, φ]`` per pose (``φ`` only for 6-DOF data).
    p_b : (N, 3) ndarray, m
        The predicted target positions in the robot base frame.
    """
    P = model.predict(data.q, data.payload_kg, data.temperature_c)
    dp, dphi = _measured_minus(data, P)
    B = model.base()
    Rb = B[:3, :3]
    E = dp @ Rb if dphi is None else np.hstack([dp @ Rb, dphi @ Rb])
    p_b = (P[:, :3, 3] - B[:3, 3]) @ Rb
    return E, p_b


def _measured_minus(data: CalibrationData, P: Array) -> tuple[Array, Array | None]:
    """Δp and the spatial rotation vector ``log(R_M R_Pᵀ)`` (measurement frame)."""
    from plugcell.kinematics import pose_error_exact

    if data.six_dof:
        e = pose_error_exact(data.poses, P)
        return e[:, :3], e[:, 3:]
    return data.positions - P[:, :3, 3], None


def hybrid_poses(poses: ArrayLike, base_rotation: ArrayLike, correction: ArrayLike) -> Array:
    """Apply a base-frame correction to physical poses: the hybrid pose.

    ``p_hybrid = p_phys + R_B · e``, ``R_hybrid = Exp(R_B · φ) · R_phys`` (module
    docstring), ``Exp`` the SO(3) exponential of a rotation vector.

    Parameters
    ----------
    poses : (N, 4, 4) array_like, m
        Physical model's predicted target poses, measurement frame.
    base_rotation : (3, 3) array_like
        ``R_B``, the rotation of the model's BASE (base frame → measurement frame).
    correction : (N, 6) array_like, m and rad
        ``[e; φ]`` in the robot base frame (:attr:`ResidualPrediction.correction`).

    Returns
    -------
    (N, 4, 4) ndarray, m
        The hybrid poses (a new array; ``poses`` is not modified).
    """
    T = np.array(poses, dtype=float, copy=True)
    Rb = np.asarray(base_rotation, float)
    c = np.asarray(correction, float)
    T[:, :3, 3] += c[:, :3] @ Rb.T
    if np.any(c[:, 3:]):
        T[:, :3, :3] = so3_exp(c[:, 3:] @ Rb.T) @ T[:, :3, :3]
    return T


class ResidualLearner:
    """Fits a :class:`LearnedResidual` on the residuals of a physical model.

    Gradient boosting (one ``HistGradientBoostingRegressor`` per component) of the
    base-frame residual ``(e, φ)`` on the features ``x = (sin q, cos q[, T / 2 K][, m / 10
    kg])``, hyper-parameters chosen by cross-validation grouped by workspace cell
    ``⌊(p_b − p_min) / cell_size_m⌋`` (:meth:`fit`).

    Parameters
    ----------
    cell_size_m : float
        Edge of the workspace cells that group poses for cross-validation (m).
    n_splits : int
        Folds of the grouped cross-validation (the data need at least as many cells).
    grid : sequence of dict
        Candidate hyper-parameters of ``HistGradientBoostingRegressor`` (merged with
        300 trees, learning rate 0.1, no early stopping); default :data:`DEFAULT_GRID`.
    domain_quantile : float
        Quantile of the held-out-cell distances that bounds the trained region.
    orientation : bool
        Also learn the orientation residual (6-DOF data only).
    use_temperature, use_payload : bool or None
        Features; ``None``: use the temperature when the data carry it and the payload
        when it varies in the data.
    trees : int
        Boosting iterations of every regressor (default 300).
    min_poses : int
        Fewest poses accepted (:data:`MIN_POSES`).
    seed : int
        Seed of the regressors (deterministic).
    n_threads : int
        OpenMP threads of the regressors (default 1: on a shared machine
        scikit-learn's default — every core — was measured 15× slower than one thread).
    shape_joints : sequence of int
        Joints (0-based) of the transferable arm-shape stage (:class:`ShapeStage`,
        default shoulder and elbow ``(1, 2)``; joint 1 must turn about the base z axis);
        ``()``: no shape stage (the layer of format 1).
    progress : callable, optional
        Called with a line of text per stage.

    Raises
    ------
    ResidualModelError
        ``cell_size_m`` not a positive finite length, ``n_splits < 2``,
        ``domain_quantile`` outside (0, 1], an empty grid, ``trees < 1``,
        ``n_threads < 1`` or a shape joint before joint 2 (0-based index < 1).
    """

    def __init__(self, *, cell_size_m: float = 0.4, n_splits: int = 5,
                 grid: Sequence[Mapping[str, Any]] = DEFAULT_GRID,
                 domain_quantile: float = 0.95, orientation: bool = True,
                 use_temperature: bool | None = None, use_payload: bool | None = None,
                 trees: int = 300, min_poses: int = MIN_POSES, seed: int = 0,
                 n_threads: int = 1, shape_joints: Sequence[int] = SHAPE_JOINTS,
                 progress: Progress | None = None) -> None:
        if not (cell_size_m > 0 and math.isfinite(cell_size_m)):
            raise ResidualModelError(f"cell size must be > 0 m, got {cell_size_m}")
        if n_splits < 2:
            raise ResidualModelError(f"n_splits must be at least 2, got {n_splits}")
        if not 0 < domain_quantile <= 1:
            raise ResidualModelError(f"domain quantile must be in (0, 1], got {domain_quantile}")
        if not grid:
            raise ResidualModelError("empty hyper-parameter grid")
        if trees < 1:
            raise ResidualModelError(f"trees must be at least 1, got {trees}")
        self.trees = int(trees)
        if n_threads < 1:
            raise ResidualModelError(f"n_threads must be at least 1, got {n_threads}")
        self.n_threads = int(n_threads)
        self.cell_size_m = float(cell_size_m)
        self.n_splits = int(n_splits)
        self.grid = tuple(dict(g) for g in grid)
        self.domain_quantile = float(domain_quantile)
        self.orientation = orientation
        self.use_temperature = use_temperature
        self.use_payload = use_payload
        self.min_poses = int(min_poses)
        self.seed = int(seed)
        self.shape_joints = tuple(int(j) for j in shape_joints)
        if any(j < 1 for j in self.shape_joints):
            raise ResidualModelError("shape_joints: joints after joint 1 (0-based index ≥ 1), "
                                     f"got {shape_joints}")
        self.progress = progress

    def _say(self, text: str) -> None:
        if self.progress is not None:
            self.progress(text)

    def _regressor(self, params: Mapping[str, Any]) -> Any:
        from sklearn.ensemble import HistGradientBoostingRegressor

        return HistGradientBoostingRegressor(
            random_state=self.seed, **{**_FIXED, "max_iter": self.trees, **params})

    def fit(self, model: ErrorModel, data: CalibrationData, *, robot: str = "",
            prior: ShapeStage | None = None) -> LearnedResidual:
        """Learn the residual of ``model`` (an identified physical model) on ``data``.

        The targets are the physical residuals in the base frame ``e = R_Bᵀ Δp``,
        ``φ = R_Bᵀ Δφ`` (:func:`residual_targets`), the features
        ``x = (sin q, cos q[, T / 2 K][, m / 10 kg])``.  The poses are grouped by
        workspace cell ``⌊(p_b − p_min) / cell_size_m⌋`` of their predicted base-frame
        position and split by ``GroupKFold(n_splits)``; each grid candidate is scored by
        the mean held-out position error ``mean ‖e − ê‖`` and the best one is refitted
        on all poses.  The in-domain threshold is the ``domain_quantile`` of the
        distances from each held-out pose to the nearest training pose of its fold; the
        layer is ``useful`` when its held-out error is below ``mean ‖e‖``.  The arm-shape
        stage (:class:`ShapeStage`) is fitted on the same folds and kept only when useful.

        Parameters
        ----------
        model : ErrorModel
            The identified physical model (its BASE gives ``R_B``).
        data : CalibrationData
            ``N ≥ min_poses`` calibration poses: joint readings ``(N, n)`` (rad), measured
            positions ``(N, 3)`` (m) and, for 6-DOF data, rotations ``(N, 3, 3)``,
            payloads ``(N,)`` (kg), temperatures ``(N,)`` (°C) or None.
        robot : str
            The robot's name, recorded in the layer.
        prior : ShapeStage, optional
            An arm-shape stage learned in another set-up of the same robot (another
            calibration's ``LearnedResidual.shape``): the targets become what it leaves,
            ``e − c_prior(q)``, and the layer carries it (:attr:`LearnedResidual.prior`).
            Its cross-validation's "physical" figure is then the physical model with the
            prior stage.

        Returns
        -------
        LearnedResidual
            The fitted layer with its cross-validation (and shape stage, or None).

        Raises
        ------
        ResidualModelError
            Too few poses (the message says how many are needed), too few workspace
            cells for the folds, or an incomplete temperature/payload column.
        """
        # threadpoolctl limits the thread pools loaded when the limit is entered: load
        # scikit-learn's (OpenMP, BLAS) first, or a first fit in a process runs on all cores
        import importlib

        from threadpoolctl import threadpool_limits

        for module in ("sklearn.ensemble", "sklearn.neighbors"):
            importlib.import_module(module)

        with threadpool_limits(self.n_threads):
            return self._fit(model, data, robot, prior)

    def check_poses(self, n: int) -> None:
        """Refuse ``n`` calibration poses if too few to learn from (before any work).

        Parameters
        ----------
        n : int
            Number of calibration poses.

        Raises
        ------
        ResidualModelError
            ``n < min_poses``, with the numbers.
        """
        if n < self.min_poses:
            raise ResidualModelError(
                f"too few poses to learn the residual from: {n}, at least {self.min_poses} "
                f"needed (spread over at least {self.n_splits} cells of {self.cell_size_m:g} m)")

    def _fit(self, model: ErrorModel, data: CalibrationData, robot: str,
             prior: ShapeStage | None = None) -> LearnedResidual:
        import sklearn
        from sklearn.model_selection import GroupKFold
        from sklearn.neighbors import NearestNeighbors

        n = len(data)
        self.check_poses(n)
        temp = data.temperature_c is not None if self.use_temperature is None \
            else self.use_temperature
        if temp and data.temperature_c is None:
            raise ResidualModelError("temperature requested as a feature but the data have no "
                                     "temperature column")
        pay = bool(np.ptp(data.payload_kg) > 0) if self.use_payload is None else self.use_payload
        X = _features(data.q, data.payload_kg, data.temperature_c, pay, temp)
        E, p_b = residual_targets(model, data)
        if prior is not None:  # learn what the other set-up's arm-shape stage leaves
            c, _, _ = prior.predict(data.q)
            k = min(c.shape[1], E.shape[1])
            E = E.copy()
            E[:, :k] -= c[:, :k]
        k_pos = 3
        n_out = 6 if (self.orientation and E.shape[1] == 6) else 3
        groups = workspace_cells(p_b, self.cell_size_m)
        n_cells = int(groups.max()) + 1
        if n_cells < self.n_splits:
            raise ResidualModelError(
                f"the poses span {n_cells} workspace cell(s) of {self.cell_size_m:g} m; the "
                f"grouped cross-validation needs at least {self.n_splits}: spread the poses "
                "wider or use smaller cells")
        folds = list(GroupKFold(n_splits=self.n_splits).split(X, E, groups))
        phys_norm = np.linalg.norm(E[:, :k_pos], axis=1)
        # stage 1 (transferable): the residual in the joint-1 frame of the arm's shape
        shape: ShapeStage | None = None
        if self.shape_joints and data.q.shape[1] > max(self.shape_joints):
            shape = self._fit_shape(data.q, E[:, :n_out], folds, phys_norm)
            if not shape.useful:  # no gain on held-out cells: not used
                shape = None
        scores: list[tuple[dict[str, Any], float]] = []
        best: tuple[float, dict[str, Any], Array] | None = None
        for i, params in enumerate(self.grid):
            pred = np.zeros((n, k_pos))
            for tr, te in folds:
                for j in range(k_pos):
                    pred[te, j] = self._regressor(params).fit(X[tr], E[tr, j]).predict(X[te])
            score = float(np.linalg.norm(E[:, :k_pos] - pred, axis=1).mean())
            scores.append((dict(params), score * 1e3))
            self._say(f"grouped {self.n_splits}-fold CV {i + 1}/{len(self.grid)} {params}: "
                      f"{phys_norm.mean() * 1e3:.3f} -> {score * 1e3:.3f} mm")
            if best is None or score < best[0]:
                best = (score, dict(params), pred)
        assert best is not None
        score, params, pred = best
        ori_phys = ori_hyb = None
        if n_out == 6:
            pred_o = np.zeros((n, 3))
            for tr, te in folds:
                for j in range(3):
                    pred_o[te, j] = self._regressor(params).fit(X[tr], E[tr, 3 + j]).predict(X[te])
            ori_phys = math.degrees(float(np.linalg.norm(E[:, 3:], axis=1).mean()))
            ori_hyb = math.degrees(float(np.linalg.norm(E[:, 3:] - pred_o, axis=1).mean()))
        threshold = self._domain_threshold(X, folds)
        self._say(f"fitting {n_out} regressors on {n} poses with {params}")
        estimators = tuple(self._regressor(params).fit(X, E[:, j]) for j in range(n_out))
        cv = CrossValidation(physical_mm=float(phys_norm.mean() * 1e3), hybrid_mm=score * 1e3,
                             physical_orientation_deg=ori_phys, hybrid_orientation_deg=ori_hyb,
                             folds=self.n_splits, cells=n_cells, cell_size_m=self.cell_size_m,
                             scores=tuple(scores), physical_errors=phys_norm,
                             hybrid_errors=np.linalg.norm(E[:, :k_pos] - pred, axis=1),
                             fold=fold_labels(folds, n), targets=E[:, :k_pos].copy(),
                             predictions=pred)
        return LearnedResidual(
            robot=robot, fingerprint=calibration_fingerprint(model), estimators=estimators,
            neighbours=NearestNeighbors(n_neighbors=1).fit(X), threshold=threshold,
            uses_temperature=temp, uses_payload=pay, orientation=n_out == 6,
            params={**_FIXED, "max_iter": self.trees, **params},
            cv=cv, useful=score < float(phys_norm.mean()), n_poses=n,
            sklearn_version=sklearn.__version__, shape=shape, prior=prior)

    def _domain_threshold(self, X: Array, folds: list[tuple[Array, Array]]) -> float:
        """The in-domain threshold: the ``domain_quantile`` of how far each held-out pose
        lay from the nearest training pose of its fold, in feature space.

        Parameters
        ----------
        X : (N, F) array
            The features of the poses.
        folds : list of (train, test) index arrays
            The grouped CV's folds.

        Returns
        -------
        float
            The threshold distance (feature units).
        """
        from sklearn.neighbors import NearestNeighbors

        dist = np.empty(len(X))
        for tr, te in folds:
            nn = NearestNeighbors(n_neighbors=1).fit(X[tr])
            dist[te] = nn.kneighbors(X[te])[0][:, 0]
        return float(np.quantile(dist, self.domain_quantile))

    def _fit_shape(self, q: ArrayLike, E: Array, folds: list[tuple[Array, Array]],
                   phys_norm: Array) -> ShapeStage:
        """The arm-shape stage on the cell folds: its hyper-parameters (the grid, held-out
        position error) and its threshold (the ``domain_quantile`` of the held-out
        distances in its feature space)."""
        from sklearn.neighbors import NearestNeighbors

        qa = np.asarray(q, float)
        n, n_out = E.shape
        Xs = shape_features(qa, self.shape_joints)
        Y = to_joint1_frame(qa[:, 0], E)
        best: tuple[float, dict[str, Any]] | None = None
        for params in self.grid:
            pred = np.zeros((n, 3))
            for tr, te in folds:
                for j in range(3):
                    pred[te, j] = self._regressor(params).fit(Xs[tr], Y[tr, j]).predict(Xs[te])
            pred = from_joint1_frame(qa[:, 0], pred)
            score = float(np.linalg.norm(E[:, :3] - pred, axis=1).mean())
            self._say(f"shape stage (sin/cos q{', q'.join(str(j + 1) for j in self.shape_joints)}"
                      f", joint-1 frame) {params}: {phys_norm.mean() * 1e3:.3f} -> "
                      f"{score * 1e3:.3f} mm")
            if best is None or score < best[0]:
                best = (score, dict(params))
        assert best is not None
        score, params = best
        dist = np.empty(n)
        for tr, te in folds:
            dist[te] = NearestNeighbors(n_neighbors=1).fit(Xs[tr]).kneighbors(Xs[te])[0][:, 0]
        estimators = tuple(self._regressor(params).fit(Xs, Y[:, j]) for j in range(n_out))
        stage = ShapeStage(
            joints=self.shape_joints, estimators=estimators,
            neighbours=NearestNeighbors(n_neighbors=1).fit(Xs),
            threshold=float(np.quantile(dist, self.domain_quantile)),
            params={**_FIXED, "max_iter": self.trees, **params},
            physical_mm=float(phys_norm.mean() * 1e3), cv_mm=score * 1e3,
            useful=score < float(phys_norm.mean()))
        return stage


def _remove_correction(data: CalibrationData, base_rotation: Array,
                       correction: Array) -> CalibrationData:
    """The measurements with a base-frame correction taken out (for re-identifying
    BASE/PROBE under the hybrid model)."""
    Rb = base_rotation
    p = data.positions - correction[:, :3] @ Rb.T
    R = None
    if data.rotations is not None:
        R = so3_exp(-(correction[:, 3:] @ Rb.T)) @ data.rotations
    return CalibrationData(data.q, p, R, data.payload_kg, data.temperature_c)


def hybrid_residuals(model: ErrorModel, layer: LearnedResidual, data: CalibrationData, *,
                     refit_base: bool = False, refit_probe: bool = False,
                     rotation_weight: float = 1.0, refit_positions_only: bool = False
                     ) -> tuple[PoseResiduals, ResidualPrediction]:
    """Physical vs hybrid residual of every pose of ``data`` (validation poses, never training).

    ``before = p_M − p_phys``, ``after = p_M − p_hybrid`` with
    ``p_hybrid = p_phys' + R_B' · e(x)``, ``R_hybrid = Exp(R_B' · φ(x)) · R_phys'``
    (:func:`hybrid_poses`).  Without refit the primed model is ``model``.  With
    ``refit_base`` BASE (and PROBE) are re-identified on ``data`` (tracker moved): for the
    physical model on the raw measurements, for the hybrid one on the measurements with
    the learned correction taken out (``p_M − R_B·e``, ``Exp(−R_B·φ)·R_M``, ``R_B`` of the
    physical refit), so that neither absorbs the other's terms.

    Parameters
    ----------
    model : ErrorModel
        The identified physical model the layer was trained on.
    layer : LearnedResidual
        The learned residual layer.
    data : CalibrationData
        ``N`` poses: joint readings ``(N, n)`` (rad), measured positions ``(N, 3)`` (m),
        rotations ``(N, 3, 3)`` or None, payloads ``(N,)`` (kg), temperatures ``(N,)``
        (°C) or None.
    refit_base : bool
        Re-identify BASE on ``data`` for both models.
    refit_probe : bool
        Also re-identify PROBE (with ``refit_base``).
    rotation_weight : float, m/rad
        Weight ``w`` of the orientation in the refit, ``Σ ‖Δp‖² + w² ‖Δφ‖²``
        (:func:`~plugcell.calibration.identify.refit_base`).
    refit_positions_only : bool
        Refit on the positions only (as in
        :func:`~plugcell.calibration.identify.refit_base`).

    Returns
    -------
    residuals : PoseResiduals
        ``before`` = the physical model, ``after`` = the hybrid model, ``(N, 3)`` m
        (orientations ``(N, 3)`` rad for 6-DOF data).
    prediction : ResidualPrediction
        The layer's prediction on ``data`` (``in_domain`` says where it fell back to
        the physical model).

    Raises
    ------
    ResidualModelError
        A feature the layer uses (temperature, payload) is missing from ``data``.
    """
    # identify imports this module (through result.py): the circle is broken
    # here, where the refit is needed
    from plugcell.calibration.identify import refit_base as _refit

    opts = {"probe": refit_probe, "rotation_weight": rotation_weight,
            "positions_only": refit_positions_only}
    pred = layer.predict(data.q, data.payload_kg, data.temperature_c)
    phys = _refit(model, data, **opts) if refit_base else model
    hyb = phys
    if refit_base and pred.in_domain.any():
        hyb = _refit(model, _remove_correction(data, phys.base()[:3, :3], pred.correction),
                     **opts)
    P_phys = phys.predict(data.q, data.payload_kg, data.temperature_c)
    P_hyb = hybrid_poses(hyb.predict(data.q, data.payload_kg, data.temperature_c),
                         hyb.base()[:3, :3],
                         pred.correction)
    return PoseResiduals.from_poses(data, P_phys, P_hyb), pred

