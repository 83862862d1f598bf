"""Planning a calibration campaign: which poses to measure (optimal experiment design).

Every pose of a campaign costs robot and tracker time, and where the poses lie decides
how well the parameters are determined and where the calibrated model can be trusted.
This module chooses ``n`` poses out of a set of *candidates* so that an optimality
criterion of the identification Jacobian is best.  Pure math: numpy, SI units, no I/O.

**Candidates** (:func:`sample_candidates`, :func:`filter_candidates`): joint readings
inside the joint and coupled limits whose nominal target lies in the working volume and
whose reflector the tracker can see — the target's facing axis ``a`` (target frame,
T-MAC: ``z``) within the acceptance angle ``γ`` of the direction to the tracker ``t``::

    angle(R_target a, t − p_target) ≤ γ

Each configuration is offered with every payload of the campaign (model 5 needs
several payloads to separate payload from gravity compliance, thesis 8.2.3).

**Information** of a set S of poses, in the identification's units::

    M(S) = Σ_{c ∈ S} X_cᵀ X_c,    X_c = W H_c diag(1/s)

``H_c`` ``(6, k)``: the analytic identification Jacobian (:mod:`.jacobian`) at the
nominal model; ``W``: the identification's row weights (orientation rows × the rotation
weight; position-only data keep the 3 position rows); ``s``: the identification's column
scaling (unit-norm columns, eq. 4.8), taken over the whole candidate set and per pose —
``s_j = ‖H_{:,j}‖ / √C`` over the C candidates — so that parameters in m, rad and
rad/(N·m) compare and the criterion does not depend on the units.  (Scaling by the
*chosen* set's own column norms would make the criterion blind to how strongly a
parameter is excited; D-optimality does not depend on the scaling at all.)

**Criteria** (all maximised; ``λ`` the eigenvalues of ``M/n``)::

    D:  (1/k) log det(M/n)                      (the parameters' confidence volume)
    A:  −trace((M/n)⁻¹)                         (the mean parameter variance)
    E:  λ_min                                   (the worst-determined direction)
    O:  λ_min / √λ_max                          (noise amplification index O4,
                                                 Nahvi & Hollerbach 1996)
    I:  −trace(W (M/n)⁻¹),  W = Σ_c X_cᵀX_c / C  (the mean prediction variance of a pose
                                                 over all candidates, ×n/σ²)

I ("integrated", or V-optimal) asks directly for what a validation measures: how well
the calibrated model predicts poses *where the robot works* — the candidates stand for
that region.  It does not depend on the column scaling at all, and on the twin it gives
the best validation accuracy of the five (docs/planning.md), so it is the default of
``plugcell plan``; D, A, E, O are the classical criteria of the calibration literature.

**Search** (:class:`PosePlanner`): a greedy start (each step adds the candidate with the
largest D-gain ``log det(I + X_c M⁻¹ X_cᵀ)``, from a small ridge ``εI``) and then exchange
excursions in the manner of DETMAX (Mitchell 1974): add the best candidate, then remove
the pose whose removal leaves the best criterion — stop when that is the pose just added.
Since removing the added pose gives back the previous design, an excursion never worsens
the criterion.  Adding or removing a pose is a rank-``r`` update (``r`` = 6 or 3 rows)::

    (M ± XᵀX)⁻¹ = M⁻¹ ∓ M⁻¹Xᵀ (I ± X M⁻¹ Xᵀ)⁻¹ X M⁻¹
    det(M ± XᵀX) = det M · det(I ± X M⁻¹ Xᵀ)

so the dispersions ``D_c = X_c M⁻¹ X_cᵀ`` (and for A ``T_c = X_c M⁻² X_cᵀ``) of all
candidates are updated with a few matrix products, never re-factorised per candidate.
For E and O (eigenvalues) the candidates to add are short-listed by their D-gain and the
short list is evaluated exactly.

**Prediction**: with a measurement noise σ per row, the parameter covariance is
``σ² (HᵀH)⁻¹`` (8.4) — the predicted standard deviations of :class:`CampaignPlan` —
and its condition number the κ (4.10) the identification will report, computed with the
identification's own scaling (unit-norm columns of the chosen poses).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from plugcell.calibration.identifiability import analyse
from plugcell.calibration.jacobian import identification_jacobian
from plugcell.calibration.model import ErrorModel
from plugcell.kinematics import Box

Array = NDArray[np.float64]

#: The optimality criteria :class:`PosePlanner` knows.
CRITERIA: tuple[str, ...] = ("D", "A", "E", "O", "I")
#: Default measurement noise per row (m, or m-equivalent for orientation rows): the
#: unmodelled residual a calibrated robot keeps (thesis 8.2: ~0.1 mm).
DEFAULT_NOISE_M = 1e-4
#: Ridge of the greedy start, relative to one pose's information (per-pose unit scaling).
GREEDY_RIDGE = 1e-6
#: Ridge kept during the exchange, relative to the mean diagonal of M: keeps M⁻¹ finite
#: for a design that does not (yet) excite every parameter; negligible otherwise.
EXCHANGE_RIDGE = 1e-10
#: Short list of candidates evaluated exactly for the eigenvalue criteria E and O.
SHORTLIST = 24
#: Dispersions are recomputed from scratch after this many rank-r updates (round-off).
REFRESH_EVERY = 16

__all__ = [
    "CRITERIA",
    "DEFAULT_NOISE_M",
    "CampaignPlan",
    "Candidates",
    "PlanningError",
    "PosePlanner",
    "Visibility",
    "criterion_value",
    "filter_candidates",
    "joint_tour",
    "planning_keys",
    "sample_candidates",
]


class PlanningError(ValueError):
    """A campaign that cannot be planned (no candidate visible, too few candidates, …)."""


# ---------------------------------------------------------------------- candidates
@dataclass(frozen=True)
class Visibility:
    """Where the tracker stands and what it can see: ``angle(R a, t − p) ≤ γ``.

    Attributes
    ----------
    tracker_position : (float, float, float), m
        The tracker's head ``t`` in the robot base frame.
    acceptance_rad : float, rad
        γ, the largest angle between the target's facing axis and the direction to
        the tracker (T-MAC: about ±45°); in (0, π].
    facing_axis : (float, float, float)
        That axis ``a`` in the target (PROBE) frame (need not be unit).

    Raises
    ------
    PlanningError
        Non-finite position, a zero axis or γ outside (0, π].
    """

    tracker_position: tuple[float, float, float]
    acceptance_rad: float
    facing_axis: tuple[float, float, float] = (0.0, 0.0, 1.0)

    def __post_init__(self) -> None:
        t = np.asarray(self.tracker_position, dtype=float)
        a = np.asarray(self.facing_axis, dtype=float)
        if t.shape != (3,) or not np.all(np.isfinite(t)):
            raise PlanningError(f"tracker position must be 3 finite numbers, got {t.tolist()}")
        if a.shape != (3,) or not np.all(np.isfinite(a)) or np.linalg.norm(a) == 0:
            raise PlanningError(f"facing axis must be a non-zero 3-vector, got {a.tolist()}")
        if not (np.isfinite(self.acceptance_rad) and 0 < self.acceptance_rad <= np.pi):
            raise PlanningError(
                f"line-of-sight acceptance must be in (0°, 180°], got "
                f"{np.degrees(self.acceptance_rad):g}°")

    def angles(self, targets: Array) -> Array:
        """Angle between each target's facing axis and the direction to the tracker.

        ``angle_i = acos((R_i â)·(t − p_i) / ‖t − p_i‖)``.

        Parameters
        ----------
        targets : (N, 4, 4) array, m
            Target poses in the robot base frame.

        Returns
        -------
        (N,) array, rad
            Angles in [0, π].
        """
        a = np.asarray(self.facing_axis, dtype=float)
        facing = targets[:, :3, :3] @ (a / np.linalg.norm(a))
        to_tracker = np.asarray(self.tracker_position) - targets[:, :3, 3]
        dist = np.linalg.norm(to_tracker, axis=1)
        cos = np.einsum("ij,ij->i", facing, to_tracker) / np.maximum(dist, 1e-12)
        return np.arccos(np.clip(cos, -1.0, 1.0))

    def visible(self, targets: Array) -> NDArray[np.bool_]:
        """Whether the tracker sees each target, ``angle_i ≤ γ``.

        Parameters
        ----------
        targets : (N, 4, 4) array, m
            Target poses in the robot base frame.

        Returns
        -------
        (N,) bool array
            Visible targets.
        """
        return self.angles(targets) <= self.acceptance_rad


@dataclass(frozen=True, eq=False)
class Candidates:
    """Poses a plan may choose from.

    Attributes
    ----------
    q : (C, n) array, rad
        Joint readings.
    payload_kg : (C,) array, kg
        Payload of each candidate.
    targets : (C, 3) array, m
        Nominal target positions in the robot base frame.
    source : (C,) int array
        The row of the configuration each came from (for ``--from``).
    dropped : dict of str to int
        How many given configurations each test left out (:func:`filter_candidates`:
        ``limits``, ``volume``, ``line of sight``; 0s omitted), and ``given``: how many
        there were.  Empty for drawn candidates.
    """

    q: Array
    payload_kg: Array
    targets: Array
    source: NDArray[np.int64]
    dropped: dict[str, int] = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.q.shape[0])

    def subset(self, index: ArrayLike) -> Candidates:
        """The candidates at ``index``.

        Parameters
        ----------
        index : array_like of int or bool
            Rows (or a mask) to keep.

        Returns
        -------
        Candidates
            The subset.
        """
        i = np.asarray(index)
        return Candidates(self.q[i], self.payload_kg[i], self.targets[i], self.source[i])


def _payload_list(payloads: Sequence[float]) -> Array:
    m = np.unique(np.asarray(list(payloads), dtype=float))
    if m.size == 0 or not np.all(np.isfinite(m)) or np.any(m < 0):
        raise PlanningError(f"payloads must be masses ≥ 0 kg, got {list(payloads)}")
    return m


def _robot_frame(model: ErrorModel) -> ErrorModel:
    """``model`` measured in the robot base frame (BASE = identity), for geometry tests."""
    return model.with_references(base=np.eye(4))


def _feasible(model: ErrorModel, q: Array, volume: Box | None,
              visibility: Visibility | None) -> tuple[NDArray[np.bool_], Array, dict[str, int]]:
    """Mask of configurations whose target is in ``volume`` and visible; the targets
    ``(N, 4, 4)`` and how many each test rejected."""
    desc = model.structure.source
    ok = desc.within_limits(q)
    counts = {"limits": int(np.count_nonzero(~ok))}
    T = np.broadcast_to(np.eye(4), (len(q), 4, 4)).copy()
    if np.any(ok):
        T[ok] = _robot_frame(model).predict(q[ok])
    if volume is not None:
        inside = volume.contains(T[:, :3, 3])
        counts["volume"] = int(np.count_nonzero(ok & ~inside))
        ok &= inside
    if visibility is not None:
        vis = visibility.visible(T)
        counts["line of sight"] = int(np.count_nonzero(ok & ~vis))
        ok &= vis
    return ok, T, counts


def _crossed(q: Array, payloads: Array, targets: Array, source: Array) -> Candidates:
    """Each configuration with each payload (configurations outer, payloads inner)."""
    p = len(payloads)
    return Candidates(
        q=np.repeat(q, p, axis=0), payload_kg=np.tile(payloads, len(q)),
        targets=np.repeat(targets, p, axis=0), source=np.repeat(source, p).astype(np.int64))


def _why(counts: dict[str, int], total: int) -> str:
    return ", ".join(f"{v} outside the {k}" for k, v in counts.items() if v) or \
        f"{total} drawn"


def filter_candidates(model: ErrorModel, q: ArrayLike, *, payloads: Sequence[float] = (0.0,),
                      payload_kg: ArrayLike | None = None, volume: Box | None = None,
                      visibility: Visibility | None = None) -> Candidates:
    """Candidates from given configurations: a file of allowed configurations or of poses
    already measured.

    Those outside the limits, the ``volume`` or the line of sight
    (``angle(R a, t − p) ≤ γ``) are left out.

    Parameters
    ----------
    model : ErrorModel
        The model (nominal targets are predicted with BASE = I, robot base frame).
    q : (N, n) array_like, rad
        Joint readings.
    payloads : sequence of float, kg
        Each configuration is offered with every one of these (unless ``payload_kg``).
    payload_kg : (N,) array_like, kg, optional
        Each configuration's own payload (poses already measured).
    volume : Box, optional
        Working volume the target must lie in (robot base frame, m).
    visibility : Visibility, optional
        The tracker's line of sight.

    Returns
    -------
    Candidates
        The usable configurations (× payloads).

    Raises
    ------
    PlanningError
        Wrong number of joints, a malformed ``payload_kg`` or ``payloads``, or none left
        (the message says which test removed them).
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    n = model.structure.n_readings
    if q.shape[1] != n:
        raise PlanningError(f"configurations have {q.shape[1]} joints, the robot has {n}")
    ok, T, counts = _feasible(model, q, volume, visibility)
    if not np.any(ok):
        raise PlanningError(f"none of the {len(q)} configurations is usable: "
                            f"{_why(counts, len(q))}")
    idx = np.flatnonzero(ok)
    if payload_kg is not None:
        m = np.asarray(payload_kg, dtype=float)
        if m.shape != (len(q),):
            raise PlanningError(f"payload_kg must be ({len(q)},), got {m.shape}")
        return Candidates(q[idx], m[idx], T[idx, :3, 3], idx.astype(np.int64),
                          dropped={"given": len(q), **{k: v for k, v in counts.items() if v}})
    crossed = _crossed(q[idx], _payload_list(payloads), T[idx, :3, 3], idx)
    crossed.dropped.update({"given": len(q), **{k: v for k, v in counts.items() if v}})
    return crossed


