"""Nominal inverse kinematics — what a controller's POS_TO_JNTP does.

The Smart H4's wrist is inclined (α4 = −60°, α5 = 60°) and offset (d5 ≠ 0), so
axes 4–6 do not meet in a point and there is no closed-form decoupling.  The
solver is numerical and works for any description (loops included):

1. **Damped least squares** (Levenberg–Marquardt with an adaptive damping per
   target) on ``pose_error_exact(T_target, T(q))`` with the manipulator Jacobian
   of the actuated joints (:mod:`plugcell.kinematics.jacobian`), step length
   limited to :data:`MAX_STEP` rad.  Converged when the position error is below
   ``tol`` metres and the orientation error below ``tol`` radians; starts that
   stall far from the target are abandoned early.
2. **Starts**: the seed (default: the description's ``home`` pose); then, for
   the targets still unsolved, groups of restarts: home turned about axis 1 to
   face the target, two elbow variants of it and home itself; the "wrist flips"
   (q4 + π, −q5, q6 + π) of these and of the seed; home turned away from the
   target and :data:`N_RANDOM_SEEDS` fixed quasi-random configurations.
3. Each start is iterated with the joint limits **relaxed** (loops kept in a
   safe band inside their coupled limit's half-turn, so they never collapse),
   then every angle is moved to its 2π-representative nearest the seed inside
   its limits; only solutions inside the joint and coupled limits count — free
   iterations find far more of them than iterations clamped at a limit.  If
   none is found, all starts are re-run with iterates projected onto the limits.
   Among the solutions the one **nearest the seed** (Euclidean in joint space)
   is returned.
4. Failures: a target farther from the shoulder than the stretched arm →
   :class:`UnreachableError` ("out of reach") at once; a converged solution
   only outside the limits → :class:`JointLimitError` naming the joint, its
   value and the limit; otherwise :class:`UnreachableError` ("no convergence")
   with the closest approach found.

All of it is vectorised over targets.  The unknowns are the joint *readings*
(a description's ``coupling`` enters through forward kinematics and the
Jacobian w.r.t. the readings), so the solution comes back as the controller
would report it, inside the limits on the readings.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import NoReturn

import numpy as np
from numpy.typing import ArrayLike, NDArray

from plugcell.kinematics.description import RobotDescription
from plugcell.kinematics.errors import JointLimitError, UnreachableError
from plugcell.kinematics.forward import forward
from plugcell.kinematics.jacobian import jacobian_from_fk
from plugcell.kinematics.parameters import GeometricParameters
from plugcell.kinematics.pose_error import pose_error_exact

Array = NDArray[np.float64]

#: Largest joint step (rad) of one iteration.
MAX_STEP = 0.5
#: Weight (metres per radian) of the orientation rows in the least-squares cost.
ORIENTATION_WEIGHT = 1.0
#: Iteration budget per start.
MAX_ITERATIONS = 200
#: Every STALL_WINDOW iterations a start whose cost fell by less than a factor
#: 1/STALL_RATIO while still above STALL_COST (≈ 3 mm) is abandoned.
STALL_WINDOW = 10
STALL_RATIO = 0.5
STALL_COST = 1e-5
#: Number of fixed quasi-random restart configurations.
N_RANDOM_SEEDS = 24
#: Margin (rad) of the safe band that keeps a loop from collapsing while joint
#: limits are relaxed: the arm–crank angle stays inside (kπ + margin, (k+1)π − margin),
#: the half-turn that holds its coupled limit.
SAFE_MARGIN = math.radians(2.0)

__all__ = ["IKResult", "inverse"]


@dataclass(frozen=True, eq=False)
class IKResult:
    """Result of :func:`inverse` (arrays batched like the targets, shape ``(...)``).

    Attributes
    ----------
    q : (..., n_readings) array, rad
        Joint readings — the solution, or the closest attempt where ``converged`` is
        False.
    converged : (...) bool array
        Whether both ``position_error`` and ``orientation_error`` are below ``tol``.
    position_error : (...) array, m
        ``‖Δp‖``, the translational part of the pose error of ``q``.
    orientation_error : (...) array, rad
        ``‖φ‖``, the rotational part of the pose error of ``q``.
    iterations : (...) int array
        Iterations spent (all starts).
    within_limits : (...) bool array
        Whether ``q`` respects the joint limits.
    reason : (...) object array of str
        ``""`` for a solution inside the limits, else the failure message (only
        visible with ``raise_errors=False``).
    """

    q: Array
    converged: NDArray[np.bool_]
    position_error: Array
    orientation_error: Array
    iterations: NDArray[np.int_]
    within_limits: NDArray[np.bool_]
    reason: NDArray[np.object_]


# ----------------------------------------------------------------------------- helpers
@dataclass(frozen=True)
class _Limits:
    lo: Array  # (n,)
    hi: Array
    pairs: tuple[tuple[int, int, float, float], ...]  # (i, j, lower, upper) on q_i − q_j


def _limits(desc: RobotDescription, enforce: bool) -> _Limits:
    n = desc.n_readings
    pairs = []
    for cl in desc.coupled_limits:
        i, j = desc.joint_index(cl.joints[0]), desc.joint_index(cl.joints[1])
        pairs.append((i, j, cl.lower, cl.upper))
    if enforce:
        return _Limits(desc.joint_limits[:, 0].copy(), desc.joint_limits[:, 1].copy(), tuple(pairs))
    # free iterations: only keep each loop inside the half-turn of its coupled limit
    safe = []
    for k_loop in range(len(desc.loops)):
        ia, ic, off = desc.loop_readings(k_loop)  # θ_arm − θ_crank = q_ia − q_ic + off
        for i, j, lo, hi in pairs:
            if {i, j} != {ia, ic}:
                continue
            # lower end of the arm − crank angle (the limit may be on crank − arm)
            low = (lo if i == ia else -hi) + off
            k = math.floor(low / math.pi)
            safe.append(
                (ia, ic, k * math.pi + SAFE_MARGIN - off, (k + 1) * math.pi - SAFE_MARGIN - off)
            )
            break
    return _Limits(np.full(n, -np.inf), np.full(n, np.inf), tuple(safe))


def _project(q: Array, lim: _Limits) -> Array:
    q = np.clip(q, lim.lo, lim.hi)
    for _ in range(3):
        for i, j, lo, hi in lim.pairs:
            diff = q[..., i] - q[..., j]
            excess = np.where(diff > hi, diff - hi, np.where(diff < lo, diff - lo, 0.0))
            q[..., i] -= 0.5 * excess
            q[..., j] += 0.5 * excess
        q = np.clip(q, lim.lo, lim.hi)
    return q


def _errors(e: Array) -> tuple[Array, Array]:
    return np.linalg.norm(e[..., :3], axis=-1), np.linalg.norm(e[..., 3:], axis=-1)


def _solve(
    desc: RobotDescription,
    params: GeometricParameters,
    T: Array,
    q0: Array,
    lim: _Limits,
    closure: str,
    point: str,
    tol: float,
    max_iter: int,
) -> tuple[Array, NDArray[np.bool_], Array, Array, NDArray[np.int_]]:
    """Levenberg–Marquardt from ``q0`` (B, n) towards ``T`` (B, 4, 4)."""
    q = _project(q0.copy(), lim)
    B = q.shape[0]

    def evaluate(qq: Array, TT: Array) -> tuple[Array, Array, NDArray[np.bool_]]:
        fk = forward(desc, params, qq, closure, raise_errors=False)
        Tq = fk.tcp if point == "tcp" else fk.flange
        e = pose_error_exact(TT, Tq)
        J = jacobian_from_fk(desc, fk, point)
        ok = fk.valid & np.all(np.isfinite(e), axis=-1)
        return np.where(ok[:, None], e, np.inf), J, ok

    e, J, ok = evaluate(q, T)
    w2 = np.array([1.0, 1.0, 1.0, ORIENTATION_WEIGHT, ORIENTATION_WEIGHT, ORIENTATION_WEIGHT]) ** 2
    cost = np.where(ok, np.sum(w2 * e * e, axis=-1), np.inf)
    mu = np.full(B, 1e-3)
    iters = np.zeros(B, dtype=int)
    ep, er = _errors(e)
    done = (ep < tol) & (er < tol)
    active = ~done & ok
    checkpoint = cost.copy()
    for it_no in range(1, max_iter + 1):
        if not np.any(active):
            break
        idx = np.flatnonzero(active)
        w = np.array([1.0, 1.0, 1.0, ORIENTATION_WEIGHT, ORIENTATION_WEIGHT, ORIENTATION_WEIGHT])
        Ja, ea = J[idx] * w[:, None], e[idx] * w
        JJt = Ja @ np.swapaxes(Ja, -1, -2)
        lam = mu[idx, None, None] * (np.trace(JJt, axis1=-2, axis2=-1)[:, None, None] / 6.0 + 1e-9)
        A = JJt + lam * np.eye(6)
        y = np.linalg.solve(A, ea[..., None])[..., 0]  # A is SPD: λ > 0
        dq = np.einsum("bji,bj->bi", Ja, y)
        big = np.max(np.abs(dq), axis=-1)
        dq *= np.minimum(1.0, MAX_STEP / np.maximum(big, 1e-300))[:, None]
        q_new = _project(q[idx] + dq, lim)
        e_new, J_new, ok_new = evaluate(q_new, T[idx])
        cost_new = np.where(ok_new, np.sum(w2 * e_new * e_new, axis=-1), np.inf)
        better = cost_new < cost[idx]
        acc = idx[better]
        q[acc], e[acc], J[acc], cost[acc] = (
            q_new[better],
            e_new[better],
            J_new[better],
            cost_new[better],
        )
        mu[acc] = np.maximum(mu[acc] / 5.0, 1e-12)
        rej = idx[~better]
        mu[rej] = mu[rej] * 8.0
        iters[idx] += 1
        ep, er = _errors(e)
        done = (ep < tol) & (er < tol)
        active = ~done & (mu < 1e8)
        if it_no % STALL_WINDOW == 0:
            # give up on starts that are stuck far from the target (local minimum)
            stalled = (cost > STALL_RATIO * checkpoint) & (cost > STALL_COST)
            active &= ~stalled
            checkpoint = cost.copy()
    ep, er = _errors(e)
    done = (ep < tol) & (er < tol)
    return q, done, ep, er, iters


def _wrap_to_seed(q: Array, seed: Array, desc: RobotDescription, enforce: bool) -> Array:
    """Each angle's 2π-representative nearest the seed (inside the limits if possible).

    Only readings whose 2π shift leaves the pose unchanged are moved
    (``desc.periodic_readings``; all of them without a coupling).
    """
    lo, hi = desc.joint_limits[:, 0], desc.joint_limits[:, 1]
    ks = np.where(desc.periodic_readings[:, None], np.arange(-3, 4) * 2.0 * np.pi, 0.0)
    cand = q[..., None] + ks  # (..., n, 7)
    inside = (cand >= lo[:, None] - 1e-9) & (cand <= hi[:, None] + 1e-9)
    dist = np.abs(cand - seed[..., None])
    if enforce:
        dist = np.where(inside, dist, dist + 1e6)
    best = np.take_along_axis(cand, np.argmin(dist, axis=-1)[..., None], axis=-1)[..., 0]
    if not enforce:
        return best
    # coupled limits: re-pick the pair's representatives jointly if violated
    for cl in desc.coupled_limits:
        i, j = desc.joint_index(cl.joints[0]), desc.joint_index(cl.joints[1])
        ci = cand[..., i, :, None]  # (..., 7, 1)
        cj = cand[..., j, None, :]  # (..., 1, 7)
        diff = ci - cj
        ok = (
            (diff >= cl.lower - 1e-9)
            & (diff <= cl.upper + 1e-9)
            & inside[..., i, :, None]
            & inside[..., j, None, :]
        )
        d2 = (ci - seed[..., i, None, None]) ** 2 + (cj - seed[..., j, None, None]) ** 2
        d2 = np.where(ok, d2, np.inf)
        flat = d2.reshape(*d2.shape[:-2], -1)
        arg = np.argmin(flat, axis=-1)
        has = np.isfinite(np.min(flat, axis=-1))
        bi, bj = np.divmod(arg, 7)
        qi = np.take_along_axis(cand[..., i, :], bi[..., None], axis=-1)[..., 0]
        qj = np.take_along_axis(cand[..., j, :], bj[..., None], axis=-1)[..., 0]
        best[..., i] = np.where(has, qi, best[..., i])
        best[..., j] = np.where(has, qj, best[..., j])
    return best


def _restart_seeds(
    desc: RobotDescription,
    params: GeometricParameters,
    T: Array,
    seed: Array,
    closure: str,
    point: str,
) -> list[Array]:
    """Deterministic restart configurations in groups of ``(B, S_g, n)``, best first.

    Group 1: home turned about axis 1 to face the target, two elbow variants of
    it (joints between axis 1 and the wrist at the quarter points of their
    ranges) and plain home.  Group 2: the "wrist flips" (q4 + π, −q5, q6 + π) of
    group 1 and of the seed.  Group 3: home turned away from the target and
    :data:`N_RANDOM_SEEDS` fixed quasi-random configurations inside the limits.
    Groups 1 and 2 are built on the kinematic joints θ_kin and mapped back to
    readings (the same thing without a coupling).
    """
    n = desc.n_actuated
    n_r = desc.n_readings
    B = T.shape[0]
    home_q = np.asarray(desc.home, dtype=float)
    home = desc.kinematic_joints(home_q)
    kin_limits = desc.kinematic_limits()
    lo, hi = kin_limits[:, 0], kin_limits[:, 1]

    def tile(x: Array) -> Array:
        return np.broadcast_to(x, (B, x.shape[-1])).copy()

    # Axis 1 is the root's z: turn home about it so the arm faces the target.
    first = desc.links[0]
    j1 = (desc.actuated_index(first.name)
          if first.is_actuated and not first.is_prismatic else None)
    fk_home = forward(desc, params, home_q, closure)
    p_home = (fk_home.tcp if point == "tcp" else fk_home.flange)[:3, 3]
    az_home = math.atan2(p_home[1], p_home[0])
    az_t = np.arctan2(T[:, 1, 3], T[:, 0, 3])
    aimed, away = tile(home), tile(home)
    if j1 is not None:
        aimed[:, j1] = home[j1] + ((az_t - az_home + np.pi) % (2 * np.pi)) - np.pi
        away[:, j1] = home[j1] + ((az_t - az_home) % (2 * np.pi)) - np.pi
    group1 = [aimed]
    if n >= 6:
        for frac in (0.25, 0.75):
            v = aimed.copy()
            for j in range(n - 3):
                if j != j1:
                    v[:, j] = lo[j] + frac * (hi[j] - lo[j])
            group1.append(v)
    group1.append(tile(home))
    group2 = []
    if n >= 6:
        seed_k = desc.kinematic_joints(seed)
        for base in (*group1, tile(seed_k) if seed_k.ndim == 1 else seed_k.copy()):
            f = base.copy()
            f[:, n - 3] += np.pi
            f[:, n - 2] *= -1.0
            f[:, n - 1] += np.pi
            group2.append(f)
    group1 = [desc.readings(g) for g in group1]
    group2 = [desc.readings(g) for g in group2]
    group3 = [desc.readings(away)]
    rng = np.random.default_rng(20240611)
    q_lo, q_hi = desc.joint_limits[:, 0], desc.joint_limits[:, 1]
    for _ in range(N_RANDOM_SEEDS):
        group3.append(tile(q_lo + rng.random(n_r) * (q_hi - q_lo)))
    return [np.stack(g, axis=1) for g in (group1, group2, group3) if g]


def _reach(desc: RobotDescription, params: GeometricParameters, point: str) -> float:
    """Upper bound of the distance from the first link's origin circle to the point."""
    loop_links = {n for lp in desc.loops for n in (lp.crank, lp.coupler, lp.follower)}
    total = 0.0
    for i in desc.chain[1:]:
        name = desc.links[i].name
        if name in loop_links:
            continue
        total += math.hypot(params.a[i], params.d[i])
    for lp in desc.loops:
        total += abs(params.a[desc.index(lp.arm)])
    if point == "tcp":
        total += float(np.linalg.norm(params.tool[:3, 3]))
    return total


