"""Accuracy statistics (8.1–8.2, 3σ of 8.3.3), pose errors, straightness (8.3.1), ISO 9283."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from plugcell.metrology import (
    MetrologyError,
    accuracy_statistics,
    iso9283_pose_accuracy,
    pose_errors,
    straightness,
    wrap_angle,
)


def test_statistics_follow_equations_8_1_and_8_2():
    dp = np.array([[3.0, 4.0, 0.0], [0.0, 0.0, 1.0], [1.0, 2.0, 2.0], [-2.0, 0.0, 0.0]]) * 1e-3
    dphi = np.radians([[0.1, 0.0, 0.0], [0.0, -0.2, 0.0], [0.0, 0.0, 0.3], [0.1, 0.1, 0.1]])
    s = accuracy_statistics(dp, dphi)
    norms = np.array([5.0, 1.0, 3.0, 2.0]) * 1e-3
    m = norms.mean()
    sd = np.sqrt(np.sum((norms - m) ** 2) / 3)  # (8.2): m − 1
    assert s.count == 4
    assert s.position.norm.mean == pytest.approx(m)
    assert s.position.norm.std == pytest.approx(sd)
    assert s.position.norm.max == pytest.approx(5e-3)
    assert s.position.norm.three_sigma == pytest.approx(m + 3 * sd)  # the thesis's 3σ
    comp_sd = np.sqrt(np.sum((dp - dp.mean(0)) ** 2, axis=0) / 3)
    np.testing.assert_allclose(s.position.components.mean, dp.mean(0))
    np.testing.assert_allclose(s.position.components.std, comp_sd)
    np.testing.assert_allclose(s.position.components.three_sigma, 3 * comp_sd)
    np.testing.assert_allclose(s.position.components.band, dp.max(0) - dp.min(0))
    assert s.position.norm.rss_three_sigma == pytest.approx(3 * np.sqrt(np.sum(comp_sd**2)))
    assert s.orientation is not None
    assert s.orientation.norm.max == pytest.approx(np.radians(0.3))


def test_three_sigma_reproduces_table_8_5():
    """mean + 3σ of the error norm gives the thesis's 6.50 / 0.87 / 0.12 mm."""
    for mean, sd, thesis in ((4.04, 0.82, 6.50), (0.39, 0.16, 0.87), (0.06, 0.02, 0.12)):
        # two-point sample with exactly this mean and (m−1) standard deviation
        half = sd / np.sqrt(2)
        dp = np.array([[mean - half, 0, 0], [mean + half, 0, 0]]) * 1e-3
        s = accuracy_statistics(dp)
        assert s.as_dict()["position"]["three_sigma"] == pytest.approx(thesis, abs=0.005)


def test_as_dict_units_and_json():
    rng = np.random.default_rng(1)
    s = accuracy_statistics(rng.normal(0, 1e-3, (20, 3)), rng.normal(0, 1e-3, (20, 3)))
    d_mm = s.as_dict()
    d_um = s.as_dict(length_unit="um", angle_unit="rad")
    assert d_mm["length_unit"] == "mm" and d_mm["angle_unit"] == "deg"
    assert d_um["position"]["mean"] == pytest.approx(1e3 * d_mm["position"]["mean"])
    assert d_mm["orientation"]["mean"] == pytest.approx(np.degrees(s.orientation.norm.mean))
    assert d_um["orientation"]["mean"] == pytest.approx(s.orientation.norm.mean)
    json.dumps(d_mm)  # plain types only
    with pytest.raises(MetrologyError, match="unknown length unit 'cm'"):
        s.as_dict(length_unit="cm")
    assert "orientation" not in accuracy_statistics(np.ones((3, 3))).as_dict()


def test_statistics_errors():
    with pytest.raises(MetrologyError, match="position_errors: needs at least 2 poses, got 1"):
        accuracy_statistics(np.zeros((1, 3)))
    with pytest.raises(MetrologyError, match="must match"):
        accuracy_statistics(np.zeros((3, 3)), np.zeros((4, 3)))
    with pytest.raises(MetrologyError, match="non-finite"):
        accuracy_statistics([[0, 0, 0], [0, np.nan, 0]])


