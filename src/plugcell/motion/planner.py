"""Planning a list of moves into a :class:`~plugcell.motion.trajectory.Trajectory`,
with every check done *before* motion.

Steps (each failure raises a :class:`~plugcell.motion.errors.TrajectoryError` naming
the move, its program line, the time and path fraction, the joint, value and limit):

1. The start readings and every PTP target inside the joint and coupled limits
   (:class:`JointRangeError`); every LIN/CIRC target reachable by inverse kinematics
   inside the limits (:class:`UnreachablePoseError`, :class:`JointRangeError`), each
   seeded with the previous target's solution.
2. Moves grouped into sections (consecutive PTPs; consecutive LIN/CIRCs), each move's
   time law (:mod:`.joint_path`, :mod:`.cartesian_path`).
3. Blends.  A blend radius ``r`` on move ``k`` lets move ``k+1`` start ``d`` before
   move ``k`` ends (superposition, :mod:`.timing`).  The deceleration phase of move
   ``k`` and the acceleration phase of move ``k+1`` are planned with *half* the
   acceleration and jerk limits, so their sums in the overlap keep the limits; the
   overlap ``d`` is the largest that

   * keeps both moves near the point: ``d ≤ T_k − t_k(r/2)``, ``d ≤ t_{k+1}(r/2)``
     (``t_k(r/2)``: when move ``k`` comes within ``r/2`` of its end for good;
     ``t_{k+1}(r/2)``: when move ``k+1`` first leaves ``r/2`` around its start) — so
     the path stays within ``r`` of the point (triangle inequality);
   * lies in those two phases: ``d ≤ T_a2,k``, ``d ≤ T_a1,k+1`` (then move ``k``'s
     speed only falls and move ``k+1``'s only rises in the overlap, and each
     channel's speed is at most its value at the overlap's edges);
   * for joint moves, keeps the speeds at the edges:
     ``w_k·σ̇_k(T_k − d) + w_{k+1}·σ̇_{k+1}(d) ≤ v`` per joint (``w = |Δq_j|``), by
     bisection — the left side grows with ``d``.  Cartesian moves skip this scalar
     bound: it is the speed of two moves in the *same* direction, so it forced the
     overlap of two tangent moves (a circle as two CIRCs) down to where both move at
     under half speed — the path slowed to a quarter of its speed at the junction,
     where the superposed speed ``‖f'_k σ̇_k + f'_{k+1} σ̇_{k+1}‖`` of tangent moves
     with mirrored profiles stays at ``v``; the grid check below bounds the speed of
     the superposition itself.

   The overlap is then verified on a dense grid (:data:`BLEND_SAMPLES`) against all
   limits (for Cartesian moves the norms of the superposed velocity, acceleration and
   jerk, and the angular acceleration's cross term ``ω_{k+1} × ω_k``), and if it fails
   the largest of :data:`BLEND_CANDIDATES` shorter overlaps that passes is taken (0: an
   exact stop; :attr:`Trajectory.blends` tells which overlap each blend got).
4. Cartesian sections are followed in joint space every ``check_step`` seconds
   (:func:`~plugcell.motion.tracking.track`, falling back on
   :func:`plugcell.kinematics.inverse` seeded with the previous solution), and at
   each point: the readings inside the limits; the Jacobian's inverse condition
   number ``σ_min/σ_max`` of ``diag(1/ℓ, 1/ℓ, 1/ℓ, 1, 1, 1)·J`` (``ℓ`` =
   ``length_scale``, m per rad) above ``min_inverse_condition``
   (:class:`SingularityError`); the joint speeds ``q̇ = J⁺·[v; ω]`` inside the joint
   speed limits (:class:`JointSpeedError`); no jump of the solution between two
   points larger than twice what the speed limits allow (a change of configuration,
   :class:`SingularityError`).  The first problem in time is reported.
   PTP sections are checked on the same grid for the limits (a blend can cut a
   corner outside them).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from plugcell.kinematics.description import RobotDescription
from plugcell.kinematics.errors import JointLimitError, KinematicsError, UnreachableError
from plugcell.kinematics.forward import forward
from plugcell.kinematics.inverse import inverse
from plugcell.kinematics.parameters import GeometricParameters
from plugcell.motion.cartesian_path import CartesianPath, Segment, segment_profile
from plugcell.motion.errors import (
    JointRangeError,
    JointSpeedError,
    MoveError,
    SingularityError,
    TrajectoryError,
    UnreachablePoseError,
)
from plugcell.motion.joint_path import JointPath, ptp_profile
from plugcell.motion.limits import CartesianLimits, JointLimits
from plugcell.motion.moves import CIRC, LIN, PTP, Move
from plugcell.motion.profile import DoubleS
from plugcell.motion.sections import CartesianSection, JointSection, Section, _Robot
from plugcell.motion.timing import Timing
from plugcell.motion.tracking import joint_rates, track
from plugcell.motion.trajectory import Trajectory

Array = NDArray[np.float64]

__all__ = ["BLEND_SAMPLES", "plan"]

#: Samples of a blend's overlap checked against the limits.
BLEND_SAMPLES = 400
#: Overlaps tried per blend, from the largest down to 0 (exact stop).
BLEND_CANDIDATES = 48
#: Margin kept below each limit in a blend (the check is on a grid).
BLEND_MARGIN = 1e-6
#: Every how many check points a Cartesian path is tracked sequentially (the rest at once).
FOLLOW_STRIDE = 5
#: Slack on position limits (rad or m).
LIMIT_TOL = 1e-9


def _err(cls: type[TrajectoryError], reason: str, moves: Sequence[Move], k: int | None,
         **kw: object) -> TrajectoryError:
    if k is None:
        return cls(reason, **kw)  # type: ignore[arg-type]
    m = moves[k]
    return cls(reason, move=k, line=m.line, kind=m.kind, **kw)  # type: ignore[arg-type]


def _limit_problem(desc: RobotDescription, q: Array) -> tuple[str, str, float, float] | None:
    """The first violated limit of ``q``: (reason, joint, value, violated bound)."""
    for j, name in enumerate(desc.reading_names):
        lo, hi = desc.joint_limits[j]
        if not lo - LIMIT_TOL <= q[j] <= hi + LIMIT_TOL:
            bound = lo if q[j] < lo else hi
            return (f"joint {name} = {q[j]:.6g} rad ({math.degrees(q[j]):.3f}°) is outside its "
                    f"limits [{math.degrees(lo):g}°, {math.degrees(hi):g}°]",
                    name, float(q[j]), float(bound))
    for cl in desc.coupled_limits:
        v = q[desc.joint_index(cl.joints[0])] - q[desc.joint_index(cl.joints[1])]
        if not cl.lower - LIMIT_TOL <= v <= cl.upper + LIMIT_TOL:
            bound = cl.lower if v < cl.lower else cl.upper
            name = f"{cl.joints[0]} - {cl.joints[1]}"
            return (f"{name} = {math.degrees(v):.3f}° is outside its coupled limits "
                    f"[{math.degrees(cl.lower):g}°, {math.degrees(cl.upper):g}°]",
                    name, float(v), float(bound))
    return None


def _sections(moves: Sequence[Move]) -> list[list[int]]:
    groups: list[list[int]] = []
    for k, m in enumerate(moves):
        cart = not isinstance(m, PTP)
        if groups and (not isinstance(moves[groups[-1][-1]], PTP)) == cart:
            groups[-1].append(k)
        else:
            if groups and moves[groups[-1][-1]].blend > 0.0:
                last = groups[-1][-1]
                raise _err(MoveError, f"blending a {moves[last].kind} into a {m.kind} move is not "
                           "supported (a joint move and a Cartesian move do not blend); set "
                           "its blend to 0", moves, last)
            groups.append([k])
    return groups


def _overlap(pa: DoubleS, frac_a: float, pb: DoubleS, frac_b: float,
             edges: tuple[Array, Array, Array] | None) -> float:
    """The overlap of a blend (module docstring, step 3).

    ``min(T_a − t_a(σ_a), t_b(σ_b), T_a2,a, T_a1,b)``; with ``edges = (wa, wb, vmax)``
    (joint moves) the largest ``d`` below it with ``wa·σ̇_a(T_a − d) + wb·σ̇_b(d) ≤ vmax``
    in every channel (bisection).
    """
    Ta = pa.duration
    d = max(0.0, min(Ta - pa.time_at(frac_a), pb.time_at(frac_b), pa.t_a2, pb.t_a))
    if edges is None:
        return d
    wa, wb, vmax = edges

    def fits(x: float) -> bool:
        return bool(np.all(wa * pa.speed_at(Ta - x) + wb * pb.speed_at(x) <= vmax))

    if fits(d):
        return d
    lo, hi = 0.0, d
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if fits(mid) else (lo, mid)
    return lo


def _shrink(
    profiles: list[DoubleS], d: Array, k: int,
    excess: Callable[[Timing, float, float], bool],
) -> float:
    """The largest overlap in ``d[k]·(1 − i/BLEND_CANDIDATES)`` whose window keeps the
    limits (0 if none).

    Not a bisection: the superposed jerk is the sum of both moves' jerks, and a
    joint that keeps its direction doubles it where the end of one jerk phase meets
    the start of the other — which only a *long* enough overlap avoids — while a
    joint that reverses adds the accelerations, which only a *short* one keeps small.
    """
    d_max = float(d[k])
    for i in range(BLEND_CANDIDATES):
        dk = d_max * (1.0 - i / BLEND_CANDIDATES)
        trial = d.copy()
        trial[k] = dk
        trial[k + 1:] = 0.0
        tm = Timing.chain(profiles, trial)
        t0 = float(tm.start[k + 1])
        if not excess(tm, t0, t0 + dk):
            return dk
    return 0.0


def _best_blends(
    radii: list[float],
    make_profiles: Callable[[bool], list[DoubleS]],
    bound: Callable[[list[DoubleS], int], float],
    excess: Callable[[list[DoubleS], int, Timing, float, float], bool],
) -> tuple[list[DoubleS], Array]:
    """Profiles and overlaps of a section: the better of two plans (module docstring).

    Plan 1 keeps every phase at the full limits and verifies each overlap; plan 2
    halves the acceleration and jerk of the blended phases, which lets the overlap
    reach its geometric bound.  The plan that flies by more of the requested blends
    wins, then the faster one.
    """
    best: tuple[tuple[int, float], list[DoubleS], Array] | None = None
    for soft in (False, True):
        if soft and not any(r > 0.0 for r in radii[:-1]):
            break
        profiles = make_profiles(soft)
        d = np.zeros(max(len(profiles) - 1, 0))
        for i in range(len(profiles) - 1):
            if radii[i] <= 0.0 or profiles[i].h == 0.0 or profiles[i + 1].h == 0.0:
                continue
            d[i] = bound(profiles, i)
            d[i] = _shrink(profiles, d, i,
                           lambda tm, lo, hi, p=profiles, i=i: excess(p, i, tm, lo, hi))
        stops = sum(1 for i in range(d.size) if radii[i] > 0.0 and d[i] == 0.0)
        key = (stops, Timing.chain(profiles, d).end)
        if best is None or key < best[0]:
            best = (key, profiles, d)
    assert best is not None
    return best[1], best[2]


# ----------------------------------------------------------------------------- PTP
def _joint_section(
    robot: _Robot, q0: Array, idx: list[int], moves: Sequence[Move], limits: JointLimits,
    check_step: float, t_offset: float,
) -> JointSection:
    desc = robot.desc
    n = desc.n_readings
    ends, scaled = [], []
    for k in idx:
        m = moves[k]
        assert isinstance(m, PTP)
        if m.target.shape != (n,):
            raise _err(MoveError, f"the target has {m.target.size} joint values, "
                       f"{desc.name} has {n} ({', '.join(desc.reading_names)})", moves, k)
        bad = _limit_problem(desc, m.target)
        if bad:
            raise _err(JointRangeError, "target: " + bad[0], moves, k, fraction=1.0,
                       joint=bad[1], value=bad[2], limit=bad[3])
        scaled.append(limits.scaled(m.speed, m.acceleration))
        ends.append(m.target)
    ends_a = np.array(ends)
    deltas = np.diff(np.vstack([q0, ends_a]), axis=0)
    radii = [moves[k].blend for k in idx]

    def make_profiles(soft: bool) -> list[DoubleS]:
        return [ptp_profile(deltas[i], scaled[i], soft and i > 0 and radii[i - 1] > 0.0,
                            soft and i < len(idx) - 1 and radii[i] > 0.0)
                for i in range(len(idx))]

    def keep(i: int) -> tuple[Array, Array, Array]:
        a, b = scaled[i], scaled[i + 1]
        return tuple((1.0 - BLEND_MARGIN) * np.maximum(getattr(a, f), getattr(b, f))
                     for f in ("velocity", "acceleration", "jerk"))  # type: ignore[return-value]

    def bound(profiles: list[DoubleS], i: int) -> float:
        r = radii[i]
        la, lb = float(np.linalg.norm(deltas[i])), float(np.linalg.norm(deltas[i + 1]))
        return _overlap(profiles[i], max(0.0, 1.0 - 0.5 * r / la), profiles[i + 1],
                        min(1.0, 0.5 * r / lb),
                        (np.abs(deltas[i]), np.abs(deltas[i + 1]), keep(i)[0]))

    def excess(profiles: list[DoubleS], i: int, tm: Timing, lo: float, hi: float) -> bool:
        v, a, j = keep(i)
        _, qd, qdd, qddd = JointPath(q0, ends_a, tm).sample(np.linspace(lo, hi, BLEND_SAMPLES))
        return bool(np.any(np.abs(qd) > v) or np.any(np.abs(qdd) > a)
                    or np.any(np.abs(qddd) > j))

    profiles, d = _best_blends(radii, make_profiles, bound, excess)
    path = JointPath(q0, ends_a, Timing.chain(profiles, d))
    section = JointSection(robot, path, tuple(idx))
    if np.any(d > 0.0):  # a blend may cut a corner outside the limits
        t = _grid(path.duration, check_step)
        q = path.sample(t)[0]
        inside = desc.within_limits(q, LIMIT_TOL)
        if not np.all(inside):
            i = int(np.flatnonzero(~inside)[0])
            mv, fr = section.locate(t[i:i + 1])
            bad = _limit_problem(desc, q[i])
            assert bad is not None
            raise _err(JointRangeError, "the blended path: " + bad[0], moves, int(mv[0]),
                       time=t_offset + float(t[i]), fraction=float(fr[0]), joint=bad[1],
                       value=bad[2], limit=bad[3])
    return section


def _grid(duration: float, step: float) -> Array:
    n = max(math.ceil(duration / step), 1)
    return np.linspace(0.0, duration, n + 1)


# ----------------------------------------------------------------------------- LIN/CIRC
def _cartesian_section(
    robot: _Robot, q0: Array, idx: list[int], moves: Sequence[Move],
    limits: JointLimits, cart: CartesianLimits | None, check_step: float,
    min_inverse_condition: float, length_scale: float, t_offset: float,
) -> CartesianSection:
    desc, params, closure = robot.desc, robot.params, robot.closure
    if cart is None:
        raise _err(MoveError, "a Cartesian move needs Cartesian limits (cartesian_limits=…)",
                   moves, idx[0])
    T_prev = forward(desc, params, q0, closure).tcp
    q_prev = q0
    segments, scaled = [], []
    for k in idx:
        m = moves[k]
        try:
            if isinstance(m, CIRC):
                seg = Segment.circle(T_prev, np.asarray(m.via), m.target)
            else:
                assert isinstance(m, LIN)
                seg = Segment.line(T_prev, m.target)
        except ValueError as exc:
            raise _err(MoveError, str(exc), moves, k) from None
        try:
            sol = inverse(desc, params, m.target, seed=q_prev, target="tcp", closure=closure)
        except JointLimitError as exc:
            raise _err(JointRangeError, f"target: {exc}", moves, k, fraction=1.0,
                       joint=exc.joint, value=exc.value,
                       limit=exc.limit[0] if exc.value < exc.limit[0] else exc.limit[1]) from None
        except UnreachableError as exc:
            raise _err(UnreachablePoseError, f"target unreachable: {exc}", moves, k,
                       fraction=1.0) from None
        q_prev = sol.q
        segments.append(seg)
        scaled.append(cart.scaled(m.speed, m.acceleration))
        T_prev = m.target
    radii = [moves[k].blend for k in idx]

    def make_profiles(soft: bool) -> list[DoubleS]:
        return [segment_profile(segments[i], scaled[i], soft and i > 0 and radii[i - 1] > 0.0,
                                soft and i < len(idx) - 1 and radii[i] > 0.0)
                for i in range(len(idx))]

    def keep(i: int) -> Array:
        a, b = scaled[i], scaled[i + 1]
        return (1.0 - BLEND_MARGIN) * np.array([max(getattr(a, f), getattr(b, f)) for f in (
            "velocity", "acceleration", "jerk", "angular_velocity", "angular_acceleration",
            "angular_jerk")])

    def bound(profiles: list[DoubleS], i: int) -> float:
        sa, sb, r = segments[i], segments[i + 1], radii[i]
        return _overlap(profiles[i], sa.fraction_within(0.5 * r, True), profiles[i + 1],
                        sb.fraction_within(0.5 * r, False), None)

    def excess(profiles: list[DoubleS], i: int, tm: Timing, lo: float, hi: float) -> bool:
        return _cartesian_excess(CartesianPath(tuple(segments), tm), lo, hi, keep(i))

    profiles, d = _best_blends(radii, make_profiles, bound, excess)
    path = CartesianPath(tuple(segments), Timing.chain(profiles, d))
    times = _grid(path.duration, check_step)
    q_table = _follow(robot, path, times, q0, idx, moves, t_offset)
    st = path.sample(times)
    twist = np.concatenate([st.v, st.omega], axis=-1)
    qd, _, J = joint_rates(desc, params, q_table, twist, None, closure)
    section = CartesianSection(robot, path, tuple(idx), times, q_table, qd)
    _check_table(section, J, limits, min_inverse_condition, length_scale, moves, t_offset)
    return section


def _cartesian_excess(path: CartesianPath, lo: float, hi: float, keep: Array) -> bool:
    """Whether the TCP's rates on ``[lo, hi]`` exceed ``keep`` (v, a, j, ω, α, ω⃛); the
    angular jerk (central differences of α) only when the rest keep their limits."""
    t = np.linspace(lo, hi, BLEND_SAMPLES)
    st = path.sample(t)
    norms = [np.linalg.norm(x, axis=-1).max() for x in
             (st.v, st.a, st.jerk, st.omega, st.alpha)]
    if np.any(np.array(norms) > keep[:5]):
        return True
    h = 1e-6
    ang_jerk = (path.sample(t + h).alpha - path.sample(t - h).alpha) / (2.0 * h)
    return bool(np.linalg.norm(ang_jerk, axis=-1).max() > keep[5])


def _follow(robot: _Robot, path: CartesianPath, times: Array, q0: Array, idx: list[int],
            moves: Sequence[Move], t_offset: float) -> Array:
    """Joint solutions along the path at ``times``, on the start's branch.

    Every :data:`FOLLOW_STRIDE`-th point is tracked from the previous one of them
    (sequentially, so on one branch); the points between are then solved at once,
    seeded by linear interpolation between their tracked neighbours — a point that does
    not converge so is tracked from its predecessor.  The table's jump check
    (:func:`_check_table`) catches a branch change between tracked points.
    """
    desc, params, closure = robot.desc, robot.params, robot.closure
    T = path.sample(times).T
    n = times.size
    table = np.full((n, q0.size), np.nan)
    table[0] = q0

    def solve(i: int, seed: Array) -> None:
        q, ok = track(desc, params, T[i:i + 1], seed[None], closure)
        if not ok[0]:
            try:
                q = inverse(desc, params, T[i], seed=seed, target="tcp", closure=closure,
                            enforce_limits=False).q[None]
            except KinematicsError as exc:
                k, frac = path.timing.fraction(times[i:i + 1])
                raise _err(UnreachablePoseError, f"no joint solution on the path: {exc}", moves,
                           idx[int(k[0])], time=t_offset + float(times[i]),
                           fraction=float(frac[0])) from None
        table[i] = q[0]

    coarse = np.unique(np.r_[np.arange(0, n, FOLLOW_STRIDE), n - 1])
    for a, b in itertools.pairwise(coarse):
        solve(int(b), table[a])
    fine = np.setdiff1d(np.arange(n), coarse)
    if fine.size:
        seeds = np.stack([np.interp(times[fine], times[coarse], table[coarse, j])
                          for j in range(q0.size)], axis=1)
        q, ok = track(desc, params, T[fine], seeds, closure)
        table[fine[ok]] = q[ok]
        for i in fine[~ok]:
            solve(int(i), table[i - 1])
    return table


def _check_table(section: CartesianSection, J: Array, limits: JointLimits, min_cond: float,
                 length_scale: float, moves: Sequence[Move], t_offset: float) -> None:
    """Limits, singularity, joint speeds and jumps along the joint table (step 4);
    ``J`` (N, 6, n): the Jacobians at the table's points."""
    desc = section.robot.desc
    t, q, qd = section.times, section.q_table, section.qd_table
    scale = np.array([1.0 / length_scale] * 3 + [1.0] * 3)
    sv = np.linalg.svd(scale[:, None] * J, compute_uv=False)
    cond = sv[:, -1] / sv[:, 0]
    problems: list[tuple[int, int, Callable[[int], TrajectoryError]]] = []

    def at(i: int) -> dict[str, object]:
        k, frac = section.locate(t[i:i + 1])
        return {"k": section.moves[0] if k.size == 0 else int(k[0]),
                "time": t_offset + float(t[i]), "fraction": float(frac[0])}

    inside = desc.within_limits(q, LIMIT_TOL)
    if not np.all(inside):
        i = int(np.flatnonzero(~inside)[0])

        def limit_error(i: int) -> TrajectoryError:
            bad = _limit_problem(desc, q[i])
            assert bad is not None
            w = at(i)
            return _err(JointRangeError, "on the path: " + bad[0], moves, w.pop("k"),
                        joint=bad[1], value=bad[2], limit=bad[3], **w)  # type: ignore[arg-type]
        problems.append((i, 0, limit_error))
    low = cond < min_cond
    if np.any(low):
        i = int(np.flatnonzero(low)[0])

        def sing_error(i: int) -> TrajectoryError:
            w = at(i)
            return _err(SingularityError,
                        f"the path comes near a singularity: inverse condition number of the "
                        f"Jacobian {cond[i]:.3g} below {min_cond:g} (joints "
                        f"{np.round(np.degrees(q[i]), 2).tolist()}°)", moves, w.pop("k"),
                        value=float(cond[i]), limit=min_cond, **w)  # type: ignore[arg-type]
        problems.append((i, 1, sing_error))
    vmax = limits.velocity
    fast = np.abs(qd) > vmax * (1.0 + 1e-9)
    if np.any(fast):
        i = int(np.flatnonzero(fast.any(axis=1))[0])
        j = int(np.argmax(np.abs(qd[i]) / vmax))

        def speed_error(i: int, j: int = j) -> TrajectoryError:
            w = at(i)
            name = desc.reading_names[j]
            return _err(JointSpeedError,
                        f"joint {name} speed {abs(qd[i, j]):.4g} rad/s "
                        f"({math.degrees(abs(qd[i, j])):.1f}°/s) exceeds its limit "
                        f"{vmax[j]:.4g} rad/s ({math.degrees(vmax[j]):.1f}°/s); slow the move "
                        f"down (speed override)", moves, w.pop("k"), joint=name,
                        value=float(abs(qd[i, j])), limit=float(vmax[j]),
                        **w)  # type: ignore[arg-type]
        problems.append((i, 2, speed_error))
    if t.size > 1:
        step = np.abs(np.diff(q, axis=0))
        allowed = 2.0 * vmax * np.diff(t)[:, None] + 1e-6
        jump = (step > allowed).any(axis=1)
        if np.any(jump):
            i = int(np.flatnonzero(jump)[0]) + 1
            j = int(np.argmax(step[i - 1] / allowed[i - 1]))

            def jump_error(i: int, j: int = j) -> TrajectoryError:
                w = at(i)
                name = desc.reading_names[j]
                return _err(SingularityError,
                            f"the joint solution jumps: joint {name} moves "
                            f"{math.degrees(step[i - 1, j]):.2f}° in {t[i] - t[i - 1]:.4f} s "
                            "(a change of configuration, near a singularity)", moves,
                            w.pop("k"), joint=name, value=float(step[i - 1, j]),
                            limit=float(allowed[i - 1, j]), **w)  # type: ignore[arg-type]
            problems.append((i, 3, jump_error))
    if problems:
        i, _, make = min(problems, key=lambda p: (p[0], p[1]))
        raise make(i)


