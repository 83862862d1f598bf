"""ABB's path coordinate system (EGM path correction): the frame as the manual defines it,
the round trips between base-frame displacements and path coordinates (hypothesis), what
a controller applies of a correction (y and z, never x), and a sampled path's tangents
against the analytic derivative (issue 37, mode (b) over EGM)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from plugcell.kinematics.path_frame import (
    TangentTracker,
    applied_displacement,
    from_path,
    path_frame,
    path_tangents,
    to_path,
)

_c = st.floats(-2.0, 2.0)
_vec = st.tuples(_c, _c, _c).map(np.array)


def _frame_args(t, z):
    """Tangent and tool z that define a frame (not parallel, not zero)."""
    assume(np.linalg.norm(t) > 1e-3 and np.linalg.norm(z) > 1e-3)
    assume(np.linalg.norm(np.cross(t / np.linalg.norm(t), z / np.linalg.norm(z))) > 1e-3)
    return t, z


@settings(max_examples=300, deadline=None)
@given(_vec, _vec)
def test_the_frame_is_the_manuals(t, z):
    """x along the tangent, y = x × z_tool normalised, z = x × y: orthonormal, right-handed,
    y across the tool's z, z in the plane of the tangent and the tool's z."""
    t, z = _frame_args(t, z)
    R = path_frame(t, z)
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-12)
    x, y, zp = R.T
    np.testing.assert_allclose(x, t / np.linalg.norm(t), atol=1e-12)
    assert y @ z == pytest.approx(0.0, abs=1e-12)
    assert np.linalg.det(np.stack([zp, t, z])) == pytest.approx(0.0, abs=1e-9)
    # an independent construction: z the part of the tool's z across the path, turned
    # back (x × (x × ẑ) = (x·ẑ) x − ẑ), y = z × x
    zh = z / np.linalg.norm(z)
    z_ind = (x @ zh) * x - zh
    z_ind /= np.linalg.norm(z_ind)
    np.testing.assert_allclose(zp, z_ind, atol=1e-9)
    np.testing.assert_allclose(y, np.cross(z_ind, x), atol=1e-9)


def test_a_tool_pointing_down_on_a_path_along_x_gives_the_base_frame():
    np.testing.assert_allclose(path_frame([2.0, 0, 0], [0, 0, -1.0]), np.eye(3), atol=1e-15)
    # along +y: x = y_b, y = −x_b, z = z_b
    np.testing.assert_allclose(path_frame([0, 1.0, 0], [0, 0, -1.0]),
                               [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-15)


@settings(max_examples=300, deadline=None)
@given(_vec, _vec, _vec)
def test_base_and_path_coordinates_round_trip(t, z, d):
    t, z = _frame_args(t, z)
    R = path_frame(t, z)
    np.testing.assert_allclose(from_path(to_path(d, R), R), d, atol=1e-12)
    np.testing.assert_allclose(to_path(from_path(d, R), R), d, atol=1e-12)
    assert np.linalg.norm(to_path(d, R)) == pytest.approx(np.linalg.norm(d), abs=1e-12)


@settings(max_examples=300, deadline=None)
@given(_vec, _vec, _vec)
def test_the_controller_applies_all_but_the_part_along_the_path(t, z, d):
    """d − (d·x) x: the path direction is never corrected; the rest exactly."""
    t, z = _frame_args(t, z)
    R = path_frame(t, z)
    x = R[:, 0]
    applied = applied_displacement(to_path(d, R), R)
    np.testing.assert_allclose(applied, d - (d @ x) * x, atol=1e-12)
    assert applied @ x == pytest.approx(0.0, abs=1e-12)
    # a displacement across the path round-trips through what the controller applies
    across = d - (d @ x) * x
    np.testing.assert_allclose(applied_displacement(to_path(across, R), R), across, atol=1e-12)


def test_vectorised_frames_are_the_single_ones():
    rng = np.random.default_rng(7)
    t, z = rng.normal(size=(20, 3)), rng.normal(size=(20, 3))
    R = path_frame(t, z)
    for k in range(20):
        np.testing.assert_allclose(R[k], path_frame(t[k], z[k]), atol=1e-15)
    d = rng.normal(size=(20, 3))
    np.testing.assert_allclose(to_path(d, R)[5], R[5].T @ d[5], atol=1e-15)


@pytest.mark.parametrize(("t", "z", "why"), [
    ([0, 0, 0], [0, 0, 1], "does not move"),
    ([0, 0, 2], [0, 0, -1], "along the tool's z"),
    ([1, 0, 0], [0, 0, 0], "zero tool z"),
    ([np.nan, 0, 0], [0, 0, 1], "not finite"),
    ([1, 0], [0, 1], "3-vectors"),
])
def test_no_frame_is_said_why(t, z, why):
    with pytest.raises(ValueError, match=why):
        path_frame(t, z)


def test_sampled_tangents_converge_to_the_derivative_of_an_arc():
    """A circular arc sampled every h: central differences give the tangent to O(h²)."""
    r, w = 0.4, 0.5  # m, rad/s
    errs = []
    for h in (0.04, 0.02, 0.01):
        s = np.arange(0.0, 2.0, h)
        p = np.stack([r * np.cos(w * s), r * np.sin(w * s), 0.1 * s], axis=1)
        dp = np.stack([-r * w * np.sin(w * s), r * w * np.cos(w * s), 0.1 + 0 * s], axis=1)
        want = dp / np.linalg.norm(dp, axis=1, keepdims=True)
        got = path_tangents(p)
        errs.append(np.max(np.linalg.norm(got[1:-1] - want[1:-1], axis=1)))
        z_tool = np.array([0, 0, -1.0])
        np.testing.assert_allclose(path_frame(got[1:-1], z_tool),
                                   path_frame(want[1:-1], z_tool), atol=5e-3)
    assert errs[0] / errs[1] == pytest.approx(4.0, rel=0.05)
    assert errs[1] / errs[2] == pytest.approx(4.0, rel=0.05)


def test_standing_still_keeps_the_last_direction_and_starts_with_the_first():
    p = np.zeros((12, 3))
    p[3:6, 0] = np.arange(1, 4) * 1e-3          # along +x
    p[6:9] = p[5]                               # stands
    p[9:, 0] = p[5, 0]
    p[9:, 1] = np.arange(1, 4) * 1e-3          # then along +y
    t = path_tangents(p)
    np.testing.assert_allclose(t[:3], np.tile([1.0, 0, 0], (3, 1)), atol=1e-12)
    np.testing.assert_allclose(t[7], [1.0, 0, 0], atol=1e-12)
    np.testing.assert_allclose(t[-1], [0, 1.0, 0], atol=1e-12)
    with pytest.raises(ValueError, match="never moves"):
        path_tangents(np.zeros((5, 3)))


def test_the_tracker_takes_chords_of_a_moving_path_only():
    tr = TangentTracker(min_step=1e-4, max_chord_s=0.1, ratio=4.0)
    assert tr.update([0, 0, 0], 0.0) is None
    assert tr.update([5e-5, 0, 0], 0.004) is None           # not far enough yet
    np.testing.assert_allclose(tr.update([0, 1e-4, 0], 0.008), [0, 1.0, 0])
    np.testing.assert_allclose(tr.update([0, 1.5e-4, 0], 0.012), [0, 1.0, 0])  # kept
    np.testing.assert_allclose(tr.update([1e-4, 1e-4, 0], 0.016), [1.0, 0, 0])
    # creeping: 1e-4 m in more than 0.1 s is no path moving
    for k in range(1, 40):
        tr.update([1e-4, 1e-4 + 3e-6 * k, 0], 0.016 + 0.004 * k)
    np.testing.assert_allclose(tr.tangent, [1.0, 0, 0])
    # a step as big as the change of what was taken off is the correction's, not the path's
    t0 = 1.0
    tr.update([0, 0, 0], t0, [0, 0, 0])
    tr.update([0, 0, 2e-4], t0 + 0.004, [0, 0, 1e-4])
    np.testing.assert_allclose(tr.tangent, [1.0, 0, 0])
    np.testing.assert_allclose(tr.update([0, 1e-3, 2e-4], t0 + 0.008, [0, 0, 1.1e-4]),
                               [0, 1.0, 0])


def _lagged(e: np.ndarray, lags) -> np.ndarray:
    """What a controller applied of the corrections ``e`` (one per 4 ms sample) when it
    applies sample ``k``'s ``lags[k]`` samples late (the sender assumes one)."""
    return np.array([e[max(k - lag, 0)] for k, lag in enumerate(lags)])