def test_pose_errors_rpy_wraps_and_rotvec():
    R_model = Rotation.from_euler("xyz", [np.pi - 0.001, 0.1, 0.2])
    R_meas = Rotation.from_euler("xyz", [-np.pi + 0.001, 0.1, 0.2])  # +0.002 rad across ±π
    M, E = np.eye(4), np.eye(4)
    M[:3, :3], E[:3, :3] = R_meas.as_matrix(), R_model.as_matrix()
    M[:3, 3], E[:3, 3] = [1.0, 2.0, 3.0], [1.0, 2.0, 2.999]
    dp, dphi = pose_errors(M, E)
    np.testing.assert_allclose(dp, [[0.0, 0.0, 0.001]], atol=1e-15)
    np.testing.assert_allclose(dphi, [[0.002, 0.0, 0.0]], atol=1e-9)
    small = Rotation.from_rotvec([1e-4, -2e-4, 3e-4])
    M[:3, :3] = (R_model * small).as_matrix()
    _, rv = pose_errors(M, E, orientation="rotvec")
    np.testing.assert_allclose(rv, [[1e-4, -2e-4, 3e-4]], atol=1e-12)
    np.testing.assert_allclose(wrap_angle([np.pi, -np.pi, 3 * np.pi]), [np.pi] * 3)


def test_straightness_bands_about_best_fit_line():
    y = np.linspace(-0.9, 0.9, 13)  # 13 points 150 mm apart (8.3.1)
    basis = np.column_stack([np.ones_like(y), y])

    def detrended(f):  # remove what a best-fit line would absorb
        return f - basis @ np.linalg.lstsq(basis, f, rcond=None)[0]

    dz = detrended(0.4e-3 * (y / 0.9) ** 2)
    dx = detrended(0.1e-3 * np.sin(7 * y))
    pts = np.column_stack([1.5 + dx, y, 0.8 + dz])
    # a tilted datum: straightness does not depend on where the line is or how it is tilted
    R = Rotation.from_euler("z", 0.3).as_matrix()
    res = straightness(pts @ R.T + [0.1, 0.2, 0.3], directions=np.eye(3)[[2, 0]] @ R.T)
    np.testing.assert_allclose(res.deviations[:, 0], dz, atol=1e-12)
    np.testing.assert_allclose(res.deviations[:, 1], dx, atol=1e-12)
    np.testing.assert_allclose(res.band, [np.ptp(dz), np.ptp(dx)], atol=1e-12)
    d = res.as_dict()
    assert d["z"]["band"] == pytest.approx(np.ptp(dz) * 1e3) and d["count"] == 13


def test_straightness_errors():
    pts = np.column_stack([np.zeros(5), np.arange(5.0), np.zeros(5)])
    with pytest.raises(MetrologyError, match=r"directions\[0\] \(y\) is parallel"):
        straightness(pts, directions=[[0, 1, 0], [1, 0, 0]], labels=("y", "x"))
    with pytest.raises(MetrologyError, match="at least 3 points"):
        straightness(pts[:2])


def test_iso9283_ap_rp():
    rng = np.random.default_rng(3)
    commanded = np.array([1.0, 0.5, 0.8])
    offset = np.array([0.3e-3, -0.4e-3, 0.0])
    attained = commanded + offset + rng.normal(0, 20e-6, (30, 3))
    r = iso9283_pose_accuracy(attained, commanded)
    bary = attained.mean(0)
    assert r.ap == pytest.approx(np.linalg.norm(bary - commanded))
    l = np.linalg.norm(attained - bary, axis=1)
    assert r.rp == pytest.approx(l.mean() + 3 * l.std(ddof=1))
    assert abs(r.ap - 0.5e-3) < 20e-6
    ang = np.radians([10.0, 0.0, 179.99]) + rng.normal(0, 1e-4, (30, 3))
    r2 = iso9283_pose_accuracy(attained, commanded, attained_angles=wrap_angle(ang),
                               commanded_angles=np.radians([10.0, 0.0, -179.99]))
    assert abs(r2.orientation_ap[2] - np.radians(-0.02)) < 1e-4  # across ±π
    assert np.all(r2.orientation_rp < 6e-4)