def _checked_arguments(
    desc: RobotDescription, q_start: ArrayLike, moves: Sequence[Move], joint_limits: JointLimits,
    check_step: float, length_scale: float,
) -> tuple[Array, tuple[Move, ...]]:
    """The arguments of :func:`plan`, checked: the start joints and the moves.

    Returns
    -------
    q0 : (n,) array, rad
        The start joints, finite and inside the joint and coupled limits.
    moves : tuple of PTP, LIN, CIRC

    Raises
    ------
    ValueError
        ``q_start`` of another shape or not finite, ``joint_limits`` for another number of
        joints, ``check_step`` or ``length_scale`` not positive.
    JointRangeError
        The start is outside the limits.
    MoveError
        A move that is not a PTP, LIN or CIRC.
    """
    n = desc.n_readings
    q0 = np.array(q_start, dtype=float)
    if q0.shape != (n,) or not np.all(np.isfinite(q0)):
        raise ValueError(f"q_start: expected {n} finite joint values, got {q_start!r}")
    if joint_limits.n != n:
        raise ValueError(f"joint_limits has {joint_limits.n} joints, {desc.name} has {n}")
    for name, x in (("check_step", check_step), ("length_scale", length_scale)):
        if not (math.isfinite(x) and x > 0.0):
            raise ValueError(f"{name} must be positive, got {x}")
    bad = _limit_problem(desc, q0)
    if bad:
        raise JointRangeError("the start: " + bad[0], joint=bad[1], value=bad[2],
                                 limit=bad[3])
    moves = tuple(moves)
    for k, m in enumerate(moves):
        if not isinstance(m, (PTP, LIN, CIRC)):
            raise MoveError(f"move {k}: expected PTP, LIN or CIRC, got {type(m).__name__}")
    return q0, moves


