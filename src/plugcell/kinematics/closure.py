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

import math
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

    def reshaped(self, shape: tuple[int, ...]) -> ClosureResult:
        """The same closure of one configuration with batch ``shape`` (of size 1)."""
        if not shape:
            return self
        return ClosureResult(self.coupler.reshape(shape), self.follower.reshape(shape),
                             self.d_driven.reshape(*shape, 2, 2),
                             self.d_lengths.reshape(*shape, 2, 4), self.valid.reshape(shape))


#: ∂(θ3', θ4')/∂(θ2, θ2') of the parallelogram, eq. (6.16)
_NOMINAL_D = np.array([[1.0, -1.0], [-1.0, 1.0]])
_NOMINAL_D.setflags(write=False)


def _wrap_near(x: Array, ref: Array) -> Array:
    """The 2π-representative of ``x`` nearest ``ref`` (arrays or floats alike)."""
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
    if np.size(theta_arm) == np.size(theta_crank) == 1:  # one configuration: floats
        diff = float(np.reshape(theta_arm, -1)[0]) - float(np.reshape(theta_crank, -1)[0])
        if abs(math.sin(diff)) >= min_sin:
            return ClosureResult(np.array(diff), np.array(np.pi - diff), _NOMINAL_D.copy(),
                                 np.zeros((2, 4)), np.array(True)).reshaped(
                (1,) * max(np.ndim(theta_arm), np.ndim(theta_crank)))
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
    D = np.broadcast_to(_NOMINAL_D, (*ta.shape, 2, 2)).copy()
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
    a_fol·e(φ4) − a_arm·e(θ_a) = 0``: ``∂φ/∂x = −(∂F/∂φ)⁻¹ ∂F/∂x``.  One
    configuration (arguments of size 1, any shape) is computed on floats
    (:func:`_fourbar_point`), with the same result.

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
    args = (theta_arm, theta_crank, a_arm, a_crank, a_coupler, a_follower)
    if all(np.size(x) == 1 for x in args):  # one configuration, however batched
        point = _fourbar_point(*(float(np.reshape(x, -1)[0]) for x in args), min_sin)
        if point is not None:
            return point.reshaped((1,) * max(np.ndim(x) for x in args))
    ta, tc, la, lc, l3, l4 = np.broadcast_arrays(*(np.asarray(x, float) for x in args))
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


def _fourbar_point(ta: float, tc: float, la: float, lc: float, l3: float, l4: float,
                   min_sin: float) -> ClosureResult | None:
    """:func:`fourbar_closure` of one configuration in floats, or ``None`` if it fails.

    The same equations in the same order (C.1–C.2, the wrap, the closed-form
    derivatives of :func:`_implicit_derivatives`), with :mod:`math` on floats instead of
    numpy on 0-d arrays: a single configuration — every cycle of a real-time loop —
    costs a third or less (benchmarks/kinematics_cycle.py).  A loop that cannot assemble or
    collapses returns ``None``, and the array code names the reason (or marks it
    invalid).
    """
    rx = la * math.cos(ta) - lc * math.cos(tc)
    ry = la * math.sin(ta) - lc * math.sin(tc)
    r2 = rx * rx + ry * ry
    sdiff = math.sin(ta - tc)
    if l3 == 0.0 or l4 == 0.0:
        return None
    c4 = (r2 - l3 * l3 - l4 * l4) / (2.0 * l3 * l4)
    if not abs(c4) <= 1.0:
        return None
    t4 = (1.0 if sdiff >= 0.0 else -1.0) * math.acos(c4)
    s4 = math.sin(t4)
    if abs(sdiff) < min_sin or abs(s4) < min_sin:
        return None
    phi3 = math.atan2(ry, rx) - math.atan2(l4 * s4, l3 + l4 * math.cos(t4))
    diff = ta - tc
    t3 = _wrap_near(phi3 - tc, diff)
    t4 = _wrap_near(t4, math.pi - diff)
    phi3 = tc + t3
    phi4 = phi3 + t4
    S = math.sin(phi4 - phi3)
    g3 = -1.0 / (l3 * S)
    g4 = 1.0 / (l4 * S)
    d3 = (la * math.sin(ta - phi4) * g3, lc * math.sin(phi4 - tc) * g3)
    d4 = (la * math.sin(ta - phi3) * g4, lc * math.sin(phi3 - tc) * g4)
    c34 = math.cos(phi4 - phi3)
    a3 = (-math.cos(ta - phi4) * g3, math.cos(tc - phi4) * g3, c34 * g3, 1.0 * g3)
    a4 = (-math.cos(ta - phi3) * g4, math.cos(tc - phi3) * g4, 1.0 * g4, c34 * g4)
    Dq = np.array([d3, (d4[0] - d3[0], d4[1] - d3[1])])
    Dq[0, 1] -= 1.0
    Da = np.array([a3, [x - y for x, y in zip(a4, a3, strict=True)]])
    return ClosureResult(np.array(t3), np.array(t4), Dq, Da, np.array(True))


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
    (two equations) gives ``∂φ/∂x = −(∂F/∂φ)⁻¹ ∂F/∂x`` with ``∂F/∂φ = [a_cpl·e⊥(φ3),
    a_fol·e⊥(φ4)]``, ``e⊥(φ) = (−sin φ, cos φ)``, determinant ``a_cpl·a_fol·S``,
    ``S = sin(φ4 − φ3)``.  Its inverse in closed form: for a column ``f = ∂F/∂x``::

        ∂φ3/∂x = −e(φ4)·f / (a_cpl·S),    ∂φ4/∂x = e(φ3)·f / (a_fol·S)

    and the columns ``f`` are ``a_arm·(sin θa, −cos θa)`` (θa), ``a_crank·e⊥(θc)``
    (θc), ``−e(θa)``, ``e(θc)``, ``e(φ3)``, ``e(φ4)`` (the four lengths), so every
    entry is a sine or cosine of an angle difference over ``a·S``; then
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
        Failing configurations (their ``S`` is replaced by 1; callers mask them).

    Returns
    -------
    d_angles : (..., 2, 2) array, rad/rad
        Rows (θ3', θ4'), columns (θa, θc).
    d_lengths : (..., 2, 4) array, rad/m
        Rows (θ3', θ4'), columns (a_arm, a_crank, a_cpl, a_fol).
    """
    S = np.where(bad, 1.0, np.sin(phi4 - phi3))
    g3 = -1.0 / (l3 * S)  # ∂φ3/∂x = g3·e(φ4)·f
    g4 = 1.0 / (l4 * S)  # ∂φ4/∂x = g4·e(φ3)·f
    # e(φ)·f for each column f: a difference of angles' sine or cosine
    d3 = np.stack([la * np.sin(ta - phi4), lc * np.sin(phi4 - tc)], axis=-1) * g3[..., None]
    d4 = np.stack([la * np.sin(ta - phi3), lc * np.sin(phi3 - tc)], axis=-1) * g4[..., None]
    c34 = np.cos(phi4 - phi3)
    a3 = np.stack([-np.cos(ta - phi4), np.cos(tc - phi4), c34, np.ones_like(c34)],
                  axis=-1) * g3[..., None]
    a4 = np.stack([-np.cos(ta - phi3), np.cos(tc - phi3), np.ones_like(c34), c34],
                  axis=-1) * g4[..., None]
    # θ3' = φ3 − θc, θ4' = φ4 − φ3
    Dq = np.stack([d3, d4 - d3], axis=-2)
    Dq[..., 0, 1] -= 1.0
    Da = np.stack([a3, a4 - a3], axis=-2)
    return Dq, Da
