"""Which error parameters can be identified, and what each kept one stands for (4.2.1.2).

The method is numerical and works for any description:

1. **Column scaling.**  Each column of the stacked Jacobian ``H`` (``(m·k, r)``) is
   divided by its norm, so metres, radians and compliance constants compare.
   A column that is zero (relative norm below ``zero_tol``) has no effect on the
   measured pose (e.g. payload constants of joint 1, whose axis is vertical).
2. **Rank-revealing elimination in priority order.**  The scaled columns are
   visited in the parameters' priority order (see :mod:`.structure`); a column
   is kept when its distance from the span of the columns kept so far exceeds
   ``rank_tol`` (a Gram–Schmidt QR with re-orthogonalisation — a rank-revealing
   QR whose pivot order is the priority).  A dropped column is an exact linear
   combination of kept ones: ``h_j = Σ_k c_jk h_k``; its error is then
   identified *through* them, and kept parameter k stands for
   ``Δg_k + Σ_j c_jk Δg_j`` (e.g. Δa2' stands for Δa2' − Δa4').
3. **Condition-number rule (4.10).**  If the condition number ``σ1/σr`` of the
   scaled kept columns exceeds ``condition_limit`` (100 in the thesis, after
   Bernhardt 1993), the parameter with the largest element in the last right
   singular vector ``v_r`` is removed, and the rule is repeated.

:func:`structural_identifiability` applies this to random configurations that
fill the joint space (the *structural* answer, a property of the model); the
same :func:`analyse` checks a real data set, whose poses may excite less.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from plugcell.calibration.jacobian import identification_jacobian
from plugcell.calibration.linalg import r_factor
from plugcell.calibration.model import THERMAL_KEY, ErrorModel, PoseBatch

Array = NDArray[np.float64]

#: Default tolerances of :func:`analyse` (on unit-norm columns).
ZERO_TOL = 1e-9
RANK_TOL = 1e-6
COEF_TOL = 1e-7
#: The thesis's condition-number limit (4.10).
THESIS_CONDITION_LIMIT = 100.0

__all__ = [
    "COEF_TOL",
    "RANK_TOL",
    "THESIS_CONDITION_LIMIT",
    "ZERO_TOL",
    "Identifiability",
    "analyse",
    "combinations_at",
    "random_configurations",
    "structural_identifiability",
]


@dataclass(frozen=True)
class Identifiability:
    """Result of :func:`analyse`.

    Attributes
    ----------
    kept : tuple of str
        Identifiable parameters (in the order given to :func:`analyse`).
    dropped : tuple of str
        Parameters identified through kept ones (``h_j = Σ_k c_jk h_k``).
    zero : tuple of str
        Parameters with no effect (``‖h_j‖ ≤ zero_tol · max_k ‖h_k‖``).
    eliminated : tuple of str
        Removed by the condition-number rule (4.10).
    combinations : dict of str to tuple of (str, float)
        ``combinations[k] = ((k, 1), (j, c_jk), …)``: kept ``k`` stands for
        ``Δg_k + Σ_j c_jk Δg_j`` (coefficients in the parameters' own units).
    via : dict of str to tuple of str
        The kept parameters a dropped ``j`` is identified through.
    condition_number : float
        ``κ = σ₁/σ_r`` of the unit-norm kept columns (inf if there are none).
    singular_values : (r,) array
        ``σ₁ ≥ … ≥ σ_r`` of those columns.
    """

    kept: tuple[str, ...]
    dropped: tuple[str, ...]
    zero: tuple[str, ...]
    eliminated: tuple[str, ...]
    combinations: dict[str, tuple[tuple[str, float], ...]]
    via: dict[str, tuple[str, ...]]
    condition_number: float
    singular_values: Array = field(repr=False)

    def stands_for(self, key: str, names: dict[str, str] | None = None, digits: int = 4) -> str:
        """Human-readable combination ``Δg_k + Σ_j c_jk Δg_j`` of kept ``key``.

        E.g. ``"Δa2' − Δa4'"``.

        Parameters
        ----------
        key : str
            A parameter key (one not in ``combinations`` stands for itself).
        names : dict of str to str, optional
            Display name per key (default: the keys).
        digits : int
            Significant digits of coefficients other than ±1.

        Returns
        -------
        str
            The combination.
        """
        terms = self.combinations.get(key, ((key, 1.0),))
        name = (lambda k: names.get(k, k)) if names else (lambda k: k)
        out = ""
        for i, (k, c) in enumerate(terms):
            sign = "−" if c < 0 else "+"
            mag = abs(c)
            coef = "" if abs(mag - 1.0) < 1e-9 else f"{mag:.{digits}g}·"
            if i == 0:
                out = ("−" if c < 0 else "") + coef + name(k)
            else:
                out += f" {sign} {coef}{name(k)}"
        return out


def analyse(
    H: Array,
    keys: Sequence[str],
    *,
    zero_tol: float = ZERO_TOL,
    rank_tol: float = RANK_TOL,
    condition_limit: float | None = None,
    protect: Sequence[str] = (),
) -> Identifiability:
    """Identifiability of the columns of ``H``, visited in ``keys`` (priority) order (4.2.1.2).

    Columns are scaled to unit norm ``ĥ_j = h_j / ‖h_j‖``; ``ĥ_j`` is kept when its
    distance from the span of the kept columns, ``‖(I − QQᵀ) ĥ_j‖``, exceeds ``rank_tol``
    (Gram–Schmidt QR in priority order); while ``κ = σ₁/σ_r > condition_limit`` the kept
    parameter with the largest ``|v_r|`` entry is eliminated (rule 4.10).  Dropped
    columns are expressed as ``h_j = Σ_k c_jk h_k`` (least squares on the unscaled columns).

    Parameters
    ----------
    H : (rows, k) array
        Stacked identification Jacobian (e.g. ``(N·6, k)``), columns in parameter units.
    keys : sequence of str
        The ``k`` parameter keys, in priority order.
    zero_tol : float
        Relative norm below which a column has no effect.
    rank_tol : float
        Distance (of a unit column) below which it depends on the kept ones.
    condition_limit : float, optional
        Apply rule 4.10 with this limit (thesis: 100); ``None``: no elimination.
    protect : sequence of str
        Keys the condition rule must not remove.

    Returns
    -------
    Identifiability
        Kept, dropped, zero and eliminated keys, their combinations and κ.

    Raises
    ------
    ValueError
        ``H`` not 2-D with ``len(keys)`` columns.
    """
    H = np.asarray(H, dtype=float)
    keys = tuple(keys)
    if H.ndim != 2 or H.shape[1] != len(keys):
        raise ValueError(f"H: expected shape (rows, {len(keys)}), got {H.shape}")
    norms = np.linalg.norm(H, axis=0)
    big = norms.max() if norms.size else 0.0
    # A column is "zero" relative to its own kind of unit: compare with the
    # largest column, scaled to be unit-free by the row scale of H.
    zero = tuple(k for k, nrm in zip(keys, norms, strict=True)
                 if not np.isfinite(nrm) or nrm <= zero_tol * max(big, 1e-300))
    Hs = H / np.where(norms > 0, norms, 1.0)
    if Hs.shape[0] > 2 * Hs.shape[1]:
        # Same column geometry (HᵀH = RᵀR), k×k instead of rows×k: fast for many poses.
        Hs = r_factor(Hs)
    idx = {k: i for i, k in enumerate(keys)}
    kept, dropped = _independent_columns(Hs, keys, zero, rank_tol)
    eliminated, kappa, sv = _condition_rule(Hs, idx, kept, condition_limit, protect)
    combinations, via = _combinations(H, norms, idx, kept, dropped)
    return Identifiability(
        kept=tuple(kept),
        dropped=tuple(dropped),
        zero=zero,
        eliminated=tuple(eliminated),
        combinations={k: tuple(v) for k, v in combinations.items()},
        via=via,
        condition_number=kappa,
        singular_values=sv,
    )


def _independent_columns(Hs: Array, keys: tuple[str, ...], zero: tuple[str, ...],
                         rank_tol: float) -> tuple[list[str], list[str]]:
    """Gram–Schmidt QR in priority order: the unit column ``ĥ_j`` is kept when
    ``‖(I − QQᵀ) ĥ_j‖ > rank_tol`` (twice orthogonalised), else dropped.

    Returns
    -------
    kept, dropped : list of str
        Keys of the independent columns and of those that depend on them (the ``zero``
        ones in neither).
    """
    Q = np.zeros((Hs.shape[0], 0))
    kept: list[str] = []
    dropped: list[str] = []
    for j, k in enumerate(keys):
        if k in zero:
            continue
        v = Hs[:, j].copy()
        for _ in range(2):
            v -= Q @ (Q.T @ v)
        r = np.linalg.norm(v)
        if r > rank_tol:
            Q = np.concatenate([Q, (v / r)[:, None]], axis=1)
            kept.append(k)
        else:
            dropped.append(k)
    return kept, dropped


def _condition_rule(Hs: Array, idx: dict[str, int], kept: list[str],
                    condition_limit: float | None, protect: Sequence[str]
                    ) -> tuple[list[str], float, Array]:
    """Rule 4.10: while ``κ = σ₁/σ_r`` of the kept unit columns exceeds
    ``condition_limit``, remove (from ``kept``, in place) the unprotected parameter with
    the largest ``|v_r|`` entry of the last right singular vector.

    Returns
    -------
    eliminated : list of str
        The removed keys, in order.
    kappa : float
        κ of the columns left (``inf`` when singular or none).
    sv : (r,) array
        Their singular values.
    """
    eliminated: list[str] = []
    while True:
        cols = [idx[k] for k in kept]
        sv = np.linalg.svd(Hs[:, cols], compute_uv=False) if cols else np.zeros(0)
        kappa = float(sv[0] / sv[-1]) if sv.size and sv[-1] > 0 else float("inf")
        if condition_limit is None or kappa <= condition_limit or len(kept) <= 1:
            return eliminated, kappa, sv
        _, _, Vt = np.linalg.svd(Hs[:, cols], full_matrices=False)
        order = np.argsort(-np.abs(Vt[-1]))
        cand = [kept[i] for i in order if kept[i] not in protect]
        if not cand:
            return eliminated, kappa, sv
        kept.remove(cand[0])
        eliminated.append(cand[0])


def _combinations(H: Array, norms: Array, idx: dict[str, int], kept: list[str],
                  dropped: list[str]
                  ) -> tuple[dict[str, list[tuple[str, float]]], dict[str, tuple[str, ...]]]:
    """Each dropped column as a combination of the kept ones, ``h_j = Σ_k c_jk h_k``
    (least squares on the unscaled columns); a coefficient counts when its scale-free
    size ``|c_jk|·‖h_k‖/‖h_j‖`` exceeds ``COEF_TOL`` (near-integers rounded).

    Returns
    -------
    combinations : dict of str to list of (str, float)
        Each kept key → itself with 1, then the dropped keys it stands for, with c.
    via : dict of str to tuple of str
        Each dropped key → the kept keys it is a combination of.
    """
    combinations: dict[str, list[tuple[str, float]]] = {k: [(k, 1.0)] for k in kept}
    via: dict[str, tuple[str, ...]] = {}
    if not (dropped and kept):
        return combinations, via
    Hkd = H[:, [idx[k] for k in kept] + [idx[k] for k in dropped]]
    if Hkd.shape[0] > 2 * Hkd.shape[1]:
        Hkd = r_factor(Hkd)  # R keeps every linear relation of the columns
    C, *_ = np.linalg.lstsq(Hkd[:, : len(kept)], Hkd[:, len(kept):], rcond=None)
    nk = norms[[idx[k] for k in kept]]
    for jd, kd in enumerate(dropped):
        rel = np.abs(C[:, jd]) * nk / norms[idx[kd]]
        used = []
        for ik, kk in enumerate(kept):
            if rel[ik] > COEF_TOL:
                c = float(C[ik, jd])
                r = round(c)
                c = float(r) if abs(c - r) < 1e-9 else c
                combinations[kk].append((kd, c))
                used.append(kk)
        via[kd] = tuple(used)
    return combinations, via


def random_configurations(model: ErrorModel, n: int, seed: int = 0) -> Array:
    """Random joint readings, ``q ~ U(q_min, q_max)`` kept where the coupled limits hold.

    Rejection sampling: uniform draws within the joint limits, kept when
    ``desc.within_limits(q)`` (loops assemble everywhere inside them).

    Parameters
    ----------
    model : ErrorModel
        The model (its robot's limits).
    n : int
        Number of configurations.
    seed : int
        Seed of the random generator.

    Returns
    -------
    (n, n_readings) array, rad
        Joint readings.

    Raises
    ------
    ValueError
        Fewer than ``n`` configurations found within the limits after 100 rounds.
    """
    desc = model.structure.source
    rng = np.random.default_rng(seed)
    lo, hi = desc.joint_limits[:, 0], desc.joint_limits[:, 1]
    out: list[Array] = []
    total = 0
    for _ in range(100):
        q = rng.uniform(lo, hi, size=(4 * n, desc.n_readings))
        q = q[desc.within_limits(q)]
        out.append(q)
        total += len(q)
        if total >= n:
            break
    q = np.concatenate(out)[:n]
    if len(q) < n:
        raise ValueError("could not draw configurations within the joint limits")
    return q


def structural_identifiability(
    model: ErrorModel,
    *,
    position_only: bool = False,
    keys: Sequence[str] | None = None,
    n_poses: int = 60,
    seed: int = 0,
    condition_limit: float | None = None,
) -> Identifiability:
    """The identifiable parameters of ``model`` on random configurations (module doc).

    ``analyse(H)`` with ``H`` the stacked identification Jacobian (eq. 6.11) at
    ``n_poses`` random configurations; payload columns are evaluated with the model's
    reference payload (or 1 kg if it has none).

    Parameters
    ----------
    model : ErrorModel
        The model, linearised at its current values.
    position_only : bool
        Only the position rows (3-DOF data).
    keys : sequence of str, optional
        Candidates (default: all of ``model.space``), visited in priority order.
    n_poses : int
        Number of random configurations.
    seed : int
        Seed of the configurations.
    condition_limit : float, optional
        Rule 4.10 limit (see :func:`analyse`).

    Returns
    -------
    Identifiability
        The structural answer.
    """
    keys = tuple(model.space.keys if keys is None else keys)
    order = [k for k in model.space.by_priority() if k in set(keys)]
    q = random_configurations(model, n_poses, seed)
    if model.payload_ref_kg <= 0 and any(model.space[k].kind == "payload" for k in keys):
        model = model.with_references(payload_ref_kg=1.0)
    m = np.full(len(q), model.payload_ref_kg)
    jac = identification_jacobian(model, random_batch(model, q, m), order)
    H = jac.H[:, :3] if position_only else jac.H
    return analyse(H.reshape(-1, len(order)), order, condition_limit=condition_limit)


def random_batch(model: ErrorModel, q: Array, payload_kg: Array, seed: int = 0) -> PoseBatch:
    """The batch of the structural analysis: with a thermal term, temperatures spread
    uniformly over ±2 K about the reference (a constant temperature would make κT a
    zero column — which is what the data check then says of isothermal data).

    Parameters
    ----------
    model : ErrorModel
        The model.
    q : (N, n_readings) array, rad
        Joint readings.
    payload_kg : (N,) array, kg
        Payloads.
    seed : int
        Seed of the temperatures.

    Returns
    -------
    PoseBatch
        The batch, with temperatures ``T_ref + U(−2, 2)`` °C when the model is thermal.
    """
    t = None
    if THERMAL_KEY in model.space:
        t = model.temperature_ref_c + np.random.default_rng(seed).uniform(-2.0, 2.0, len(q))
    return model.batch(q, payload_kg, t)


def combinations_at(
    model: ErrorModel,
    kept: Sequence[str],
    dropped: Sequence[str],
    *,
    position_only: bool = False,
    n_poses: int = 60,
    seed: int = 0,
) -> dict[str, tuple[tuple[str, float], ...]]:
    """What each ``kept`` parameter stands for, linearised at ``model``'s current values.

    The combinations of :func:`analyse` are first-order statements at the point
    where the Jacobian is evaluated (the nominal robot in the structural analysis).
    Away from it the dependencies are no longer exact — e.g. a four-bar with
    uneven links is not invariant under equal changes of crank and follower — so
    a noise-free identification reproduces the combination *at the identified
    point* (least-squares coefficients of the dropped columns on the kept ones
    there), not the nominal one; thesis Table 8-1 shows the same second-order
    differences.  ``C = argmin ‖H_kept C − H_dropped‖`` (least squares), kept ``k``
    stands for ``Δg_k + Σ_j C_kj Δg_j``.

    Parameters
    ----------
    model : ErrorModel
        The model at the point of linearisation (e.g. identified values).
    kept, dropped : sequence of str
        The kept and dropped parameter keys.
    position_only : bool
        Only the position rows.
    n_poses : int
        Number of random configurations.
    seed : int
        Seed of the configurations.

    Returns
    -------
    dict of str to tuple of (str, float)
        ``{kept: ((kept, 1.0), (dropped, coefficient), …)}`` like
        :attr:`Identifiability.combinations` (no coefficient rounding).
    """
    kept, dropped = list(kept), list(dropped)
    q = random_configurations(model, n_poses, seed)
    if model.payload_ref_kg <= 0 and any(model.space[k].kind == "payload" for k in kept + dropped):
        model = model.with_references(payload_ref_kg=1.0)
    m = np.full(len(q), model.payload_ref_kg)
    H = identification_jacobian(model, random_batch(model, q, m), kept + dropped).H
    if position_only:
        H = H[:, :3]
    H = H.reshape(-1, len(kept) + len(dropped))
    C = np.linalg.lstsq(H[:, : len(kept)], H[:, len(kept):], rcond=None)[0] if dropped else None
    out: dict[str, tuple[tuple[str, float], ...]] = {}
    for i, k in enumerate(kept):
        terms = [(k, 1.0)]
        if C is not None:
            terms += [(d, float(C[i, j])) for j, d in enumerate(dropped) if C[i, j] != 0.0]
        out[k] = tuple(terms)
    return out
