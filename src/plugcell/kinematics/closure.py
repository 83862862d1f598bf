"""Closure of the parallelogram loop: passive joint angles from the driven ones.

Notation (Smart H4, thesis 6.1 and Fig. 6-3): the *arm* (link 2, length a_arm)
and the *crank* (link 2', a_crank) turn about the same axis z1 with DH angles
θ_arm = θ2 and θ_crank = θ2' (readings plus offsets); the *coupler* (3', a_cpl)
hangs from the crank's end and the *follower* (4', a_fol) from the coupler's end.
The loop closes when the follower's end frame meets the arm's end frame at the
cut joint 3 (constraints 6.4–6.5).  In the loop plane (x1, y1)::

    a_crank·e(θ_crank) + a_cpl·e(φ3) + a_fol·e(φ4) = a_arm·e(θ_arm),   e(φ) = (cos φ, sin φ)

with absolute directions φ3 = θ_crank + θ3' and φ4 = φ3 + θ4'.

* :func:`nominal_closure` — the parallelogram solution (6.10):
  θ3' = θ_arm − θ_crank, θ4' = π − θ_arm + θ_crank.
* :func:`fourbar_closure` — the exact planar four-bar for arbitrary lengths
  (appendix C, eqs. C.1–C.2, re-derived because the printed text is garbled):
  with ``r = a_arm·e(θ_arm) − a_crank·e(θ_crank)``,

      cos θ4' = (|r|² − a_cpl² − a_fol²) / (2·a_cpl·a_fol),
      θ4' = σ·acos(…),  σ = sign sin(θ_arm − θ_crank)   (the branch continuous with
                                                          the nominal parallelogram),
      φ3 = atan2(r) − atan2(a_fol·sin θ4', a_cpl + a_fol·cos θ4'),   θ3' = φ3 − θ_crank,

  each angle wrapped to the 2π-representative nearest its nominal value.

Both return the derivatives of the passive angles with respect to the driven
angles (implicit-function theorem on the closure equation above) — what the
manipulator Jacobian needs (thesis 6.39) — and, for the four-bar, with respect to
the four lengths (the exact counterpart of the linearisation 6.18–6.19).

The closure uses the planar lengths ``a`` and the driven angles only; twists,
``d`` and Hayati β of the loop links act on the open chain, not on the closure
(design note, thesis 8.1).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from plugcell.kinematics.errors import LoopClosureError

Array = NDArray[np.float64]

#: A loop with |sin(θ_arm − θ_crank)| or |sin θ4'| below this value is collapsed.
MIN_SIN = 1e-6

__all__ = ["MIN_SIN", "ClosureResult", "fourbar_closure", "nominal_closure"]


@dataclass(frozen=True, eq=False)
class ClosureResult:
    """Passive angles of one loop and their derivatives (all ``(...)``-batched).

    Attributes
    ----------
    coupler, follower : (...) array, rad
        The passive angles θ3', θ4'.
    d_driven : (..., 2, 2) array, rad/rad
        ``∂(θ3', θ4')/∂(θ_arm, θ_crank)``: rows (θ3', θ4'), columns (θ_arm, θ_crank).
    d_lengths : (..., 2, 4) array, rad/m
        ``∂(θ3', θ4')/∂(a_arm, a_crank, a_cpl, a_fol)`` (zeros for the nominal closure).
    valid : (...) bool array
        False where the loop cannot assemble or collapses (only when called with
        ``raise_errors=False``; the angles and derivatives there are NaN).
    """

    coupler: Array
    follower: Array
    d_driven: Array
    d_lengths: Array
    valid: NDArray[np.bool_]


def _wrap_near(x: Array, ref: Array) -> Array:
    """The 2π-representative of ``x`` nearest ``ref``."""
    return ref + (x - ref + np.pi) % (2.0 * np.pi) - np.pi


def _first_bad(mask: NDArray[np.bool_]) -> tuple[int, ...] | None:
    if mask.ndim == 0:
        return None
    return tuple(int(i) for i in np.argwhere(mask)[0])


def _where(idx: tuple[int, ...] | None) -> str:
    return "" if idx is None else f" (configuration {idx[0] if len(idx) == 1 else idx})"


def nominal_closure(
    theta_arm: ArrayLike,
    theta_crank: ArrayLike,
    *,
    raise_errors: bool = True,
    min_sin: float = MIN_SIN,
) -> ClosureResult:
    """Parallelogram closure, thesis eq. (6.10): θ3' = θ2 − θ2', θ4' = π − θ2 + θ2'.

    Derivatives are the constants of eq. (6.16),
    ``∂(θ3', θ4')/∂(θ2, θ2') = [[1, −1], [−1, 1]]``; the length derivatives are zero.

    Parameters
    ----------
    theta_arm : (...) array_like, rad
        DH angle θ2 of the arm.
    theta_crank : (...) array_like, rad
        DH angle θ2' of the crank; broadcast with ``theta_arm``.
    raise_errors : bool, default True
        With ``False``, collapsed configurations are marked invalid (NaN angles).
    min_sin : float
        Collapse threshold on ``|sin(θ2 − θ2')|``.

    Returns
    -------
    ClosureResult
        θ3', θ4' ``(...)`` rad and their derivatives.

    Raises
    ------
    LoopClosureError
        When ``|sin(θ2 − θ2')| < min_sin`` (the parallelogram collapses into a line),
        unless ``raise_errors=False``.
    """
    ta, tc = np.broadcast_arrays(np.asarray(theta_arm, float), np.asarray(theta_crank, float))
    diff = ta - tc
    bad = np.abs(np.sin(diff)) < min_sin
    if raise_errors and np.any(bad):
        idx = _first_bad(bad)
        v = float(diff[idx] if idx is not None else diff)
        raise LoopClosureError(
            f"the parallelogram collapses: arm − crank angle = {np.degrees(v):.6g}° "
            f"(sin ≈ 0){_where(idx)}",
            idx,
        )
    t3 = np.where(bad, np.nan, diff)
    t4 = np.where(bad, np.nan, np.pi - diff)
    D = np.broadcast_to(np.array([[1.0, -1.0], [-1.0, 1.0]]), (*ta.shape, 2, 2)).copy()
    L = np.zeros((*ta.shape, 2, 4))
    return ClosureResult(t3, t4, D, L, ~bad)


def _follower_angle(r2: Array, l3: Array, l4: Array, sdiff: Array) -> tuple[Array, Array]:
    """The follower's angle θ4' of a four-bar by the law of cosines (eq. C.1).

    ``cos θ4' = (|r|² − a_cpl² − a_fol²) / (2·a_cpl·a_fol)``, ``θ4' = σ·acos(cos θ4')``
    with ``σ = sign sin(θ_arm − θ_crank)`` (``+1`` at 0): the assembly branch of the
    nominal parallelogram.

    Parameters
    ----------
    r2 : (...) array, m²
        ``|r|²``, the squared gap the coupler and follower span.
    l3, l4 : (...) array, m
        ``a_cpl``, ``a_fol``.
    sdiff : (...) array
        ``sin(θ_arm − θ_crank)``.

    Returns
    -------
    c4 : (...) array
        ``cos θ4'`` as computed (outside [−1, 1] where the loop cannot close).
    t4 : (...) array, rad
        ``θ4'`` (``acos`` of ``c4`` clipped to [−1, 1]), not yet wrapped.
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        c4 = (r2 - l3 * l3 - l4 * l4) / (2.0 * l3 * l4)
    sigma = np.where(sdiff >= 0.0, 1.0, -1.0)
    return c4, sigma * np.arccos(np.clip(c4, -1.0, 1.0))


def _nan_where(bad: NDArray[np.bool_], t3: Array, t4: Array, Dq: Array,
               Da: Array) -> tuple[Array, Array, Array, Array]:
    """The closure's angles ``(...)`` and derivatives ``(..., 2, k)`` with NaN where the
    loop failed (``bad``)."""
    nan = np.nan
    return (np.where(bad, nan, t3), np.where(bad, nan, t4),
            np.where(bad[..., None, None], nan, Dq), np.where(bad[..., None, None], nan, Da))


def fourbar_closure(
    theta_arm: ArrayLike,
    theta_crank: ArrayLike,
    a_arm: ArrayLike,
    a_crank: ArrayLike,
    a_coupler: ArrayLike,
    a_follower: ArrayLike,
    *,
    raise_errors: bool = True,
    min_sin: float = MIN_SIN,
) -> ClosureResult:
    """Exact planar four-bar closure (appendix C, eqs. C.1–C.2, re-derived).

    With ``r = a_arm·e(θ_arm) − a_crank·e(θ_crank)``, ``e(φ) = (cos φ, sin φ)``::

        cos θ4' = (|r|² − a_cpl² − a_fol²) / (2·a_cpl·a_fol)
        θ4'     = σ·acos(cos θ4'),  σ = sign sin(θ_arm − θ_crank)
        θ3'     = atan2(r) − atan2(a_fol sin θ4', a_cpl + a_fol cos θ4') − θ_crank

    i.e. the assembly branch continuous with the nominal parallelogram, each angle
    wrapped to the 2π-representative nearest its nominal value (6.10).  Derivatives
    by the implicit-function theorem on ``F = a_crank·e(θ_c) + a_cpl·e(φ3) +
    a_fol·e(φ4) − a_arm·e(θ_a) = 0``: ``∂φ/∂x = −(∂F/∂φ)⁻¹ ∂F/∂x``.

    Parameters
    ----------
    theta_arm, theta_crank : (...) array_like, rad
        DH angles of the arm (θ2) and the crank (θ2').
    a_arm, a_crank, a_coupler, a_follower : (...) array_like, m
        Planar lengths ``a`` of the four loop links.  All arguments broadcast together.
    raise_errors : bool, default True
        With ``False``, failing configurations are marked invalid (NaN angles).
    min_sin : float
        Collapse threshold on ``|sin θ4'|`` and ``|sin(θ_arm − θ_crank)|``.

    Returns
    -------
    ClosureResult
        θ3', θ4' ``(...)`` rad, their derivatives w.r.t. the driven angles and the four
        lengths, and ``valid``.

    Raises
    ------
    LoopClosureError
        If the loop cannot be assembled (``|cos θ4'| > 1``: the coupler and follower
        cannot span the gap) or collapses (sin θ4' ≈ 0 or sin(θ_arm − θ_crank) ≈ 0),
        unless ``raise_errors=False``.
    """
    ta, tc, la, lc, l3, l4 = np.broadcast_arrays(
        *(
            np.asarray(x, float)
            for x in (theta_arm, theta_crank, a_arm, a_crank, a_coupler, a_follower)
        )
    )
    rx = la * np.cos(ta) - lc * np.cos(tc)
    ry = la * np.sin(ta) - lc * np.sin(tc)
    r2 = rx * rx + ry * ry
    sdiff = np.sin(ta - tc)
    c4, t4 = _follower_angle(r2, l3, l4, sdiff)
    cannot = ~(np.abs(c4) <= 1.0)
    s4 = np.sin(t4)
    collapsed = ~cannot & ((np.abs(sdiff) < min_sin) | (np.abs(s4) < min_sin))
    bad = cannot | collapsed
    if raise_errors and np.any(bad):
        raise _closure_error(bad, cannot, r2, l3, l4, ta - tc, t4)
    phi3 = np.arctan2(ry, rx) - np.arctan2(l4 * s4, l3 + l4 * np.cos(t4))
    t3 = phi3 - tc
    diff = ta - tc
    t3 = _wrap_near(t3, diff)
    t4 = _wrap_near(t4, np.pi - diff)
    phi3 = tc + t3
    phi4 = phi3 + t4

    Dq, Da = _implicit_derivatives(ta, tc, la, lc, l3, l4, phi3, phi4, bad)
    return ClosureResult(*_nan_where(bad, t3, t4, Dq, Da), ~bad)


def _closure_error(
    bad: NDArray[np.bool_],
    cannot: NDArray[np.bool_],
    r2: Array,
    l3: Array,
    l4: Array,
    diff: Array,
    t4: Array,
) -> LoopClosureError:
    """The error naming why the first ``bad`` configuration's loop fails.

    Either it cannot be assembled (``cannot``: the gap ``|r| = √r2`` between the crank
    and arm ends lies outside ``[|a_cpl − a_fol|, a_cpl + a_fol]``) or it collapses
    (``sin(θ_arm − θ_crank) ≈ 0`` or ``sin θ4' ≈ 0``).

    Parameters
    ----------
    bad, cannot : (...) bool arrays
        Failing configurations; those that cannot be assembled.
    r2 : (...) array, m²
        ``|r|²``.
    l3, l4 : (...) arrays, m
        Coupler and follower lengths.
    diff, t4 : (...) arrays, rad
        ``θ_arm − θ_crank`` and θ4'.

    Returns
    -------
    LoopClosureError
        With the lengths (m) or angles (degrees) and the configuration's index.
    """
    idx = _first_bad(bad)
    pick = (lambda x: float(x[idx])) if idx is not None else float
    if bool(cannot[idx] if idx is not None else cannot):
        gap = np.sqrt(pick(r2))
        msg = (
            f"the four-bar loop cannot be assembled: the gap between the crank and arm "
            f"ends is {gap:.6g} m but coupler ({pick(l3):.6g} m) and follower "
            f"({pick(l4):.6g} m) span [{abs(pick(l3) - pick(l4)):.6g}, "
            f"{pick(l3) + pick(l4):.6g}] m{_where(idx)}"
        )
    else:
        msg = (
            f"the four-bar loop collapses: arm − crank angle = "
            f"{np.degrees(pick(diff)):.6g}°, follower angle θ4' = "
            f"{np.degrees(pick(t4)):.6g}° (sin ≈ 0){_where(idx)}"
        )
    return LoopClosureError(msg, idx)


def _implicit_derivatives(
    ta: Array,
    tc: Array,
    la: Array,
    lc: Array,
    l3: Array,
    l4: Array,
    phi3: Array,
    phi4: Array,
    bad: NDArray[np.bool_],
) -> tuple[Array, Array]:
    """Derivatives of θ3', θ4' by the implicit-function theorem on the closure.

    ``F(φ3, φ4; θa, θc, a) = a_crank·e(θc) + a_cpl·e(φ3) + a_fol·e(φ4) − a_arm·e(θa) = 0``
    (two equations) gives ``∂φ/∂x = −(∂F/∂φ)⁻¹ ∂F/∂x``, ``∂F/∂φ = [a_cpl·e⊥(φ3),
    a_fol·e⊥(φ4)]`` with determinant ``a_cpl·a_fol·sin(φ4 − φ3)``; then
    ``θ3' = φ3 − θc`` and ``θ4' = φ4 − φ3``.

    Parameters
    ----------
    ta, tc : (...) arrays, rad
        Arm and crank angles θa, θc.
    la, lc, l3, l4 : (...) arrays, m
        Arm, crank, coupler and follower lengths.
    phi3, phi4 : (...) arrays, rad
        Absolute coupler and follower angles φ3 = θc + θ3', φ4 = φ3 + θ4'.
    bad : (...) bool array
        Failing configurations (their determinant is replaced by 1; callers mask them).

    Returns
    -------
    d_angles : (..., 2, 2) array, rad/rad
        Rows (θ3', θ4'), columns (θa, θc).
    d_lengths : (..., 2, 4) array, rad/m
        Rows (θ3', θ4'), columns (a_arm, a_crank, a_cpl, a_fol).
    """
    def perp(phi: Array) -> Array:
        return np.stack([-np.sin(phi), np.cos(phi)], axis=-1)

    def unit(phi: Array) -> Array:
        return np.stack([np.cos(phi), np.sin(phi)], axis=-1)

    M = np.stack([l3[..., None] * perp(phi3), l4[..., None] * perp(phi4)], axis=-1)  # (...,2,2)
    det = l3 * l4 * np.sin(phi4 - phi3)
    det = np.where(bad, 1.0, det)
    Minv = np.empty_like(M)
    Minv[..., 0, 0] = M[..., 1, 1]
    Minv[..., 0, 1] = -M[..., 0, 1]
    Minv[..., 1, 0] = -M[..., 1, 0]
    Minv[..., 1, 1] = M[..., 0, 0]
    Minv /= det[..., None, None]
    # ∂F/∂(θa, θc) and ∂F/∂(a_arm, a_crank, a_cpl, a_fol), columns
    Fq = np.stack([-la[..., None] * perp(ta), lc[..., None] * perp(tc)], axis=-1)
    Fa = np.stack([-unit(ta), unit(tc), unit(phi3), unit(phi4)], axis=-1)
    dphi_dq = -Minv @ Fq  # rows (φ3, φ4)
    dphi_da = -Minv @ Fa
    # θ3' = φ3 − θc, θ4' = φ4 − φ3
    Dq = np.empty_like(dphi_dq)
    Dq[..., 0, 0] = dphi_dq[..., 0, 0]
    Dq[..., 0, 1] = dphi_dq[..., 0, 1] - 1.0
    Dq[..., 1, :] = dphi_dq[..., 1, :] - dphi_dq[..., 0, :]
    Da = np.empty_like(dphi_da)
    Da[..., 0, :] = dphi_da[..., 0, :]
    Da[..., 1, :] = dphi_da[..., 1, :] - dphi_da[..., 0, :]
    return Dq, Da
