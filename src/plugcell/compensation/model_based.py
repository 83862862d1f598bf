"""Model-based error compensation, thesis 4.2.1.3 (eqs. 4.11–4.12) and 6.5.1.

For desired tool poses ``x^d`` (robot base frame, see :mod:`.model`) find the
commanded joint readings θ for which the identified model predicts ``x^d``:

a. θ from the *nominal* inverse kinematics — what the controller's ``POS_TO_JNTP``
   returns (:func:`nominal_joints`; the thesis's robot calls it before handing the
   joints to ``H4Compensation``, 8.3.2);
b./c. the identified model's pose ``x^a(θ)`` — deflections from link masses (6.31)
   and payload (6.41) included, the parallelogram closed exactly (6.20);
d. ``Δx = x^d ⊖ x^a`` — position difference at the tool point and the rotation
   vector of ``R_d R_aᵀ`` (the project's convention, :mod:`plugcell.kinematics.pose_error`,
   the exact form of B.15's rotational part);
e. ``δθ = J(θ)⁻¹ Δx`` (4.11), ``θ ← θ + δθ`` (4.12);
f. repeat from b. until ``‖Δx‖ < tol`` (the thesis: 10⁻⁶, the 6-vector in metres
   and radians);
g. the joints go to the controller.

Vectorised: one batch of targets is iterated together, converged targets drop out.
A target fails clearly — :class:`~plugcell.compensation.errors.CompensationError`
with ``kind`` — when nominal IK finds no solution (``"unreachable"``), when the
iteration does not reach ``tol`` within ``max_iterations`` or diverges
(``"no_convergence"``), or when the compensated joints leave the joint or coupled
limits (``"joint_limit"``).  With ``raise_errors=False`` the failures are reported
per target in :class:`CompensationResult` instead.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from plugcell.compensation.errors import CompensationError
from plugcell.compensation.pose_model import PoseModel
from plugcell.kinematics import RobotDescription, inverse
from plugcell.kinematics.pose_error import pose_error_exact

Array = NDArray[np.float64]

#: Convergence threshold on ‖Δx‖ (metres and radians in one 6-vector), thesis 6.5.1 f.
TOLERANCE = 1e-6
#: Iteration budget of step f.
MAX_ITERATIONS = 20
#: Largest joint increment (rad) accepted in one step; larger means the model and
#: the nominal start disagree wildly (a wrong model, or a singular configuration).
MAX_STEP = 0.2

__all__ = [
    "MAX_ITERATIONS",
    "TOLERANCE",
    "CompensationResult",
    "compensate",
    "compensate_joints",
    "nominal_joints",
]


@dataclass(frozen=True, eq=False)
class CompensationResult:
    """Compensated joints for a batch of ``N`` targets.

    Attributes
    ----------
    q : (N, n) array, rad
        Compensated joint readings — the commanded joints.
    q_start : (N, n) array, rad
        Where the iteration started (nominal IK).
    converged : (N,) bool array
        ``‖Δx‖ < tol`` reached.
    within_limits : (N,) bool array
        ``q`` inside the joint and coupled limits.
    iterations : (N,) int array
        Steps e. taken.
    residual : (N,) array
        Final ``‖Δx‖`` (the 6-vector in m and rad).
    position_error : (N,) array, m
        ``‖Δp‖`` of the final Δx.
    orientation_error : (N,) array, rad
        ``‖φ‖`` of the final Δx.
    reason : (N,) object array of str
        ``""`` for a usable target, else why it failed.
    kind : (N,) object array of str
        ``""`` or the :class:`CompensationError` kind.
    hybrid_fallback : (N,) bool array or None
        With a learned residual layer: targets compensated with the physical model
        alone; ``None`` without a layer.
    """

    q: Array
    q_start: Array
    converged: NDArray[np.bool_]
    within_limits: NDArray[np.bool_]
    iterations: NDArray[np.int_]
    residual: Array
    position_error: Array
    orientation_error: Array
    reason: NDArray[np.object_]
    kind: NDArray[np.object_]
    #: with a learned residual layer: targets compensated with the physical model alone
    #: because the layer's correction did not settle (a boundary of its trained region
    #: or of its trees between the iterates); ``None`` without a layer
    hybrid_fallback: NDArray[np.bool_] | None = None

    def __len__(self) -> int:
        return int(self.q.shape[0])

    @property
    def ok(self) -> NDArray[np.bool_]:
        """``(N,)`` targets whose compensated joints can be sent: ``converged ∧ within_limits``."""
        return self.converged & self.within_limits

    def first_error(self) -> CompensationError | None:
        """The failure of the first failing target as an exception.

        Returns
        -------
        CompensationError or None
            ``None`` if every target is ok.
        """
        bad = np.flatnonzero(~self.ok)
        if not bad.size:
            return None
        k = int(bad[0])
        return CompensationError(f"target {k}: {self.reason[k]}", kind=str(self.kind[k]), index=k)


def _targets(T_target: ArrayLike) -> Array:
    T = np.asarray(T_target, dtype=float)
    if T.ndim == 2:
        T = T[None]
    if T.ndim != 3 or T.shape[-2:] != (4, 4):
        raise ValueError(f"T_target: expected shape (N, 4, 4), got {T.shape}")
    if not np.all(np.isfinite(T)):
        raise ValueError("T_target: values must be finite")
    return T


def _payload(payload_kg: ArrayLike | float, N: int) -> Array:
    m = np.broadcast_to(np.asarray(payload_kg, dtype=float), (N,)).copy()
    if not np.all(np.isfinite(m) & (m >= 0)):
        raise ValueError("payload_kg: masses must be finite and ≥ 0")
    return m


def joint_step(J: Array, dx: Array) -> Array:
    """The joint step that makes the pose error ``Δx``: ``δθ = J⁻¹ Δx`` (4.11).

    The pseudo-inverse ``δθ = J⁺ Δx`` (least squares, minimum norm) where ``J`` is not
    square or (any in a batch) singular.

    Parameters
    ----------
    J : (..., 6, n) array
        Jacobians, ``[v; ω]`` per unit joint rate (m/rad, rad/rad).
    dx : (..., 6) array
        Pose errors ``[Δp (m); φ (rad)]``.

    Returns
    -------
    (..., n) array, rad
    """
    if J.shape[-1] == 6:
        try:
            return np.linalg.solve(J, dx[..., None])[..., 0]
        except np.linalg.LinAlgError:
            pass
    return np.einsum("...ij,...j->...i", np.linalg.pinv(J), dx)


def _limit_reason(desc: RobotDescription, q: Array) -> tuple[str, str, float, tuple[float, float]]:
    """Which limit ``q`` violates: (message, joint, value, limit)."""
    for j, name in enumerate(desc.reading_names):
        lo, hi = desc.joint_limits[j]
        if not lo - 1e-9 <= q[j] <= hi + 1e-9:
            return (
                f"compensated joint {name} = {math.degrees(q[j]):.4f}° is outside its limits "
                f"[{math.degrees(lo):g}°, {math.degrees(hi):g}°]",
                name, float(q[j]), (float(lo), float(hi)),
            )
    for cl in desc.coupled_limits:
        v = q[desc.joint_index(cl.joints[0])] - q[desc.joint_index(cl.joints[1])]
        if not cl.lower - 1e-9 <= v <= cl.upper + 1e-9:
            name = f"{cl.joints[0]} - {cl.joints[1]}"
            return (
                f"compensated joints violate the coupled limit {name} = {math.degrees(v):.4f}° "
                f"outside [{math.degrees(cl.lower):g}°, {math.degrees(cl.upper):g}°]",
                name, float(v), (float(cl.lower), float(cl.upper)),
            )
    return ("compensated joints are outside the limits", "", float("nan"), (0.0, 0.0))


def _newton_iterations(
    model: PoseModel, T: Array, q0: Array, m: Array, tol: float, max_iterations: int
) -> tuple[Array, Array, NDArray[np.int_], NDArray[np.bool_]]:
    """Steps b.–f. of 6.5.1 on a batch: Newton's iteration, converged targets drop out.

    Per active target ``Δx = e(T, T_model(q))`` (the exact pose error) and
    ``q ← q + J(q)⁻¹ Δx`` (eqs. 4.11–4.12, :func:`joint_step`), until ``‖Δx‖ < tol`` or
    ``max_iterations`` steps.  A target diverges — and stops — when ``‖Δx‖`` is not
    finite or a step is not finite or above :data:`MAX_STEP` in any joint.

    Parameters
    ----------
    model
        The identified model.
    T : (N, 4, 4) array, m
        Desired tool poses.
    q0 : (N, n) array, rad
        Start joints (not changed).
    m : (N,) array, kg
        Payloads.
    tol, max_iterations
        Stop when ``‖Δx‖ < tol`` (m and rad); the iteration bound.

    Returns
    -------
    q : (N, n) array, rad
        The iterated joints.
    dx : (N, 6) array
        The last ``Δx = [Δp (m); φ (rad)]`` evaluated per target (``inf`` if never).
    iterations : (N,) int array
        Steps taken per target.
    diverged : (N,) bool array
        Targets stopped by a non-finite error or a too large or non-finite step.
    """
    N = T.shape[0]
    q = q0.copy()
    dx_all = np.full((N, 6), np.inf)
    iters = np.zeros(N, dtype=int)
    diverged = np.zeros(N, dtype=bool)
    active = np.arange(N)
    for it in range(max_iterations + 1):
        if not active.size:
            break
        Ta, J = model.evaluate(q[active], m[active])
        dx = pose_error_exact(T[active], Ta)
        dx_all[active] = dx
        res = np.linalg.norm(dx, axis=-1)
        bad = ~np.isfinite(res)
        keep = (res >= tol) & ~bad
        diverged[active[bad]] = True
        if it == max_iterations:
            break
        active = active[keep]
        if not active.size:
            break
        dq = joint_step(J[keep], dx[keep])
        big = ~np.all(np.isfinite(dq), axis=-1) | (np.max(np.abs(dq), axis=-1) > MAX_STEP)
        diverged[active[big]] = True
        active = active[~big]
        q[active] += dq[~big]
        iters[active] += 1
    return q, dx_all, iters, diverged


def _failure_reasons(
    desc: RobotDescription, q: Array, converged: NDArray[np.bool_],
    within: NDArray[np.bool_], diverged: NDArray[np.bool_], residual: Array, tol: float,
    max_iterations: int,
) -> tuple[NDArray[np.object_], NDArray[np.object_]]:
    """Why each target of a Newton batch failed: ``(reason, kind)``, ``""`` where it did not.

    ``"no_convergence"`` for a target not converged (diverged, or ``‖Δx‖ ≥ tol`` after
    ``max_iterations``), ``"joint_limit"`` for a converged target outside the limits.
    """
    N = q.shape[0]
    reason = np.full(N, "", dtype=object)
    kind = np.full(N, "", dtype=object)
    for k in np.flatnonzero(~converged):
        kind[k] = "no_convergence"
        if diverged[k]:
            reason[k] = (
                "model-based compensation diverged (a joint step above "
                f"{math.degrees(MAX_STEP):g}° or a singular Jacobian); "
                f"last ‖Δx‖ = {residual[k]:.3g}"
            )
        else:
            reason[k] = (
                f"model-based compensation did not converge in {max_iterations} iterations: "
                f"‖Δx‖ = {residual[k]:.3g} ≥ {tol:g}"
            )
    for k in np.flatnonzero(converged & ~within):
        kind[k] = "joint_limit"
        reason[k] = _limit_reason(desc, q[k])[0]
    return reason, kind


def compensate_joints(
    model: PoseModel,
    T_target: ArrayLike,
    q_start: ArrayLike,
    payload_kg: ArrayLike | float = 0.0,
    *,
    tol: float = TOLERANCE,
    max_iterations: int = MAX_ITERATIONS,
    check_limits: bool = True,
    raise_errors: bool = True,
) -> CompensationResult:
    """Steps b.–f. of 6.5.1 from given start joints (e.g. the controller's nominal IK).

    Newton iterations on the identified model: ``Δx = e(T_target, T_model(q))`` (the
    exact pose error), ``q ← q + J(q)⁻¹ · Δx`` (eq. 4.11; a pseudo-inverse for a
    singular or non-square ``J``), until ``‖Δx‖ < tol``.

    Parameters
    ----------
    model
        The identified model (or a hybrid one with a learned residual layer).
    T_target
        Desired tool poses, shape ``(N, 4, 4)``, metres, in the robot base frame.
    q_start
        Joint readings to start from, shape ``(N, n)`` or ``(n,)``, radians.
    payload_kg
        Payload, scalar or shape ``(N,)``, kg.
    tol, max_iterations
        Stop when ‖Δx‖ < ``tol`` (m and rad); the iteration bound.
    check_limits
        Refuse solutions outside the joint limits.
    raise_errors
        With ``False``, failures are reported per target instead of raising.

    Returns
    -------
    CompensationResult
        The compensated joint readings ``(N, n)`` radians, with per-target
        convergence and residuals.

    Raises
    ------
    CompensationError
        For the first failing target (unless ``raise_errors=False``).
    """
    if not (tol > 0 and max_iterations >= 0):
        raise ValueError("tol must be > 0 and max_iterations ≥ 0")
    if getattr(model, "residual", None) is not None:
        return _compensate_hybrid(model, T_target, q_start, payload_kg, tol=tol,
                                  max_iterations=max_iterations, check_limits=check_limits,
                                  raise_errors=raise_errors)
    T = _targets(T_target)
    N = T.shape[0]
    desc = model.description
    n = desc.n_readings
    q0 = np.broadcast_to(np.asarray(q_start, dtype=float), (N, n)).copy()
    if not np.all(np.isfinite(q0)):
        raise ValueError("q_start: joint values must be finite")
    m = _payload(payload_kg, N)

    q, dx_all, iters, diverged = _newton_iterations(model, T, q0, m, tol, max_iterations)
    residual = np.linalg.norm(dx_all, axis=-1)
    converged = (residual < tol) & ~diverged
    within = desc.within_limits(q) if check_limits else np.ones(N, dtype=bool)
    reason, kind = _failure_reasons(desc, q, converged, within, diverged, residual, tol,
                                    max_iterations)
    result = CompensationResult(
        q=q, q_start=q0, converged=converged, within_limits=within, iterations=iters,
        residual=residual, position_error=np.linalg.norm(dx_all[:, :3], axis=-1),
        orientation_error=np.linalg.norm(dx_all[:, 3:], axis=-1), reason=reason, kind=kind,
    )
    if raise_errors:
        _raise_first(result, desc)
    return result


#: rounds of the hybrid model's outer fixed point
HYBRID_ROUNDS = 4


def _compensate_hybrid(model: Any, T_target: ArrayLike, q_start: ArrayLike,
                       payload_kg: ArrayLike | float, *, tol: float, max_iterations: int,
                       check_limits: bool, raise_errors: bool) -> CompensationResult:
    """Compensation on a hybrid model (physical + learned layer, hybrid pose = ``G(q)·T(q)``).

    The layer's correction ``G`` is piecewise constant in ``q``, so Newton's iteration on
    the hybrid pose can alternate across a step of it.  Instead, an outer fixed point:
    solve the physical model for the target with the correction taken out,
    ``T(q) = G_k⁻¹ · T_target`` (b.–f. of 6.5.1), re-evaluate ``G_{k+1} = G(q)`` and
    repeat until it no longer changes (‖Δ‖ < tol; at most :data:`HYBRID_ROUNDS`
    rounds).  A target whose correction keeps changing sits on a step of the layer: it
    is compensated with the physical model alone and marked in ``hybrid_fallback``.
    """
    T = _targets(T_target)
    N = T.shape[0]
    n = model.description.n_actuated
    q = np.broadcast_to(np.asarray(q_start, dtype=float), (N, n)).copy()
    m = _payload(payload_kg, N)
    phys = model.physical()
    G = model.correction(q, m)
    iters = np.zeros(N, dtype=int)
    moving = np.ones(N, dtype=bool)
    res = None
    for _ in range(HYBRID_ROUNDS):
        res = compensate_joints(phys, np.linalg.inv(G) @ T, q, m, tol=tol,
                                max_iterations=max_iterations, check_limits=check_limits,
                                raise_errors=False)
        iters += res.iterations
        q = res.q
        G_new = model.correction(q, m)
        moving = np.linalg.norm(pose_error_exact(G_new, G), axis=-1) >= tol
        G = G_new
        if not moving.any():
            break
    assert res is not None
    if moving.any():  # on a step of the layer: the physical model for these targets
        k = np.flatnonzero(moving)
        r2 = compensate_joints(phys, T[k], q[k], m[k], tol=tol, max_iterations=max_iterations,
                               check_limits=check_limits, raise_errors=False)
        q[k] = r2.q
        iters[k] += r2.iterations
    Tq = model.evaluate(q, m)[0]
    Tq[moving] = phys.evaluate(q[moving], m[moving])[0]
    dx = pose_error_exact(T, Tq)
    residual = np.linalg.norm(dx, axis=-1)
    converged = residual < tol
    within = model.description.within_limits(q) if check_limits else np.ones(N, dtype=bool)
    reason = np.full(N, "", dtype=object)
    kind = np.full(N, "", dtype=object)
    for i in np.flatnonzero(~converged):
        kind[i], reason[i] = "no_convergence", (
            f"hybrid compensation did not converge: ‖Δx‖ = {residual[i]:.3g} ≥ {tol:g}")
    for i in np.flatnonzero(converged & ~within):
        kind[i], reason[i] = "joint_limit", _limit_reason(model.description, q[i])[0]
    out = CompensationResult(
        q=q, q_start=np.broadcast_to(np.asarray(q_start, dtype=float), (N, n)).copy(),
        converged=converged, within_limits=within, iterations=iters, residual=residual,
        position_error=np.linalg.norm(dx[:, :3], axis=-1),
        orientation_error=np.linalg.norm(dx[:, 3:], axis=-1), reason=reason, kind=kind,
        hybrid_fallback=moving)
    if raise_errors:
        _raise_first(out, model.description)
    return out


def _raise_first(result: CompensationResult, desc: RobotDescription) -> None:
    bad = np.flatnonzero(~result.ok)
    if not bad.size:
        return
    k = int(bad[0])
    if result.kind[k] == "joint_limit":
        msg, joint, value, limit = _limit_reason(desc, result.q[k])
        raise CompensationError(f"target {k}: {msg}", kind="joint_limit", index=k, joint=joint,
                                value=value, limit=limit)
    raise CompensationError(f"target {k}: {result.reason[k]}", kind=str(result.kind[k]), index=k)


def nominal_joints(
    model: PoseModel, T_target: ArrayLike, seed: ArrayLike | None = None
) -> tuple[Array, NDArray[np.bool_], NDArray[np.object_]]:
    """Step a.: the controller's nominal IK (``POS_TO_JNTP``) of the tool poses.

    Nominal description geometry with the model's tool as the controller's tool:
    solves ``T_nominal(q) · tool = T_target`` (:func:`~plugcell.kinematics.inverse`).

    Parameters
    ----------
    model : PoseModel
        The model (its description and tool).
    T_target : (N, 4, 4) or (4, 4) array_like, m
        Desired tool poses in the robot base frame.
    seed : (n,) or (N, n) array_like, rad, optional
        IK seed (default the description's home).

    Returns
    -------
    q : (N, n) array, rad
        Nominal joint readings.
    ok : (N,) bool array
        Converged inside the limits.
    reason : (N,) object array of str
        The IK's message where no solution inside the limits exists.

    Raises
    ------
    ValueError
        Malformed or non-finite targets.
    """
    T = _targets(T_target)
    desc = model.description
    params = desc.nominal_parameters().replace(tool=np.asarray(model.tool))
    res = inverse(desc, params, T, seed, target="tcp", raise_errors=False)
    ok = np.asarray(res.converged) & np.asarray(res.within_limits)
    return np.asarray(res.q), ok, np.asarray(res.reason, dtype=object)


def compensate(
    model: PoseModel,
    T_target: ArrayLike,
    payload_kg: ArrayLike | float = 0.0,
    *,
    seed: ArrayLike | None = None,
    tol: float = TOLERANCE,
    max_iterations: int = MAX_ITERATIONS,
    raise_errors: bool = True,
) -> CompensationResult:
    """The whole of 6.5.1: nominal IK (a.), then iterate on the identified model (b.–f.).

    ``q₀ = IK_nominal(x^d)``, then ``q ← q + J(q)⁻¹ (x^d ⊖ x^a(q))`` (4.11, 4.12) until
    ``‖Δx‖ < tol`` (:func:`compensate_joints`).  Targets without a nominal solution fail
    with kind ``"unreachable"``.

    Parameters
    ----------
    model : PoseModel
        The identified model.
    T_target : (N, 4, 4) or (4, 4) array_like, m
        Desired tool poses in the robot base frame.
    payload_kg : float or (N,) array_like, kg
        Payload.
    seed : (n,) or (N, n) array_like, rad, optional
        Joint seed of the nominal IK (default the description's home).
    tol : float
        Stop when ‖Δx‖ < tol (m and rad).
    max_iterations : int
        Iteration bound.
    raise_errors : bool
        With ``False``, failures are reported per target instead of raising.

    Returns
    -------
    CompensationResult
        Compensated joint readings ``(N, n)``, rad, with per-target convergence.

    Raises
    ------
    ValueError
        Malformed targets, payloads or tolerances.
    CompensationError
        For the first failing target (unless ``raise_errors=False``).
    """
    T = _targets(T_target)
    q_nom, ok, why = nominal_joints(model, T, seed)
    res = compensate_joints(model, T, q_nom, payload_kg, tol=tol, max_iterations=max_iterations,
                            raise_errors=False)
    if not np.all(ok):
        bad = np.flatnonzero(~ok)
        conv = res.converged.copy()
        conv[bad] = False
        reason, kind = res.reason.copy(), res.kind.copy()
        for k in bad:
            reason[k] = f"no nominal joint solution: {why[k] or 'inverse kinematics failed'}"
            kind[k] = "unreachable"
        res = CompensationResult(
            q=res.q, q_start=res.q_start, converged=conv, within_limits=res.within_limits,
            iterations=res.iterations, residual=res.residual, position_error=res.position_error,
            orientation_error=res.orientation_error, reason=reason, kind=kind,
            hybrid_fallback=res.hybrid_fallback,
        )
    if raise_errors:
        _raise_first(res, model.description)
    return res
