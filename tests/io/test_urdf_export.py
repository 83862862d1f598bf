"""Export of a calibration: the exported URDF's FK (by pinocchio), the UR kinematics file
expanded by the official xacro, and the TOML description all equal plugcell's calibrated
geometric model to 1e-9 m on 1 000 configurations."""

from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path

import numpy as np
import pytest
from pinocchio_fk import pinocchio_tip_poses
from shared_data import UR_XACRO, URDF_DIR
from yourdfpy_fk import yourdfpy_tip_poses

from plugcell.calibration import CalibrationData, Calibrator
from plugcell.calibration.result import CalibrationResult
from plugcell.io.export import ExportError, export_calibration
from plugcell.io.params import params_document
from plugcell.io.robot_schema import description_from_dict, description_to_dict
from plugcell.io.robots import RobotSource, load_robot
from plugcell.io.urdf import import_urdf
from plugcell.kinematics import RobotDescription, forward

needs_urdf = pytest.mark.skipif(not URDF_DIR.is_dir(), reason="../shared/data/urdf not available")

ROBOT = """<robot name="arm">
  <link name="base_link"><inertial><mass value="5"/><origin xyz="0 0 0.1"/>
    <inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial>
    <visual><geometry><mesh filename="package://arm/meshes/base.stl"/></geometry></visual></link>
  <link name="l1"><inertial><mass value="4"/><origin xyz="0 0.1 0.2"/>
    <inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>
  <link name="l2"><inertial><mass value="3"/><origin xyz="0.3 0 0"/>
    <inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>
  <link name="l3"/><link name="l4"/><link name="l5"/><link name="l6"/>
  <link name="flange"/><link name="tool0"/><link name="camera"/>
  <joint name="j1" type="revolute"><parent link="base_link"/><child link="l1"/>
    <origin xyz="0 0 0.4" rpy="0 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/>
    <origin xyz="0.15 0 0" rpy="1.5707963267948966 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="j3" type="revolute"><parent link="l2"/><child link="l3"/>
    <origin xyz="0.6 0 0" rpy="0 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="j4" type="continuous"><parent link="l3"/><child link="l4"/>
    <origin xyz="0.05 0.5 0" rpy="-1.5707963267948966 0 0"/><axis xyz="0 0 1"/></joint>
  <joint name="j5" type="revolute"><parent link="l4"/><child link="l5"/>
    <origin xyz="0 0 0" rpy="1.5707963267948966 0 0"/><axis xyz="0 -1 0"/>
    <limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="j6" type="revolute"><parent link="l5"/><child link="l6"/>
    <origin xyz="0 0.1 0" rpy="-1.5707963267948966 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="l6-flange" type="fixed"><parent link="l6"/><child link="flange"/>
    <origin xyz="0 0 0.08" rpy="0 0 0"/></joint>
  <joint name="flange-tool0" type="fixed"><parent link="flange"/><child link="tool0"/>
    <origin xyz="0 0 0" rpy="0 1.5707963267948966 0"/></joint>
  <joint name="l3-camera" type="fixed"><parent link="l3"/><child link="camera"/>
    <origin xyz="0.1 0 0" rpy="0 0 0"/></joint>
</robot>
"""


def _calibrate(desc: RobotDescription, model: str = "serial", seed: int = 0,
               n: int = 150) -> CalibrationResult:
    """An exact calibration of ``desc`` perturbed by ~1 mm / 0.05° (noise-free poses)."""
    rng = np.random.default_rng(seed)
    p = desc.nominal_parameters()
    n = p.n_links
    chain = {desc.links[i].name for i in desc.chain}
    mask = np.array([lk in chain for lk in p.link_names], dtype=float)
    true = p.replace(theta=p.theta + rng.normal(0, 1e-3, n) * mask,
                     d=p.d + rng.normal(0, 1e-3, n) * mask, a=p.a + rng.normal(0, 1e-3, n) * mask,
                     alpha=p.alpha + rng.normal(0, 1e-3, n) * mask)
    base = np.eye(4)
    base[:3, 3] = [2.0, -1.0, 0.3]
    probe = np.eye(4)
    probe[:3, 3] = [0.02, 0.01, 0.1]
    lim = desc.joint_limits
    q = rng.uniform(np.maximum(lim[:, 0], -2.5), np.minimum(lim[:, 1], 2.5),
                    size=(600, desc.n_actuated))
    q = q[desc.within_limits(q)][:n]
    T = base @ forward(desc, true, q).flange @ probe
    return Calibrator(desc, model).fit(CalibrationData.from_poses(q, T))


