"""The analytic identification Jacobian H(g) (eqs. 4.3, 6.11), exact at any parameter point.

Convention (the project's one, :mod:`plugcell.kinematics.pose_error`): the pose
error is ``Δx = [p_measured − p; φ]`` with φ the small rotation, about the axes of
the measurement frame, taking the predicted orientation to the measured one, and
the translation referenced at the target (TCP) point ``p``.  A column of H is the
derivative of the predicted target pose with respect to one parameter, as
``[ṗ; ω]`` in the measurement frame, so ``Δx ≈ H Δg``.  In this convention the
thesis's open-chain columns (6.12, B.13 — written there for the translation
referenced at the base origin, B.15) become the geometric-Jacobian form::

    H_θi = [z_{i−1} × (p − p_{i−1}); z_{i−1}]      H_di = [z_{i−1}; 0]
    H_ai = [x̃_i; 0]      H_αi = [x̃_i × (p − p_i); x̃_i]      H_βi = [y_i × (p − p_i); y_i]

with ``x̃_i = R_i Ry(−β_i) e_x`` the x axis about which α turns (``x_i`` when β = 0).

**Loop columns** (6.20–6.22, derived exactly): a parameter that acts on the
closure adds ``Σ_k (∂θ_k/∂g) H_θk`` over the passive joints k, the derivatives of
the exact four-bar closure (implicit-function theorem, :mod:`plugcell.kinematics.closure`).
At the nominal parallelogram they are the thesis's constants (6.16) and m_ij
(6.19), e.g. ``H_θ2 = H_θ3' − H_θ4'`` and ``H_a2 = −m11 H_θ3' − m21 H_θ4'``.

**BASE** (6.24, D.5): ``BASE = BASE_ref·Tx(a0)Ty(b0)Rx(α0)Ry(β0)Rz(θ0)Tz(d0)``; a0, b0
translate along the reference x, y axes, α0, β0, θ0 turn about the successive
x, y, z axes through ``o = BASE_ref·(a0, b0, 0)``.  For BASE_ref = I these are
D.5 with the translation moved from the origin to the TCP (``v + ω × p``).

**PROBE** (frame 7): the columns of a DH link whose parent frame is
``F_n·Rx(−90°)`` — θ7 turns about, and d7 translates along, the flange's y axis.

**Compliance** (6.32, 6.42): ``H_c = Σ_j H_qj R_jc(q)`` — the reading-space joint
columns times the regressor (the deflection enters through the readings).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from plugcell.calibration.model import ErrorModel, PoseBatch
from plugcell.kinematics import GeometricParameters, RobotDescription, forward
from plugcell.kinematics.forward import FKResult
from plugcell.kinematics.transforms import cross, dh_hayati, rot_x, rot_y, translation

Array = NDArray[np.float64]

__all__ = ["JacobianResult", "identification_jacobian"]

_FIELDS = ("theta", "d", "a", "alpha", "beta")


@dataclass(frozen=True, eq=False)
class JacobianResult:
    """Predicted poses and the identification Jacobian ``H`` (``Δx ≈ H Δg``) for ``keys``.

    Attributes
    ----------
    poses : (N, 4, 4) array, m
        Predicted target poses ``T = BASE · T_n^0 · PROBE`` (eq. 6.23), measurement frame.
    H : (N, 6, k) array
        Rows: ``[ṗ (m per unit of the parameter); ω (rad per unit)]``; column c is
        ``∂T/∂g_c`` for ``keys[c]``.
    keys : tuple of str
        The parameters of the columns.
    """

    poses: Array
    H: Array
    keys: tuple[str, ...]


def _cat(a: Array, b: Array | None) -> Array:
    return np.concatenate([a, np.zeros_like(a) if b is None else b], axis=-1)


def identification_jacobian(
    model: ErrorModel, batch: PoseBatch, keys: Sequence[str] | None = None
) -> JacobianResult:
    """Analytic identification Jacobian of ``model`` at the readings of ``batch`` (eq. 6.11).

    ``Δx_i ≈ H_i Δg`` with the columns of the module docstring: link columns
    ``H_θ = [z_{i−1} × (p − p_{i−1}); z_{i−1}]``, ``H_d = [z_{i−1}; 0]``, ``H_a = [x̃_i; 0]``,
    ``H_α = [x̃_i × (p − p_i); x̃_i]``, ``H_β = [y_i × (p − p_i); y_i]`` (6.12, B.13), loop
    terms ``Σ_k (∂θ_k/∂g) H_θk`` (6.20–6.22), BASE (D.5), PROBE (frame 7), compliance
    ``H_c = Σ_j H_qj R_jc(q)`` (6.32, 6.42) and thermal ``∂p/∂κT = ΔT · R_B p_fl``.
    Vectorised over poses: one forward-kinematics pass, no loop over poses.

    Parameters
    ----------
    model : ErrorModel
        The model, at its current parameter values (the Jacobian is exact there).
    batch : PoseBatch
        ``N`` joint readings (rad), payloads (kg), regressors and temperatures.
    keys : sequence of str, optional
        The parameters (columns); default every parameter of ``model.space``.

    Returns
    -------
    JacobianResult
        Predicted poses ``(N, 4, 4)`` (m) and ``H`` ``(N, 6, k)``.
    """
    keys = tuple(model.space.keys if keys is None else keys)
    s = model.structure
    desc = s.desc
    params = model.geometric_parameters()
    fk = forward(desc, params, model.chain_joints(batch), closure="fourbar")
    B = model.base()
    frames = fk.frames
    scale = model.thermal_scale(batch)
    if scale is not None:  # every length scaled: the frame origins in the base frame
        frames = frames.copy()
        frames[..., :3, 3] *= scale[:, None, None]
    W = B @ frames  # (N, L, 4, 4) world frames
    N = W.shape[0]
    i_fl = desc.index(desc.flange)
    T_fl = W[:, i_fl]
    T = T_fl @ model.probe()
    p = T[:, :3, 3]

    cols = _link_columns(desc, params, W, B, p, scale)
    if desc.loops:
        _add_closure_terms(desc, fk, cols)
    H = np.empty((N, 6, len(keys)))
    comp_col = _compliance_columns(model, batch, cols, keys)
    base_cols = probe_cols = None
    for c, key in enumerate(keys):
        prm = model.space[key]
        if prm.kind == "link":
            H[:, :, c] = cols[prm.field][:, desc.index(prm.link)]  # type: ignore[index,arg-type]
        elif prm.kind == "base":
            if base_cols is None:
                base_cols = _base_columns(model, p)
            H[:, :, c] = base_cols[prm.field]  # type: ignore[index]
        elif prm.kind == "probe":
            if probe_cols is None:
                probe_cols = _probe_columns(model, T_fl, p)
            H[:, :, c] = probe_cols[prm.field]  # type: ignore[index]
        elif prm.kind == "thermal":
            # ∂p/∂κT = ΔT · R_B p_fl (unscaled flange position in the base frame)
            dT = batch.delta_t(model.temperature_ref_c)
            H[:, :3, c] = dT[:, None] * (B[:3, :3] @ fk.flange[:, :3, 3, None])[..., 0]
            H[:, 3:, c] = 0.0
        else:
            H[:, :, c] = comp_col[key]
    return JacobianResult(poses=T, H=H, keys=keys)


def _link_columns(
    desc: RobotDescription,
    params: GeometricParameters,
    W: Array,
    B: Array,
    p: Array,
    scale: Array | None,
) -> dict[str, Array]:
    """Open-chain columns of every link's five parameters (eqs. 6.12, B.13).

    With ``z_{i−1}``, ``p_{i−1}`` the axis and origin of link i's parent frame, ``x̃_i =
    cos β_i x_i + sin β_i z_i``, ``y_i`` and ``p_i`` of its own frame (world frames)::

        H_θ = [z_{i−1} × (p − p_{i−1}); z_{i−1}]   H_d = [z_{i−1}; 0]   H_a = [x̃_i; 0]
        H_α = [x̃_i × (p − p_i); x̃_i]             H_β = [y_i × (p − p_i); y_i]

    zero for links off the chain to the flange; ``H_d`` and ``H_a`` scaled by the
    thermal ``scale`` (every length is).

    Parameters
    ----------
    desc, params
        The robot and its geometric parameters.
    W : (N, L, 4, 4) array, m
        World frames of the links.
    B : (4, 4) array, m
        The BASE frame (parent of the root links).
    p : (N, 3) array, m
        The probe's world position.
    scale : (N,) array or None
        Thermal length scale ``1 + κT·ΔT`` per pose.

    Returns
    -------
    dict
        Field (``"theta"``, ``"d"``, ``"a"``, ``"alpha"``, ``"beta"``) → ``(N, L, 6)``
        columns (position rows m per unit, rotation rows rad per unit).
    """
    N, L = W.shape[:2]
    parent = np.array(
        [desc.index(lk.parent) if lk.parent != "base" else L for lk in desc.links], dtype=np.intp
    )
    W_ext = np.concatenate([W, np.broadcast_to(B, (N, 1, 4, 4))], axis=1)
    Pf = W_ext[:, parent]
    z, op = Pf[..., :3, 2], Pf[..., :3, 3]
    o = W[..., :3, 3]
    cb, sb = np.cos(params.beta)[:, None], np.sin(params.beta)[:, None]
    xt = W[..., :3, 0] * cb + W[..., :3, 2] * sb
    y = W[..., :3, 1]
    pp = p[:, None, :]
    on_chain = np.zeros(L, dtype=bool)
    on_chain[list(desc.chain)] = True
    m = on_chain[None, :, None]
    cols = {
        "theta": _cat(cross(z, pp - op), z) * m,
        "d": _cat(z, None) * m * (1.0 if scale is None else scale[:, None, None]),
        "a": _cat(xt, None) * m * (1.0 if scale is None else scale[:, None, None]),
        "alpha": _cat(cross(xt, pp - o), xt) * m,
        "beta": _cat(cross(y, pp - o), y) * m,
    }
    return cols


def _add_closure_terms(desc: RobotDescription, fk: FKResult, cols: dict[str, Array]) -> None:
    """Add to ``cols`` the parameters' action through the loops' passive angles (6.20–6.22).

    A passive angle θ_k moves with the driven joints and the loop lengths:
    ``H_θ,j += Σ_k (∂θ_k/∂θ_j) H_θk`` for the actuated links j and ``H_a,l += Σ_k
    (∂θ_k/∂a_l) H_θk`` for every link l (exact four-bar derivatives of ``fk``).
    ``cols``: as :func:`_link_columns` returns, ``(N, L, 6)`` per field, updated in place.
    """
    pidx = [desc.index(n) for n in fk.passive_names]
    Hp = cols["theta"][:, pidx]  # (N, n_p, 6)
    act = [desc.index(n) for n in desc.actuated]
    cols["theta"][:, act] += np.einsum("npj,npk->njk", fk.passive_jacobian, Hp)
    cols["a"] += np.einsum("npl,npk->nlk", fk.passive_d_a, Hp)


def _compliance_columns(
    model: ErrorModel, batch: PoseBatch, cols: dict[str, Array], keys: Sequence[str]
) -> dict[str, Array]:
    """Columns of the joint compliances among ``keys`` (eqs. 6.32, 6.42).

    ``H_c = Σ_j H_qj R_jc(q)``: the column ``H_qj`` of each joint reading (θ of a revolute
    link, d of a prismatic one, through the reading map of a coupling) weighted by the
    compliance regressors ``R`` (N·m per joint and compliance) of ``batch``.

    Returns
    -------
    dict
        Compliance key → its ``(N, 6)`` column (m, rad per rad/(N·m)); empty when
        ``keys`` holds none.
    """
    desc = model.structure.desc
    comp = model.compliance_keys
    want_comp = [k for k in keys if k in comp]
    if not want_comp:
        return {}
    act = [desc.index(n) for n in desc.actuated]
    # a joint's column: θ of a revolute link, d of a prismatic one
    Hj = np.where(desc.prismatic_links[None, :, None], cols["d"][:, act],
                  cols["theta"][:, act])
    Hq = np.swapaxes(Hj, 1, 2) @ model.structure.reading_map  # (N, 6, n_read)
    ci = [comp.index(k) for k in want_comp]
    Hc = Hq @ batch.regressors[:, :, ci]  # (N, 6, n_c)
    return dict(zip(want_comp, np.moveaxis(Hc, -1, 0), strict=True))


def _base_columns(model: ErrorModel, p: Array) -> dict[str, Array]:
    """Columns of a0, b0, α0, β0, θ0, d0 (6.24/D.5 in our convention)."""
    a0, b0, al0, be0, _, _ = model.base_parameters()
    Fa = model.base_ref @ translation([a0, b0, 0.0])
    ob = Fa[:3, 3]
    ex, ey = model.base_ref[:3, 0], model.base_ref[:3, 1]
    Fb = Fa @ rot_x(al0)
    yb = Fb[:3, 1]
    zc = (Fb @ rot_y(be0))[:3, 2]
    r = p - ob
    ones = np.ones((len(p), 1))

    def rot(u: Array) -> Array:
        return np.concatenate([cross(u, r), ones * u], axis=-1)

    def tra(u: Array) -> Array:
        return np.concatenate([ones * u, np.zeros((len(p), 3))], axis=-1)

    return {"a": tra(ex), "b": tra(ey), "alpha": rot(ex), "beta": rot(yb), "theta": rot(zc),
            "d": tra(zc)}


def _probe_columns(model: ErrorModel, T_fl: Array, p: Array) -> dict[str, Array]:
    """Columns of θ7, d7, a7, α7 of the virtual frame 7 (6.2.2)."""
    t7, d7, a7, al7 = model.probe_parameters()
    Pv = T_fl @ rot_x(-0.5 * math.pi)
    F7 = Pv @ dh_hayati(t7, d7, a7, 0.5 * math.pi + al7)
    z, op = Pv[:, :3, 2], Pv[:, :3, 3]
    x, o = F7[:, :3, 0], F7[:, :3, 3]
    return {
        "theta": _cat(cross(z, p - op), z),
        "d": _cat(z, None),
        "a": _cat(x, None),
        "alpha": _cat(cross(x, p - o), x),
    }
