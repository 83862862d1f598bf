"""Vendor pose notations (plugcell.io.units) and the nearest representation of a rotation."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from plugcell.io.units import UnitsError, notation_from_pose, pose_from_notation
from plugcell.kinematics.rotations import (
    angles_to_matrix,
    matrix_to_quat,
    nearest_angles,
    quat_to_matrix,
    rpy_to_matrix,
    zyz_to_matrix,
)
from plugcell.kinematics.transforms import rot_x as _rx
from plugcell.kinematics.transforms import rot_y as _ry
from plugcell.kinematics.transforms import rot_z as _rz
from plugcell.kinematics.transforms import so3_exp

D = np.radians


def rot_x(a):
    return _rx(a)[:3, :3]


def rot_y(a):
    return _ry(a)[:3, :3]


def rot_z(a):
    return _rz(a)[:3, :3]


def test_each_vendor_convention():
    v = np.array([100.0, -200.0, 300.0, 30.0, -40.0, 50.0])
    kuka = pose_from_notation(v, "kuka")
    np.testing.assert_allclose(kuka[:3, :3], rot_z(D(30)) @ rot_y(D(-40)) @ rot_x(D(50)),
                               atol=1e-15)
    np.testing.assert_allclose(kuka[:3, 3], [0.1, -0.2, 0.3])
    fanuc = pose_from_notation(v, "fanuc")  # W, P, R about fixed X, Y, Z
    np.testing.assert_allclose(fanuc[:3, :3], rot_z(D(50)) @ rot_y(D(-40)) @ rot_x(D(30)),
                               atol=1e-15)
    comau = pose_from_notation(v, "comau")
    np.testing.assert_allclose(comau[:3, :3], zyz_to_matrix(D(30), D(-40), D(50)), atol=1e-15)
    ur = pose_from_notation([0.1, -0.2, 0.3, 0.0, 0.0, np.pi / 2], "ur")
    np.testing.assert_allclose(ur[:3, :3], rot_z(np.pi / 2), atol=1e-15)
    np.testing.assert_allclose(ur[:3, 3], [0.1, -0.2, 0.3])
    h = np.sqrt(0.5)
    abb = pose_from_notation([1, 2, 3, h, 0, 0, h], "abb")   # 90° about z
    np.testing.assert_allclose(abb[:3, :3], rot_z(np.pi / 2), atol=1e-15)


def test_bad_notation_values():
    with pytest.raises(UnitsError, match="expected 7 numbers"):
        pose_from_notation(np.zeros(6), "abb")
    with pytest.raises(UnitsError, match="zero norm"):
        pose_from_notation(np.zeros(7), "abb")
    with pytest.raises(UnitsError, match="unknown pose notation"):
        pose_from_notation(np.zeros(6), "yaskawa")


_ang = st.floats(-179.9, 179.9)


@settings(max_examples=200, deadline=None)
@given(a=_ang, b=st.floats(-89.9, 89.9), c=_ang, dx=st.floats(-0.5, 0.5),
       notation=st.sampled_from(["kuka", "fanuc", "comau", "ur", "abb"]))
def test_round_trip_and_small_changes_stay_near(a, b, c, dx, notation):
    if notation == "abb":
        q = matrix_to_quat(rpy_to_matrix(D(a), D(b), D(c)))
        v = np.array([1.0, 2.0, 3.0, *q])
    elif notation == "ur":
        v = np.array([1.0, 2.0, 3.0, *(np.array([a, b, c]) / 100.0)])
    else:
        v = np.array([1.0, 2.0, 3.0, a, b, c])
    T = pose_from_notation(v, notation)
    np.testing.assert_allclose(notation_from_pose(T, notation, v), v, atol=1e-9)
    # a small turn moves the numbers a little (no jump to the other triple or sign) —
    # away from gimbal lock (Comau ZYZ: B = 0), where it cannot
    if notation == "comau" and abs(b) < 5:
        return
    T2 = T.copy()
    T2[:3, :3] = so3_exp(np.array([1e-3 * dx, 2e-3, -1e-3])) @ T[:3, :3]
    v2 = notation_from_pose(T2, notation, v)
    np.testing.assert_allclose(pose_from_notation(v2, notation), T2, atol=1e-12)
    # a 0.13° turn changes the outer angles by up to 0.13°·2/|cos B| (|sin B| for ZYZ)
    sens = abs(np.sin(D(b))) if notation == "comau" else abs(np.cos(D(b)))
    bound = 0.15 * (1 + 2 / sens) if notation in ("kuka", "fanuc", "comau") else 0.01
    change = v2 - v
    if notation in ("kuka", "fanuc", "comau"):  # 179.9° → −179.95° is a change of 0.15°
        change[3:] = (change[3:] + 180.0) % 360.0 - 180.0
    assert np.abs(change).max() < bound


@pytest.mark.parametrize("notation", ["kuka", "fanuc"])
def test_a_turn_across_180_stays_on_its_triple(notation):
    # found by the property above: W = 179.9° turned by 0.13° is W = −179.99…°, not the
    # other triple (W ≈ 0°, P ≈ 180°, R ≈ −119°) that is nearer without wrapping
    v = np.array([1.0, 2.0, 3.0, 179.9, 0.0, 61.0])
    T = pose_from_notation(v, notation)
    T2 = T.copy()
    T2[:3, :3] = so3_exp(np.array([0.0, 2e-3, -1e-3])) @ T[:3, :3]
    v2 = notation_from_pose(T2, notation, v)
    np.testing.assert_allclose(pose_from_notation(v2, notation), T2, atol=1e-12)
    assert np.all(np.abs(v2[3:]) <= 180.0)
    assert np.abs((v2[3:] - v[3:] + 180.0) % 360.0 - 180.0).max() < 0.2


@pytest.mark.parametrize("conv", ["zyz", "rpy", "xyz"])
def test_gimbal_lock_keeps_the_reference_split(conv):
    mid = 0.0 if conv == "zyz" else np.pi / 2
    ref = np.array([0.3, mid, -0.2])
    if conv == "rpy":
        ref = np.array([-0.2, mid, 0.3])
    R = angles_to_matrix(ref, conv)
    np.testing.assert_allclose(nearest_angles(R, conv, ref), ref, atol=1e-12)
    # the locked sum changes by 0.01: shared equally between the outer angles
    turn = rot_x(0.01) if conv == "xyz" else rot_z(0.01)  # about the locked axis
    out = nearest_angles(turn @ R, conv, ref)
    np.testing.assert_allclose(angles_to_matrix(out, conv), turn @ R, atol=1e-12)
    assert np.abs(out - ref).max() < 0.0051


def test_angle_at_180_keeps_its_sign():
    v = np.array([0.0, 0.0, 0.0, -180.0, 0.0, 180.0])
    T = pose_from_notation(v, "kuka")
    np.testing.assert_allclose(notation_from_pose(T, "kuka", v), v, atol=1e-9)


def test_quaternion_sign_and_rotvec_near_pi():
    q = np.array([-0.5, 0.5, -0.5, 0.5])
    v = np.array([0, 0, 0, *q])
    np.testing.assert_allclose(notation_from_pose(pose_from_notation(v, "abb"), "abb", v), v,
                               atol=1e-12)
    np.testing.assert_allclose(quat_to_matrix(matrix_to_quat(rot_x(0.7))), rot_x(0.7),
                               atol=1e-15)
    r = np.array([0, 0, 0, 0.0, 0.0, -3.1415])
    np.testing.assert_allclose(notation_from_pose(pose_from_notation(r, "ur"), "ur", r), r,
                               atol=1e-12)