def _shoulder_distance(params: GeometricParameters, T: Array) -> Array:
    """Distance of the target point from the circle swept by the first link's origin."""
    a1, d1 = abs(params.a[0]), params.d[0]
    rho = np.hypot(T[:, 0, 3], T[:, 1, 3])
    return np.hypot(rho - a1, T[:, 2, 3] - d1)


def _fmt_index(idx: tuple[int, ...] | None) -> str:
    if idx is None:
        return ""
    return f"target {idx[0] if len(idx) == 1 else idx}: "


# ----------------------------------------------------------------------------- API
def inverse(
    desc: RobotDescription,
    params: GeometricParameters | None,
    T_target: ArrayLike,
    seed: ArrayLike | None = None,
    *,
    enforce_limits: bool = True,
    tol: float = 1e-10,
    closure: str = "fourbar",
    target: str = "flange",
    max_iterations: int = MAX_ITERATIONS,
    raise_errors: bool = True,
) -> IKResult:
    """Joint readings that put the flange (or TCP) at ``T_target``.

    Damped least-squares iterations on the exact pose error ``e(q)`` between the
    target and ``T(q)`` (position, rotation vector):
    ``q ← q + Jᵀ (J Jᵀ + λ I)⁻¹ · e(q)``, ``λ = μ · tr(J Jᵀ) / 6`` with ``μ`` adapted
    per iteration (``J``: :func:`manipulator_jacobian`), until ``‖e‖ < tol``, from the
    seed and, when that fails, from further seeds; the converged solution nearest
    the seed wins (module docstring).

    Parameters
    ----------
    desc
        The robot.
    params
        Geometric parameters; ``None``: the nominal ones (an identified model's for
        model-based compensation).
    T_target
        Pose(s), shape ``(..., 4, 4)``, metres, in the robot base frame, of the flange
        (``target="flange"``, default) or of the TCP = flange · tool (``"tcp"``).
    seed
        Joint readings, shape ``(n_readings,)`` or ``(..., n_readings)``, radians;
        default ``desc.home``.
    enforce_limits
        Only solutions inside the joint and coupled limits count.
    tol
        Convergence threshold: metres for the position, radians for the orientation.
    closure, target, max_iterations
        As in :func:`forward`; which frame ``T_target`` places; the iteration bound.
    raise_errors
        With ``False``, failures are reported in ``IKResult.converged``,
        ``within_limits`` and ``reason`` instead of raising.

    Returns
    -------
    IKResult
        ``q`` ``(..., n_readings)`` radians, with per-target convergence, limits and
        reasons.

    Raises
    ------
    UnreachableError, JointLimitError
        For the first failing target (unless ``raise_errors=False``).
    """
    params = desc.nominal_parameters() if params is None else params
    if target not in ("flange", "tcp"):
        raise ValueError(f"target must be 'flange' or 'tcp', got {target!r}")
    Tf, s, batch = _flat_targets_and_seeds(desc, T_target, seed)
    far, failures = _out_of_reach(desc, params, Tf, target)
    todo = ~far
    search = _Search(desc, params, Tf, s, closure, target, tol, max_iterations, enforce_limits)
    starts = [s[:, None, :], *_restart_seeds(desc, params, Tf, s, closure, target)]
    outside_q, outside_d = search.free_stage(starts, todo)
    rows = np.flatnonzero(todo & ~search.ok)
    if rows.size and enforce_limits:
        search.limited_stage(starts, rows)
        for k in rows:
            if not search.ok[k] and np.isfinite(outside_d[k]):
                failures[int(k)] = _limit_failure(desc, outside_q[k])
    for k in np.flatnonzero(todo & ~search.ok):
        failures.setdefault(int(k), search.no_convergence(int(k)))
    reason = np.full(Tf.shape[0], "", dtype=object)
    for k, f in failures.items():
        reason[k] = f.message
    if failures and raise_errors:
        _raise_first(failures, batch)
    return search.result(batch, reason)


