"""Prismatic joints: a 6R robot on a linear track (7 axes) — FK against pinocchio, the
manipulator and identification Jacobians against central differences, a calibration of
the track's position and tilt, description files and the command line in mm."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest
from derivatives import central_differences
from track_robot import TRACK_ROBOT

from plugcell.calibration import CalibrationData, Calibrator
from plugcell.calibration.identifiability import random_configurations
from plugcell.calibration.jacobian import identification_jacobian
from plugcell.calibration.model import ErrorModel
from plugcell.io.robot_schema import description_from_dict, description_to_dict
from plugcell.io.robots import description_to_toml, load_robot
from plugcell.io.urdf import import_urdf
from plugcell.kinematics import (
    DescriptionError,
    RobotDescription,
    forward,
    manipulator_jacobian,
    pose_error,
)

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "support"))


@pytest.fixture(scope="module")
def track(tmp_path_factory: pytest.TempPathFactory) -> tuple[RobotDescription, str]:
    f = tmp_path_factory.mktemp("track") / "track_ur.urdf"
    f.write_text(TRACK_ROBOT)
    imp = import_urdf(f)
    return imp.description, imp.urdf


def _q(desc: RobotDescription, n: int, seed: int) -> np.ndarray:
    lim = desc.joint_limits
    return np.random.default_rng(seed).uniform(lim[:, 0], lim[:, 1], size=(n, desc.n_readings))


def test_track_robot_is_seven_axes_with_a_prismatic_first(track: tuple[RobotDescription,
                                                                       str]) -> None:
    desc, _ = track
    assert desc.n_readings == 7
    assert desc.link("track").is_prismatic and desc.link("track").is_actuated
    assert list(desc.prismatic_readings) == [True] + [False] * 6
    assert list(desc.periodic_readings) == [False] + [True] * 6
    assert list(desc.prismatic_links) == [True] + [False] * 6
    assert list(desc.revolute_links[0]) == list(range(1, 7))  # the track moves d, not θ
    np.testing.assert_allclose(desc.joint_limits[0], [0.0, 3.0])


def test_track_fk_matches_pinocchio(track: tuple[RobotDescription, str]) -> None:
    from pinocchio_fk import pinocchio_tip_poses

    desc, urdf = track
    q = _q(desc, 1000, 1)
    ours = forward(desc, None, q).world_tcp
    ref = pinocchio_tip_poses(urdf, desc.actuated, "tool0", q)
    assert np.abs(ours[:, :3, 3] - ref[:, :3, 3]).max() < 1e-9
    assert np.abs(ours[:, :3, :3] - ref[:, :3, :3]).max() < 1e-9
    # the carriage moves 1 m along (about) x when the track reading grows by 1 m
    q0 = np.zeros((2, 7))
    q0[1, 0] = 1.0
    p = forward(desc, None, q0).flange[:, :3, 3]
    np.testing.assert_allclose(p[1] - p[0], [math.cos(0.002), 0, math.sin(0.002)], atol=1e-3)


def test_manipulator_jacobian_matches_central_differences(track: tuple[RobotDescription,
                                                                       str]) -> None:
    desc, _ = track
    q = _q(desc, 5, 2)
    for point in ("flange", "tcp"):
        J = manipulator_jacobian(desc, None, q, point=point)

        def pose(qq: np.ndarray, point: str = point) -> np.ndarray:
            fk = forward(desc, None, qq)
            return fk.tcp if point == "tcp" else fk.flange

        T0 = pose(q)
        fd = central_differences(lambda qq, pose=pose, T0=T0: pose_error(pose(qq), T0), q)
        np.testing.assert_allclose(J, fd, atol=1e-7)
        for i in range(len(q)):  # one configuration: the float path, the same columns
            np.testing.assert_allclose(manipulator_jacobian(desc, None, q[i], point=point),
                                       J[i], rtol=1e-12, atol=1e-14)
    assert np.allclose(J[:, 3:, 0], 0.0)  # a prismatic joint does not turn the tool


@pytest.mark.parametrize("gravity", [False, True])
def test_identification_jacobian_matches_central_differences(
        track: tuple[RobotDescription, str], gravity: bool) -> None:
    desc, _ = track
    rng = np.random.default_rng(5)
    m = ErrorModel.create(desc, "serial", gravity=gravity)
    v = rng.normal(size=len(m.space)) * 2e-3
    for i, p in enumerate(m.space):
        if p.kind == "gravity":
            v[i] = rng.normal() * 1e-7
    model = m.with_values(v)
    q = random_configurations(model, 6, seed=3)
    batch = model.batch(q)
    jac = identification_jacobian(model, batch)
    np.testing.assert_allclose(jac.poses, model.predict_batch(batch), atol=1e-14)
    T0 = model.predict_batch(batch)
    h = 1e-6
    for c, k in enumerate(model.space.keys):
        Tp = model.updated({k: h}).predict_batch(batch)
        Tm = model.updated({k: -h}).predict_batch(batch)
        fd = (pose_error(Tp, T0) - pose_error(Tm, T0)) / (2 * h)
        an = jac.H[:, :, c]
        scale = max(np.abs(an).max(), np.abs(fd).max())
        assert np.abs(an - fd).max() <= 1e-7 * scale + 1e-9, k
    if gravity:
        assert "ctrack" in model.space.keys or any(p.kind == "gravity" and p.joint == "track"
                                                   for p in model.space)


def test_calibration_finds_the_track_tilt(track: tuple[RobotDescription, str]) -> None:
    """Noise-free poses of a robot whose track is tilted and offset: the fit is exact."""
    desc, _ = track
    p = desc.nominal_parameters()
    i_track, i_1 = p.index("track"), p.index("j1")
    true = p.perturbed({("track", "alpha"): 1e-3, ("track", "theta"): -8e-4,
                        ("track", "a"): 2e-3, ("j1", "d"): 1e-3, ("j2", "a"): -5e-4})
    assert i_track != i_1
    base = np.eye(4)
    base[:3, 3] = [1.0, -2.0, 0.1]
    probe = np.eye(4)
    probe[:3, 3] = [0.0, 0.03, 0.12]
    q = _q(desc, 120, 8)
    T = base @ forward(desc, true, q).flange @ probe
    res = Calibrator(desc, "serial").fit(CalibrationData.from_poses(q, T))
    assert res.calibration_before.position.norm.mean > 3e-4  # BASE/PROBE fitted, nominal
    assert res.calibration.position.norm.max < 1e-7
    q_val = _q(desc, 50, 9)
    T_val = base @ forward(desc, true, q_val).flange @ probe
    assert np.abs(res.predict(q_val)[:, :3, 3] - T_val[:, :3, 3]).max() < 1e-7


def test_description_file_round_trip_in_metres(tmp_path: Path,
                                               track: tuple[RobotDescription, str]) -> None:
    desc, _ = track
    text = description_to_toml(desc)
    assert 'joint = "prismatic"' in text
    f = tmp_path / "track.toml"
    f.write_text(text)
    back = load_robot(f)
    np.testing.assert_allclose(back.joint_limits, desc.joint_limits, atol=1e-12)
    np.testing.assert_allclose(back.home, desc.home, atol=1e-12)
    k = back.index("track")
    assert description_to_dict(back)["links"][k]["limits"] == [0.0, 3.0]
    d = description_to_dict(back)
    d["links"][k]["limits"] = [1.0, 0.5]
    with pytest.raises(DescriptionError, match=rf"links\[{k}\].limits"):
        description_from_dict(d)
    d["links"][k]["limits"] = [0.0, 3.0]
    d["home"][0] = 4.0
    with pytest.raises(DescriptionError, match=r"home\[0\]: joint track = 4000 mm is outside"):
        description_from_dict(d)
    assert "joint track = 3500.0000 mm outside [0 mm, 3000 mm]" in back.limit_violations(
        np.r_[3.5, np.zeros(6)])[0]


def test_cli_fk_takes_millimetres(tmp_path: Path, track: tuple[RobotDescription, str],
                                  capsys: pytest.CaptureFixture[str]) -> None:
    import json

    from plugcell.apps.cli import main

    desc, _ = track
    f = tmp_path / "track.toml"
    f.write_text(description_to_toml(desc))
    assert main(["kin", "fk", "--robot", str(f), "--joints", "1500,10,-80,70,-30,90,20"]) == 0
    out = json.loads(capsys.readouterr().out)
    q = np.r_[1.5, np.radians([10, -80, 70, -30, 90, 20])]
    np.testing.assert_allclose(out["T"], forward(desc, None, q).flange, atol=1e-11)
    assert main(["kin", "ik", "--robot", str(f), "--pose",
                 ",".join(str(v) for v in out["pose_mm_zyz"]),
                 "--start", "1400,0,-90,90,0,90,0"]) == 0
    sol = json.loads(capsys.readouterr().out)
    assert sol["position_error_mm"] < 1e-3
    assert 0 <= sol["joints"][0] <= 3000


@pytest.mark.slow
def test_track_robot_command_line_end_to_end(tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    """calibrate --robot track.urdf on a measurement file with the track in mm, export the
    URDF (pinocchio = calibrated model), compensate (joints back in degrees and mm)."""
    import json

    from pinocchio_fk import pinocchio_tip_poses

    from plugcell.apps.cli import main
    from plugcell.io.measurements import MeasurementSet, write_measurements
    from plugcell.io.params import result_from_params
    from plugcell.kinematics.rotations import matrix_to_angles

    urdf = tmp_path / "track_ur.urdf"
    urdf.write_text(TRACK_ROBOT)
    desc = import_urdf(urdf).description
    true = desc.nominal_parameters().perturbed({("track", "alpha"): 1e-3, ("j2", "a"): 5e-4})
    base = np.eye(4)
    base[:3, 3] = [1.0, -2.0, 0.1]
    probe = np.eye(4)
    probe[:3, 3] = [0.0, 0.03, 0.12]
    for name, seed in (("cal.csv", 1), ("val.csv", 2)):
        q = _q(desc, 80, seed)
        T = base @ forward(desc, true, q).flange @ probe
        ms = MeasurementSet(q, T[:, :3, 3], matrix_to_angles(T[:, :3, :3], "rpy"), "rpy")
        write_measurements(tmp_path / name, ms, joint_scale=desc.reading_scale())
    assert "1" in (tmp_path / "cal.csv").read_text().splitlines()[2]  # the track in mm
    params = tmp_path / "params.json"
    assert main(["calibrate", "--robot", str(urdf), "--model", "serial", "--data",
                 str(tmp_path / "cal.csv"), "--validate", str(tmp_path / "val.csv"),
                 "--out", str(params), "--quiet"]) == 0
    d = json.loads(params.read_text())
    assert d["validation"]["mean_mm"] < 1e-4
    out = tmp_path / "cal.urdf"
    assert main(["export", "--params", str(params), "--format", "urdf", "--out", str(out),
                 "--include-base", "--include-probe"]) == 0
    res = result_from_params(d, desc)
    q = _q(desc, 200, 3)
    ref = pinocchio_tip_poses(out.read_text(), desc.actuated, "probe", q)
    assert np.abs(ref[:, :3, 3] - res.predict(q)[:, :3, 3]).max() < 1e-9
    # compensation: the targets of known joints come back as those joints (deg and mm)
    qt = _q(desc, 3, 4)
    Tt = np.linalg.inv(res.model.base()) @ res.predict(qt)
    from plugcell.kinematics.rotations import matrix_to_zyz

    rows = ["name,x,y,z,rx,ry,rz"] + [
        f"P{i},{','.join(f'{v:.9f}' for v in Tt[i, :3, 3] * 1e3)},"
        f"{','.join(f'{v:.9f}' for v in np.degrees(matrix_to_zyz(Tt[i, :3, :3])))}"
        for i in range(3)]
    (tmp_path / "targets.csv").write_text("\n".join(rows) + "\n")
    capsys.readouterr()
    assert main(["compensate", "--params", str(params), "--targets",
                 str(tmp_path / "targets.csv"), "--out", str(tmp_path / "joints.csv")]) == 0
    lines = [ln for ln in (tmp_path / "joints.csv").read_text().splitlines()
             if not ln.startswith("#")][1:]
    got = np.array([[float(v) for v in ln.split(",")[1:8]] for ln in lines])
    # 7 axes for a 6-DOF pose: any of the solutions; the model puts the tool on the target
    q_back = got * desc.reading_scale()  # degrees and the track's mm → SI
    assert np.all((got[:, 0] >= 0) & (got[:, 0] <= 3000))
    T_back = np.linalg.inv(res.model.base()) @ res.predict(q_back)
    assert np.abs(T_back[:, :3, 3] - Tt[:, :3, 3]).max() < 1e-6


def test_plan_and_twin_files_hold_the_track_in_millimetres(tmp_path: Path) -> None:
    """plan → twin measure --plan → calibrate with a prismatic axis: every file holds the
    track in mm (as measurement files do), so the three commands agree on it."""
    import json

    from plugcell.apps.cli import main

    urdf = tmp_path / "track_ur.urdf"
    urdf.write_text(TRACK_ROBOT)
    plan, cal, val, params = (tmp_path / n for n in ("plan.csv", "cal.csv", "val.csv", "p.json"))
    assert main(["plan", "--robot", str(urdf), "--model", "serial", "--poses", "40",
                 "--out", str(plan)]) == 0

    def track_column(path: Path) -> np.ndarray:
        rows = [ln for ln in path.read_text().splitlines() if not ln.startswith("#")][1:]
        return np.array([float(r.split(",")[0]) for r in rows])

    planned = track_column(plan)
    assert planned.max() > 500.0  # mm on a 0–3000 mm track (its metres read as radians: < 172°)
    assert main(["twin", "measure", "--robot", str(urdf), "--plan", str(plan), "--out",
                 str(cal), "--quiet"]) == 0
    np.testing.assert_allclose(track_column(cal), planned, atol=0.05)  # the track's error
    assert main(["twin", "measure", "--robot", str(urdf), "--poses", "30", "--pose-seed", "5",
                 "--out", str(val), "--quiet"]) == 0
    assert main(["calibrate", "--robot", str(urdf), "--model", "serial", "--data", str(cal),
                 "--validate", str(val), "--out", str(params), "--quiet"]) == 0
    d = json.loads(params.read_text())
    assert d["validation"]["mean_mm"] < d["validation"]["before"]["mean_mm"]
