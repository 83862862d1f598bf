"""Frames from axes, transform inversion, BASE parametrisation (6.24, D.6), rigid registration."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from plugcell.metrology import (
    MetrologyError,
    base_matrix_from_parameters,
    base_parameters_from_matrix,
    fit_rigid_transform,
    frame_from_axes,
    invert_transform,
)


def _tran(axis: int, d: float) -> np.ndarray:
    T = np.eye(4)
    T[axis, 3] = d
    return T


def _rot(axis: str, a: float) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler(axis, a).as_matrix()
    return T


def _base_product(a0, b0, al, be, th, d0):
    """Eq. 6.24 as the literal product of elementary transforms (independent check)."""
    return (
        _tran(0, a0) @ _tran(1, b0) @ _rot("x", al) @ _rot("y", be) @ _rot("z", th) @ _tran(2, d0)
    )


# ------------------------------------------------------------------ frame_from_axes


def test_frame_from_y_follows_appendix_d():
    z = np.array([0.1, -0.2, 1.0])
    y = np.array([0.05, 1.0, 0.3])  # not perpendicular to z
    T = frame_from_axes([1.0, 2.0, 3.0], z=z, y=y)
    R = T[:3, :3]
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-15)
    assert np.linalg.det(R) == pytest.approx(1.0)
    np.testing.assert_allclose(R[:, 2], z / np.linalg.norm(z), atol=1e-15)  # z kept exactly
    x_expected = np.cross(y, z)
    np.testing.assert_allclose(R[:, 0], x_expected / np.linalg.norm(x_expected), atol=1e-15)
    assert R[:, 1] @ y > 0  # y keeps its sense
    np.testing.assert_allclose(T[:3, 3], [1.0, 2.0, 3.0])
    np.testing.assert_allclose(T[3], [0, 0, 0, 1])


def test_frame_from_x():
    T = frame_from_axes(np.zeros(3), z=[0, 0, 2.0], x=[1.0, 1.0, 0.5])
    np.testing.assert_allclose(T[:3, :3], _rot("z", np.pi / 4)[:3, :3], atol=1e-15)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"z": [0, 0, 1]}, "exactly one of x= or y="),
        ({"z": [0, 0, 1], "x": [1, 0, 0], "y": [0, 1, 0]}, "exactly one of x= or y="),
        ({"z": [0, 0, 1], "y": [0, 0, -3]}, "y is parallel to z"),
        ({"z": [0, 0, 1], "x": [0, 0, 1]}, "x is parallel to z"),
        ({"z": [0, 0, 0], "x": [1, 0, 0]}, "z: zero-length"),
        ({"z": [0, 0, 1], "x": [1, np.nan, 0]}, "x: non-finite"),
    ],
)
def test_frame_from_axes_errors(kwargs, match):
    with pytest.raises(MetrologyError, match=match):
        frame_from_axes(np.zeros(3), **kwargs)


def test_invert_transform_vectorised():
    Rs = Rotation.random(5, random_state=1).as_matrix()
    T = np.tile(np.eye(4), (5, 1, 1))
    T[:, :3, :3] = Rs
    T[:, :3, 3] = np.random.default_rng(1).normal(size=(5, 3))
    np.testing.assert_allclose(invert_transform(T) @ T, np.tile(np.eye(4), (5, 1, 1)), atol=1e-14)
    np.testing.assert_allclose(invert_transform(T[0]), np.linalg.inv(T[0]), atol=1e-14)


# --------------------------------------------------------------- BASE parameters


def test_base_matrix_matches_product_of_elementary_transforms():
    p = (2.5, -1.2, np.radians(3.0), np.radians(-7.0), np.radians(160.0), -0.8)
    np.testing.assert_allclose(base_matrix_from_parameters(*p), _base_product(*p), atol=1e-15)


@settings(max_examples=200, deadline=None, derandomize=True)
@given(
    a0=st.floats(-10, 10), b0=st.floats(-10, 10), d0=st.floats(-5, 5),
    alpha=st.floats(-1.5, 1.5), beta=st.floats(-1.5, 1.5), theta=st.floats(-3.14, 3.14),
)
def test_base_parameters_round_trip(a0, b0, d0, alpha, beta, theta):
    T = base_matrix_from_parameters(a0, b0, alpha, beta, theta, d0)
    p = base_parameters_from_matrix(T)
    np.testing.assert_allclose(
        p.as_array(), [a0, b0, alpha, beta, theta, d0], atol=1e-9 * (1 + abs(d0) / np.cos(alpha))
    )
    np.testing.assert_allclose(p.matrix(), T, atol=1e-12)


def test_base_parameters_vectorised_and_any_rotation_round_trips():
    rng = np.random.default_rng(5)
    T = np.tile(np.eye(4), (50, 1, 1))
    T[:, :3, :3] = Rotation.random(50, random_state=5).as_matrix()
    T[:, :3, 3] = rng.normal(size=(50, 3))
    T = T[np.abs(T[:, 2, 2]) > 0.05]  # away from the singularity
    p = base_parameters_from_matrix(T)
    assert p.as_array().shape == (len(T), 6)
    assert np.all(np.abs(p.beta0) <= np.pi / 2)
    np.testing.assert_allclose(p.matrix(), T, atol=1e-12)


def test_base_parameters_errors():
    with pytest.raises(MetrologyError, match=r"singular .* d0 undefined"):
        base_parameters_from_matrix(_rot("x", np.pi / 2))
    bad = np.eye(4)
    bad[0, 0] = 2.0
    with pytest.raises(MetrologyError, match="not a proper rotation"):
        base_parameters_from_matrix(bad)
    with pytest.raises(MetrologyError, match=r"\(\.\.\., 4, 4\)"):
        base_parameters_from_matrix(np.eye(3))


# ---------------------------------------------------------------- rigid transform


def test_rigid_transform_recovers_pose_under_noise():
    rng = np.random.default_rng(6)
    T = np.eye(4)
    T[:3, :3] = Rotation.random(random_state=6).as_matrix()
    T[:3, 3] = [2.0, -1.0, 0.5]
    a = rng.uniform(-1, 1, (60, 3))
    b = a @ T[:3, :3].T + T[:3, 3] + rng.normal(0, 20e-6, (60, 3))
    fit = fit_rigid_transform(a, b)
    assert np.linalg.norm(fit.translation - T[:3, 3]) < 20e-6
    dR = Rotation.from_matrix(fit.rotation.T @ T[:3, :3]).magnitude()
    assert dR < 2e-5
    assert 20e-6 < fit.rms < 50e-6  # ≈ sqrt(3)·σ·sqrt((N−6)/N)
    np.testing.assert_allclose(fit.residuals, b - fit.apply(a), atol=1e-15)
    np.testing.assert_allclose(fit.inverse() @ fit.transform, np.eye(4), atol=1e-14)


def test_rigid_transform_weights_ignore_an_outlier_and_no_reflection():
    rng = np.random.default_rng(7)
    a = rng.uniform(-1, 1, (10, 3))
    b = a + np.array([0.1, 0.2, 0.3])
    b[0] += 0.05
    w = np.ones(10)
    w[0] = 0.0
    fit = fit_rigid_transform(a, b, weights=w)
    np.testing.assert_allclose(fit.translation, [0.1, 0.2, 0.3], atol=1e-12)
    np.testing.assert_allclose(fit.rotation, np.eye(3), atol=1e-12)
    mirrored = fit_rigid_transform(a, a * [1, 1, -1])
    assert np.linalg.det(mirrored.rotation) == pytest.approx(1.0)


@pytest.mark.parametrize(
    ("a", "b", "kw", "match"),
    [
        (np.zeros((2, 3)), np.zeros((2, 3)), {}, "at least 3 points"),
        (np.eye(3), np.eye(4)[:, :3], {}, "differ in shape"),
        ([[0, 0, 0], [1, 1, 1], [2, 2, 2.0]], [[0, 0, 0], [1, 1, 1], [2, 2, 2.0]], {},
         "collinear"),
        (np.eye(3), np.eye(3), {"weights": [1.0, 1.0, -1.0]}, ">= 0"),
        (np.eye(3), np.eye(3), {"weights": [1.0, 1.0, 0.0]}, "3 positive"),
    ],
)
def test_rigid_transform_errors(a, b, kw, match):
    with pytest.raises(MetrologyError, match=match):
        fit_rigid_transform(a, b, **kw)