def _raise_first(failures: dict[int, _Failure], batch: tuple[int, ...]) -> NoReturn:
    """Raise the failure of the first failing target (flat index ``k``), naming its
    index in the batch of shape ``batch`` (``None`` for a single target)."""
    k = min(failures)
    idx = tuple(int(i) for i in np.unravel_index(k, batch)) if batch else None
    raise failures[k].exception(idx)


def _flat_targets_and_seeds(
    desc: RobotDescription, T_target: ArrayLike, seed: ArrayLike | None
) -> tuple[Array, Array, tuple[int, ...]]:
    """Check the targets and the seed and flatten them to one batch axis.

    Parameters
    ----------
    desc
        The robot.
    T_target
        Pose(s), shape ``(..., 4, 4)``, metres; finite.
    seed
        Joint readings ``(n_readings,)`` or ``(..., n_readings)``, radians, broadcast
        against the targets' batch; ``None``: ``desc.home``.

    Returns
    -------
    T : (B, 4, 4) array, m
        The targets, ``B`` the product of the batch shape.
    seed : (B, n_readings) array, rad
        One seed per target (a copy).
    batch : tuple of int
        The batch shape ``(...)`` of ``T_target``.

    Raises
    ------
    ValueError
        A wrong shape or a non-finite value, naming the argument.
    """
    T = np.asarray(T_target, dtype=float)
    if T.shape[-2:] != (4, 4):
        raise ValueError(f"T_target: expected shape (..., 4, 4), got {T.shape}")
    if not np.all(np.isfinite(T)):
        raise ValueError("T_target: values must be finite")
    batch = T.shape[:-2]
    n = desc.n_readings
    Tf = T.reshape(-1, 4, 4)
    B = Tf.shape[0]
    s = np.asarray(desc.home if seed is None else seed, dtype=float)
    if s.shape[-1:] != (n,):
        raise ValueError(
            f"seed: expected {n} joint values for {list(desc.reading_names)}, got shape {s.shape}"
        )
    if not np.all(np.isfinite(s)):
        raise ValueError("seed: values must be finite")
    return Tf, np.broadcast_to(s, (*batch, n)).reshape(B, n).copy(), batch


