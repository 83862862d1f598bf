"""BASE and PROBE by the procedures of Appendix D, measured with the simulated tracker.

The world here is a bare geometric stand-in for a robot (a BASE, a flange frame,
a joint axis) — the metrology must recover what the features encode, exactly
without noise and within the tracker noise with it.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from plugcell.metrology import (
    SMR_RADIUS_HALF_INCH,
    MetrologyError,
    base_from_features,
    base_matrix_from_parameters,
    base_parameters_from_matrix,
    invert_transform,
    probe_from_flange_features,
)
from plugcell.sim.twin.tracker import LaserTracker

H = SMR_RADIUS_HALF_INCH


def _rz(q: float) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("z", q).as_matrix()
    return T


def _apply(T: np.ndarray, p) -> np.ndarray:
    p = np.atleast_2d(p)
    return p @ T[:3, :3].T + T[:3, 3]


def _angle(Ra: np.ndarray, Rb: np.ndarray) -> float:
    return Rotation.from_matrix(Ra.T @ Rb).magnitude()


# The true world (tracker frame, metres).
BASE_TRUE = base_matrix_from_parameters(
    2.6, 1.1, np.radians(0.4), np.radians(-0.3), np.radians(160.0), -0.85
)
FLANGE_TRUE = np.eye(4)  # flange frame F_n in the tracker frame at the PROBE set-up pose
FLANGE_TRUE[:3, :3] = Rotation.from_euler("xyz", [20, -100, 35], degrees=True).as_matrix()
FLANGE_TRUE[:3, 3] = [2.9, 0.4, 0.25]
PROBE_TRUE = np.eye(4)
PROBE_TRUE[:3, :3] = Rotation.from_euler("xyz", [0.5, -1.0, 90.0], degrees=True).as_matrix()
PROBE_TRUE[:3, 3] = [0.06, -0.01, 0.12]


def _appendix_d_features(measure):
    """Feature points of App. D.1 and D.2, each taken through ``measure(true_position)``."""
    # D.1: SMR in the dowel hole at +y (50 mm), joint n turned one positive turn.
    smr_flange = np.array([0.0, 0.05, H])
    circle = [measure(_apply(FLANGE_TRUE @ _rz(q), smr_flange)[0])
              for q in np.linspace(0, 2 * np.pi, 24, endpoint=False)]
    holes = [measure(_apply(FLANGE_TRUE, [0.0, y, H])[0]) for y in (-0.05, -0.05, 0.05, 0.05)]
    # D.2: SMR on joint 1 (r = 0.35 m, 0.4 m up), joint 1 turned −60° → +60°.
    j1 = [measure(_apply(BASE_TRUE @ _rz(q), [0.35, 0.0, 0.4])[0])
          for q in np.radians(np.linspace(-60, 60, 25))]
    # SMR resting on the base surface (z = 0 of F0) around the robot.
    plane = [measure(_apply(BASE_TRUE, [0.5 * np.cos(a), 0.5 * np.sin(a), H])[0])
             for a in np.radians(np.arange(-180, 180, 45))]
    # T-MAC while the robot moves along +x0 (it rides 1 m up, 0.1 m off the x-z plane).
    line = [measure(_apply(BASE_TRUE, [x, 0.1, 1.0])[0]) for x in np.linspace(1.0, 2.0, 11)]
    return (np.array(circle), np.array(holes), np.array(j1), np.array(plane), np.array(line))


def test_noise_free_features_give_exact_base_and_probe():
    circle, holes, j1, plane, line = _appendix_d_features(lambda p: p)
    est = probe_from_flange_features(circle, holes, FLANGE_TRUE @ PROBE_TRUE)
    np.testing.assert_allclose(est.flange_pose, FLANGE_TRUE, atol=1e-12)
    np.testing.assert_allclose(est.probe, PROBE_TRUE, atol=1e-12)
    assert est.circle.radius == pytest.approx(0.05)
    assert est.hole_line_tilt < 1e-12
    base = base_from_features(j1, plane, line)
    np.testing.assert_allclose(base.base, BASE_TRUE, atol=1e-12)
    p = base.parameters
    np.testing.assert_allclose(
        p.as_array(), [2.6, 1.1, np.radians(0.4), np.radians(-0.3), np.radians(160.0), -0.85],
        atol=1e-12,
    )
    assert base.axis_plane_angle < 1e-9 and base.line_tilt < 1e-9


def test_smr_offset_zero_reproduces_appendix_d_literally():
    """D.1 takes the circle centre as O_n: PROBE then carries the SMR height along z_n."""
    circle, holes, *_ = _appendix_d_features(lambda p: p)
    est = probe_from_flange_features(circle, holes, FLANGE_TRUE @ PROBE_TRUE, smr_offset=0.0)
    np.testing.assert_allclose(est.probe[:3, :3], PROBE_TRUE[:3, :3], atol=1e-12)
    np.testing.assert_allclose(est.probe[:3, 3], PROBE_TRUE[:3, 3] - [0, 0, H], atol=1e-12)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_base_and_probe_agree_with_truth_within_tracker_noise(seed):
    tracker = LaserTracker(seed=seed)
    aim_rng = np.random.default_rng(100 + seed)

    def measure(p):  # Move to a nominal position a few mm off, then a 1 s SMR reading
        tracker.point_at(p + aim_rng.uniform(-0.003, 0.003, 3))
        return tracker.measure(p, 1.0, mode="3dof").position

    circle, holes, j1, plane, line = _appendix_d_features(measure)
    T_tmac = FLANGE_TRUE @ PROBE_TRUE
    tracker.point_at(T_tmac)
    tmac = tracker.measure(T_tmac, 1.0, mode="6dof").pose

    # Expected size of the errors from the tracker's own 1 s σ at ~3 m.
    _, s_lat = tracker.spec.position_sigma(3.0, 1.0)
    s_ang = tracker.spec.orientation_sigma(1.0)
    # PROBE: y_n from two holes 0.1 m apart → σ_angle ≲ √2·σ/0.1 m, plus the T-MAC's own σ;
    # the translation error is that angle times the lever |PROBE p| ≈ 0.14 m plus σ.
    ang_tol = 2 * (np.sqrt(2) * s_lat / 0.1 + s_ang)
    pos_tol = 2 * s_lat + 0.14 * ang_tol
    est = probe_from_flange_features(circle, holes, tmac)
    assert _angle(est.probe[:3, :3], PROBE_TRUE[:3, :3]) < ang_tol
    assert np.linalg.norm(est.probe[:3, 3] - PROBE_TRUE[:3, 3]) < pos_tol
    assert est.circle.rms < 4 * s_lat

    base = base_from_features(j1, plane, line)
    # z0 from a 0.35 m-radius arc, x0 from a 1 m line: angles ≲ 2σ/0.3 m, origin ≲ 4σ
    assert _angle(base.base[:3, :3], BASE_TRUE[:3, :3]) < 2 * s_lat / 0.3
    assert np.linalg.norm(base.base[:3, 3] - BASE_TRUE[:3, 3]) < 4 * s_lat
    # and it is a far better start than a 1 mm / 0.1° guess
    assert np.linalg.norm(base.base[:3, 3] - BASE_TRUE[:3, 3]) < 0.1e-3
    d = base_parameters_from_matrix(base.base).as_array() - base_parameters_from_matrix(
        BASE_TRUE).as_array()
    assert np.all(np.abs(d[[2, 3, 4]]) < np.radians(0.01))


def test_feature_errors_are_precise():
    circle, holes, j1, plane, line = _appendix_d_features(lambda p: p)
    T = FLANGE_TRUE @ PROBE_TRUE
    along_z = _apply(FLANGE_TRUE, [[0, 0, 0.0], [0, 0, 0.05]])
    with pytest.raises(MetrologyError, match="nearly along z_n"):
        probe_from_flange_features(circle, along_z, T)
    with pytest.raises(MetrologyError, match="hole_points: needs at least 2 points"):
        probe_from_flange_features(circle, holes[:1], T)
    with pytest.raises(MetrologyError, match="tmac_measurement: expected a 4x4"):
        probe_from_flange_features(circle, holes, T[:3])
    with pytest.raises(MetrologyError, match="collinear"):
        base_from_features(line, plane, line)
    vertical = _apply(BASE_TRUE, [[1, 0, 0.5], [1, 0, 1.0], [1, 0, 1.5]])
    with pytest.raises(MetrologyError, match="nearly along z_0"):
        base_from_features(j1, plane, vertical)
    with pytest.raises(MetrologyError, match="smr_offset: must be finite"):
        base_from_features(j1, plane, line, smr_offset=float("nan"))


def test_a_circle_in_no_order_is_refused_without_a_hint_and_a_repeat_is_not():
    """z_n and z_0 are signed by the joint's rotation sense: points shuffled around the
    circle cannot give it (the axis would be the SVD's, PROBE or BASE turned by 180°
    without a word), so the frame is refused — unless a hint signs the axis; a point
    measured twice in a row (the live wizard's lag) keeps the sense."""
    circle, holes, j1, plane, line = _appendix_d_features(lambda p: p)
    T = FLANGE_TRUE @ PROBE_TRUE
    shuffled = circle[np.random.default_rng(3).permutation(len(circle))]
    with pytest.raises(MetrologyError, match="circle_points: the points go back and forth"):
        probe_from_flange_features(shuffled, holes, T)
    hinted = probe_from_flange_features(shuffled, holes, T, normal_hint=FLANGE_TRUE[:3, 2])
    np.testing.assert_allclose(hinted.probe, PROBE_TRUE, atol=1e-9)
    twice = np.insert(circle, 5, circle[4], axis=0)
    np.testing.assert_allclose(probe_from_flange_features(twice, holes, T).probe, PROBE_TRUE,
                               atol=1e-9)
    with pytest.raises(MetrologyError, match=r"joint1_circle_points: .* signs z_0"):
        base_from_features(j1[[0, 5, 2, 9, 1, 20, 3]], plane, line)


def test_probe_inverse_relation_d3():
    """PROBE = (T_n^LT)⁻¹ T_TMAC^LT, so T_n^LT · PROBE reproduces the T-MAC reading."""
    circle, holes, *_ = _appendix_d_features(lambda p: p)
    T = FLANGE_TRUE @ PROBE_TRUE
    est = probe_from_flange_features(circle, holes, T)
    np.testing.assert_allclose(est.flange_pose @ est.probe, T, atol=1e-12)
    np.testing.assert_allclose(invert_transform(est.flange_pose) @ T, est.probe, atol=1e-12)
