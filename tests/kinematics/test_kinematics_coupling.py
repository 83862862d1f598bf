"""Vendor joint conventions: a coupling maps controller readings to kinematic joints.

θ_kin = M · readings + offset (docs/robot-description.md, "Vendor joint conventions").
Checked here: the shipped Fanuc M-20iA against its ROS-Industrial URDF joint chain,
coupled vs hand-converted descriptions (identical FK), Jacobians w.r.t. readings
against central differences, IK returning readings, precise errors for bad coupling
input, and property tests of the ``[coupling]`` parser (dict and TOML text).
"""

from __future__ import annotations

import contextlib
import copy
import io
import math
import re
import tomllib
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from coupling_testlib import hand_converted, mimic_elbow, sign_flipped_h4, wrist_gear_elbow
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from kinematics_testlib import perturbed_params, random_configs
from scipy.spatial.transform import Rotation

from plugcell.io.robot_schema import description_from_dict, description_to_dict
from plugcell.io.robots import load_robot, load_robot_file
from plugcell.kinematics import (
    DescriptionError,
    RobotDescription,
    forward,
    inverse,
    manipulator_jacobian,
    pose_error_exact,
    translation,
)

DEG = math.pi / 180.0


# ----------------------------------------------------------------------------- Fanuc
_URDF_ORIGINS = [
    (0, 0, 0.525), (0.15, 0, 0), (0, 0, 0.79), (0, 0, 0.25), (0.835, 0, 0), (0.1, 0, 0)
]
_URDF_AXES = [(0, 0, 1), (0, 1, 0), (0, -1, 0), (-1, 0, 0), (0, -1, 0), (-1, 0, 0)]


def _urdf_tool0(q_ros: np.ndarray) -> np.ndarray:
    """ROS-I fanuc_m20ia_support/urdf/m20ia_macro.xacro: base_link → tool0 (all rpy 0)."""
    T = np.eye(4)
    for origin, axis, angle in zip(_URDF_ORIGINS, _URDF_AXES, q_ros, strict=True):
        R = np.eye(4)
        R[:3, :3] = Rotation.from_rotvec(np.array(axis, float) * angle).as_matrix()
        T = T @ translation(origin) @ R
    tool0 = np.eye(4)
    tool0[:3, :3] = Rotation.from_euler("xyz", [math.pi, -math.pi / 2, 0.0]).as_matrix()
    return T @ tool0


def test_fanuc_readings_match_the_ros_industrial_urdf(fanuc):
    """The ROS-I driver's J23_factor = 1: URDF joint_3 = J3 + J2; the rest are the readings."""
    assert fanuc.reading_names == ("J1", "J2", "J3", "J4", "J5", "J6")
    J = random_configs(fanuc, 200, seed=3)
    fk = forward(fanuc, None, J)
    for k in range(len(J)):
        q_ros = J[k].copy()
        q_ros[2] = J[k, 2] + J[k, 1]
        np.testing.assert_allclose(fk.flange[k], _urdf_tool0(q_ros), atol=1e-12)


def test_fanuc_convention_in_words(fanuc):
    """J2 = 0: upper arm vertical; J3 = 0: forearm horizontal whatever J2 is."""
    for j2 in (-60.0, 0.0, 45.0):
        fk = forward(fanuc, None, np.radians([0, j2, 0, 0, 0, 0]))
        elbow, wrist = fk.frame("2")[:3, 3], fk.frame("4")[:3, 3]
        forearm = wrist - elbow  # 0.25 up, 0.835 forward when J3 = 0
        assert forearm[2] == pytest.approx(0.25, abs=1e-12)
        assert forearm[0] == pytest.approx(0.835, abs=1e-12)
    arm = forward(fanuc, None, np.zeros(6))
    assert arm.frame("2")[:3, 3] == pytest.approx([0.15, 0.0, 0.525 + 0.79])


# ----------------------------------------------------------------------------- identities
def test_no_coupling_is_the_identity(elbow):
    q = random_configs(elbow, 5, seed=1)
    assert elbow.coupling is None
    assert elbow.reading_names == elbow.actuated and elbow.n_readings == 6
    assert elbow.kinematic_joints(q) is not None
    np.testing.assert_array_equal(elbow.kinematic_joints(q), q)
    np.testing.assert_array_equal(elbow.readings(q), q)
    np.testing.assert_array_equal(elbow.reading_jacobian, np.eye(6))
    assert elbow.uncoupled() is elbow
    assert elbow.periodic_readings.all()