def _out_of_reach(
    desc: RobotDescription, params: GeometricParameters, T: Array, point: str
) -> tuple[NDArray[np.bool_], dict[int, _Failure]]:
    """The targets farther from the shoulder than the stretched arm, refused at once.

    A target is out of reach when ``_shoulder_distance(T) > _reach(desc)``: its distance
    from the circle swept by the first link's origin exceeds the sum of the link lengths.
    The test applies only where the first link turns about the base z (not on a track,
    nor with a prismatic joint further on); elsewhere no target is refused.

    Parameters
    ----------
    desc, params
        The robot and its geometric parameters.
    T : (B, 4, 4) array, m
        The targets, of the flange or of the TCP (``point``).
    point
        ``"flange"`` or ``"tcp"``.

    Returns
    -------
    far : (B,) bool array
        Which targets are out of reach.
    failures : dict
        Target index → its "out of reach" failure, for the ``far`` targets.
    """
    first = desc.links[0]
    simple = first.is_actuated and not first.is_prismatic and not desc.prismatic_links.any()
    reach = _reach(desc, params, point) if simple else math.inf
    dist = _shoulder_distance(params, T)
    far = dist > reach
    failures = {}
    for k in np.flatnonzero(far):
        failures[int(k)] = _Failure(
            f"pose is out of reach: {dist[k]:.4f} m from the shoulder, the arm reaches at "
            f"most {reach:.4f} m",
            reach_reason="out of reach",
        )
    return far, failures


