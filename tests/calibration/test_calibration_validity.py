"""The validity region of a calibration (plugcell.calibration.validity) and where it shows."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from plugcell.calibration import CalibrationData, Calibrator, ErrorModel
from plugcell.calibration.identifiability import random_configurations
from plugcell.calibration.validity import ValidityRegion
from plugcell.io.params import (
    params_document,
    params_json,
    result_from_params,
    validity_document,
    validity_from_document,
)

_HERE = Path(__file__).resolve()
IPA = next((p / "shared" / "data" / "ipa-robot-accuracy" for p in _HERE.parents
            if (p / "shared" / "data" / "ipa-robot-accuracy").is_dir()), None)


@pytest.fixture(scope="module")
def model(h4):
    return ErrorModel.create(h4, "loop", gravity=True)


def test_every_calibration_pose_is_inside(model):
    q = random_configurations(model, 150, 2)
    region = ValidityRegion.from_poses(model, q, np.full(150, 36.0))
    check = region.check(q, 36.0)
    assert not check.outside.any()
    np.testing.assert_allclose(check.distance_m, 0.0, atol=1e-12)
    # a farthest-point subsample still covers every calibration pose
    small = ValidityRegion.from_poses(model, q, max_poses=20)
    assert len(small.poses) == 20 and small.n_poses == 150
    assert small.cover_m > 0 and small.threshold_m >= small.cover_m
    assert not small.check(q).outside.any()


def test_lever_arms_are_target_motion_per_radian(model):
    q = random_configurations(model, 80, 3)
    region = ValidityRegion.from_poses(model, q)
    robot = model.with_references(base=np.eye(4))
    # distance of a configuration moved by δ on joint j alone = ℓ_j·δ (m)
    d = region.distance(q[:1] + np.eye(6)[[0]] * 1e-3)
    assert d[0] == pytest.approx(region.lever_m[0] * 1e-3, rel=1e-9)
    # ℓ_1 is the RMS distance of the target from the vertical axis 1 (a rotation about it)
    p = robot.predict(q)[:, :3, 3]
    assert region.lever_m[0] == pytest.approx(np.sqrt(np.mean(np.sum(p[:, :2] ** 2, 1))),
                                              rel=1e-4)
    assert np.all(region.lever_m >= 0.1 * region.lever_m.max() - 1e-15)


def test_outside_poses_are_flagged_with_how_far(model, h4):
    q = random_configurations(model, 200, 4)
    inner = q[np.abs(q[:, 0]) < math.radians(40)]
    region = ValidityRegion.from_poses(model, inner, np.full(len(inner), 18.0))
    far = inner[:3].copy()
    far[:, 0] = math.radians(120.0)
    mid = (region.target_lower + region.target_upper) / 2
    check = region.check(far, [18.0, 40.0, 18.0], targets=[[5.0, 0, 0], mid, mid])
    assert check.outside.all()
    assert np.degrees(check.joint_excess_rad[0]) == pytest.approx(
        120.0 - np.degrees(inner[:, 0].max()), rel=1e-9)
    assert check.worst_joint[0] == 0
    assert check.payload_excess_kg.tolist() == [0.0, 22.0, 0.0]
    assert check.target_excess_m[0] > 0 and check.target_excess_m[1] == 0
    text = check.reasons(1, h4.actuated)
    assert "joint 1" in text and "beyond its calibrated range" in text
    assert "payload 22 kg" in text and "mm from the nearest calibration pose" in text
    msg = check.message("targets")
    assert msg.startswith("3 of 3 targets outside the calibrated region")
    s = check.summary()
    assert s["outside"] == 3 and s["outside_indices"] == [0, 1, 2]
    assert s["beyond_payload"] == 1 and s["beyond_volume"] == 1


def test_round_trip_through_params_json(model):
    q = random_configurations(model, 120, 5)
    region = ValidityRegion.from_poses(model, q, np.linspace(0, 36, 120))
    back = validity_from_document(json.loads(json.dumps(validity_document(region))))
    probe = random_configurations(model, 50, 6)
    a, b = region.check(probe), back.check(probe)
    np.testing.assert_allclose(a.distance_m, b.distance_m, rtol=1e-7)
    np.testing.assert_array_equal(a.outside, b.outside)
    assert back.payload_kg == (0.0, 36.0)
    with pytest.raises(ValueError, match="validity: missing key 'threshold_mm'"):
        validity_from_document({k: v for k, v in validity_document(region).items()
                                  if k != "threshold_mm"})


@pytest.fixture(scope="module")
def calibrated(h4):
    """Model 2 on noise-free poses of a perturbed robot, joint 1 within ±30°."""
    truth = ErrorModel.create(h4, "loop")
    rng = np.random.default_rng(0)
    truth = truth.with_values(rng.normal(0, 2e-4, len(truth.space)))
    q = random_configurations(truth, 400, 7)
    q = q[np.abs(q[:, 0]) < math.radians(30)][:80]
    data = CalibrationData.from_poses(q, truth.predict(q))
    qv = random_configurations(truth, 40, 8)
    val = CalibrationData.from_poses(qv, truth.predict(qv))
    return Calibrator(h4, "loop").fit(data, validation=val), data


def test_result_records_its_region_and_flags_validation(calibrated):
    result, data = calibrated
    assert result.validity is not None and result.validity.n_poses == len(data)
    d = params_document(result)
    assert d["validity"]["poses"] == len(data)
    assert d["validation"]["region"]["outside"] > 0
    assert any(w.startswith("validation: ") and "outside the calibrated region" in w
               for w in result.warnings)


def test_old_params_json_without_region_still_loads(calibrated, h4):
    result, data = calibrated
    d = json.loads(params_json(result))
    del d["validity"]
    old = result_from_params(d, h4)
    assert old.validity is None and old.check_region(data.q) is None
    np.testing.assert_allclose(old.predict(data.q), result.predict(data.q), atol=1e-12)
    new = result_from_params(json.loads(params_json(result)), h4)
    assert not new.check_region(data.q).outside.any()


def test_compensate_flags_targets_outside(calibrated, tmp_path, capsys):
    from plugcell.apps.cli import main
    from plugcell.kinematics.rotations import matrix_to_angles

    result, data = calibrated
    params = tmp_path / "params.json"
    params.write_text(params_json(result))
    q = data.q[:2].copy()
    q[1, 0] = math.radians(120.0)  # joint 1 far outside ±30°
    T = result.model.predict(q)
    base_inv = np.linalg.inv(result.model.base())
    T = base_inv @ T
    A = np.degrees(matrix_to_angles(T[:, :3, :3], "zyz"))
    rows = ["name,x,y,z,rx,ry,rz"] + [
        f"P{i},{','.join(f'{v:.6f}' for v in (*T[i, :3, 3] * 1e3, *A[i]))}" for i in range(2)]
    (tmp_path / "t.csv").write_text("\n".join(rows) + "\n")
    out = tmp_path / "j.csv"
    assert main(["compensate", "--params", str(params), "--targets", str(tmp_path / "t.csv"),
                 "--out", str(out), "--payload-kg", "0"]) == 0
    err = capsys.readouterr().err
    assert "1 of 2 targets outside the calibrated region" in err and "(P1)" in err
    lines = [ln for ln in out.read_text().splitlines() if not ln.startswith("#")]
    assert lines[0].endswith("outside_region,region_distance_mm")
    assert lines[1].split(",")[-2] == "0" and lines[2].split(",")[-2] == "1"


def test_compute_service_region_function(calibrated):
    from plugcell.devices.compute.functions import FUNCTIONS, FunctionError, Parameters

    result, data = calibrated
    p = Parameters(result, result.model.structure.source, json.loads(params_json(result)))
    q = np.degrees(data.q[:3]).copy()
    q[2, 0] = 150.0
    out = FUNCTIONS["region"](None, p, q)
    assert out.shape == (3, 3) and out[:, 0].tolist() == [0.0, 0.0, 1.0]
    assert out[2, 2] == pytest.approx(150.0 - np.degrees(data.q[:, 0].max()), rel=1e-6)
    old = Parameters(result_from_params(
        {k: v for k, v in p.document.items() if k != "validity"}, p.description),
        p.description, p.document)
    with pytest.raises(FunctionError, match="no calibrated region"):
        FUNCTIONS["region"](None, old, q)


@pytest.mark.skipif(IPA is None, reason="IPA robot-accuracy data not available")
def test_ipa_series_c_region_flags_series_a(ur10, monkeypatch):
    """Calibrated on 300 poses of series C, every pose of series A lies outside (joint 1
    and the elbow cover other ranges), and there the calibration does not help."""
    monkeypatch.syspath_prepend(str(_HERE.parents[2] / "benchmarks"))
    from calibration_ur10 import SERIES, read_series
    from plugcell.kinematics.rotations import angles_to_matrix

    def load(key, n):
        q, p, a = read_series(IPA / SERIES[key][0])
        idx = np.linspace(0, len(q) - 1, n).astype(int)
        return CalibrationData(q[idx], p[idx], angles_to_matrix(a[idx], "xyz"))

    c, a = load("C", 300), load("A", 300)
    res = Calibrator(ur10, "serial").fit(c)
    inside = res.check_region(c.q)
    assert not inside.outside.any()
    check = res.check_region(a.q)
    assert check.outside.all() and np.all(check.distance_m > check.threshold_m)
    assert np.all(check.joint_excess_rad > 0)
    before, after = res.evaluate(a, refit_base=True, refit_probe=True)
    assert after.position.norm.mean > 0.9 * before.position.norm.mean


@pytest.mark.slow
def test_report_shows_the_coverage(calibrated, h4):
    from plugcell.io.calibration_report import render_report

    result, data = calibrated
    qv = random_configurations(result.model, 10, 9)
    val = CalibrationData.from_poses(qv, result.model.predict(qv))
    page = render_report(result.with_validation(val), data, val)
    assert "Calibrated region (where the model may be trusted)" in page
    assert "Coverage of the joint ranges" in page
    assert f"{result.validity.threshold_m * 1e3:.0f} mm</b>" in page
    assert "poses outside" in page
    old = result_from_params(
        {k: v for k, v in json.loads(params_json(result)).items() if k != "validity"}, h4)
    assert "Calibrated region" not in render_report(old, data)


def test_compute_compensation_notes_targets_outside_the_region(calibrated):
    """compensate_joints (the compensation functions of the compute service) warn, with
    how far, when a compensated target lies outside the calibrated region; the compute
    service turns the warning into its process's note (the Completed reason)."""
    from plugcell.devices.compute.functions import FUNCTIONS, FunctionContext, Parameters
    from plugcell.devices.compute.workspace import Workspace

    result, data = calibrated
    p = Parameters(result, result.model.structure.source, json.loads(params_json(result)))
    ctx = FunctionContext(Workspace("R1"))
    inside = np.degrees(data.q[:2])
    FUNCTIONS["compensate_joints"](ctx, p, inside)
    assert ctx.warnings == []
    outside = inside.copy()
    outside[1, 0] = np.degrees(data.q[:, 0].max()) + 25.0
    FUNCTIONS["compensate_joints"](ctx, p, outside)
    assert len(ctx.warnings) == 1
    w = ctx.warnings[0]
    assert w.startswith("compensate_joints: 1 of 2 targets outside the calibrated region")
    assert "target 2: joint" in w and "beyond its calibrated range" in w


def test_a_step_beyond_a_range_counts_by_the_target_motion_it_makes(model):
    """A joint's excess counts once it moves the target by more than τ/20: a compensation's
    0.05° correction at the edge of a range, or a joint the campaign held nearly fixed, is
    no extrapolation; 20° is."""
    from plugcell.calibration.validity import RANGE_TOL_FRACTION

    q = random_configurations(model, 150, 9)
    q[:, 5] = np.linspace(0.0, math.radians(0.5), len(q))  # joint 6 nearly fixed
    region = ValidityRegion.from_poses(model, q, np.zeros(len(q)))
    edge = q[np.argmax(q[:, 0])].copy()
    probes = np.array([edge, edge, edge])
    probes[0, 0] += math.radians(0.05)
    probes[1, 5] += math.radians(0.05)
    probes[2, 0] += math.radians(20.0)
    check = region.check(probes)
    assert check.beyond_range.tolist() == [False, False, True]
    assert check.worst_joint[2] == 0
    motion = check.joint_excess_rad[2] * region.lever_m[0]
    assert motion > RANGE_TOL_FRACTION * region.threshold_m
    assert check.reasons(0) == "" and "joint 1 20.0° beyond" in check.reasons(2)