def test_readings_invert_kinematic_joints(fanuc):
    q = random_configs(fanuc, 50, seed=2)
    th = fanuc.kinematic_joints(q)
    np.testing.assert_allclose(th[:, 2], -q[:, 1] - q[:, 2], atol=1e-15)
    np.testing.assert_allclose(th[:, 1], q[:, 1] - math.pi / 2, atol=1e-15)
    np.testing.assert_allclose(fanuc.readings(th), q, atol=1e-12)


@pytest.mark.parametrize("seed", [0, 1])
def test_coupled_and_hand_converted_give_identical_fk(fanuc, seed):
    hand = hand_converted(fanuc)
    q = random_configs(fanuc, 100, seed=seed)
    params = perturbed_params(fanuc, seed)
    # the hand-converted rows carry the coupling offsets in theta
    shift = hand.nominal_parameters().theta - fanuc.nominal_parameters().theta
    q_hand = q @ fanuc.coupling.matrix.T
    for p, p_hand in ((None, None), (params, params.replace(theta=params.theta + shift))):
        a, b = forward(fanuc, p, q), forward(hand, p_hand, q_hand)
        np.testing.assert_allclose(a.flange, b.flange, atol=1e-12)
        np.testing.assert_allclose(a.theta, b.theta, atol=1e-12)


def test_uncoupled_description_is_the_kinematic_robot(fanuc):
    kin = fanuc.uncoupled()
    q = random_configs(fanuc, 20, seed=4)
    np.testing.assert_allclose(
        forward(fanuc, None, q).flange, forward(kin, None, fanuc.kinematic_joints(q)).flange,
        atol=1e-12,
    )
    assert kin.within_limits(fanuc.kinematic_joints(q)).all()
    np.testing.assert_allclose(kin.home, fanuc.kinematic_joints(fanuc.home))


# ----------------------------------------------------------------------------- Jacobians
def _gear_and_mimic(elbow: RobotDescription) -> list[RobotDescription]:
    return [wrist_gear_elbow(elbow), mimic_elbow(elbow)]


def _fd_jacobian(desc, params, q, point, h=1e-6):
    fk0 = forward(desc, params, q)
    T0 = fk0.tcp if point == "tcp" else fk0.flange
    cols = []
    for j in range(desc.n_readings):
        dq = np.zeros(desc.n_readings)
        dq[j] = h
        fp, fm = forward(desc, params, q + dq), forward(desc, params, q - dq)
        Tp = fp.tcp if point == "tcp" else fp.flange
        Tm = fm.tcp if point == "tcp" else fm.flange
        cols.append((pose_error_exact(Tp, T0) - pose_error_exact(Tm, T0)) / (2 * h))
    return np.stack(cols, axis=-1)


def test_jacobian_wrt_readings_matches_central_differences(fanuc, elbow, h4):
    h4_flipped = sign_flipped_h4(h4)
    for desc in (fanuc, *_gear_and_mimic(elbow), h4_flipped):
        params = perturbed_params(desc, 5)
        for q in random_configs(desc, 4, seed=7):
            for point in ("flange", "tcp"):
                J = manipulator_jacobian(desc, params, q, point)
                assert J.shape == (6, desc.n_readings)
                np.testing.assert_allclose(J, _fd_jacobian(desc, params, q, point),
                                           atol=1e-8, err_msg=f"{desc.name} {point}")


def test_mimic_coupling_round_trip(elbow):
    _, mimic = _gear_and_mimic(elbow)
    assert mimic.n_readings == 5 and mimic.n_actuated == 6
    q = random_configs(mimic, 10, seed=8)
    th = mimic.kinematic_joints(q)
    np.testing.assert_allclose(th[:, 2], -0.8 * q[:, 1] + 0.1, atol=1e-15)
    np.testing.assert_allclose(mimic.readings(th), q, atol=1e-12)
    assert list(mimic.periodic_readings) == [True, False, True, True, True]


# ----------------------------------------------------------------------------- loops
def test_loop_robot_with_coupling(h4):
    flipped = sign_flipped_h4(h4)
    assert flipped.loop_readings(0) == h4.loop_readings(0)
    q = random_configs(flipped, 30, seed=9)
    np.testing.assert_allclose(
        forward(flipped, None, q).flange,
        forward(h4, None, flipped.kinematic_joints(q)).flange, atol=1e-12,
    )
    np.testing.assert_array_equal(flipped.within_limits(q),
                                  h4.within_limits(flipped.kinematic_joints(q)))