def _q(desc: RobotDescription, n: int = 1000) -> np.ndarray:
    lim = desc.joint_limits
    return np.random.default_rng(11).uniform(lim[:, 0], lim[:, 1], size=(n, desc.n_actuated))


def _max_dp(A: np.ndarray, B: np.ndarray) -> float:
    return float(np.abs(A[:, :3, 3] - B[:, :3, 3]).max())


def _max_dr(A: np.ndarray, B: np.ndarray) -> float:
    R = np.einsum("nji,njk->nik", A[:, :3, :3], B[:, :3, :3])
    s = np.linalg.norm(R - np.eye(3), axis=(1, 2)) / (2 * math.sqrt(2))
    return float((2 * np.arcsin(np.clip(s, 0, 1))).max())


@pytest.fixture(scope="module")
def arm(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, RobotDescription,
                                                           CalibrationResult]:
    f = tmp_path_factory.mktemp("arm") / "arm.urdf"
    f.write_text(ROBOT)
    desc = import_urdf(f).description
    return f, desc, _calibrate(desc)


def test_exported_urdf_matches_calibrated_model(arm: tuple[Path, RobotDescription,
                                                           CalibrationResult]) -> None:
    f, desc, res = arm
    assert res.calibration.position.norm.max < 1e-5  # the fit found the perturbation
    out = export_calibration(res, desc, "urdf", source=RobotSource(str(f)),
                             include_base=True, include_probe=True)
    q = _q(desc)
    model = res.model.predict(q)  # BASE · F_n'(q) · PROBE (no compliance in model 1)
    ref = pinocchio_tip_poses(out.text, desc.actuated, "probe", q)
    assert _max_dp(ref, model) < 1e-9 and _max_dr(ref, model) < 1e-9
    # the tip link is the calibrated chain's tip: BASE · F_n'(q) · tool
    tip = res.model.base() @ forward(desc, res.model.geometric_parameters(), q).tcp
    ref_tip = pinocchio_tip_poses(out.text, desc.actuated, "tool0", q)
    assert _max_dp(ref_tip, tip) < 1e-9 and _max_dr(ref_tip, tip) < 1e-9
    # links, meshes, inertias and limits of the source are kept
    assert 'filename="package://arm/meshes/base.stl"' in out.text
    assert '<mass value="4"/>' in out.text and 'name="camera"' in out.text
    assert out.side is None  # BASE and PROBE are in the file, model 1 has no compliance


def test_urdf_without_frames_writes_them_to_the_side(arm: tuple[Path, RobotDescription,
                                                                CalibrationResult]) -> None:
    f, desc, res = arm
    out = export_calibration(res, desc, "urdf", source=RobotSource(str(f)))
    assert out.side is not None
    assert any("BASE" in r for r in out.side["not_in_main_file"])
    base = np.array(out.side["base"]["matrix"])
    probe = np.array(out.side["probe_in_tip"]["matrix"])
    q = _q(desc, 50)
    ref = base @ pinocchio_tip_poses(out.text, desc.actuated, "tool0", q) @ probe
    assert _max_dp(ref, res.model.predict(q)) < 1e-9


def test_toml_export_loads_back_to_the_calibrated_model(
        tmp_path: Path, arm: tuple[Path, RobotDescription, CalibrationResult]) -> None:
    _, desc, res = arm
    out = export_calibration(res, desc, "toml")
    g = tmp_path / "cal.toml"
    g.write_text(out.text)
    back = load_robot(g)
    q = _q(desc)
    model = res.model.predict(q)
    got = forward(back, None, q).world_tcp
    assert _max_dp(got, model) < 1e-9 and _max_dr(got, model) < 1e-9
    # and a second export of the loaded description writes the same file
    g2 = tmp_path / "again.toml"
    from plugcell.io.robots import description_to_toml

    g2.write_text(description_to_toml(back))
    # unchanged up to the round-off of radians → degrees → radians (files hold degrees)
    np.testing.assert_allclose(load_robot(g2).nominal_parameters().table(),
                               back.nominal_parameters().table(), atol=1e-14, rtol=0)


@pytest.mark.slow
def test_generic_urdf_of_a_toml_robot(tmp_path: Path) -> None:
    desc = load_robot("elbow6")
    res = _calibrate(desc, seed=3, n=60)
    out = export_calibration(res, desc, "urdf", source=RobotSource("elbow6"),
                             include_base=True, include_probe=True)
    q = _q(desc)
    ref = pinocchio_tip_poses(out.text, desc.actuated, "probe", q)
    model = res.model.predict(q)
    assert _max_dp(ref, model) < 1e-9 and _max_dr(ref, model) < 1e-9


