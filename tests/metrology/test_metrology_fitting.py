"""Best-fit line, plane and circle: accuracy, conventions, degenerate input."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from plugcell.metrology import MetrologyError, fit_circle, fit_line, fit_plane


def _random_rotation(seed: int) -> np.ndarray:
    return Rotation.random(random_state=seed).as_matrix()


# ---------------------------------------------------------------------------- line


def test_line_recovers_direction_and_distances():
    rng = np.random.default_rng(1)
    d = np.array([1.0, 2.0, -0.5]) / np.linalg.norm([1.0, 2.0, -0.5])
    p0 = np.array([2.0, -1.0, 0.3])
    t = np.linspace(-0.6, 0.9, 40)
    pts = p0 + t[:, None] * d + rng.normal(0, 20e-6, (40, 3))
    fit = fit_line(pts)
    assert np.degrees(np.arccos(abs(fit.direction @ d))) < 0.005
    assert fit.direction @ d > 0  # first → last point
    # residuals are the perpendicular distances (independent formula: |(p−c) × u|)
    expected = np.linalg.norm(np.cross(pts - fit.point, fit.direction), axis=1)
    np.testing.assert_allclose(fit.residuals, expected, atol=1e-15)
    np.testing.assert_allclose(fit.distance(pts), expected, atol=1e-15)
    assert 5e-6 < fit.rms < 40e-6
    assert np.isclose(np.linalg.norm(fit.direction), 1.0)


def test_line_exact_and_sign_conventions():
    pts = np.array([[0.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, -3.0, 0.0]])
    fit = fit_line(pts)
    np.testing.assert_allclose(fit.direction, [0.0, -1.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(fit.residuals, 0.0, atol=1e-15)
    hinted = fit_line(pts, direction_hint=[0.0, 1.0, 0.0])
    np.testing.assert_allclose(hinted.direction, [0.0, 1.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(fit.project([[5.0, -2.0, 1.0]]), [[0.0, -2.0, 0.0]], atol=1e-15)
    two = fit_line([[1.0, 1.0, 1.0], [1.0, 1.0, 2.0]])
    np.testing.assert_allclose(two.direction, [0.0, 0.0, 1.0], atol=1e-15)


@pytest.mark.parametrize(
    ("points", "match"),
    [
        ([[0.0, 0.0, 0.0]], "at least 2 points, got 1"),
        ([[1.0, 2.0, 3.0]] * 5, "coincide"),
        ([[0.0, 0.0, np.nan], [1.0, 0.0, 0.0]], r"non-finite .* row\(s\) \[0\]"),
        ([[0.0, 0.0], [1.0, 0.0]], r"\(N, 3\)"),
    ],
)
def test_line_degenerate_input(points, match):
    with pytest.raises(MetrologyError, match=match):
        fit_line(points)


# --------------------------------------------------------------------------- plane


def test_plane_recovers_normal_with_signed_residuals():
    rng = np.random.default_rng(2)
    R = _random_rotation(2)
    n = R[:, 2]
    uv = rng.uniform(-0.5, 0.5, (30, 2))
    h = rng.normal(0.0, 30e-6, 30)
    pts = np.array([1.0, 2.0, -0.4]) + uv @ R[:, :2].T + h[:, None] * n
    fit = fit_plane(pts, normal_hint=n)
    assert fit.normal @ n > 0
    assert np.degrees(np.arccos(min(1.0, fit.normal @ n))) < 0.01
    # signed residuals equal the noise we added, up to the fitted plane's offset/tilt
    np.testing.assert_allclose(fit.residuals, fit.signed_distance(pts), atol=1e-15)
    assert np.corrcoef(fit.residuals, h)[0, 1] > 0.95
    assert abs(fit.residuals.sum()) < 1e-12
    assert np.isclose(fit.flatness, fit.residuals.max() - fit.residuals.min())
    u, v = fit.basis()
    np.testing.assert_allclose(np.cross(u, v), fit.normal, atol=1e-15)


def test_plane_default_sign_is_largest_component_positive():
    pts = [[0, 0, 1.0], [1, 0, 1.0], [0, 1, 1.0], [1, 1, 1.0]]
    np.testing.assert_allclose(fit_plane(pts).normal, [0, 0, 1.0], atol=1e-15)
    np.testing.assert_allclose(fit_plane(pts, normal_hint=[0, 0, -1]).normal, [0, 0, -1.0])


@pytest.mark.parametrize(
    ("points", "match"),
    [
        ([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]], "at least 3 points, got 2"),
        ([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [2.0, 2.0, 2.0], [3.0, 3.0, 3.0]], "collinear"),
        ([[0.0, 0.0, 0.0]] * 3, "coincide"),
        ([[0.0, 0.0, 0.0], [1.0, np.inf, 0.0], [0.0, 1.0, 0.0]], "non-finite"),
    ],
)
def test_plane_degenerate_input(points, match):
    with pytest.raises(MetrologyError, match=match):
        fit_plane(points)


# -------------------------------------------------------------------------- circle


def _circle_points(centre, R, radius, angles):
    return centre + radius * (np.cos(angles)[:, None] * R[:, 0] + np.sin(angles)[:, None] * R[:, 1])


def test_circle_full_turn_exact():
    R = _random_rotation(3)
    c = np.array([2.5, -0.7, 0.4])
    pts = _circle_points(c, R, 0.05, np.linspace(0, 2 * np.pi, 24, endpoint=False))
    fit = fit_circle(pts)
    np.testing.assert_allclose(fit.centre, c, atol=1e-12)
    np.testing.assert_allclose(fit.normal, R[:, 2], atol=1e-12)  # right-hand rule
    assert fit.radius == pytest.approx(0.05, abs=1e-12)
    assert fit.rms < 1e-12
    assert fit.sweep == pytest.approx(2 * np.pi * 23 / 24)
    # reversed traversal flips the normal, not the geometry
    rev = fit_circle(pts[::-1])
    np.testing.assert_allclose(rev.normal, -R[:, 2], atol=1e-12)
    np.testing.assert_allclose(rev.centre, c, atol=1e-12)
    # helpers
    np.testing.assert_allclose(fit.point_at(fit.angles(pts)), pts, atol=1e-12)


def test_circle_noisy_arc_and_geometric_optimality():
    rng = np.random.default_rng(4)
    R = _random_rotation(4)
    c = np.array([1.0, 2.0, 0.5])
    ang = np.linspace(-np.pi / 3, np.pi / 3, 25)  # a 120° arc (joint 1 rotated ±60°)
    pts = _circle_points(c, R, 0.35, ang) + rng.normal(0, 15e-6, (25, 3))
    fit = fit_circle(pts)
    assert np.linalg.norm(fit.centre - c) < 100e-6
    assert abs(fit.radius - 0.35) < 100e-6
    assert np.degrees(np.arccos(fit.normal @ R[:, 2])) < 0.01
    np.testing.assert_allclose(fit.distances, np.hypot(fit.residuals, fit.out_of_plane))
    assert fit.rms == pytest.approx(np.sqrt(np.mean(fit.distances**2)))
    # the in-plane fit is geometric: perturbing centre or radius only increases Σ residual²
    u, v = fit.basis()
    q = fit.plane.project(pts)

    def sse(centre, radius):
        return np.sum((np.linalg.norm(q - centre, axis=1) - radius) ** 2)

    best = sse(fit.centre, fit.radius)
    for dc in (1e-6 * u, -1e-6 * u, 1e-6 * v, -1e-6 * v):
        assert sse(fit.centre + dc, fit.radius) > best
    assert sse(fit.centre, fit.radius + 1e-6) > best and sse(fit.centre, fit.radius - 1e-6) > best


def test_circle_hint_overrides_order_and_random_order_falls_back():
    R = np.eye(3)
    pts = _circle_points(np.zeros(3), R, 1.0, np.array([0.0, 2.0, 1.0, 4.0, 3.0]))
    fit = fit_circle(pts)  # not in angular order: plane convention (+z largest)
    np.testing.assert_allclose(fit.normal, [0, 0, 1.0], atol=1e-12)
    assert not fit.oriented  # and it says its sign means nothing
    fit = fit_circle(pts, normal_hint=[0, 0, -1])
    np.testing.assert_allclose(fit.normal, [0, 0, -1.0], atol=1e-12)
    assert fit.oriented


@pytest.mark.parametrize("sense", [1.0, -1.0])
@pytest.mark.parametrize("repeat", [0, 2, 4])
def test_a_point_measured_twice_does_not_lose_the_rotation_sense(sense, repeat):
    """The live PROBE wizard's 180° flip: one reflector position measured twice in a row
    (with the tracker's 10 µm noise) made the points "not in order" and the normal's sign
    the SVD's.  A repeat less than SAME_ANGLE apart is no turn back: the normal follows
    the rotation, either way round; a real turn back still leaves it unoriented."""
    rng = np.random.default_rng(7)
    R = _random_rotation(5)
    ang = sense * np.radians([0.0, 30.0, 60.0, 90.0, 120.0, 150.0])
    ang = np.insert(ang, repeat + 1, ang[repeat])
    pts = _circle_points(np.array([0.3, 0.1, 0.9]), R, 0.06, ang) + rng.normal(0, 10e-6, (7, 3))
    fit = fit_circle(pts)
    assert fit.oriented
    np.testing.assert_allclose(fit.normal, sense * R[:, 2], atol=1e-3)
    assert fit.sweep == pytest.approx(np.radians(150.0), abs=1e-3)
    back = _circle_points(np.zeros(3), R, 0.06, sense * np.radians([0.0, 40.0, 30.0, 90.0]))
    assert not fit_circle(back).oriented


@pytest.mark.parametrize(
    ("points", "match"),
    [
        ([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]], "at least 3 points, got 2"),
        ([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]], "collinear"),
        ([[np.nan, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 1.0, 0.0]], "non-finite"),
    ],
)
def test_circle_degenerate_input(points, match):
    with pytest.raises(MetrologyError, match=match):
        fit_circle(points)


@settings(max_examples=40, deadline=None, derandomize=True)
@given(
    seed=st.integers(0, 10_000),
    radius=st.floats(0.01, 2.0),
    sweep=st.floats(0.5, 2 * np.pi),
    n=st.integers(3, 40),
)
def test_circle_is_equivariant_under_rigid_motion(seed, radius, sweep, n):
    R = _random_rotation(seed)
    t = np.random.default_rng(seed).uniform(-5, 5, 3)
    pts = _circle_points(np.zeros(3), np.eye(3), radius, np.linspace(0, sweep, n))
    fit = fit_circle(pts @ R.T + t)
    np.testing.assert_allclose(fit.centre, t, atol=1e-9 * (1 + radius))
    np.testing.assert_allclose(fit.normal, R[:, 2], atol=1e-9)
    assert fit.radius == pytest.approx(radius, rel=1e-9)