def test_loop_arm_crank_must_be_a_difference_of_readings(h4):
    d = description_to_dict(h4)
    lims = [lk.pop("limits") for lk in d["links"] if lk["joint"] == "actuated"]
    M = np.eye(6)
    M[2, 1] = 1.0  # θ2' = R2 + R3: θ2 − θ2' = −R3, not a difference of two readings
    d["coupling"] = {"readings": list("ABCDEF"), "matrix": M.tolist(), "limits": lims}
    d["coupled_limits"] = [{"joints": ["B", "C"], "min": 25.0, "max": 155.0}]
    with pytest.raises(DescriptionError, match=r"coupling.matrix: loops\[0\]: the arm − crank"):
        description_from_dict(d)


# ----------------------------------------------------------------------------- IK
def test_inverse_returns_readings_inside_the_reading_limits(fanuc):
    q = random_configs(fanuc, 12, seed=11)
    T = forward(fanuc, None, q).flange
    res = inverse(fanuc, None, T)
    assert res.q.shape == (12, 6)
    assert fanuc.within_limits(res.q).all()
    np.testing.assert_allclose(forward(fanuc, None, res.q).flange, T, atol=1e-9)


def test_inverse_of_a_loop_robot_with_coupling(h4):
    flipped = sign_flipped_h4(h4)
    q = random_configs(flipped, 8, seed=13)
    T = forward(flipped, None, q).flange
    res = inverse(flipped, None, T, seed=q + 0.05)
    assert flipped.within_limits(res.q).all()
    np.testing.assert_allclose(forward(flipped, None, res.q).flange, T, atol=1e-9)
    # the readings are the uncoupled robot's solution, mapped back
    ref = inverse(h4, None, T, seed=flipped.kinematic_joints(q + 0.05))
    np.testing.assert_allclose(flipped.kinematic_joints(res.q), ref.q, atol=1e-8)


def test_inverse_of_a_mimic_robot_returns_its_five_readings(elbow):
    mimic = mimic_elbow(elbow)
    q = random_configs(mimic, 6, seed=14)
    T = forward(mimic, None, q).flange
    res = inverse(mimic, None, T, seed=q + 0.02)
    assert res.q.shape == (6, 5)
    np.testing.assert_allclose(forward(mimic, None, res.q).flange, T, atol=1e-9)


def test_inverse_does_not_wrap_readings_of_fractional_gears(elbow):
    gear, _ = _gear_and_mimic(elbow)
    q = random_configs(gear, 6, seed=12)
    T = forward(gear, None, q).flange
    res = inverse(gear, None, T, seed=q + 0.05)
    np.testing.assert_allclose(forward(gear, None, res.q).flange, T, atol=1e-9)


# ----------------------------------------------------------------------------- errors
@pytest.fixture(scope="module")
def fanuc_dict(fanuc) -> dict[str, Any]:
    return description_to_dict(fanuc)


def _set(path: tuple, value: Any):
    def f(d: dict[str, Any]) -> None:
        parent = d
        for key in path[:-1]:
            parent = parent[key]
        if value is _DELETE:
            del parent[path[-1]]
        else:
            parent[path[-1]] = value

    return f


_DELETE = object()
_EYE5 = np.eye(6)[:, :5].tolist()
_SINGULAR = np.eye(6)
_SINGULAR[:, 4] = _SINGULAR[:, 3]