@pytest.fixture(scope="module")
def h4_loop() -> tuple[RobotDescription, CalibrationResult]:
    desc = load_robot("smart_h4")
    return desc, _calibrate(desc, model="loop", seed=1, n=60)


def test_loop_calibration_is_no_serial_equivalent(
        h4_loop: tuple[RobotDescription, CalibrationResult]) -> None:
    """--serial-equivalent asks for a serial calibration; the message names what works."""
    desc, res = h4_loop
    with pytest.raises(ExportError, match=r"identified the loop itself; export it without "
                       r"--serial-equivalent.*--format toml: exact.*--model serial"):
        export_calibration(res, desc, "urdf", serial_equivalent=True)


@pytest.mark.slow
def test_loop_robot_serial_equivalent() -> None:
    desc = load_robot("smart_h4")
    res = _calibrate(desc, model="serial", seed=2, n=60)
    out = export_calibration(res, desc, "urdf", serial_equivalent=True, include_base=True,
                             include_probe=True)
    assert out.side is None  # BASE, PROBE in the file; the URDF's joints are the readings (mimics)
    q = np.radians([[0, -90, -187, 0, 90, 0], [10, -80, -190, 20, 60, -30]])
    ref = yourdfpy_tip_poses(out.text, desc.reading_names, "probe", q)
    model = res.model.predict(q)
    assert _max_dp(ref, model) < 1e-9 and _max_dr(ref, model) < 1e-9


@needs_urdf
@pytest.mark.slow
def test_ur_kinematics_yaml_expands_to_the_calibrated_ur10(tmp_path: Path) -> None:
    """The official ur_description xacro with the exported YAML is the calibrated robot."""
    args = {"ur_type": "ur10", "name": "ur10"}
    imp = import_urdf(UR_XACRO, args)
    res = _calibrate(imp.description, seed=5)
    src = RobotSource(str(UR_XACRO), args)
    out = export_calibration(res, imp.description, "ur-kinematics", source=src)
    y = tmp_path / "default_kinematics.yaml"
    y.write_text(out.text)
    again = import_urdf(UR_XACRO, {**args, "kinematics_params": str(y)})
    q = _q(imp.description)
    tcp = np.array(out.side["tcp_in_tip"]["matrix"])
    base = np.array(out.side["base"]["matrix"])
    ref = base @ pinocchio_tip_poses(again.urdf, imp.description.actuated, "tool0", q) @ tcp
    model = res.model.predict(q)
    assert _max_dp(ref, model) < 1e-9 and _max_dr(ref, model) < 1e-9
    # the calibrated geometry up to the flange's offset (folded into the TCP)
    flange_fix = np.array(out.side["flange_correction"]["matrix"])
    tip = forward(imp.description, res.model.geometric_parameters(), q).tcp
    ref_tip = pinocchio_tip_poses(again.urdf, imp.description.actuated, "tool0", q) @ flange_fix
    assert _max_dp(ref_tip, tip) < 1e-9


