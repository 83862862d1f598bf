"""URDF/xacro import: the imported robot's FK equals pinocchio's FK of the same URDF.

Vendor robots of ../shared/data/urdf (skipped without the data), random URDF chains
(hypothesis), and every bad input with its message naming the file and the element.
"""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pinocchio_fk import pinocchio_tip_poses
from shared_data import FANUC_XACRO, STAUBLI_XACRO, UR_XACRO, URDF_DIR

from plugcell.io.robot_schema import description_from_dict, description_to_dict
from plugcell.io.robots import RobotSource, description_to_toml, load_robot
from plugcell.io.urdf import PackageResolver, import_urdf
from plugcell.kinematics import DescriptionError, RobotDescription, forward
from plugcell.kinematics.joint_chain import ChainJoint, JointChain, chain_forward, line_step

needs_urdf = pytest.mark.skipif(not URDF_DIR.is_dir(), reason="../shared/data/urdf not available")

VENDOR = [
    pytest.param(UR_XACRO, {"ur_type": "ur10", "name": "ur10"}, id="ur10"),
    pytest.param(UR_XACRO, {"ur_type": "ur10e", "name": "ur10e"}, id="ur10e"),
    pytest.param(UR_XACRO, {"ur_type": "ur5e", "name": "ur5e"}, id="ur5e"),
    pytest.param(FANUC_XACRO, {}, id="fanuc_m20ia"),
    pytest.param(STAUBLI_XACRO, {}, id="staubli_tx2_60l"),
]


def _pose_errors(A: np.ndarray, B: np.ndarray) -> tuple[float, float]:
    """Largest position (m) and rotation (rad) difference of two pose stacks."""
    dp = np.abs(A[:, :3, 3] - B[:, :3, 3]).max()
    R = np.einsum("nji,njk->nik", A[:, :3, :3], B[:, :3, :3])
    # ‖R − I‖_F = 2√2·|sin(φ/2)|: the angle φ without arccos's loss of precision near 0
    s = np.linalg.norm(R - np.eye(3), axis=(1, 2)) / (2 * math.sqrt(2))
    return float(dp), float((2 * np.arcsin(np.clip(s, 0, 1))).max())


def _random_q(desc: RobotDescription, n: int, seed: int) -> np.ndarray:
    lim = desc.joint_limits
    return np.random.default_rng(seed).uniform(lim[:, 0], lim[:, 1], size=(n, desc.n_actuated))


# =============================================================================== vendor robots
@needs_urdf
@pytest.mark.parametrize(("path", "args"), VENDOR)
def test_vendor_robot_matches_pinocchio(path: Path, args: dict[str, str]) -> None:
    imp = import_urdf(path, args)
    desc = imp.description
    assert desc.n_actuated == 6
    assert imp.tip_link == "tool0"
    q = _random_q(desc, 1000, seed=7)
    ours = forward(desc, None, q).world_tcp
    ref = pinocchio_tip_poses(imp.urdf, desc.actuated, imp.tip_link, q)
    dp, dr = _pose_errors(ours, ref)
    assert dp < 1e-9 and dr < 1e-9, (dp, dr)


@needs_urdf
@pytest.mark.parametrize(("path", "args"), VENDOR)
def test_vendor_description_round_trips_through_toml(tmp_path: Path, path: Path,
                                                     args: dict[str, str]) -> None:
    desc = import_urdf(path, args).description
    f = tmp_path / "robot.toml"
    f.write_text(description_to_toml(desc), encoding="utf-8")
    back = load_robot(f)
    assert back.actuated == desc.actuated
    np.testing.assert_allclose(back.joint_limits, desc.joint_limits, atol=1e-12)
    q = _random_q(desc, 50, seed=3)
    dp, dr = _pose_errors(forward(back, None, q).world_tcp, forward(desc, None, q).world_tcp)
    assert dp < 1e-12 and dr < 1e-12