@pytest.mark.parametrize(
    ("mutate", "expected"),
    [
        (_set(("coupling", "matrix"), [r[:5] for r in np.eye(6).tolist()]),
         "coupling.matrix: expected 6×6 (one row per actuated joint"),
        (_set(("coupling", "matrix"), np.eye(6)[:5].tolist()),
         "coupling.matrix: expected 6×6"),
        (_set(("coupling", "matrix", 2), [0, 1, 1, 0, 0]),
         "coupling.matrix[2]: expected 6 numbers like row 0 (one per reading), got 5"),
        (_set(("coupling", "matrix", 2, 1), "x"),
         "coupling.matrix[2][1]: expected a number, got 'x'"),
        (_set(("coupling", "matrix", 3, 3), float("nan")),
         "coupling.matrix[3][3]: expected a finite number, got nan"),
        (_set(("coupling", "matrix"), _SINGULAR.tolist()),
         "coupling.matrix: singular: rank 5 < 6 readings"),
        (_set(("coupling", "matrix"), "eye"), "coupling.matrix: expected an array, got 'eye'"),
        (_set(("coupling", "offsets"), [0.0] * 5),
         "coupling.offsets: expected 6 numbers (one per actuated joint), got 5"),
        (_set(("coupling", "offsets", 1), float("inf")),
         "coupling.offsets[1]: expected a finite number, got inf"),
        (_set(("coupling", "limits"), [[-1, 1]] * 5),
         "coupling.limits: expected 6 [lower, upper] pairs (one per reading), got 5"),
        (_set(("coupling", "limits", 2), [10, -10]),
         "coupling.limits[2]: lower limit 10 must be below upper limit -10"),
        (_set(("coupling", "limits"), _DELETE), "coupling.limits: missing required key"),
        (_set(("coupling", "readings", 4), "J1"),
         "coupling.readings[4]: duplicate reading name 'J1' (also readings[0])"),
        (_set(("coupling", "readings"), ["J1", "J2"]),
         "coupling.limits: expected 2 [lower, upper] pairs"),
        (_set(("coupling", "gear"), 1.0), "coupling.gear: unknown key"),
        (_set(("links", 1, "limits"), [-90.0, 90.0]),
         "links[1].limits: with a [coupling] the joint limits are on the readings"),
        (_set(("home",), [0.0, 0.0, 0.0, 0.0, -150.0, 0.0]),
         "home[4]: joint J5 = -150° is outside its limits [-140°, 140°]"),
        (_set(("coupled_limits",), [{"joints": ["2", "3"], "min": -10.0, "max": 10.0}]),
         "coupled_limits[0].joints[0]: '2' is not a joint reading"),
    ],
)
def test_bad_coupling_input_gives_precise_errors(fanuc_dict, mutate, expected):
    d = copy.deepcopy(fanuc_dict)
    mutate(d)
    with pytest.raises(DescriptionError) as exc:
        description_from_dict(d)
    assert expected in str(exc.value)


def test_a_reading_that_moves_nothing_is_named(fanuc_dict):
    d = copy.deepcopy(fanuc_dict)
    d["coupling"]["matrix"] = [[*r[:5], 0.0] for r in d["coupling"]["matrix"]]
    with pytest.raises(DescriptionError, match="reading 'J6' \\(column 5\\) moves no joint"):
        description_from_dict(d)


def test_errors_name_the_file(tmp_path: Path):
    text = (Path(__file__).parents[2] / "src/plugcell/robots/fanuc_m20ia.toml").read_text()
    bad = text.replace("[0.0,  0.0,  0.0,  0.0,  0.0, -1.0],   # θ6 = −J6",
                       "[0.0,  0.0,  0.0,  0.0,  0.0],   # θ6 = −J6")
    assert bad != text
    f = tmp_path / "my_fanuc.toml"
    f.write_text(bad)
    with pytest.raises(DescriptionError) as exc:
        load_robot_file(f)
    assert str(exc.value).startswith(
        "my_fanuc.toml: coupling.matrix[5]: expected 6 numbers like row 0"
    )


def test_to_dict_round_trip_keeps_the_coupling(fanuc):
    back = description_from_dict(description_to_dict(fanuc))
    np.testing.assert_array_equal(back.coupling.matrix, fanuc.coupling.matrix)
    np.testing.assert_allclose(back.coupling.offset, fanuc.coupling.offset, atol=1e-15)
    np.testing.assert_allclose(back.joint_limits, fanuc.joint_limits, atol=1e-15)
    assert back.reading_names == fanuc.reading_names
    assert description_to_dict(back) == description_to_dict(fanuc)


# ----------------------------------------------------------------------------- properties
_leaf = st.one_of(
    st.none(), st.booleans(), st.integers(-10, 10), st.floats(allow_nan=True),
    st.text(max_size=4), st.lists(st.floats(-3, 3), max_size=7),
    st.lists(st.lists(st.integers(-2, 2), max_size=7), max_size=7),
)


@st.composite
def _mutated_coupling(draw: st.DrawFn) -> dict[str, Any]:
    d = description_to_dict(load_robot("fanuc_m20ia"))
    c = d["coupling"]
    for _ in range(draw(st.integers(1, 3))):
        key = draw(st.sampled_from(["readings", "matrix", "offsets", "limits", "new"]))
        where = draw(st.sampled_from(["whole", "item", "delete"]))
        if key == "new" or where == "whole" or key not in c:
            c[key] = draw(_leaf)
        elif where == "delete":
            del c[key]
        elif isinstance(c[key], list) and c[key]:
            c[key][draw(st.integers(0, len(c[key]) - 1))] = draw(_leaf)
    return d


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(_mutated_coupling())
def test_coupling_parser_raises_only_description_errors(d):
    try:
        desc = description_from_dict(d)
    except DescriptionError as exc:
        assert str(exc).startswith(("coupling", "home", "links", "coupled_limits"))
        return
    assert desc.coupling is not None
    q = desc.home
    np.testing.assert_allclose(desc.kinematic_joints(q),
                               desc.coupling.matrix @ q + desc.coupling.offset)


