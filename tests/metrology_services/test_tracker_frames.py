"""Eqs. (7.1)–(7.2) and the conversions of Table 7-3 (pure functions)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from plugcell.devices.tracker.frames import FROM_MATRIX, TO_MATRIX, FrameError, RequesterFrames
from plugcell.io.units import pose_from_robot, robot_from_pose


def _vector(draw_angles):
    return st.tuples(
        *(st.floats(-3000, 3000) for _ in range(3)),
        *(st.floats(-draw_angles, draw_angles) for _ in range(3)),
    )


@settings(max_examples=60, deadline=None)
@given(v=_vector(40.0), convention=st.sampled_from(["rpy", "zyz", "prj"]))
def test_to_matrix_and_back_gives_the_same_pose(v, convention):
    T = pose_from_robot(v, convention)
    back = pose_from_robot(robot_from_pose(T, convention), convention)
    np.testing.assert_allclose(back, T, atol=1e-9)
    np.testing.assert_allclose(T[:3, 3], np.array(v[:3]) * 1e-3)


def test_the_option_words_of_table_7_3_name_the_conventions():
    assert TO_MATRIX == {"rpy2tr": "rpy", "euler2tr": "zyz", "prj2tr": "prj"}
    assert FROM_MATRIX == {"tr2rpy": "rpy", "tr2euler": "zyz", "tr2prj": "prj"}


def test_euler_is_comau_zyz_in_mm_and_degrees():
    T = pose_from_robot([100, 200, 300, 90, 90, 0], "zyz")
    # Rz(90)·Ry(90): the frame's z axis is the reference y axis
    np.testing.assert_allclose(T[:3, 3], [0.1, 0.2, 0.3])
    np.testing.assert_allclose(T[:3, 2], [0.0, 1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(robot_from_pose(T, "zyz"), [100, 200, 300, 90, 90, 0],
                               atol=1e-9)


def test_eq_7_2_undoes_eq_7_1_for_each_requester():
    rng = np.random.default_rng(3)
    f = RequesterFrames()
    base = [3000.0, -400.0, 200.0, 20.0, 10.0, -30.0]
    probe = [10.0, 40.0, 150.0, 5.0, 80.0, 15.0]
    f.set_base(base, "euler2tr")
    f.set_probe(probe, "euler2tr")
    for _ in range(5):
        robot = list(rng.uniform(-1000, 1000, 3)) + list(rng.uniform(-80, 80, 3))
        M = f.reflector(robot)  # eq. 7.1: where the tracker finds the reflector
        np.testing.assert_allclose(
            M, pose_from_robot(base, "zyz") @ pose_from_robot(robot, "zyz")
            @ pose_from_robot(probe, "zyz"), atol=1e-12)
        back = f.measurement(M)  # eq. 7.2, as a 6-vector (ZYZ: B ≥ 0 may flip A, C)
        np.testing.assert_allclose(pose_from_robot(back, "zyz"),
                                   pose_from_robot(robot, "zyz"), atol=1e-9)


def test_the_requesters_convention_is_the_one_of_its_last_set_base():
    f = RequesterFrames()
    assert f.convention == "zyz"  # Comau's, thesis 7.4
    f.set_base([0, 0, 0, 10, 20, 30], "rpy2tr")
    assert f.convention == "rpy"
    X = pose_from_robot([1, 2, 3, 40, 5, 6], "rpy")
    seen = f.base @ X  # PROBE is the identity
    np.testing.assert_allclose(f.measurement(seen), [1, 2, 3, 40, 5, 6], atol=1e-9)
    np.testing.assert_allclose(f.measurement(seen, "tr2rpy"), [1, 2, 3, 40, 5, 6], atol=1e-9)
    euler = f.measurement(seen, "tr2euler")
    np.testing.assert_allclose(pose_from_robot(euler, "zyz"), X, atol=1e-12)


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda f: f.set_base([0] * 6, "xyz2tr"), "unknown option 'xyz2tr'"),
        (lambda f: f.set_probe([0] * 5, "rpy2tr"), "expected 6 numbers"),
        (lambda f: f.set_base([0, 0, np.nan, 0, 0, 0], ""), "finite"),
        (lambda f: f.measurement(np.eye(4), "rpy2tr"), "use tr2rpy, tr2euler, tr2prj"),
        (lambda f: f.reflector([0, 0, 0, 8, 72, -67], "prj2tr"), "projective angles"),
    ],
)
def test_bad_vectors_and_options_are_refused_with_the_reason(call, message):
    with pytest.raises(FrameError, match=message):
        call(RequesterFrames())