def test_cli_export(tmp_path: Path, arm: tuple[Path, RobotDescription, CalibrationResult],
                    capsys: pytest.CaptureFixture[str]) -> None:
    from plugcell.apps.cli import main

    f, desc, res = arm
    d = params_document(res)
    d["robot_source"] = RobotSource(str(f)).absolute().to_dict()
    d["description"] = description_to_dict(desc)
    params = tmp_path / "params.json"
    params.write_text(json.dumps(d, default=float))
    out = tmp_path / "cal.urdf"
    assert main(["export", "--params", str(params), "--format", "urdf", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "cal.urdf.extra.json" in text and "BASE" in text
    assert (tmp_path / "cal.urdf.extra.json").is_file()
    assert main(["export", "--params", str(params), "--format", "ur-kinematics", "--out",
                 str(tmp_path / "k.yaml")]) == 2
    assert "cannot export as ur-kinematics" in capsys.readouterr().err
    bad = tmp_path / "bad.json"
    bad.write_text("[1]")
    assert main(["export", "--params", str(bad), "--format", "toml", "--out",
                 str(tmp_path / "x.toml")]) == 2
    assert "bad.json: expected a JSON object" in capsys.readouterr().err


@pytest.mark.slow
@pytest.mark.skipif(not (URDF_DIR.parent / "ipa-robot-accuracy").is_dir(),
                    reason="../shared/data/ipa-robot-accuracy not available")
def test_ipa_ur10_calibrates_alike_from_xacro_and_hand_dh(tmp_path: Path) -> None:
    """docs/results/ur10.md's figures with the imported ur_description (within 0.002 mm)."""
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
    from calibration_ur10 import SERIES, read_series, ur10_toml
    from plugcell.kinematics.rotations import angles_to_matrix

    ipa = URDF_DIR.parent / "ipa-robot-accuracy"
    sets = {}
    for key in "AB":
        q, p, a = read_series(ipa / SERIES[key][0])
        sets[key] = CalibrationData(q, p, angles_to_matrix(a, "xyz"))
    (tmp_path / "ur10.toml").write_text(ur10_toml())
    figures = []
    for desc in (load_robot(tmp_path / "ur10.toml"),
                 import_urdf(UR_XACRO, {"ur_type": "ur10", "name": "ur10"}).description):
        res = Calibrator(desc, "serial").fit(sets["A"])
        _, val = res.evaluate(sets["B"], refit_base=True)
        figures.append([res.calibration.position.norm.mean, res.calibration.position.norm.max,
                        val.position.norm.mean, val.position.norm.max])
    f = np.array(figures) * 1e3
    assert np.abs(f[0] - f[1]).max() < 0.002
    # docs/results/ur10.md: calibration A 0.403 / 1.158, validation B 0.498 / 2.413 mm
    np.testing.assert_allclose(f[1], [0.403, 1.158, 0.498, 2.413], atol=0.0015)


@pytest.mark.slow
def test_loop_robot_toml_export_is_exact(
        h4_loop: tuple[RobotDescription, CalibrationResult]) -> None:
    """A calibrated parallelogram that is no longer one is a ``fourbar`` loop of the file."""
    desc, res = h4_loop
    out = export_calibration(res, desc, "toml")
    assert 'type = "fourbar"' in out.text
    back = description_from_dict(tomllib.loads(out.text))
    q = _q(desc, 2000)
    q = q[desc.within_limits(q)]
    got = forward(back, None, q).world_tcp
    model = res.model.predict(q)  # model 2: geometry only
    assert len(q) > 200 and _max_dp(got, model) < 1e-9 and _max_dr(got, model) < 1e-9


def test_cli_export_source_gone(tmp_path: Path, arm: tuple[Path, RobotDescription,
                                                           CalibrationResult],
                                capsys: pytest.CaptureFixture[str]) -> None:
    """The source URDF moved: the message says so and how to give it; --robot does."""
    from plugcell.apps.cli import main

    f, desc, res = arm
    d = params_document(res)
    d["robot_source"] = {"ref": str(tmp_path / "moved.urdf")}
    d["description"] = description_to_dict(desc)
    params = tmp_path / "params.json"
    params.write_text(json.dumps(d, default=float))
    out = tmp_path / "cal.urdf"
    assert main(["export", "--params", str(params), "--format", "urdf", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "params.json: the robot's source URDF" in err and "--robot FILE" in err
    assert main(["export", "--params", str(params), "--format", "urdf", "--out", str(out),
                 "--robot", str(f)]) == 0
    assert main(["export", "--params", str(params), "--format", "toml", "--out",
                 str(tmp_path / "cal.toml")]) == 0  # the embedded description suffices


def test_side_file_names_the_thermal_term_and_a_learned_layer(
        arm: tuple[Path, RobotDescription, CalibrationResult]) -> None:
    """No format carries κT or a learned residual layer: the side file says so, with values."""
    f, desc, _ = arm
    rng = np.random.default_rng(4)
    lim = desc.joint_limits
    q = rng.uniform(np.maximum(lim[:, 0], -2.5), np.minimum(lim[:, 1], 2.5), size=(80, 6))
    t = rng.uniform(15.0, 30.0, len(q))
    T = forward(desc, None, q).flange
    T[:, :3, 3] *= (1.0 + 2e-5 * (t - t.mean()))[:, None]  # lengths grow 20 µm/m/K
    data = CalibrationData(q, T[:, :3, 3], T[:, :3, :3], temperature_c=t)
    res = Calibrator(desc, "serial", thermal=True).fit(data)
    layer = {"kind": "learned", "file": "params.residual.joblib"}
    for fmt in ("toml", "urdf"):
        out = export_calibration(res, desc, fmt, source=RobotSource(str(f)),
                                 residual_model=layer)
        reasons = " ".join(out.side["not_in_main_file"])
        assert "thermal expansion κT" in reasons and "params.residual.joblib" in reasons
        assert out.side["thermal"]["kT_per_K"] == pytest.approx(2e-5, rel=1e-3)
        assert out.side["thermal"]["temperature_ref_c"] == pytest.approx(t.mean())
        assert out.side["residual_model"] == layer