# ----------------------------------------------------------------------------- API
def plan(
    desc: RobotDescription,
    q_start: ArrayLike,
    moves: Sequence[Move],
    joint_limits: JointLimits,
    cartesian_limits: CartesianLimits | None = None,
    *,
    params: GeometricParameters | None = None,
    closure: str = "nominal",
    check_step: float = 0.01,
    min_inverse_condition: float = 0.005,
    length_scale: float = 1.0,
) -> Trajectory:
    """Plan ``moves`` from ``q_start`` and check them before motion (module docstring).

    Parameters
    ----------
    desc : RobotDescription
        The robot (joint limits, loops, tool).
    q_start : (n,) array_like, rad
        Readings at the start.
    moves : sequence of PTP, LIN, CIRC
    joint_limits : JointLimits
        Speed, acceleration and jerk per reading (the machine data).
    cartesian_limits : CartesianLimits, optional
        Required when there is a LIN or CIRC.
    params : GeometricParameters, optional
        The controller's model (default: the description's nominal parameters).
    closure : {"nominal", "fourbar"}
        Loop closure of the model (the controller's: ``"nominal"``).
    check_step : float, s
        Spacing of the checks (and of the joint table) along Cartesian moves.
    min_inverse_condition : float
        Singularity threshold on ``σ_min/σ_max`` of the scaled Jacobian.
    length_scale : float, m
        ``ℓ`` of the scaling (metres counted as one radian).

    Returns
    -------
    Trajectory

    Raises
    ------
    TrajectoryError
        Its subclasses :class:`MoveError` (bad move data), :class:`JointRangeError`,
        :class:`JointSpeedError`, :class:`SingularityError`, :class:`UnreachablePoseError`.
    ValueError
        Bad arguments (shapes, a limit set for another number of joints).
    """
    params = desc.nominal_parameters() if params is None else params
    q0, moves = _checked_arguments(desc, q_start, moves, joint_limits, check_step, length_scale)
    robot = _Robot(desc, params, closure)
    sections: list[Section] = []
    starts: list[float] = []
    t, q = 0.0, q0
    for idx in _sections(moves):
        if isinstance(moves[idx[0]], PTP):
            sec: Section = _joint_section(robot, q, idx, moves, joint_limits, check_step, t)
        else:
            sec = _cartesian_section(robot, q, idx, moves, joint_limits, cartesian_limits,
                                     check_step, min_inverse_condition, length_scale, t)
        sections.append(sec)
        starts.append(t)
        t += sec.duration
        q = sec.joints(np.array([sec.duration]), 0)[0][0]
    return Trajectory(tuple(sections), np.array(starts), moves, q0)