@needs_urdf
def test_ur10_import_is_the_ur10_dh() -> None:
    """The UR10's rows are its published DH (|a|, d, α) with β rows on the parallel axes."""
    desc = import_urdf(UR_XACRO, {"ur_type": "ur10", "name": "ur10"}).description
    rows = [(abs(lk.a), lk.d, abs(math.sin(lk.alpha)), lk.hayati) for lk in desc.links]
    expect = [(0.0, 0.1273, 1, False), (0.612, 0, 0, True), (0.5723, 0, 0, True),
              (0.0, 0.163941, 1, False), (0.0, 0.1157, 1, False), (0.0, 0.0922, 0, False)]
    np.testing.assert_allclose(np.array(rows, dtype=float), np.array(expect, dtype=float),
                               atol=1e-9)
    assert np.allclose(desc.tool, np.eye(4), atol=1e-12)  # DH frame 6 is tool0
    assert [lk.mass for lk in desc.links] == [7.1, 12.7, 4.27, 2.0, 2.0, 0.365]


@needs_urdf
def test_package_path_and_environment(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A copied xacro outside its package finds the packages via --package-path / env."""
    src = (FANUC_XACRO.parent / "m20ia_macro.xacro").read_text()
    top = tmp_path / "cell.urdf.xacro"
    top.write_text(
        '<?xml version="1.0"?>\n<robot xmlns:xacro="http://wiki.ros.org/xacro" name="cell">\n'
        '  <xacro:include filename="$(find fanuc_m20ia_support)/urdf/m20ia_macro.xacro"/>\n'
        '  <xacro:fanuc_m20ia prefix=""/>\n</robot>\n')
    assert "fanuc_m20ia" in src
    with pytest.raises(DescriptionError, match=r"cell.urdf.xacro.*unknown package "
                       r"'fanuc_m20ia_support'"):
        import_urdf(top)
    a = import_urdf(top, package_paths=[URDF_DIR / "fanuc"]).description
    monkeypatch.setenv("PLUGCELL_PACKAGE_PATH", f"/nonexistent:{URDF_DIR / 'fanuc'}")
    b = import_urdf(top).description
    q = _random_q(a, 5, 1)
    assert np.allclose(forward(a, None, q).tcp, forward(b, None, q).tcp)


def test_resolver_order(tmp_path: Path) -> None:
    (tmp_path / "one" / "pkg").mkdir(parents=True)
    (tmp_path / "two" / "pkg").mkdir(parents=True)
    (tmp_path / "two" / "own" / "urdf").mkdir(parents=True)
    (tmp_path / "two" / "own" / "package.xml").write_text("<package/>")
    f = tmp_path / "two" / "own" / "urdf" / "r.xacro"
    r = PackageResolver((tmp_path / "one",), f)
    assert r.find("pkg") == (tmp_path / "one" / "pkg").resolve()
    assert PackageResolver((), f).find("pkg") == (tmp_path / "two" / "pkg").resolve()
    assert PackageResolver((), f).find("own") == (tmp_path / "two" / "own").resolve()
    with pytest.raises(LookupError, match="unknown package 'nope'"):
        r.find("nope")


# =============================================================================== random chains
def _xyz(v: np.ndarray) -> str:
    return " ".join(repr(float(x)) for x in v)


def _chain_urdf(joints: list[dict[str, object]], name: str = "rand") -> str:
    links = ["base"] + [f"l{i}" for i in range(len(joints))]
    out = [f'<robot name="{name}">'] + [f'  <link name="{lk}"/>' for lk in links]
    for i, j in enumerate(joints):
        body = (f'    <parent link="{links[i]}"/><child link="{links[i + 1]}"/>\n'
                f'    <origin xyz="{_xyz(j["xyz"])}" rpy="{_xyz(j["rpy"])}"/>\n')
        if j["type"] != "fixed":
            body += f'    <axis xyz="{_xyz(j["axis"])}"/>\n'
        if j["type"] in ("revolute", "prismatic"):
            body += '    <limit lower="-3" upper="3" effort="1" velocity="1"/>\n'
        out.append(f'  <joint name="j{i}" type="{j["type"]}">\n{body}  </joint>')
    out.append("</robot>")
    return "\n".join(out)


_AXES = [np.array(a, float) for a in
         ((0, 0, 1), (0, 1, 0), (1, 0, 0), (0, 0, -1), (0, -1, 0), (1, 1, 0), (0.3, -0.2, 0.9))]
_ANGLES = st.sampled_from([0.0, math.pi / 2, -math.pi / 2, math.pi]) | st.floats(-3.1, 3.1)
_LEN = st.sampled_from([0.0]) | st.floats(-0.8, 0.8)


@st.composite
def _joint(draw: st.DrawFn) -> dict[str, object]:
    kind = draw(st.sampled_from(["revolute", "revolute", "continuous", "prismatic", "fixed"]))
    return {"type": kind,
            "xyz": np.array([draw(_LEN) for _ in range(3)]),
            "rpy": np.array([draw(_ANGLES) for _ in range(3)]),
            "axis": draw(st.sampled_from(_AXES))}


@settings(max_examples=60, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(_joint(), min_size=1, max_size=9), st.integers(0, 2**31 - 1))
def test_random_chain_matches_pinocchio(tmp_path_factory: pytest.TempPathFactory,
                                        joints: list[dict[str, object]], seed: int) -> None:
    """Any chain of revolute/continuous/prismatic/fixed joints converts exactly to DH/Hayati
    rows (a robot on a linear track included)."""
    if all(j["type"] == "fixed" for j in joints):
        joints = [*joints, {"type": "revolute", "xyz": np.zeros(3), "rpy": np.zeros(3),
                            "axis": _AXES[0]}]
    f = tmp_path_factory.mktemp("urdf") / "rand.urdf"
    f.write_text(_chain_urdf(joints))
    imp = import_urdf(f)
    desc = imp.description
    assert desc.n_actuated == sum(j["type"] != "fixed" for j in joints)
    q = np.random.default_rng(seed).uniform(-3, 3, size=(20, desc.n_actuated))
    ours = forward(desc, None, q).world_tcp
    ref = pinocchio_tip_poses(imp.urdf, desc.actuated, imp.tip_link, q)
    dp, dr = _pose_errors(ours, ref)
    assert dp < 1e-9 and dr < 1e-9, (dp, dr)


@settings(max_examples=200, deadline=None, derandomize=True)
@given(st.floats(-3.1, 3.1), st.floats(-1, 1), st.floats(-1, 1), st.floats(-1e-5, 1e-5),
       st.floats(-1e-5, 1e-5))
def test_line_step_nearly_parallel_is_exact(th: float, px: float, py: float, ex: float,
                                            ey: float) -> None:
    """The Hayati branch puts the new z axis exactly on a (nearly) parallel line."""
    F = np.eye(4)
    F[:3, :3] = np.array([[math.cos(th), -math.sin(th), 0], [math.sin(th), math.cos(th), 0],
                          [0, 0, 1]])
    w = np.array([ex, ey, 1.0])
    p = np.array([px, py, 0.3])
    row = line_step(F, p, w)
    from plugcell.kinematics.joint_chain import _row_transform

    G = F @ _row_transform(row)
    z, o = G[:3, 2], G[:3, 3]
    wn = w / np.linalg.norm(w)
    assert np.allclose(z, wn, atol=1e-12)
    off = (o - p) - ((o - p) @ wn) * wn  # distance of the new origin from the line
    assert np.linalg.norm(off) < 1e-12


def test_chain_forward_reference() -> None:
    chain = JointChain("c", (ChainJoint("a", "revolute", np.eye(4), np.array([0, 0, 1.0])),))
    T = chain_forward(chain, np.array([math.pi / 2]))
    assert np.allclose(T[:3, 0], [0, 1, 0])


# =============================================================================== bad input
_GOOD = """<robot name="r">
  <link name="base"/><link name="a"/><link name="b"/><link name="tool0"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="a"/>
    <origin xyz="0 0 0.3" rpy="0 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="a"/><child link="b"/>
    <origin xyz="0.4 0 0" rpy="1.5707963267948966 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="t" type="fixed"><parent link="b"/><child link="tool0"/>
    <origin xyz="0 0 0.1" rpy="0 0 0"/></joint>
</robot>
"""


def _write(tmp_path: Path, text: str, name: str = "robot.urdf") -> Path:
    f = tmp_path / name
    f.write_text(text)
    return f


def test_good_urdf(tmp_path: Path) -> None:
    imp = import_urdf(_write(tmp_path, _GOOD))
    assert imp.description.actuated == ("j1", "j2")
    assert imp.tip_link == "tool0" and imp.base_link == "base"
    imp2 = import_urdf(_write(tmp_path, _GOOD), base_link="a", tip_link="b")
    assert imp2.description.actuated == ("j2",)


@pytest.mark.parametrize(("text", "kwargs", "match"), [
    (_GOOD.replace("</robot>", ""), {}, r"robot.urdf: malformed XML"),
    (_GOOD.replace('type="fixed"', 'type="floating"'), {},
     r"robot.urdf: joint 't': floating joints cannot be part of a robot's chain"),
    (_GOOD.replace('<parent link="b"/><child link="tool0"/>',
                   '<parent link="b"/><child link="a"/>'), {"tip_link": "b"},
     r"robot.urdf: link 'a'.*closed loop"),
    (_GOOD, {"tip_link": "flange"}, r"robot.urdf: --tip-link flange.*no link 'flange'"),
    (_GOOD, {"base_link": "b", "tip_link": "a"}, r"'a' does not hang below the base link 'b'"),
    (_GOOD.replace('<child link="b"/>', '<child link="x"/>'), {},
     r"robot.urdf: joint 'j2': <child>.*unknown link 'x'"),
    (_GOOD.replace('xyz="0.4 0 0"', 'xyz="0.4 0"'), {},
     r"joint 'j2': <origin xyz>.*expected 3 finite number"),
    (_GOOD.replace('lower="-2" upper="2"', 'lower="2" upper="2"'), {},
     r"joint 'j2': <limit>.*lower 2.0 must be below upper 2.0"),
    (_GOOD.replace('<axis xyz="0 0 1"/>\n    <limit lower="-2"',
                   '<axis xyz="0 0 1"/><mimic joint="jx"/>\n    <limit lower="-2"'), {},
     r"robot.urdf: joints\[1\] \(j2\).mimic: mimics 'jx', which is not a moving joint"),
    (_GOOD.replace('type="fixed"', 'type="prismatic"'), {},
     r"robot.urdf: joint 't': a prismatic joint needs <limit lower= upper=>"),
    ('<robot name="r"><link name="a"/><link name="b"/></robot>', {},
     r"robot.urdf: the URDF has 2 root links"),
    ('<robot name="r"><link name="a"/></robot>', {}, r"robot.urdf: the robot has no moving joint"),
    ("<robut/>", {}, r"robot.urdf: not a URDF"),
])
def test_bad_urdf(tmp_path: Path, text: str, kwargs: dict[str, str], match: str) -> None:
    with pytest.raises(DescriptionError, match=match):
        import_urdf(_write(tmp_path, text), **kwargs)


def test_mimic_joint_becomes_a_coupling(tmp_path: Path) -> None:
    """URDF <mimic>: the mimic joint is no reading; θ_j2 = −2·q_j1 + 0.3 (the coupling)."""
    text = _GOOD.replace('<axis xyz="0 0 1"/>\n    <limit lower="-2"',
                         '<axis xyz="0 1 0"/><mimic joint="j1" multiplier="-2" offset="0.3"/>'
                         '\n    <limit lower="-2"')
    imp = import_urdf(_write(tmp_path, text))
    desc = imp.description
    assert desc.reading_names == ("j1",) and desc.actuated == ("j1", "j2")
    np.testing.assert_allclose(desc.coupling.matrix, [[1.0], [-2.0]])
    np.testing.assert_allclose(desc.coupling.offset, [0.0, 0.3])
    q = np.random.default_rng(4).uniform(-3, 3, size=(200, 1))
    ours = forward(desc, None, q).world_tcp
    ref = pinocchio_tip_poses(imp.urdf, desc.actuated, imp.tip_link, desc.kinematic_joints(q))
    dp, dr = _pose_errors(ours, ref)
    assert dp < 1e-9 and dr < 1e-9
    back = tmp_path / "m.toml"
    back.write_text(description_to_toml(desc))
    assert load_robot(back).coupling is not None


def test_branching_robot_needs_tip(tmp_path: Path) -> None:
    text = _GOOD.replace("</robot>", """
  <link name="c"/><joint name="j3" type="revolute"><parent link="a"/><child link="c"/>
    <axis xyz="1 0 0"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
</robot>""")
    with pytest.raises(DescriptionError, match=r"branches into several actuated chains"):
        import_urdf(_write(tmp_path, text))
    assert import_urdf(_write(tmp_path, text), tip_link="c").description.actuated == ("j1", "j3")


def test_xacro_errors(tmp_path: Path) -> None:
    pkg = tmp_path / "mine" / "urdf"
    pkg.mkdir(parents=True)
    head = '<?xml version="1.0"?>\n<robot xmlns:xacro="http://wiki.ros.org/xacro" name="r">\n'
    f = _write(pkg, head + '<xacro:include filename="$(find nopkg)/x.xacro"/>\n</robot>',
               "a.urdf.xacro")
    with pytest.raises(DescriptionError, match=r"a.urdf.xacro: xacro: unknown package 'nopkg'"):
        import_urdf(f)
    f = _write(pkg, head + '<xacro:property name="p" value="${1/0}"/><link name="${p}"/>'
               "\n</robot>", "b.xacro")
    with pytest.raises(DescriptionError, match=r"b.xacro: xacro: division by zero"):
        import_urdf(f)
    f = _write(pkg, head + '<link name="$(arg n)"/>\n</robot>', "c.xacro")
    with pytest.raises(DescriptionError, match=r"c.xacro: xacro: .*--robot-arg n=VALUE"):
        import_urdf(f)
    f = _write(pkg, head + '<link name="a">\n</robot>', "d.xacro")
    with pytest.raises(DescriptionError, match=r"d.xacro: malformed XML"):
        import_urdf(f)
    with pytest.raises(DescriptionError, match=r"--robot-arg x: a plain .urdf file takes no"):
        import_urdf(_write(tmp_path, _GOOD), {"x": "1"})


def test_robot_source_options_only_for_urdf() -> None:
    with pytest.raises(DescriptionError, match=r"--robot-arg: applies to .urdf/.xacro robots"):
        RobotSource("smart_h4", {"a": "b"}).load()
    src = RobotSource("x.urdf.xacro", {"ur_type": "ur10"}, ("/p",), "b", "t")
    assert RobotSource.from_dict(src.to_dict()) == src
    assert src.argv() == ["--robot", "x.urdf.xacro", "--robot-arg", "ur_type=ur10",
                          "--package-path", "/p", "--base-link", "b", "--tip-link", "t"]


@settings(max_examples=150, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(st.data())
def test_mutated_urdf_gives_description_error_or_robot(tmp_path: Path, data: st.DataObject) -> None:
    """Any damage to a URDF is a DescriptionError naming the file — never another exception."""
    text = _GOOD
    for _ in range(data.draw(st.integers(1, 3))):
        i = data.draw(st.integers(0, len(text) - 1))
        n = data.draw(st.integers(0, 12))
        ins = data.draw(st.sampled_from(["", "<", ">", '"', " ", "x", "-1", "nan", "joint",
                                         "link", "/>", "</joint>", "fixed", "1e400", "&"]))
        text = text[:i] + ins + text[i + n:]
    f = _write(tmp_path, text, "m.urdf")
    try:
        desc = import_urdf(f).description
    except DescriptionError as exc:
        assert str(exc).startswith("m.urdf")
    else:
        assert desc.n_actuated >= 1
        assert np.all(np.isfinite(forward(desc, None, np.zeros(desc.n_actuated)).tcp))


def test_toml_of_imported_robot_is_a_description_file(tmp_path: Path) -> None:
    desc = import_urdf(_write(tmp_path, _GOOD)).description
    d = tomllib.loads(description_to_toml(desc, header="hello"))
    assert description_from_dict(d).actuated == desc.actuated


# =============================================================================== command line
def test_cli_describe_and_fk_of_a_urdf(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from plugcell.apps.cli import main

    f = _write(tmp_path, _GOOD)
    assert main(["kin", "describe", "--robot", str(f), "--format", "toml"]) == 0
    toml_text = capsys.readouterr().out
    g = tmp_path / "r.toml"
    g.write_text(toml_text)
    assert main(["kin", "fk", "--robot", str(g), "--joints", "10,20"]) == 0
    a = capsys.readouterr().out
    assert main(["kin", "fk", "--robot", str(f), "--joints", "10,20"]) == 0
    assert capsys.readouterr().out == a
    assert main(["kin", "describe", "--robot", str(f), "--tip-link", "nope"]) == 2
    assert "robot.urdf: --tip-link nope: no link 'nope'" in capsys.readouterr().err
    assert main(["kin", "fk", "--robot", str(f), "--robot-arg", "oops", "--joints", "1,2"]) == 2
    assert "--robot-arg 'oops': expected NAME=VALUE" in capsys.readouterr().err


@needs_urdf
def test_cli_ur10_xacro(capsys: pytest.CaptureFixture[str]) -> None:
    from plugcell.apps.cli import main

    assert main(["kin", "describe", "--robot", str(UR_XACRO), "--robot-arg", "ur_type:=ur10",
                 "--robot-arg", "name=ur10"]) == 0
    out = capsys.readouterr().out  # a URDF robot is printed as a description file
    assert '"shoulder_pan_joint"' in out and "d = 0.1273" in out
    assert tomllib.loads(out)["name"] == "ur10"
    assert main(["kin", "describe", "--robot", str(UR_XACRO), "--robot-arg", "ur_type:=ur10",
                 "--robot-arg", "name=ur10", "--format", "json"]) == 0
    assert '"d": 0.1273' in capsys.readouterr().out


@needs_urdf
def test_cli_fk_prints_the_tip_link(capsys: pytest.CaptureFixture[str]) -> None:
    """kin fk of a URDF robot whose tip is not the DH flange prints T_tcp = pinocchio's tool0."""
    import json

    from plugcell.apps.cli import main

    q = [10.0, -20.0, 30.0, 40.0, -50.0, 60.0]
    assert main(["kin", "fk", "--robot", str(FANUC_XACRO), "--joints",
                 ",".join(str(v) for v in q)]) == 0
    out = json.loads(capsys.readouterr().out)
    imp = import_urdf(FANUC_XACRO)
    ref = pinocchio_tip_poses(imp.urdf, imp.description.actuated, "tool0",
                              np.radians([q]))[0]
    np.testing.assert_allclose(out["T_tcp"], ref, atol=1e-11)


@settings(max_examples=200, deadline=None, derandomize=True)
@given(st.lists(st.text(max_size=8), max_size=4))
def test_robot_arg_parser(pairs: list[str]) -> None:
    from plugcell.apps.commands.robotargs import parse_robot_args

    try:
        d = parse_robot_args(pairs)
    except ValueError as exc:
        assert "--robot-arg" in str(exc) and "NAME=VALUE" in str(exc)
    else:
        for p in pairs:
            name = p.partition("=")[0].strip().removesuffix(":")
            assert name in d


@settings(max_examples=200, deadline=None, derandomize=True)
@given(st.recursive(st.none() | st.booleans() | st.integers() | st.text(max_size=5),
                    lambda c: st.lists(c, max_size=3)
                    | st.dictionaries(st.sampled_from(["ref", "args", "package_paths",
                                                       "base_link", "tip_link", "x"]), c,
                                      max_size=5), max_leaves=10))
def test_robot_source_from_any_json(d: object) -> None:
    """PARAMS.json's robot_source: a RobotSource or a DescriptionError, nothing else."""
    try:
        src = RobotSource.from_dict(d)
    except DescriptionError as exc:
        assert str(exc).startswith("robot_source")
    else:
        assert RobotSource.from_dict(src.to_dict()) == src


def test_description_of_params(tmp_path: Path) -> None:
    from plugcell.io.robots import description_of_params

    f = _write(tmp_path, _GOOD)
    desc = import_urdf(f).description
    assert description_of_params(
        {"description": description_to_dict(desc)}).actuated == ("j1", "j2")
    assert description_of_params({"robot_source": {"ref": str(f)}}).actuated == ("j1", "j2")
    assert description_of_params({"robot": "elbow6"}).name == "elbow6"
    with pytest.raises(DescriptionError, match=r"P.json: description: links"):
        description_of_params({"description": {**description_to_dict(desc), "links": 3}}, "P.json")
    with pytest.raises(DescriptionError, match=r"P.json: robot_source: .*not found"):
        description_of_params({"robot_source": {"ref": str(tmp_path / "gone.urdf")}}, "P.json")


_XACRO = """<?xml version="1.0"?>
<robot xmlns:xacro="http://wiki.ros.org/xacro" name="x">
  <xacro:arg name="len" default="0.4"/>
  <xacro:property name="l" value="$(arg len)"/>
  <xacro:macro name="seg" params="n parent">
    <link name="l${n}"/>
    <joint name="j${n}" type="revolute"><parent link="${parent}"/><child link="l${n}"/>
      <origin xyz="${l} 0 0" rpy="0 ${pi/2} 0"/><axis xyz="0 0 1"/>
      <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  </xacro:macro>
  <link name="base"/>
  <xacro:seg n="1" parent="base"/>
  <xacro:seg n="2" parent="l1"/>
</robot>
"""


def test_xacro_arguments_reach_the_robot(tmp_path: Path) -> None:
    f = _write(tmp_path, _XACRO, "x.urdf.xacro")
    a = import_urdf(f).description
    b = import_urdf(f, {"len": "0.7"}).description
    q = np.array([[0.3, -0.2]])
    pa, pb = forward(a, None, q).tcp[0, :3, 3], forward(b, None, q).tcp[0, :3, 3]
    assert not np.allclose(pa, pb)


@settings(max_examples=100, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(st.data())
def test_mutated_xacro_gives_description_error_or_robot(tmp_path: Path,
                                                       data: st.DataObject) -> None:
    """Any damage to a xacro file is a DescriptionError naming it — never another exception."""
    text = _XACRO
    for _ in range(data.draw(st.integers(1, 3))):
        i = data.draw(st.integers(0, len(text) - 1))
        n = data.draw(st.integers(0, 10))
        ins = data.draw(st.sampled_from(["", "<", ">", '"', "${", "}", "$(arg len)", "$(find q)",
                                         "xacro:", "/>", "1/0", "n", "&", "$(", "l9"]))
        text = text[:i] + ins + text[i + n:]
    f = _write(tmp_path, text, "m.urdf.xacro")
    args = data.draw(st.dictionaries(st.sampled_from(["len", "other"]),
                                     st.sampled_from(["0.5", "x", "", "${1}"]), max_size=2))
    try:
        desc = import_urdf(f, args).description
    except DescriptionError as exc:
        assert str(exc).startswith("m.urdf.xacro")
    else:
        assert desc.n_readings >= 1


@st.composite
def _near_parallel_chain(draw: st.DrawFn) -> JointChain:
    """Chains whose consecutive axes are parallel, nearly parallel (1e-9 … 1e-2 rad) or
    not: every branch of the row conversion, prismatic joints included."""
    joints = []
    for k in range(draw(st.integers(1, 7))):
        kind = draw(st.sampled_from(["revolute", "revolute", "prismatic", "fixed"]))
        tilt = draw(st.sampled_from([0.0, 1e-9, 1e-6, 1e-4, 5e-3, 2e-2, 0.5, math.pi / 2,
                                     math.pi]))
        az = draw(st.floats(-math.pi, math.pi))
        T = np.eye(4)
        c, s = math.cos(tilt), math.sin(tilt)
        R = np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
        Rz = np.array([[math.cos(az), -math.sin(az), 0], [math.sin(az), math.cos(az), 0],
                       [0, 0, 1]])
        T[:3, :3] = Rz @ R
        T[:3, 3] = [draw(st.floats(-0.5, 0.5)) for _ in range(3)]
        lim = (-2.0, 2.0)
        joints.append(ChainJoint(f"j{k}", kind, T, np.array([0.0, 0.0, 1.0]),
                                 None if kind == "fixed" else lim))
    if all(j.kind == "fixed" for j in joints):
        joints.append(ChainJoint("jz", "revolute", np.eye(4), np.array([0.0, 0.0, 1.0]),
                                 (-2.0, 2.0)))
    return JointChain("c", tuple(joints))


@settings(max_examples=300, deadline=None, derandomize=True)
@given(_near_parallel_chain(), st.integers(0, 2**31 - 1))
def test_conversion_is_exact_for_any_axes(chain: JointChain, seed: int) -> None:
    """description_from_chain reproduces the chain's own FK (origin · Rot/Trans per joint).

    To 1e-11 m: the common normal of axes just beyond the Hayati threshold (0.57°) is
    conditioned like 1/sin² ≈ 1e4, which turns 1e-16 round-off into ~1e-12 m.
    """
    from plugcell.kinematics.joint_chain import description_from_chain

    desc = description_from_chain(chain)
    q = np.random.default_rng(seed).uniform(-2, 2, size=(8, desc.n_readings))
    ours = forward(desc, None, q).tcp
    ref = np.array([chain_forward(chain, row) for row in q])
    dp, dr = _pose_errors(ours, ref)
    assert dp < 1e-11 and dr < 1e-11, (dp, dr)
