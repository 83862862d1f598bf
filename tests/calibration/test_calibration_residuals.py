"""The residual of every pose (``PoseResiduals``): consistent with the model and with the
accuracy statistics (8.1–8.2) the result reports, and exported as the residual file
(``plugcell.io.params.residuals_document``)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from plugcell.calibration import CalibrationData, CalibrationResult, Calibrator, PoseResiduals
from plugcell.io.params import (
    RESIDUALS_FORMAT,
    params_document,
    residuals_document,
    residuals_json,
    result_from_params,
)
from plugcell.kinematics.transforms import so3_exp
from plugcell.sim.twin.campaign import measure_poses, working_volume_joints
from plugcell.sim.twin.robot import RobotTwin
from plugcell.sim.twin.scenario import TwinScenario
from plugcell.sim.twin.tracker import LaserTracker


def _campaign(n: int, seed: int) -> CalibrationData:
    """Twin measurements: unmodelled effects and tracker noise leave real residuals."""
    robot = RobotTwin(TwinScenario(seed=2))
    q = working_volume_joints(robot.description, robot.reveal_truth().profile, n,
                              np.random.default_rng(seed))
    data, _ = measure_poses(robot, LaserTracker(seed=2), q)
    return CalibrationData.from_measurements(data)


@pytest.fixture(scope="module")
def sets() -> tuple[CalibrationData, CalibrationData]:
    return _campaign(40, 11), _campaign(20, 12)


@pytest.fixture(scope="module")
def result(h4, sets) -> CalibrationResult:
    cal, val = sets
    return Calibrator(h4, "loop").fit(cal, validation=val)


def _same_stats(res: PoseResiduals, after, before) -> None:
    """The per-pose vectors are what the reported statistics are the statistics of."""
    for which, stats in (("after", after), ("before", before)):
        norms = res.norms(which)
        assert norms.mean() == pytest.approx(stats.position.norm.mean, rel=1e-12)
        assert norms.max() == pytest.approx(stats.position.norm.max, rel=1e-12)
        assert np.sqrt(np.mean(norms**2)) == pytest.approx(stats.position.norm.rms, rel=1e-12)
        dp, dphi = res.errors(which)
        np.testing.assert_allclose(dp.mean(axis=0), stats.position.components.mean,
                                   rtol=1e-10, atol=1e-15)
        if stats.orientation is not None:
            assert dphi is not None
            assert np.linalg.norm(dphi, axis=1).mean() == pytest.approx(
                stats.orientation.norm.mean, rel=1e-12)


def test_calibration_residuals_are_the_vectors_of_the_reported_accuracy(result, sets):
    cal, _ = sets
    res = result.calibration_residuals
    assert isinstance(res, PoseResiduals) and len(res) == result.n_poses == 40
    assert res.six_dof
    np.testing.assert_array_equal(res.positions, cal.positions)
    # measured − predicted by the calibrated model, and by the nominal one
    np.testing.assert_allclose(res.after, cal.positions - result.predict(cal.q, cal.payload_kg)[
        :, :3, 3], atol=1e-12)
    np.testing.assert_allclose(res.before, cal.positions - result.predict_nominal(
        cal.q, cal.payload_kg)[:, :3, 3], atol=1e-12)
    np.testing.assert_allclose(res.after, result.residuals(cal)[:, :3], atol=1e-12)
    _same_stats(res, result.calibration, result.calibration_before)
    # calibration improved every figure; the residuals are not trivially zero
    assert 0.01e-3 < res.norms("after").mean() < 0.3 * res.norms("before").mean()
    with pytest.raises(ValueError, match="read-only"):
        res.after[0, 0] = 1.0


def test_validation_residuals_follow_the_validation_statistics(h4, result, sets):
    _, val = sets
    res = result.validation_residuals
    assert res is not None and len(res) == result.n_validation == 20
    np.testing.assert_array_equal(res.positions, val.positions)
    _same_stats(res, result.validation, result.validation_before)
    # the same with the tracker moved and BASE re-identified on the validation poses
    moved = np.eye(4)
    moved[:3, :3] = so3_exp([0.1, -0.05, 1.2])
    moved[:3, 3] = [0.8, -2.0, 0.3]
    val_moved = CalibrationData.from_poses(val.q, moved @ val.poses, val.payload_kg)
    refit = result.with_validation(val_moved, refit_base=True)
    _same_stats(refit.validation_residuals, refit.validation, refit.validation_before)
    stale = result.evaluate_poses(val_moved)  # the old BASE: metres off
    assert stale.norms().mean() > 100 * refit.validation_residuals.norms().mean()


def test_residual_file_per_pose_in_mm_matches_its_summaries(result):
    doc = json.loads(residuals_json(result))
    assert doc["format"] == RESIDUALS_FORMAT and doc["six_dof"] is True
    assert doc["model"] == {"number": 2, "name": "loop"}
    poses = doc["poses"]
    assert [p["set"] for p in poses] == ["calibration"] * 40 + ["validation"] * 20
    assert [p["index"] for p in poses[:3]] == [1, 2, 3]
    for name in ("calibration", "validation"):
        mine = [p for p in poses if p["set"] == name]
        after = np.array([p["after_mm"] for p in mine])
        before = np.array([p["before_mm"] for p in mine])
        summary = doc["sets"][name]
        assert summary["poses"] == len(mine)
        assert np.linalg.norm(after, axis=1).mean() == pytest.approx(summary["mean_mm"],
                                                                     rel=1e-9)
        assert np.linalg.norm(before, axis=1).mean() == pytest.approx(
            summary["before"]["mean_mm"], rel=1e-9)
        assert max(p["after_norm_mm"] for p in mine) == pytest.approx(summary["max_mm"])
        assert summary == params_document(result)[name]
    first = poses[0]
    np.testing.assert_allclose(first["measured_mm"],
                               result.calibration_residuals.positions[0] * 1e3)
    assert first["weight"] == 1.0 and len(first["orientation_after_deg"]) == 3
    assert "weight" not in poses[-1]


def test_positions_only_and_a_result_rebuilt_from_params(h4, sets, result):
    cal, _ = sets
    pos = CalibrationData(q=cal.q, positions=cal.positions, payload_kg=cal.payload_kg)
    res = Calibrator(h4, "loop").fit(pos)
    r = res.calibration_residuals
    assert not r.six_dof and r.orientation_after is None
    _same_stats(r, res.calibration, res.calibration_before)
    assert "orientation_after_deg" not in residuals_document(res)["poses"][0]
    assert "validation" not in residuals_document(res)["sets"]
    loaded = result_from_params(params_document(result), h4)
    assert loaded.calibration_residuals is None
    with pytest.raises(ValueError, match="no per-pose residuals"):
        residuals_document(loaded)
    again = loaded.evaluate_poses(cal)  # a saved calibration recomputes them from the data
    np.testing.assert_allclose(again.after, result.calibration_residuals.after, atol=1e-9)


def test_pose_residuals_check_their_shapes():
    z = np.zeros((4, 3))
    with pytest.raises(ValueError, match=r"after must be \(4, 3\)"):
        PoseResiduals(z, z, np.zeros((3, 3)))
    with pytest.raises(ValueError, match="both or neither"):
        PoseResiduals(z, z, z, orientation_before=z)
    with pytest.raises(ValueError, match="'before' or 'after'"):
        PoseResiduals(z, z, z).errors("during")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="at least 2 poses"):
        PoseResiduals(z[:1], z[:1], z[:1]).accuracy()