def test_a_standing_path_keeps_its_direction_while_the_controller_catches_up():
    """CI of stop 45 (docs/abb-egm.md's compensation, the machine starved): the path had
    stopped, the correction's ramp had ended, and the controller — some cycles behind —
    moved the standing point by the rest of it: that catch-up was taken for the path's
    tangent (90° off), and the path correction went out in the wrong frame."""
    T, n = 0.004, 300
    t = np.arange(n) * T
    s = np.clip((t - 0.2) / 0.5, 0, 1)
    e = (s * s * (3 - 2 * s))[:, None] * np.array([-0.1, 0.0, -1.0]) * 3e-3  # 3 mm ramp
    assumed = _lagged(e, np.ones(n, int))
    lags = np.ones(n, int)
    lags[170:182] = np.arange(2, 14)  # 48 ms behind at the ramp's end, then catching up
    p = np.zeros((n, 3)) + _lagged(e, lags) - assumed
    for lag_s, kept in ((0.05, True), (0.0, False)):  # lag_s = 0: the rule before
        tr = TangentTracker(lag_s=lag_s)
        tr.tangent = np.array([0.0, 1.0, 0.0])  # the direction the path last moved in
        for k in range(n):
            tr.update(p[k], t[k], assumed[k])
        assert np.allclose(tr.tangent, [0.0, 1.0, 0.0]) is kept, tr.tangent