_entry = st.sampled_from([0.0, 1.0, -1.0, 0.5, -0.25, 2.0, 1.0 / 3.0])


@st.composite
def _coupling_toml(draw: st.DrawFn) -> tuple[str, np.ndarray, np.ndarray, int]:
    n_r = draw(st.integers(4, 6))
    M = np.array(draw(st.lists(st.lists(_entry, min_size=n_r, max_size=n_r),
                               min_size=6, max_size=6)))
    off = np.array(draw(st.lists(st.floats(-360, 360), min_size=6, max_size=6)))
    rows = ",\n  ".join("[" + ", ".join(repr(float(x)) for x in r) + "]" for r in M)
    names = ", ".join(f'"R{j}"' for j in range(n_r))
    toml = (
        f"[coupling]\nreadings = [{names}]\nmatrix = [\n  {rows},\n]\n"
        f"offsets = [{', '.join(repr(float(x)) for x in off)}]\n"
        f"limits = [{', '.join(['[-170.0, 170.0]'] * n_r)}]\n"
    )
    return toml, M, off, n_r


_FANUC_TEXT = (Path(__file__).parents[2] / "src/plugcell/robots/fanuc_m20ia.toml").read_text()
_HEAD, _REST = _FANUC_TEXT.split("[coupling]")
_LINKS = _REST[_REST.index("[[links]]"):]


@settings(max_examples=60, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(_coupling_toml())
def test_toml_coupling_parser(tmp_path, case):
    toml, M, off, n_r = case
    head = _HEAD.replace("home = [0.0, 0.0, 0.0, 0.0, -90.0, 0.0]", f"home = {[0.0] * n_r}")
    f = tmp_path / "r.toml"
    f.write_text(head + toml + "\n" + _LINKS)
    rank = np.linalg.matrix_rank(M)
    zero_col = not np.all(np.any(M != 0, axis=0))
    try:
        desc = load_robot_file(f)
    except DescriptionError as exc:
        assert str(exc).startswith("r.toml: coupling.matrix: ")
        assert zero_col or rank < n_r
        return
    assert rank == n_r
    q = np.linspace(-1.0, 1.0, n_r)
    np.testing.assert_allclose(desc.kinematic_joints(q), M @ q + np.radians(off), atol=1e-12)
    np.testing.assert_allclose(desc.readings(desc.kinematic_joints(q)), q, atol=1e-9)


# ----------------------------------------------------------------------------- docs
_DOC = Path(__file__).parents[2] / "docs" / "robot-description.md"


def _doc_section() -> str:
    text = _DOC.read_text(encoding="utf-8")
    return text[text.index("## Vendor joint conventions"):text.index("## Errors")]


def test_docs_fanuc_coupling_is_the_shipped_one(fanuc):
    (snippet,) = re.findall(r"```toml\n(.*?)```", _doc_section(), flags=re.S)
    c = tomllib.loads(snippet)["coupling"]
    np.testing.assert_array_equal(c["matrix"], fanuc.coupling.matrix)
    np.testing.assert_allclose(np.radians(c["offsets"]), fanuc.coupling.offset)
    np.testing.assert_allclose(np.radians(c["limits"]), fanuc.joint_limits)
    assert tuple(c["readings"]) == fanuc.reading_names


def test_docs_pose_check_prints_the_documented_table():
    section = _doc_section()
    (code,) = re.findall(r"```python\n(.*?)```", section, flags=re.S)
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        exec(compile(code, "docs/robot-description.md", "exec"), {})
    printed = [[float(x) for x in re.findall(r"-?\d+\.?\d*", line.split("X Y Z")[1])]
               for line in out.getvalue().splitlines()]
    rows = [line for line in section.splitlines() if re.match(r"\| -?\d", line)]
    assert len(rows) == len(printed) == 4
    for row, got in zip(rows, printed, strict=True):
        cells = row.strip("|").split("|")
        want = [float(x) for x in re.findall(r"[-−]?\d+\.?\d*",
                                             (cells[1] + "," + cells[2]).replace("−", "-"))]
        np.testing.assert_allclose(got, want, atol=0.006)