@dataclass
class _Search:
    """The multi-start search over a batch of targets, and per target its best start.

    The problem (robot, targets ``T`` (B, 4, 4) m, seeds (B, n) rad, tolerances) is fixed;
    ``q``, ``ep``, ``er`` and ``ok`` hold per target the best result so far: the
    solution nearest the seed (``ok``) or, while none is found, the closest approach
    (smallest ``‖Δp‖ + ‖φ‖``); ``iters`` counts the iterations of all its starts.
    """

    desc: RobotDescription
    params: GeometricParameters
    T: Array
    seed: Array
    closure: str
    point: str
    tol: float
    max_iterations: int
    enforce: bool
    q: Array = field(init=False)
    ep: Array = field(init=False)
    er: Array = field(init=False)
    ok: NDArray[np.bool_] = field(init=False)
    iters: NDArray[np.int_] = field(init=False)

    def __post_init__(self) -> None:
        B = self.T.shape[0]
        self.q = self.seed.copy()
        self.ep = np.full(B, np.inf)
        self.er = np.full(B, np.inf)
        self.ok = np.zeros(B, dtype=bool)
        self.iters = np.zeros(B, dtype=int)

    def solve(self, group: Array, lim: _Limits, rows: NDArray[np.intp]) -> tuple[Array, ...]:
        """Iterate from each start of ``group`` for the targets ``rows``.

        Parameters
        ----------
        group : (B, S, n) array, rad
            ``S`` starts per target.
        lim
            The limits the iterates are projected onto.
        rows : (R,) int array
            The targets to solve.

        Returns
        -------
        q : (R, S, n) array, rad
            The end points, each angle moved to its 2π-representative nearest the seed.
        converged : (R, S) bool array
        position_error : (R, S) array, m
        orientation_error : (R, S) array, rad
        """
        n = self.desc.n_readings
        S = group.shape[1]
        Tr = np.repeat(self.T[rows], S, axis=0)
        sr = np.repeat(self.seed[rows], S, axis=0)
        qr, cr, epr, err_r, itr = _solve(
            self.desc, self.params, Tr, group[rows].reshape(-1, n), lim, self.closure,
            self.point, self.tol, self.max_iterations,
        )
        qr = _wrap_to_seed(qr, sr, self.desc, self.enforce)
        self.iters[rows] += itr.reshape(-1, S).sum(axis=1)
        return qr.reshape(-1, S, n), cr.reshape(-1, S), epr.reshape(-1, S), err_r.reshape(-1, S)

    def keep(
        self, rows: NDArray[np.intp], qr: Array, good: Array, epr: Array, err_r: Array
    ) -> None:
        """Record per target the good start nearest the seed, else the closest approach.

        Nearest: least ``‖q − seed‖²`` among the ``good`` starts; a target without one
        keeps the start of least ``‖Δp‖ + ‖φ‖`` if that beats its best so far.
        Shapes as returned by :meth:`solve`; ``good`` (R, S) bool.
        """
        dist2 = np.sum((qr - self.seed[rows, None, :]) ** 2, axis=-1)
        score = np.where(good, dist2, np.inf)
        pick = np.argmin(score, axis=1)
        r = np.arange(rows.size)
        found = np.isfinite(score[r, pick])
        resid = epr + err_r
        pick = np.where(found, pick, np.argmin(resid, axis=1))
        better = found | (resid[r, pick] < self.ep[rows] + self.er[rows])
        upd = rows[better]
        self.q[upd] = qr[r, pick][better]
        self.ep[upd] = epr[r, pick][better]
        self.er[upd] = err_r[r, pick][better]
        self.ok[rows[found]] = True

    def free_stage(self, starts: list[Array], todo: NDArray[np.bool_]) -> tuple[Array, Array]:
        """Stage 1: every group of starts iterated with the joint limits relaxed.

        Loops are kept in their safe band (:func:`_limits` with ``enforce=False``); each
        angle is then moved to its 2π-representative nearest the seed and a converged
        solution counts if it is inside the limits (when enforced).  Free iterations
        find far more solutions than iterations clamped at the limits.  Groups are run
        in order, each only for the ``todo`` targets still unsolved.

        Returns
        -------
        outside_q : (B, n) array, rad
            Per target the converged solution nearest the seed, limits ignored (NaN if
            none converged).
        outside_d : (B,) array, rad²
            Its ``‖q − seed‖²`` (∞ if none).
        """
        lim_free = _limits(self.desc, False)
        B, n = self.seed.shape
        outside_q = np.full((B, n), np.nan)
        outside_d = np.full(B, np.inf)
        for group in starts:
            rows = np.flatnonzero(todo & ~self.ok)
            if not rows.size:
                break
            qr, cr, epr, err_r = self.solve(group, lim_free, rows)
            good = cr & (self.desc.within_limits(qr) if self.enforce else True)
            self.keep(rows, qr, good, epr, err_r)
            d2 = np.where(cr, np.sum((qr - self.seed[rows, None, :]) ** 2, axis=-1), np.inf)
            pick = np.argmin(d2, axis=1)
            r = np.arange(rows.size)
            closer = d2[r, pick] < outside_d[rows]
            outside_d[rows[closer]] = d2[r, pick][closer]
            outside_q[rows[closer]] = qr[r, pick][closer]
        return outside_q, outside_d

    def limited_stage(self, starts: list[Array], rows: NDArray[np.intp]) -> None:
        """Stage 2: all starts at once with iterates projected onto the joint limits.

        Finds the solutions that only a path along a limit leads to; run for the
        targets ``rows`` the free stage left unsolved.
        """
        qr, cr, epr, err_r = self.solve(
            np.concatenate(starts, axis=1), _limits(self.desc, True), rows
        )
        self.keep(rows, qr, cr & self.desc.within_limits(qr), epr, err_r)

    def no_convergence(self, k: int) -> _Failure:
        """The failure of target ``k`` that no start solved: its closest approach."""
        return _Failure(
            f"no joint solution found (no convergence from the seed and the restarts; "
            f"closest approach {self.ep[k] * 1e3:.3f} mm, {math.degrees(self.er[k]):.3f}°); "
            f"the pose is probably outside the workspace"
        )

    def result(self, batch: tuple[int, ...], reason: NDArray[np.object_]) -> IKResult:
        """The best result per target, reshaped to the targets' ``batch`` shape."""
        conv_final = (self.ep < self.tol) & (self.er < self.tol)
        within = self.desc.within_limits(self.q)
        return IKResult(
            q=self.q.reshape((*batch, self.desc.n_readings)),
            converged=conv_final.reshape(batch),
            position_error=self.ep.reshape(batch),
            orientation_error=self.er.reshape(batch),
            iterations=self.iters.reshape(batch),
            within_limits=within.reshape(batch),
            reason=reason.reshape(batch),
        )


