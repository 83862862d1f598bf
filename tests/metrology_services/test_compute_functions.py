"""The registered functions of the compute service on the digital twin (8.2, 6.5.1, 8.4.1)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from plugcell.calibration import CalibrationData, Calibrator
from plugcell.compensation import IdentifiedModel
from plugcell.devices.compute.expr import EvaluationError, evaluate
from plugcell.devices.compute.functions import FUNCTIONS, FunctionContext, Parameters
from plugcell.devices.compute.workspace import Workspace
from plugcell.io.robots import load_robot
from plugcell.io.units import pose_from_robot, robot_from_pose
from plugcell.sim.twin.campaign import measure_poses, working_volume_joints
from plugcell.sim.twin.robot import RobotTwin
from plugcell.sim.twin.scenario import TwinScenario
from plugcell.sim.twin.tracker import LaserTracker


def rows(m) -> tuple[np.ndarray, np.ndarray]:
    """A measurement set as the robot program sends it: joints (deg), poses (mm, deg ZYZ)."""
    return np.rad2deg(m.joints), np.hstack([m.positions * 1e3, np.rad2deg(m.angles)])


@pytest.fixture(scope="module")
def campaign():
    """60 calibration and 30 validation poses of the twin (seed 0, 36 kg), ZYZ angles."""
    robot = RobotTwin(TwinScenario(seed=0, payload_kg=36.0))
    tracker = LaserTracker(seed=0)
    profile = robot.reveal_truth().profile
    q = working_volume_joints(robot.description, profile, 60, np.random.default_rng(1))
    qv = working_volume_joints(robot.description, profile, 30, np.random.default_rng(2))
    cal, _ = measure_poses(robot, tracker, q, rotation="zyz")
    val, _ = measure_poses(robot, tracker, qv, rotation="zyz")
    return cal, val


@pytest.fixture
def ws(campaign, tmp_path):
    w = Workspace("ROBOT")
    cal, val = campaign
    for name, value in zip(("mJ", "mT", "vJ", "vT"), (*rows(cal), *rows(val)), strict=True):
        w.set(name, value)
    w.ctx = FunctionContext(w, robot="smart_h4", params_dir=tmp_path / "params")
    return w


def ev(ws: Workspace, text: str) -> list[str]:
    return evaluate(text, ws, FUNCTIONS, context=ws.ctx)


@pytest.fixture
def identified(ws):
    ev(ws, "params = calibrate(mJ, mT, model=4, payload=36)")
    return ws


def test_calibrate_identifies_what_the_calibration_engine_does(identified, campaign):
    ws = identified
    params = ws.get("params")
    assert isinstance(params, Parameters)
    cal, val = campaign
    direct = Calibrator(load_robot("smart_h4"), model=4).fit(CalibrationData.from_measurements(cal))
    assert params.result.keys == direct.keys
    np.testing.assert_allclose(params.result.model.values, direct.model.values, atol=1e-12)
    ev(ws, "s = summary(params); v = validate(params, vJ, vT, payload=36)")
    s, v = ws.get("s")[0], ws.get("v")[0]
    assert s[0] == 60 and v[0] == 30
    assert s[2] == pytest.approx(direct.calibration.position.norm.mean * 1e3)
    before, after = direct.evaluate(CalibrationData.from_measurements(val))
    assert v[1] == pytest.approx(before.position.norm.mean * 1e3)
    assert v[2] == pytest.approx(after.position.norm.mean * 1e3)
    assert v[2] < 0.3 < 1.0 < v[1]  # calibrated well below a millimetre (thesis: < 1 mm)


def test_residuals_give_every_pose_measured_and_measured_minus_model(identified, campaign):
    ws = identified
    ev(ws, "r = residuals(params, vJ, vT, payload=36); v = validate(params, vJ, vT, payload=36)"
           "; rc = residuals(params, mJ, mT, payload=36); s = summary(params)")
    r, v = ws.get("r"), ws.get("v")[0]
    assert r.shape == (30, 6)
    _, val = campaign
    np.testing.assert_allclose(r[:, :3], val.positions * 1e3, atol=1e-9)  # measured, mm
    model = ws.get("params").result
    predicted = model.predict(np.deg2rad(ws.get("vJ")), 36.0)[:, :3, 3] * 1e3
    np.testing.assert_allclose(r[:, 3:], r[:, :3] - predicted, atol=1e-9)  # measured − model
    norms = np.linalg.norm(r[:, 3:], axis=1)
    assert norms.mean() == pytest.approx(v[2]) and norms.max() == pytest.approx(v[4])
    assert np.linalg.norm(ws.get("rc")[:, 3:], axis=1).mean() == pytest.approx(ws.get("s")[0][2])
    ws.set("row1", ws.get("vT")[:1, :3])  # one position: a residual, no statistics needed
    ev(ws, "one = residuals(params, row(vJ, 1), row1, payload=36)")
    np.testing.assert_allclose(ws.get("one"), r[:1], atol=1e-9)
    with pytest.raises(EvaluationError, match=r"residuals\(\): mJ has 30 rows but mT has 60"):
        ev(ws, "residuals(params, vJ, mT)")
    with pytest.raises(EvaluationError, match="identified parameters expected"):
        ev(ws, "residuals(mJ, mJ, mT)")


def test_parameters_saved_and_loaded_predict_the_same(identified, tmp_path):
    ws = identified
    ev(ws, "save_params(params, 'h4_36kg'); again = load_params('h4_36kg')")
    doc = json.loads((tmp_path / "params" / "h4_36kg.json").read_text())
    assert doc["format"] and doc["robot"] == "smart_h4"  # a PARAMS.json like plugcell calibrate's
    q = np.deg2rad(ws.get("vJ")[:5])
    np.testing.assert_allclose(ws.get("again").result.predict(q, 36.0),
                               ws.get("params").result.predict(q, 36.0), atol=1e-12)
    ev(ws, "s1 = summary(params); s2 = summary(again)")
    np.testing.assert_allclose(ws.get("s1"), ws.get("s2"))
    ev(ws, "b = frame(again, 'base'); p = frame(again, 'probe', angles='rpy')")
    T = ws.get("params").result.model.base()
    np.testing.assert_allclose(pose_from_robot(ws.get("b")[0], "zyz"), T, atol=1e-12)
    P = ws.get("params").result.model.probe()
    np.testing.assert_allclose(pose_from_robot(ws.get("p")[0], "rpy"), P, atol=1e-12)


@pytest.mark.parametrize(
    ("text", "reason"),
    [
        ("load_params('../../etc/passwd')", "parameter set name"),
        ("load_params('.hidden')", "parameter set name"),
        ("load_params('a..b')", "no '..'"),
        ("load_params('missing')", "no parameter set 'missing'"),
        ("save_params(mJ, 'x')", "identified parameters expected"),
        ("calibrate(mJ, mT, robot='/etc/passwd')", "robot '/etc/passwd' unknown"),
        ("calibrate(size(mJ), mT)", "mJ: 6 columns expected, got 1×2"),
        ("calibrate(mJ, vT)", "mJ has 60 rows but mT has 30"),
        ("calibrate(mJ, mT, model=5)", "carry no payload"),
        ("calibrate(mJ, mT, angles='zyx')", "angles: unknown angle convention 'zyx'; "
         "expected one of zyz, rpy, xyz, prj"),
        ("frame(mJ, 'base')", "identified parameters expected"),
    ],
)
def test_functions_refuse_bad_arguments_with_the_reason(ws, text, reason):
    with pytest.raises(EvaluationError, match=reason):
        ev(ws, text)


def test_model_based_compensation_reaches_the_targets_on_the_identified_model(identified):
    ws = identified
    params = ws.get("params")
    model = IdentifiedModel(params.result.model)
    targets = np.array([[1500, 0, 1200, 0, 150, 0], [1600, 200, 1000, 10, 140, 5]], float)
    ws.set("targets", targets)
    ev(ws, "q = compensate(params, targets, payload=36)")
    reached = model.pose(np.deg2rad(ws.get("q")), 36.0)
    for T, v in zip(reached, targets, strict=True):
        np.testing.assert_allclose(T, pose_from_robot(v, "zyz"), atol=1e-6)
    # H4Compensation: from the nominal joints of the targets to the compensated ones
    ev(ws, "qc = compensate_joints(params, q, payload=36)")
    assert ws.get("qc").shape == (2, 6)
    with pytest.raises(EvaluationError, match="target 1: no nominal joint solution"):
        ws.set("far", [[9000, 0, 0, 0, 90, 0]])
        ev(ws, "compensate(params, far)")


def test_calc_targets_builds_the_frames_of_8_4_1_in_the_robot_frame(tmp_path):
    """Four bars of six holes on a tilted part: origins, common z, each bar's y (8.4.1)."""
    rng = np.random.default_rng(5)
    part = pose_from_robot([2500, 300, -400, 20, 30, 10], "zyz")  # the part in the tracker
    local = []
    for bar in range(4):
        for k in range(6):
            local.append([k * 100.0, bar * 300.0 + 0.2 * k * bar, 0.0])
    local = np.array(local) * 1e-3
    holes = (part[:3, :3] @ local.T).T + part[:3, 3] + rng.normal(0, 1e-5, local.shape)
    corners = holes[[0, 5, 18, 23]]
    base = [3000, 500, -200, 10, 5, 30]
    ws = Workspace("ROBOT")
    ws.set("holes", holes * 1e3)
    ws.set("corners", corners * 1e3)
    ws.set("base", base)
    evaluate("t = calc_targets(holes, corners, base)", ws, FUNCTIONS,
             context=FunctionContext(ws, params_dir=tmp_path))
    targets = ws.get("t")
    assert targets.shape == (24, 6)
    B = pose_from_robot(base, "zyz")
    tracker_frames = np.stack([B @ pose_from_robot(t, "zyz") for t in targets])
    np.testing.assert_allclose(tracker_frames[:, :3, 3], holes, atol=1e-9)  # origins: the holes
    z = tracker_frames[:, :3, 2]
    np.testing.assert_allclose(np.abs(z @ part[:3, 2]), 1.0, atol=1e-6)  # common z: the normal
    assert np.all(z @ (-holes.mean(axis=0)) > 0)  # facing the tracker
    x_part = part[:3, 0]
    y = tracker_frames[:6, :3, 1]  # bar 0: holes along the part's x
    np.testing.assert_allclose(y @ x_part, 1.0, atol=1e-6)
    np.testing.assert_allclose(np.cross(tracker_frames[0, :3, 1], z[0]),
                               tracker_frames[0, :3, 0], atol=1e-12)  # x = y × z
    with pytest.raises(EvaluationError, match="not a whole number of bars"):
        evaluate("calc_targets(holes, corners, base, per_bar=5)", ws, FUNCTIONS,
                 context=FunctionContext(ws, params_dir=tmp_path))