@settings(max_examples=40, deadline=None)
@given(speed=st.floats(0.01, 0.5), seed=st.integers(0, 2**16),
       most_late=st.integers(0, 12), along=st.floats(-1.0, 1.0))
def test_a_straight_path_under_a_late_applied_correction_keeps_its_tangent(
        speed, seed, most_late, along):
    """A LIN along +y at ``speed`` that stops; a 3 mm correction ramping in across it
    (in the plane normal to the path, along ``(along, 0, −1)``) while it moves and after
    it stands, which the controller applies 1 to 1 + ``most_late`` samples late
    (≤ ``lag_s``): every tangent taken, the last one too (the path standing), is the
    path's within asin(1/ratio).  (With ``lag_s = 0``, the rule before, tangents strayed
    by up to 77°: ``benchmarks/path_tangent_lag.py``.)"""
    T, n = 0.004, 400
    t = np.arange(n) * T
    v = np.clip(1 - (t - 0.3) / 0.2, 0, 1) * speed
    path = np.stack([np.zeros(n), np.cumsum(v) * T, np.zeros(n)], 1)
    s = np.clip((t - 0.25) / 0.5, 0, 1)
    e = (s * s * (3 - 2 * s))[:, None] * np.array([along, 0.0, -1.0]) * 3e-3
    lags = 1 + np.random.default_rng(seed).integers(0, most_late + 1, n)
    assumed = _lagged(e, np.ones(n, int))
    p = path + _lagged(e, lags) - assumed
    tr = TangentTracker()
    for k in range(n):
        got = tr.update(p[k], t[k], assumed[k])
        if got is not None:
            assert got[1] >= np.cos(np.arcsin(1 / tr.ratio)) - 1e-12, (k, got)
    assert tr.tangent is not None