@dataclass
class _Failure:
    """Why one target failed, and which exception that maps to."""

    message: str
    kind: str = "unreachable"  # or "limit"
    reach_reason: str = "no convergence"
    joint: str = ""
    value: float = 0.0
    limit: tuple[float, float] = (0.0, 0.0)

    def exception(self, idx: tuple[int, ...] | None) -> Exception:
        msg = _fmt_index(idx) + self.message
        if self.kind == "limit":
            return JointLimitError(
                msg, joint=self.joint, value=self.value, limit=self.limit, index=idx
            )
        return UnreachableError(msg, reason=self.reach_reason, index=idx)


def _limit_failure(desc: RobotDescription, q: Array) -> _Failure:
    for j, name in enumerate(desc.reading_names):
        lo, hi = desc.joint_limits[j]
        if not lo - 1e-9 <= q[j] <= hi + 1e-9:
            return _Failure(
                f"no solution inside the joint limits; the nearest solution has joint {name} = "
                f"{math.degrees(q[j]):.3f}° outside [{math.degrees(lo):g}°, {math.degrees(hi):g}°]",
                kind="limit",
                joint=name,
                value=float(q[j]),
                limit=(float(lo), float(hi)),
            )
    for cl in desc.coupled_limits:
        v = q[desc.joint_index(cl.joints[0])] - q[desc.joint_index(cl.joints[1])]
        if not cl.lower - 1e-9 <= v <= cl.upper + 1e-9:
            return _Failure(
                f"no solution inside the joint limits; the nearest solution has {cl.joints[0]} − "
                f"{cl.joints[1]} = {math.degrees(v):.3f}° outside "
                f"[{math.degrees(cl.lower):g}°, {math.degrees(cl.upper):g}°]",
                kind="limit",
                joint=f"{cl.joints[0]} - {cl.joints[1]}",
                value=float(v),
                limit=(cl.lower, cl.upper),
            )
    return _Failure("no solution inside the joint limits", kind="limit")  # pragma: no cover
