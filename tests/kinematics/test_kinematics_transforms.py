"""Homogeneous transforms, the DH/Hayati link (A.2, B.1) and SO(3) exp/log."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from scipy.spatial.transform import Rotation

from plugcell.kinematics import (
    cross,
    dh_hayati,
    invert,
    rot_x,
    rot_y,
    rot_z,
    skew,
    so3_exp,
    so3_log,
    translation,
    vee,
)

RNG = np.random.default_rng(7)


@pytest.mark.parametrize(("fn", "axis"), [(rot_x, "x"), (rot_y, "y"), (rot_z, "z")])
def test_elementary_rotations_match_scipy(fn, axis):
    a = RNG.uniform(-4, 4, 50)
    T = fn(a)
    assert T.shape == (50, 4, 4)
    np.testing.assert_allclose(
        T[:, :3, :3], Rotation.from_euler(axis, a[:, None]).as_matrix(), atol=1e-15
    )
    np.testing.assert_array_equal(T[:, 3], np.tile([0, 0, 0, 1.0], (50, 1)))
    np.testing.assert_array_equal(T[:, :3, 3], 0.0)


def test_broadcasting_shapes():
    assert rot_z(0.3).shape == (4, 4)
    assert rot_x(np.zeros((2, 3))).shape == (2, 3, 4, 4)
    assert translation(np.zeros((5, 3))).shape == (5, 4, 4)
    assert dh_hayati(np.zeros((2, 1)), 0.1, np.zeros(4), 0.0).shape == (2, 4, 4, 4)
    with pytest.raises(ValueError, match=r"\(\.\.\., 3\)"):
        translation(np.zeros(2))


def test_invert_is_inverse():
    T = (
        translation(RNG.normal(size=(20, 3)))
        @ rot_x(RNG.normal(size=20))
        @ rot_z(RNG.normal(size=20))
    )
    np.testing.assert_allclose(invert(T) @ T, np.broadcast_to(np.eye(4), T.shape), atol=1e-14)
    np.testing.assert_allclose(invert(T), np.linalg.inv(T), atol=1e-13)


def test_dh_hayati_is_composition_of_elementary_transforms():
    n = 200
    th, d, a, al, be = (RNG.uniform(-3, 3, n) for _ in range(5))
    T = dh_hayati(th, d, a, al, be)
    ref = (
        rot_z(th)
        @ translation(np.stack([0 * d, 0 * d, d], -1))
        @ translation(np.stack([a, 0 * a, 0 * a], -1))
        @ rot_x(al)
        @ rot_y(be)
    )
    np.testing.assert_allclose(T, ref, atol=1e-14)


def test_dh_without_beta_is_eq_A2():
    th, d, a, al = 0.7, 0.2, 1.1, -0.4
    c, s, ca, sa = np.cos(th), np.sin(th), np.cos(al), np.sin(al)
    A2 = np.array(
        [[c, -s * ca, s * sa, a * c], [s, c * ca, -c * sa, a * s], [0, sa, ca, d], [0, 0, 0, 1]]
    )
    np.testing.assert_allclose(dh_hayati(th, d, a, al), A2, atol=1e-15)
    np.testing.assert_allclose(dh_hayati(th, d, a, al, 0.0), A2, atol=1e-15)


def test_skew_vee():
    v = RNG.normal(size=(10, 3))
    u = RNG.normal(size=(10, 3))
    np.testing.assert_allclose(
        np.einsum("...ij,...j->...i", skew(v), u), np.cross(v, u), atol=1e-15
    )
    np.testing.assert_allclose(vee(skew(v)), v, atol=1e-15)


def test_so3_exp_matches_scipy_and_log_inverts_it():
    w = RNG.normal(size=(500, 3))
    w *= (RNG.uniform(0, np.pi - 1e-6, 500) / np.linalg.norm(w, axis=1))[:, None]
    R = so3_exp(w)
    np.testing.assert_allclose(R, Rotation.from_rotvec(w).as_matrix(), atol=1e-14)
    np.testing.assert_allclose(so3_log(R), w, atol=1e-9)


@pytest.mark.parametrize("angle", [0.0, 1e-12, 1e-9, 1e-6, 1e-3, np.pi - 1e-3, np.pi - 1e-7, np.pi])
def test_so3_log_robust_near_zero_and_pi(angle):
    axes = RNG.normal(size=(50, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    w = axes * angle
    R = Rotation.from_rotvec(w).as_matrix()
    got = so3_log(R)
    assert np.all(np.isfinite(got))
    # same rotation back, angle preserved (at π the axis sign is free)
    np.testing.assert_allclose(so3_exp(got), R, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(got, axis=1), angle, atol=1e-9)
    if angle < 3.0:
        np.testing.assert_allclose(got, w, atol=1e-12 + 1e-9 * angle)


# -------------------------------------------------------------------------- cross
@st.composite
def _cross_pairs(draw):
    """Two arrays with a length-3 axis at the same place from the end, broadcasting."""
    batch = draw(hnp.array_shapes(min_dims=0, max_dims=3, min_side=1, max_side=4))
    tail = draw(hnp.array_shapes(min_dims=0, max_dims=2, min_side=1, max_side=3))
    axis = -1 - len(tail)
    shapes = hnp.mutually_broadcastable_shapes(num_shapes=2, base_shape=batch + tail)
    sa, sb = draw(shapes).input_shapes

    def with_vector(s):  # the length-3 axis put back in front of the tail
        cut = len(s) - len(tail) if len(s) >= len(tail) else 0
        return (*s[:cut], 3, *s[cut:]) if len(s) >= len(tail) else (3, *tail)

    values = st.floats(-1e3, 1e3, allow_nan=False)
    a = draw(hnp.arrays(np.float64, with_vector(sa), elements=values))
    b = draw(hnp.arrays(np.float64, with_vector(sb), elements=values))
    return a, b, axis


@given(_cross_pairs())
def test_cross_is_numpys_to_the_last_bit(pair):
    """``cross`` computes numpy.cross's products and differences: the same bits, any
    shapes that broadcast, any axis from the end (the one-pair path included)."""
    a, b, axis = pair
    np.testing.assert_array_equal(cross(a, b, axis=axis), np.cross(a, b, axis=axis))


def test_cross_of_one_pair_and_its_refusals():
    a, b = RNG.normal(size=3), RNG.normal(size=3)
    assert np.array_equal(cross(a, b), np.cross(a, b))
    for sa, sb in (((1, 3), (3,)), ((3,), (1, 1, 3)), ((1, 3), (1, 3))):  # one pair, batched
        got = cross(a.reshape(sa), b.reshape(sb))
        assert np.array_equal(got, np.cross(a.reshape(sa), b.reshape(sb))), (sa, sb)
        assert got.shape == np.broadcast_shapes(sa, sb)
    np.testing.assert_allclose(cross(a, b) @ a, 0.0, atol=1e-12)  # ⟂ to both
    np.testing.assert_allclose(cross(a, b), skew(a) @ b, atol=1e-12)
    with pytest.raises(ValueError, match=r"cross: a of shape \(2,\) has no length-3 axis -1"):
        cross([1.0, 2.0], [1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="cross: b of shape"):
        cross(np.ones((3, 2)), np.ones(3), axis=-2)
    with pytest.raises(ValueError, match="is not the same axis from the end"):
        cross(np.ones((3, 5)), np.ones(3), axis=0)
    with pytest.raises(ValueError, match=r"a of shape \(3,\) has no length-3 axis 1"):
        cross(np.ones(3), np.ones((1, 3)), axis=1)  # one pair, an axis one of them lacks


_ROTVEC = hnp.arrays(np.float64, 3, elements=st.floats(-4.0, 4.0, allow_nan=False))


@given(w=_ROTVEC, scale=st.sampled_from([1.0, 1e-9, 1e-5, "pi"]))
def test_so3_log_of_one_rotation_is_the_batchs_to_the_last_bit(w, scale):
    """One rotation takes the float path of Shepperd's method (one case, not four): the
    same rotation vector as its row in a batch, bit for bit, near 0 and π too."""
    if scale == "pi":
        n = np.linalg.norm(w)
        w = w / n * np.pi if n > 1e-3 else np.array([np.pi, 0.0, 0.0])
    else:
        w = w * scale
    R = so3_exp(np.stack([w, 0.5 * w + 0.1, -w]))
    batch = so3_log(R)
    for i in range(3):
        np.testing.assert_array_equal(so3_log(R[i]), batch[i])
        one = so3_log(R[i][None, None])  # one rotation in a batch of one
        assert one.shape == (1, 1, 3)
        np.testing.assert_array_equal(one[0, 0], batch[i])


def test_so3_log_of_one_matrix_far_from_any_rotation_is_the_batchs():
    """Axis-aligned half turns (ties of Shepperd's cases), −I, zeros, NaN and inf: one
    matrix gives what its row in a batch gives (the array code, NaN where it fails)."""
    R = np.stack([np.diag([1.0, -1.0, -1.0]), np.diag([-1.0, 1.0, -1.0]),
                  np.diag([-1.0, -1.0, 1.0]), -np.eye(3), np.zeros((3, 3)),
                  np.full((3, 3), np.nan), np.full((3, 3), np.inf), np.eye(3)])
    with np.errstate(all="ignore"):
        batch = so3_log(R)
        for i in range(len(R)):
            np.testing.assert_array_equal(so3_log(R[i]), batch[i])