def test_housekeeping_functions(ws):
    ev(ws, "a = [1, 2; 3, 4]; b = append(a, [5, 6]); r = row(b, 3); n = size(b)")
    np.testing.assert_allclose(ws.get("r"), [[5, 6]])
    np.testing.assert_allclose(ws.get("n"), [[3, 2]])
    ev(ws, "clear('a', 'b')")
    assert "a" not in ws and "b" not in ws and "r" in ws
    ev(ws, "clear('a', 'never_set')")  # absent names: nothing to do (programs clear first)
    with pytest.raises(EvaluationError, match="bad matrix name"):
        ev(ws, "clear('r', '1x')")
    assert "r" in ws  # a refused clear removes nothing
    ev(ws, "clear()")
    assert ws.names() == []
    np.testing.assert_allclose(robot_from_pose(np.eye(4), "zyz"), np.zeros(6), atol=1e-12)


def test_appendix_d_estimates_base_and_probe_from_smr_features(tmp_path):
    """The wizards of the visualisation service (7.5, App. D) as functions."""
    B = pose_from_robot([2800, -400, -300, 12, 3, -25], "zyz")
    F = pose_from_robot([900, 150, 1100, 40, 120, 10], "zyz")  # flange, robot frame
    P = pose_from_robot([5, -20, 95, 0, 8, 90], "zyz")
    h = 6.35  # mm, SMR centre above the surface it sits on

    def pts(T, local):  # local points (mm) → tracker frame (mm)
        local = np.asarray(local, float) * 1e-3
        return ((T[:3, :3] @ local.T).T + T[:3, 3]) * 1e3

    t = np.deg2rad(np.arange(0, 300, 30))
    ws = Workspace("ROBOT")
    ws.set("fc", pts(B @ F, np.c_[40 * np.cos(t), 40 * np.sin(t), np.full_like(t, h)]))
    ws.set("fh", pts(B @ F, [[0, -25, h], [0, 25, h]]))
    ws.set("tmac", robot_from_pose(B @ F @ P, "zyz"))
    ws.set("bc", pts(B, np.c_[300 * np.cos(t), 300 * np.sin(t), np.full_like(t, 450)]))
    ws.set("bp", pts(B, [[500, 0, h], [0, 500, h], [-400, -300, h], [300, -450, h]]))
    ws.set("bl", pts(B, [[x, 200, 900] for x in (700, 900, 1100, 1300)]))
    evaluate("probe = probe_from_features(fc, fh, tmac); base = base_from_features(bc, bp, bl)",
             ws, FUNCTIONS, context=FunctionContext(ws, params_dir=tmp_path))
    np.testing.assert_allclose(pose_from_robot(ws.get("probe")[0], "zyz"), P, atol=1e-9)
    np.testing.assert_allclose(pose_from_robot(ws.get("base")[0], "zyz"), B, atol=1e-9)
