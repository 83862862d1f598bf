"""Homogeneous transforms and the rotation group SO(3).

Every function broadcasts over leading axes: an angle array of shape ``(...)``
gives transforms of shape ``(..., 4, 4)``.  Units are SI (metres, radians).

The link transform is the DH + Hayati form of thesis eq. (4.13)/(B.1)::

    T_i^{i-1} = Rot(z, θ) · Tran(z, d) · Tran(x, a) · Rot(x, α) · Rot(y, β)

which reduces to the plain Denavit–Hartenberg link (A.2) for β = 0.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]

__all__ = [
    "cross",
    "dh_hayati",
    "identity",
    "invert",
    "rot_x",
    "rot_y",
    "rot_z",
    "skew",
    "so3_exp",
    "so3_log",
    "translation",
    "vee",
]


def _f(x: ArrayLike) -> Array:
    return np.asarray(x, dtype=float)


def identity(shape: tuple[int, ...] = ()) -> Array:
    """Identity transforms, ``T = I₄``, one per index of ``shape``.

    Parameters
    ----------
    shape : tuple of int
        Batch shape ``(...)``; ``()`` for a single transform.

    Returns
    -------
    T : (..., 4, 4) array
        Identity homogeneous transforms (a fresh, writable copy).
    """
    return np.broadcast_to(np.eye(4), (*shape, 4, 4)).copy()


def _rot(a: ArrayLike, axis: int) -> Array:
    a = _f(a)
    c, s = np.cos(a), np.sin(a)
    T = np.zeros((*a.shape, 4, 4))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    T[..., axis, axis] = 1.0
    T[..., i, i] = c
    T[..., j, j] = c
    T[..., i, j] = -s
    T[..., j, i] = s
    T[..., 3, 3] = 1.0
    return T


def rot_x(a: ArrayLike) -> Array:
    """Homogeneous rotation about x, ``Rx(a) = [R 0; 0 1]``.

    ``R = [[1, 0, 0], [0, cos a, −sin a], [0, sin a, cos a]]``
    (right-handed: positive counter-clockwise seen from +x).

    Parameters
    ----------
    a : (...) array_like, rad
        Rotation angles.

    Returns
    -------
    T : (..., 4, 4) array
        Rotation transforms (no translation).
    """
    return _rot(a, 0)


def rot_y(a: ArrayLike) -> Array:
    """Homogeneous rotation about y, ``Ry(a) = [R 0; 0 1]``.

    ``R = [[cos a, 0, sin a], [0, 1, 0], [−sin a, 0, cos a]]``
    (right-handed: positive counter-clockwise seen from +y).

    Parameters
    ----------
    a : (...) array_like, rad
        Rotation angles.

    Returns
    -------
    T : (..., 4, 4) array
        Rotation transforms (no translation).
    """
    return _rot(a, 1)


def rot_z(a: ArrayLike) -> Array:
    """Homogeneous rotation about z, ``Rz(a) = [R 0; 0 1]``.

    ``R = [[cos a, −sin a, 0], [sin a, cos a, 0], [0, 0, 1]]``
    (right-handed: positive counter-clockwise seen from +z).

    Parameters
    ----------
    a : (...) array_like, rad
        Rotation angles.

    Returns
    -------
    T : (..., 4, 4) array
        Rotation transforms (no translation).
    """
    return _rot(a, 2)


def translation(v: ArrayLike) -> Array:
    """Pure translation, ``T = [I₃ v; 0 1]``.

    Parameters
    ----------
    v : (..., 3) array_like, m
        Translation vectors.

    Returns
    -------
    T : (..., 4, 4) array, m
        Translation transforms.

    Raises
    ------
    ValueError
        If the last axis of ``v`` is not 3.
    """
    v = _f(v)
    if v.shape[-1:] != (3,):
        raise ValueError(f"translation: expected shape (..., 3), got {v.shape}")
    T = identity(v.shape[:-1])
    T[..., :3, 3] = v
    return T


def invert(T: ArrayLike) -> Array:
    """Inverse of rigid transforms, ``T⁻¹ = [Rᵀ  −Rᵀp; 0 1]`` for ``T = [R p; 0 1]``.

    Exact only for rigid transforms (``R`` orthonormal); the bottom row is not read.

    Parameters
    ----------
    T : (..., 4, 4) array_like, m
        Rigid transforms.

    Returns
    -------
    T_inv : (..., 4, 4) array, m
        Their inverses.
    """
    T = _f(T)
    R = T[..., :3, :3]
    p = T[..., :3, 3]
    Ti = np.zeros_like(T)
    Rt = np.swapaxes(R, -1, -2)
    Ti[..., :3, :3] = Rt
    Ti[..., :3, 3] = -np.einsum("...ij,...j->...i", Rt, p)
    Ti[..., 3, 3] = 1.0
    return Ti


def dh_hayati(
    theta: ArrayLike,
    d: ArrayLike,
    a: ArrayLike,
    alpha: ArrayLike,
    beta: ArrayLike = 0.0,
) -> Array:
    """DH + Hayati link transform, thesis eq. (B.1) (β = 0 gives the DH link A.2).

    ``A(θ, d, a, α, β) = Rz(θ) · Tz(d) · Tx(a) · Rx(α) · Ry(β)``, i.e. rotation
    ``R = Rz(θ) Rx(α) Ry(β)`` and translation ``p = (a cos θ, a sin θ, d)``.
    All arguments broadcast together.

    Parameters
    ----------
    theta : (...) array_like, rad
        Joint angle θ about z.
    d : (...) array_like, m
        Offset along z.
    a : (...) array_like, m
        Link length along the new x.
    alpha : (...) array_like, rad
        Twist α about the new x.
    beta : (...) array_like, rad
        Hayati twist β about the new y (0: plain DH).

    Returns
    -------
    T : (..., 4, 4) array, m
        Link transforms ``T_i^{i-1}``, shape ``broadcast_shape + (4, 4)``.
    """
    theta, d, a, alpha, beta = np.broadcast_arrays(_f(theta), _f(d), _f(a), _f(alpha), _f(beta))
    ct, st = np.cos(theta), np.sin(theta)
    ca, sa = np.cos(alpha), np.sin(alpha)
    cb, sb = np.cos(beta), np.sin(beta)
    T = np.zeros((*theta.shape, 4, 4))
    T[..., 0, 0] = ct * cb - st * sa * sb
    T[..., 0, 1] = -st * ca
    T[..., 0, 2] = ct * sb + st * sa * cb
    T[..., 0, 3] = a * ct
    T[..., 1, 0] = st * cb + ct * sa * sb
    T[..., 1, 1] = ct * ca
    T[..., 1, 2] = st * sb - ct * sa * cb
    T[..., 1, 3] = a * st
    T[..., 2, 0] = -ca * sb
    T[..., 2, 1] = sa
    T[..., 2, 2] = ca * cb
    T[..., 2, 3] = d
    T[..., 3, 3] = 1.0
    return T


#: The components of ``a × b``: (k, i, j) with ``(a × b)_k = a_i b_j − a_j b_i``.
_CROSS = ((0, 1, 2), (1, 2, 0), (2, 0, 1))


def cross(a: ArrayLike, b: ArrayLike, axis: int = -1) -> Array:
    """Cross product of 3-vectors along ``axis``, broadcasting the other axes.

    ``a × b = (a₁b₂ − a₂b₁, a₂b₀ − a₀b₂, a₀b₁ − a₁b₀)``, computed as
    :func:`numpy.cross` computes it (the same products and differences, so the same
    result to the last bit) without its axis handling, which costs tens of µs a call: a
    real-time cycle's Jacobians call it dozens of times.

    Parameters
    ----------
    a, b : (..., 3, ...) array_like
        The vectors; their length-3 axis is ``axis`` (negative counts from the end, as
        the other axes broadcast).
    axis : int
        The vectors' axis in ``a``, ``b`` and the result.

    Returns
    -------
    c : array
        ``a × b``, shape the broadcast of ``a`` and ``b``.

    Raises
    ------
    ValueError
        ``a`` or ``b`` has no length-3 axis ``axis``, or they do not broadcast.
    """
    a, b = _f(a), _f(b)
    if (a.size == b.size == 3 and a.shape[-1:] == b.shape[-1:] == (3,)
            and (axis == -1 or axis == a.ndim - 1 == b.ndim - 1)):  # one pair: floats
        (a0, a1, a2), (b0, b1, b2) = a.reshape(3).tolist(), b.reshape(3).tolist()
        out = np.array([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0])
        return out.reshape((1,) * (max(a.ndim, b.ndim) - 1) + (3,))
    axes = []
    for name, x in (("a", a), ("b", b)):
        if not -x.ndim <= axis < x.ndim or x.shape[axis] != 3:
            raise ValueError(f"cross: {name} of shape {x.shape} has no length-3 axis {axis}")
        axes.append(axis - x.ndim if axis >= 0 else axis)
    if axes[0] != axes[1]:
        raise ValueError(f"cross: axis {axis} is not the same axis from the end of shapes "
                         f"{a.shape} and {b.shape}")
    tail = (slice(None),) * (-axes[0] - 1)
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    for k, i, j in _CROSS:
        ai, aj, bi, bj = (x[(..., m, *tail)] for x, m in ((a, i), (a, j), (b, i), (b, j)))
        out[(..., k, *tail)] = ai * bj - aj * bi
    return out


def skew(v: ArrayLike) -> Array:
    """Skew-symmetric matrix ``[v]×`` with ``[v]× u = v × u``.

    ``[v]× = [[0, −v_z, v_y], [v_z, 0, −v_x], [−v_y, v_x, 0]]``.

    Parameters
    ----------
    v : (..., 3) array_like
        Vectors (any unit; the result has the same).

    Returns
    -------
    S : (..., 3, 3) array
        Their cross-product matrices.
    """
    v = _f(v)
    S = np.zeros((*v.shape[:-1], 3, 3))
    S[..., 0, 1] = -v[..., 2]
    S[..., 0, 2] = v[..., 1]
    S[..., 1, 0] = v[..., 2]
    S[..., 1, 2] = -v[..., 0]
    S[..., 2, 0] = -v[..., 1]
    S[..., 2, 1] = v[..., 0]
    return S


def vee(S: ArrayLike) -> Array:
    """Inverse of :func:`skew` applied to the skew-symmetric part of ``S``.

    ``v = ½ (S₂₁ − S₁₂, S₀₂ − S₂₀, S₁₀ − S₀₁)``, so ``vee(skew(v)) = v`` and the
    symmetric part of ``S`` is ignored.

    Parameters
    ----------
    S : (..., 3, 3) array_like
        Matrices (skew-symmetric up to noise).

    Returns
    -------
    v : (..., 3) array
        The vectors of their skew-symmetric parts.
    """
    S = _f(S)
    return 0.5 * np.stack(
        [S[..., 2, 1] - S[..., 1, 2], S[..., 0, 2] - S[..., 2, 0], S[..., 1, 0] - S[..., 0, 1]],
        axis=-1,
    )


def so3_exp(w: ArrayLike) -> Array:
    """Rotation matrix of the rotation vector ``w`` (Rodrigues' formula).

    ``R = exp([w]×) = I + (sin θ/θ) [w]× + ((1 − cos θ)/θ²) [w]×²`` with
    ``θ = ‖w‖``; Taylor series of both coefficients for θ < 1e-4.

    Parameters
    ----------
    w : (..., 3) array_like, rad
        Rotation vectors (axis × angle).

    Returns
    -------
    R : (..., 3, 3) array
        Rotation matrices.
    """
    w = _f(w)
    th2 = np.sum(w * w, axis=-1)
    th = np.sqrt(th2)
    small = th < 1e-4
    ths = np.where(small, 1.0, th)
    A = np.where(small, 1.0 - th2 / 6.0 + th2 * th2 / 120.0, np.sin(ths) / ths)
    B = np.where(small, 0.5 - th2 / 24.0 + th2 * th2 / 720.0, (1.0 - np.cos(ths)) / ths**2)
    K = skew(w)
    return np.eye(3) + A[..., None, None] * K + B[..., None, None] * (K @ K)


def _matrix_to_quat(R: Array) -> Array:
    """Unit quaternions ``(w, x, y, z)`` with ``w ≥ 0`` by Shepperd's method (robust)."""
    if R.shape[-2:] == (3, 3) and R.size == 9:  # one rotation, however batched
        one = _matrix_to_quat_one(R.reshape(3, 3))
        if one is not None:
            return one.reshape(*R.shape[:-2], 4)
    m00, m11, m22 = R[..., 0, 0], R[..., 1, 1], R[..., 2, 2]
    tr = m00 + m11 + m22
    cand = np.stack([tr, m00, m11, m22], axis=-1)
    k = np.argmax(cand, axis=-1)
    q = np.empty((*R.shape[:-2], 4))
    # case 0: w largest
    t0 = np.sqrt(np.maximum(1.0 + tr, 0.0)) * 2.0  # 4w
    t1 = np.sqrt(np.maximum(1.0 + m00 - m11 - m22, 0.0)) * 2.0  # 4x
    t2 = np.sqrt(np.maximum(1.0 - m00 + m11 - m22, 0.0)) * 2.0  # 4y
    t3 = np.sqrt(np.maximum(1.0 - m00 - m11 + m22, 0.0)) * 2.0  # 4z
    r21_12 = R[..., 2, 1] - R[..., 1, 2]
    r02_20 = R[..., 0, 2] - R[..., 2, 0]
    r10_01 = R[..., 1, 0] - R[..., 0, 1]
    r01_10 = R[..., 0, 1] + R[..., 1, 0]
    r02p20 = R[..., 0, 2] + R[..., 2, 0]
    r12_21 = R[..., 1, 2] + R[..., 2, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        q0 = np.stack([t0 / 4, r21_12 / t0, r02_20 / t0, r10_01 / t0], axis=-1)
        q1 = np.stack([r21_12 / t1, t1 / 4, r01_10 / t1, r02p20 / t1], axis=-1)
        q2 = np.stack([r02_20 / t2, r01_10 / t2, t2 / 4, r12_21 / t2], axis=-1)
        q3 = np.stack([r10_01 / t3, r02p20 / t3, r12_21 / t3, t3 / 4], axis=-1)
    q = np.where((k == 0)[..., None], q0, q)
    q = np.where((k == 1)[..., None], q1, q)
    q = np.where((k == 2)[..., None], q2, q)
    q = np.where((k == 3)[..., None], q3, q)
    q = np.where((q[..., :1] < 0), -q, q)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def _matrix_to_quat_one(R: Array) -> Array | None:
    """:func:`_matrix_to_quat` of one rotation on floats: only the case Shepperd's method
    picks (the largest of the trace and the diagonal, the first of equals), the same
    operations in the same order, so the same quaternion — without numpy's per-call
    cost of the four cases, a real-time cycle's pose errors call it dozens of times.
    ``None`` for a matrix no rotation is near (the picked ``4|q_k|`` not positive, or
    not finite): the array code gives what it gives."""
    (m00, m01, m02), (m10, m11, m12), (m20, m21, m22) = R.tolist()
    tr = m00 + m11 + m22
    cand = (tr, m00, m11, m22)
    k = cand.index(max(cand))
    d = (1.0 + tr, 1.0 + m00 - m11 - m22, 1.0 - m00 + m11 - m22, 1.0 - m00 - m11 + m22)[k]
    t = math.sqrt(max(d, 0.0)) * 2.0  # 4|q_k|
    if not 0.0 < t < math.inf:
        return None
    r21_12, r02_20, r10_01 = m21 - m12, m02 - m20, m10 - m01
    r01_10, r02p20, r12_21 = m01 + m10, m02 + m20, m12 + m21
    if k == 0:
        q = [t / 4, r21_12 / t, r02_20 / t, r10_01 / t]
    elif k == 1:
        q = [r21_12 / t, t / 4, r01_10 / t, r02p20 / t]
    elif k == 2:
        q = [r02_20 / t, r01_10 / t, t / 4, r12_21 / t]
    else:
        q = [r10_01 / t, r02p20 / t, r12_21 / t, t / 4]
    out = np.array(q)
    if out[0] < 0:
        out = -out
    return out / np.linalg.norm(out, axis=-1, keepdims=True)


def so3_log(R: ArrayLike) -> Array:
    """Rotation vector of ``R``, ``w = log(R)∨ = θ·u`` with angle θ in [0, π].

    Computed from the unit quaternion ``(q_w, q_v)`` (Shepperd's method, ``q_w ≥ 0``):
    ``θ = 2 atan2(‖q_v‖, q_w)``, ``w = θ · q_v / ‖q_v‖`` (→ ``2 q_v / q_w`` for small
    ``‖q_v‖``).  Robust near 0 and near π, where the quaternion's vector part is well
    conditioned.  At exactly π the sign of the axis is that of the quaternion
    Shepperd's method returns — deterministic.

    Parameters
    ----------
    R : (..., 3, 3) array_like
        Rotation matrices.

    Returns
    -------
    w : (..., 3) array, rad
        Rotation vectors, ``‖w‖ ≤ π``.
    """
    R = _f(R)
    q = _matrix_to_quat(R)
    w = q[..., 0]
    v = q[..., 1:]
    n = np.linalg.norm(v, axis=-1)
    angle = 2.0 * np.arctan2(n, w)
    small = n < 1e-8
    ns = np.where(small, 1.0, n)
    # angle / n → 2/w (1 + O(n²)) for small n (w ≈ 1)
    scale = np.where(small, 2.0 / np.where(small, w, 1.0), angle / ns)
    return scale[..., None] * v