def sample_candidates(model: ErrorModel, count: int, *, payloads: Sequence[float] = (0.0,),
                      volume: Box | None = None, visibility: Visibility | None = None,
                      seed: int = 0, max_draws: int = 2_000_000, chunk: int = 20_000,
                      give_up: int = 100_000) -> Candidates:
    """About ``count`` candidates: configurations uniform in joint space over the feasible
    set (joint and coupled limits, target in ``volume``, visible), each with every payload.

    Rejection sampling: a first chunk is drawn within the joint limits; later chunks are
    drawn in the joint-space bounding box of the accepted ones widened by a quarter of the
    limit range on each side (clipped to the limits) — the feasible set is tested exactly
    every time, so the distribution is uniform on the feasible set as long as it lies in
    that box.

    Parameters
    ----------
    model : ErrorModel
        The model.
    count : int
        Candidates wanted (configurations × payloads, rounded up to whole configurations).
    payloads : sequence of float, kg
        Payloads each configuration is offered with.
    volume : Box, optional
        Working volume (robot base frame, m).
    visibility : Visibility, optional
        The tracker's line of sight.
    seed : int
        Random seed.
    max_draws : int
        Most configurations drawn (fewer than ``count`` are returned when reached).
    chunk : int
        Configurations drawn per round.
    give_up : int
        Draws after which, with nothing feasible, the sampling fails.

    Returns
    -------
    Candidates
        Up to ``count`` candidates.

    Raises
    ------
    PlanningError
        ``count < 1``, bad payloads, or nothing feasible after ``give_up`` draws.
    """
    if count < 1:
        raise PlanningError(f"the number of candidates must be positive, got {count}")
    m = _payload_list(payloads)
    n_cfg = -(-count // len(m))
    desc = model.structure.source
    rng = np.random.default_rng(seed)
    lim_lo, lim_hi = desc.joint_limits[:, 0], desc.joint_limits[:, 1]
    lo, hi = lim_lo.copy(), lim_hi.copy()
    kept_q: list[Array] = []
    kept_T: list[Array] = []
    total = 0
    drawn = 0
    counts: dict[str, int] = {}
    while total < n_cfg and drawn < max_draws and (total > 0 or drawn < give_up):
        q = rng.uniform(lo, hi, size=(chunk, len(lo)))
        drawn += chunk
        ok, T, c = _feasible(model, q, volume, visibility)
        for k, v in c.items():
            counts[k] = counts.get(k, 0) + v
        kept_q.append(q[ok])
        kept_T.append(T[ok, :3, 3])
        total += int(np.count_nonzero(ok))
        if total >= 20 and np.array_equal(lo, lim_lo) and np.array_equal(hi, lim_hi):
            acc = np.concatenate(kept_q)
            pad = 0.25 * (lim_hi - lim_lo)
            lo = np.maximum(lim_lo, acc.min(axis=0) - pad)
            hi = np.minimum(lim_hi, acc.max(axis=0) + pad)
    if total == 0:
        raise PlanningError(
            f"no feasible candidate in {drawn} configurations drawn within the joint limits "
            f"({_why(counts, drawn)}): the working volume, the tracker position or the "
            "line-of-sight angle exclude every pose")
    q = np.concatenate(kept_q)[:n_cfg]
    T = np.concatenate(kept_T)[:n_cfg]
    return _crossed(q, m, T, np.arange(len(q)))


# ---------------------------------------------------------------------- criteria
def _check_criterion(criterion: str) -> str:
    c = str(criterion).strip().upper()
    if c not in CRITERIA:
        raise PlanningError(f"unknown criterion {criterion!r}; choose one of "
                            f"{', '.join(CRITERIA)} (D-, A-, E-, I-optimal or O = "
                            "noise amplification index)")
    return c


def _value_from_information(M: Array, criterion: str) -> float:
    """The criterion (maximised) of a symmetric information matrix ``M`` (module doc)."""
    k = M.shape[0]
    if criterion == "D":
        sign, logdet = np.linalg.slogdet(M)
        return float(logdet / k) if sign > 0 else -np.inf
    if criterion == "A":
        w = np.linalg.eigvalsh(M)
        return float(-np.sum(1.0 / w)) if w[0] > 0 else -np.inf
    w = np.linalg.eigvalsh(M)
    if criterion == "E":
        return float(w[0])
    return float(w[0] / np.sqrt(w[-1])) if w[-1] > 0 else -np.inf


def criterion_value(X: Array, criterion: str, *, region: Array | None = None) -> float:
    """The optimality criterion of a design, from ``M/n = Σ_c X_cᵀ X_c / n`` (module doc).

    ``D = (1/k) log det(M/n)``, ``A = −trace((M/n)⁻¹)``, ``E = λ_min``,
    ``O = λ_min / √λ_max``, ``I = −trace(W (M/n)⁻¹)`` with ``W = Σ_{region} X_cᵀX_c / C``
    (−inf for a singular design where the criterion needs an inverse).

    Parameters
    ----------
    X : (n, r, k) array
        Scaled Jacobian blocks of the design's poses (dimensionless).
    criterion : {"D", "A", "E", "O", "I"}
        The criterion (case-insensitive).
    region : (C, r, k) array, optional
        Blocks of the poses the I-criterion averages over (required for I).

    Returns
    -------
    float
        The criterion value (maximised).

    Raises
    ------
    PlanningError
        Unknown criterion, or I without ``region``.
    """
    c = _check_criterion(criterion)
    X = np.asarray(X, dtype=float)
    if c == "I":
        if region is None:
            raise PlanningError("the I-criterion needs the region's blocks (region=)")
        X, c = _whiten(X, np.asarray(region, dtype=float)), "A"
    Xf = X.reshape(-1, X.shape[-1])
    return _value_from_information(Xf.T @ Xf / X.shape[0], c)


# ---------------------------------------------------------------------- the plan
@dataclass(frozen=True, eq=False)
class CampaignPlan:
    """The chosen poses, ordered for measuring (payload groups, short moves).

    Attributes
    ----------
    index : (n,) int array
        Rows of the candidates.
    q : (n, n_joints) array, rad
        Joint readings.
    payload_kg : (n,) array, kg
        Payloads.
    keys : tuple of str
        The parameters planned for.
    criterion : str
        The criterion (``D``, ``A``, ``E``, ``O`` or ``I``).
    value : float
        Its value for ``M/n`` (module doc).
    sigma : (k,) array
        Predicted standard deviation ``σ_j = noise_m √((HᵀH)⁻¹)_jj`` (8.4) of each
        parameter, in its SI unit.
    condition_number : float
        κ = σ₁/σ_k of the unit-norm-column Jacobian of the chosen poses (4.10).
    noise_m : float, m
        The measurement noise σ per row assumed.
    history : tuple of float
        The criterion after the greedy start and after each improving exchange.
    exchanges : int
        Number of improving exchanges.
    n_candidates : int
        Number of candidates chosen from.
    unidentifiable : tuple of str
        Parameters the candidates cannot determine (left out).
    targets : (n, 3) array, m
        Nominal target positions in the robot base frame.
    """

    index: NDArray[np.int64]
    q: Array
    payload_kg: Array
    keys: tuple[str, ...]
    criterion: str
    value: float
    sigma: Array
    condition_number: float
    noise_m: float
    history: tuple[float, ...]
    exchanges: int
    n_candidates: int
    unidentifiable: tuple[str, ...] = ()
    targets: Array = field(default_factory=lambda: np.zeros((0, 3)))

    def __len__(self) -> int:
        return int(self.index.shape[0])


def planning_keys(model: ErrorModel, payloads: Sequence[float] = (0.0,), *,
                  position_only: bool = False, n_poses: int = 60, seed: int = 0
                  ) -> tuple[str, ...]:
    """The parameters the identification keeps for ``model`` (structural analysis, as
    :class:`~plugcell.calibration.identify.Calibrator` does): random configurations in
    the limits, the payloads cycled over them (several payloads separate payload from
    gravity constants); ``analyse(H).kept`` of the stacked Jacobian (4.2.1.2).

    Parameters
    ----------
    model : ErrorModel
        The model at nominal values.
    payloads : sequence of float, kg
        Payloads of the campaign.
    position_only : bool
        Only the position rows.
    n_poses : int
        Number of random configurations.
    seed : int
        Their seed.

    Returns
    -------
    tuple of str
        The kept keys, in priority order.

    Raises
    ------
    PlanningError
        Bad payloads.
    """
    from plugcell.calibration.identifiability import random_configurations

    m = _payload_list(payloads)
    if model.space.of_kind("payload") and model.payload_ref_kg <= 0:
        model = model.with_references(payload_ref_kg=max(float(m.max()), 1.0))
    keys = model.space.by_priority()
    q = random_configurations(model, n_poses, seed)
    pm = np.resize(m if len(m) > 1 else np.full(1, model.payload_ref_kg or m[0]), len(q))
    H = identification_jacobian(model, model.batch(q, pm), keys).H
    if position_only:
        H = H[:, :3]
    return analyse(H.reshape(-1, len(keys)), keys).kept


class PosePlanner:
    """Choose poses maximising an optimality criterion of ``M = Σ X_cᵀ X_c`` (module doc).

    Parameters
    ----------
    model : ErrorModel
        The error model to be identified (nominal values; its BASE reference places the
        tracker, its PROBE the target).
    keys : sequence of str, optional
        Its parameters to plan for (default :func:`planning_keys`).
    criterion : {"D", "A", "E", "O", "I"}
        The criterion; ``"I"``: the mean prediction variance over the candidates.
    rotation_weight : float, m/rad
        Weight of the orientation rows, as the identification.
    position_only : bool
        The tracker measures positions only.
    noise_m : float, m
        σ per row for the predicted parameter deviations.
    max_exchanges : int, optional
        Bound on the exchange excursions.

    Raises
    ------
    PlanningError
        Unknown criterion, non-positive weight or noise.
    """

    def __init__(self, model: ErrorModel, keys: Sequence[str] | None = None, *,
                 criterion: str = "D", rotation_weight: float = 1.0,
                 position_only: bool = False, noise_m: float = DEFAULT_NOISE_M,
                 max_exchanges: int | None = None) -> None:
        self.model = model
        self.keys = None if keys is None else tuple(keys)
        self.criterion = _check_criterion(criterion)
        if not (np.isfinite(rotation_weight) and rotation_weight > 0):
            raise PlanningError(f"rotation weight must be positive, got {rotation_weight}")
        if not (np.isfinite(noise_m) and noise_m > 0):
            raise PlanningError(f"measurement noise must be positive, got {noise_m}")
        self.rotation_weight = float(rotation_weight)
        self.position_only = position_only
        self.noise_m = float(noise_m)
        self.max_exchanges = max_exchanges

    # -------------------------------------------------------------- Jacobian blocks
    def blocks(self, candidates: Candidates, keys: Sequence[str]) -> Array:
        """Row-weighted identification Jacobian ``W H_c`` of every candidate (eq. 6.11).

        Parameters
        ----------
        candidates : Candidates
            The candidates (readings and payloads).
        keys : sequence of str
            The parameters (columns).

        Returns
        -------
        (C, r, k) array
            ``r = 6`` (orientation rows × ``rotation_weight``) or 3 (position only);
            position rows in m per parameter unit, orientation rows in m/rad × rad per
            parameter unit.
        """
        model = self.model
        if model.space.of_kind("payload") and model.payload_ref_kg <= 0:
            model = model.with_references(
                payload_ref_kg=max(float(np.max(candidates.payload_kg)), 1.0))
        H = identification_jacobian(model, model.batch(candidates.q, candidates.payload_kg),
                                    list(keys)).H
        if self.position_only:
            return np.ascontiguousarray(H[:, :3])
        H = H.copy()
        H[:, 3:] *= self.rotation_weight
        return H

    # -------------------------------------------------------------- the search
    def plan(self, candidates: Candidates, n: int, *, blocks: Array | None = None) -> CampaignPlan:
        """Choose ``n`` of ``candidates`` (greedy start, exchange improvement).

        Maximises the criterion of ``M(S)/n`` over sets S of ``n`` candidates (module
        doc); the predicted σ are ``noise_m · √diag((HᵀH)⁻¹)`` (8.4).

        Parameters
        ----------
        candidates : Candidates
            The candidates.
        n : int
            Number of poses.
        blocks : (C, r, k) array, optional
            The candidates' Jacobian blocks if already computed (:meth:`blocks`, with
            ``self.keys``).

        Returns
        -------
        CampaignPlan
            The chosen poses in measuring order and their predicted statistics.

        Raises
        ------
        PlanningError
            ``n < 1``, ``n`` larger than the candidates or too small for the parameters,
            or blocks of the wrong shape.
        """
        C = len(candidates)
        if n < 1:
            raise PlanningError(f"the number of poses must be positive, got {n}")
        if n > C:
            raise PlanningError(f"{n} poses asked for, but only {C} candidates are feasible; "
                                "draw more candidates (--candidates) or relax the constraints")
        keys = self.keys if self.keys is not None else planning_keys(
            self.model, np.unique(candidates.payload_kg), position_only=self.position_only)
        H = self.blocks(candidates, keys) if blocks is None else np.asarray(blocks, float)
        if H.shape[0] != C or H.shape[2] != len(keys):
            raise PlanningError(f"blocks: expected ({C}, r, {len(keys)}), got {H.shape}")
        scale = np.linalg.norm(H.reshape(-1, len(keys)), axis=0) / np.sqrt(C)
        # parameters the candidates cannot determine at all are left out
        check = analyse(H.reshape(-1, len(keys)), keys, rank_tol=1e-3)
        missing = tuple(k for k in keys if k not in check.kept)
        if missing:
            cols = [keys.index(k) for k in check.kept]
            keys, H, scale = tuple(check.kept), H[:, :, cols], scale[cols]
        r, k = H.shape[1], H.shape[2]
        if n * r < k:
            raise PlanningError(f"{n} poses give {n * r} equations for {k} parameters; "
                                f"plan at least {-(-k // r)} poses (better {3 * -(-k // r)})")
        X = np.ascontiguousarray(H / scale)
        # I: trace(W M⁻¹) = trace(M'⁻¹) for the blocks X L⁻ᵀ, W = L Lᵀ — A-optimal there
        Xc = _whiten(X, X) if self.criterion == "I" else X
        search = "A" if self.criterion == "I" else self.criterion
        sel, history, exchanges = _Search(Xc, search, self.max_exchanges).run(n)
        sel = _measuring_order(candidates, sel)
        Xs = X[sel].reshape(-1, k)
        Ms = Xs.T @ Xs
        Xw = Xc[sel].reshape(-1, k)
        value = _value_from_information(Xw.T @ Xw / n, search)
        cov = np.linalg.pinv(Ms) / np.outer(scale, scale)
        d = np.sqrt(np.diag(Ms))
        w = np.linalg.eigvalsh(Ms / np.outer(d, d))
        kappa = float(np.sqrt(w[-1] / w[0])) if w[0] > 0 else float("inf")
        return CampaignPlan(
            index=sel.astype(np.int64), q=candidates.q[sel], payload_kg=candidates.payload_kg[sel],
            keys=tuple(keys), criterion=self.criterion, value=value,
            sigma=self.noise_m * np.sqrt(np.maximum(np.diag(cov), 0.0)),
            condition_number=kappa, noise_m=self.noise_m, history=tuple(history),
            exchanges=exchanges, n_candidates=C, unidentifiable=missing,
            targets=candidates.targets[sel])


class _Search:
    """Greedy start + DETMAX excursions on scaled blocks ``X`` ``(C, r, k)``."""

    def __init__(self, X: Array, criterion: str, max_exchanges: int | None) -> None:
        self.X = X
        self.C, self.r, self.k = X.shape
        self.Xf = X.reshape(-1, self.k)
        self.XT = np.ascontiguousarray(self.Xf.T)  # (k, C·r): products read it row-wise
        self.criterion = criterion
        self.max_exchanges = max_exchanges
        self.I = np.eye(self.r)

    # state: M (with ridge), Minv, dispersions D (C, r, r), for A: T (C, r, r)
    def _refresh(self) -> None:
        self.Minv = np.linalg.inv(self.M)
        self.Minv = 0.5 * (self.Minv + self.Minv.T)
        V = (self.Minv @ self.XT).T.reshape(self.C, self.r, self.k)
        self.D = _outer(self.X, V)
        if self.criterion == "A":
            self.T = _outer(V, V)
        self.updates = 0

    def _update(self, j: int, sign: float) -> None:
        """M ← M + sign·X_jᵀX_j with the rank-r formulas (module doc)."""
        Xj = self.X[j]
        self.M += sign * (Xj.T @ Xj)
        self.updates += 1
        if self.updates >= REFRESH_EVERY:
            self._refresh()
            return
        U = self.Minv @ Xj.T                      # (k, r) = M⁻¹ X_jᵀ
        Sinv = np.linalg.inv(self.I + sign * (Xj @ U))
        Sinv = 0.5 * (Sinv + Sinv.T)
        if self.criterion == "A":
            # G = X_c M⁻¹ X_jᵀ, GS = G S⁻¹, E = X_c M⁻² X_jᵀ: one pass over the candidates
            G, GS, E = self._times(np.hstack([U, U @ Sinv, self.Minv @ U]), 3)
            cross = _outer(E, GS)
            GSW = self._times_small(GS, U.T @ U)
            self.T = self.T - sign * (cross + cross.transpose(0, 2, 1)) + _outer(GSW, GS)
            self.D = self.D - sign * _outer(GS, G)
        else:
            # G S⁻¹ Gᵀ = (G L)(G L)ᵀ with S⁻¹ = L Lᵀ
            (GL,) = self._times(U @ np.linalg.cholesky(Sinv), 1)
            self.D = self.D - sign * _outer(GL, GL)
        self.Minv = self.Minv - sign * (U @ Sinv @ U.T)

    def _times(self, W: Array, parts: int) -> list[Array]:
        """``X_c W`` for every candidate, ``W`` ``(k, parts·r)``, split into ``parts``
        arrays ``(C, r, r)`` — one pass over the candidates' blocks."""
        P = W.T @ self.XT                        # (parts·r, C·r)
        P = P.reshape(parts, self.r, self.C, self.r).transpose(0, 2, 3, 1)
        return [P[i] for i in range(parts)]

    @staticmethod
    def _times_small(A: Array, W: Array) -> Array:
        """``A_c W`` for every c (``A`` ``(C, r, r)``, ``W`` ``(r, r)``)."""
        return (A.reshape(-1, A.shape[-1]) @ W).reshape(A.shape)

    def _exact(self, M: Array) -> float:
        n = max(self.n, 1)
        return _value_from_information(M / n, self.criterion)

    def _gain_add(self, cand: NDArray[np.int64]) -> Array:
        """Criterion after adding each of ``cand`` (D, A exact; E, O short-listed)."""
        D = self.D[cand]
        if self.criterion == "D":
            sign, ld = np.linalg.slogdet(self.I + D)
            return np.where(sign > 0, ld, -np.inf)
        if self.criterion == "A":
            Sinv = np.linalg.inv(self.I + D)
            return np.einsum("cij,cji->c", Sinv, self.T[cand])  # reduction of trace(M⁻¹)
        sign, ld = np.linalg.slogdet(self.I + D)
        score = np.full(len(cand), -np.inf)
        top = np.argsort(-np.where(sign > 0, ld, -np.inf))[:SHORTLIST]
        Ms = self.M[None] + np.matmul(self.X[cand[top]].transpose(0, 2, 1), self.X[cand[top]])
        score[top] = [self._exact(m) for m in Ms]
        return score

    def _value_removed(self, sel: NDArray[np.int64]) -> Array:
        """Criterion (to maximise, comparable among ``sel``) after removing each pose."""
        D = self.D[sel]
        if self.criterion == "D":
            sign, ld = np.linalg.slogdet(self.I - D)
            return np.where(sign > 0, ld, -np.inf)
        if self.criterion == "A":
            S = self.I - D
            out = np.full(len(sel), -np.inf)
            good = np.linalg.det(S) > 1e-12
            if np.any(good):
                out[good] = -np.einsum("cij,cji->c", np.linalg.inv(S[good]), self.T[sel][good])
            return out
        Ms = self.M[None] - np.matmul(self.X[sel].transpose(0, 2, 1), self.X[sel])
        return np.array([self._exact(m) for m in Ms])

    def run(self, n: int) -> tuple[Array, list[float], int]:
        C, k = self.C, self.k
        self.n = n
        # ---- greedy start (D-gain) from a small ridge
        self.M = GREEDY_RIDGE * np.eye(k)
        self.Minv = np.eye(k) / GREEDY_RIDGE
        self.D = _outer(self.X, self.X) / GREEDY_RIDGE
        self.updates = 0
        crit, self.criterion = self.criterion, "D"
        chosen = np.zeros(C, dtype=bool)
        for _ in range(n):
            free = np.flatnonzero(~chosen)
            g = self._gain_add(free)
            j = int(free[int(np.argmax(g))])
            chosen[j] = True
            self._update(j, +1.0)
        self.criterion = crit
        sel = np.flatnonzero(chosen)
        M = self.X[sel].reshape(-1, k)
        M = M.T @ M
        self.ridge = EXCHANGE_RIDGE * max(float(np.trace(M)) / k, 1e-300)
        self.M = M + self.ridge * np.eye(k)
        self._refresh()
        value = self._exact(self.M)
        history = [value]
        # ---- exchange excursions (DETMAX): add the best, remove the best
        limit = self.max_exchanges if self.max_exchanges is not None else 10 * n + 50
        exchanges = 0
        while exchanges < limit and n < C:
            free = np.flatnonzero(~chosen)
            g = self._gain_add(free)
            j = int(free[int(np.argmax(g))])
            if not np.isfinite(g.max()):
                break
            chosen[j] = True
            self._update(j, +1.0)
            sel = np.flatnonzero(chosen)
            v = self._value_removed(sel)
            i = int(sel[int(np.argmax(v))])
            if i == j:
                chosen[j] = False
                self._update(j, -1.0)
                break
            chosen[i] = False
            self._update(i, -1.0)
            new = self._exact(self.M)
            if not new > value + 1e-12 * max(1.0, abs(value)):
                # round-off only: undo the exchange and stop
                chosen[i], chosen[j] = True, False
                self._update(i, +1.0)
                self._update(j, -1.0)
                break
            value = new
            history.append(value)
            exchanges += 1
        return np.flatnonzero(chosen), history, exchanges


def _whiten(X: Array, region: Array) -> Array:
    """Blocks ``X L⁻ᵀ`` with ``L Lᵀ = W = Σ_c R_cᵀ R_c / C`` the mean information of the
    ``region`` blocks ``R``: in these coordinates A-optimality is I-optimality."""
    from scipy.linalg import solve_triangular

    k = X.shape[-1]
    Rf = region.reshape(-1, k)
    L = np.linalg.cholesky(Rf.T @ Rf / region.shape[0])
    Xf = X.reshape(-1, k)
    return np.ascontiguousarray(solve_triangular(L, Xf.T, lower=True).T).reshape(X.shape)


def _outer(A: Array, B: Array) -> Array:
    """``A_c B_cᵀ`` for every c: ``(C, r, m)``, ``(C, r, m)`` → ``(C, r, r)``."""
    return np.einsum("cik,cjk->cij", A, B, optimize=True)


def joint_tour(q: ArrayLike) -> NDArray[np.int64]:
    """A measuring order of joint configurations: a nearest-neighbour tour in joint
    space, the distance of two poses their largest joint move (the move's time at one
    joint speed), from the pose nearest the mean.

    Parameters
    ----------
    q : array_like, shape (C, n)
        Joint configurations (rad).

    Returns
    -------
    ndarray of int, shape (C,)
        The indices of ``q`` in measuring order.
    """
    q = np.asarray(q, dtype=float)
    if len(q) == 0:
        return np.zeros(0, dtype=np.int64)
    cur = int(np.argmin(np.max(np.abs(q - q.mean(axis=0)), axis=1)))
    left = set(range(len(q)))
    left.remove(cur)
    order = [cur]
    while left:
        rest = np.array(sorted(left))
        cur = int(rest[np.argmin(np.max(np.abs(q[rest] - q[cur]), axis=1))])
        left.remove(cur)
        order.append(cur)
    return np.asarray(order, dtype=np.int64)


def _measuring_order(candidates: Candidates, sel: Array) -> NDArray[np.int64]:
    """``sel`` ordered for measuring: grouped by payload (ascending: one payload change
    per group), inside a group a :func:`joint_tour`."""
    out: list[int] = []
    for m in np.unique(candidates.payload_kg[sel]):
        group = [int(i) for i in sel if candidates.payload_kg[i] == m]
        out += [group[o] for o in joint_tour(candidates.q[group])]
    return np.asarray(out, dtype=np.int64)
