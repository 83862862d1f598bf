"""The one robot-units boundary (io/units.py): mm and degrees ↔ metres and 4×4."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from plugcell.io.units import (
    CONVENTIONS,
    UnitsError,
    convention_name,
    pose_from_robot,
    robot_from_pose,
)

MM = st.floats(-5000, 5000, allow_nan=False)
DEG = st.floats(-179.0, 179.0, allow_nan=False)


def test_a_comau_position_is_millimetres_and_zyz_degrees() -> None:
    T = pose_from_robot([1000.0, -250.0, 40.0, 90.0, 0.0, 0.0])
    np.testing.assert_allclose(T[:3, 3], [1.0, -0.25, 0.04], atol=1e-15)
    np.testing.assert_allclose(T[:3, :3], [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-15)
    np.testing.assert_array_equal(T[3], [0, 0, 0, 1])
    # Z-Y-Z: Rz(a)·Ry(b)·Rz(c) — b = 90° tips z onto x
    T = pose_from_robot([0, 0, 0, 0, 90, 0])
    np.testing.assert_allclose(T[:3, 2], [1, 0, 0], atol=1e-15)


def test_roll_pitch_yaw_turns_about_fixed_axes() -> None:
    T = pose_from_robot([0, 0, 0, 0, 0, 90], "rpy")  # yaw: about Z
    np.testing.assert_allclose(T[:3, 0], [0, 1, 0], atol=1e-15)
    T = pose_from_robot([0, 0, 0, 90, 0, 0], "rpy")  # roll: about X
    np.testing.assert_allclose(T[:3, 1], [0, 0, 1], atol=1e-15)


@settings(max_examples=200, deadline=None)
@given(st.tuples(MM, MM, MM), DEG, st.floats(5.0, 175.0), DEG)
def test_euler_poses_come_back_as_they_went(xyz, a, b, c) -> None:
    v = np.array([*xyz, a, b, c])
    np.testing.assert_allclose(robot_from_pose(pose_from_robot(v)), v, atol=1e-8)


@settings(max_examples=200, deadline=None)
@given(st.tuples(MM, MM, MM), DEG, st.floats(-85.0, 85.0), DEG,
       st.sampled_from(sorted(CONVENTIONS)))
def test_every_convention_gives_back_the_same_transform(xyz, a, b, c, convention) -> None:
    try:
        T = pose_from_robot([*xyz, a, b, c], convention)
    except UnitsError:  # projective angles outside their domain
        assert convention == "prj"
        return
    np.testing.assert_allclose(pose_from_robot(robot_from_pose(T, convention), convention), T,
                               atol=1e-9)


def test_the_old_name_euler_is_zyz_with_a_deprecation_warning() -> None:
    v = [100.0, -20.0, 300.0, 30.0, 40.0, 50.0]
    with pytest.warns(DeprecationWarning, match="'euler' is deprecated: use 'zyz'"):
        T = pose_from_robot(v, "euler")
    np.testing.assert_array_equal(T, pose_from_robot(v, "zyz"))
    with pytest.warns(DeprecationWarning):
        np.testing.assert_array_equal(robot_from_pose(T, "euler"), robot_from_pose(T, "zyz"))
    assert convention_name("rpy") == "rpy"


@pytest.mark.parametrize("name", ["ZYZ", "zyx", "", "quat"])
def test_an_unknown_convention_is_refused_naming_the_known(name: str) -> None:
    with pytest.raises(UnitsError, match=f"unknown angle convention {name!r}; expected one of "
                                         "zyz, rpy, xyz, prj"):
        pose_from_robot([0.0] * 6, name)
    with pytest.raises(UnitsError, match="unknown angle convention"):
        robot_from_pose(np.eye(4), name)


@pytest.mark.parametrize(("values", "reason"), [
    ([1, 2, 3, 4, 5], "expected 6 numbers (x, y, z mm, 3 angles deg), got 5"),
    ([1, 2, 3, 4, 5, float("nan")], "values must be finite"),
    ([0, 0, 0, 0, 0, float("inf")], "values must be finite"),
])
def test_what_is_no_pose_is_refused_with_the_reason(values, reason) -> None:
    with pytest.raises(UnitsError) as caught:
        pose_from_robot(values)
    assert str(caught.value) == reason
