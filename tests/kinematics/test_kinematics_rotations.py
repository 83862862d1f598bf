"""Orientation conventions: round trips, independent formulas (scipy), gimbal lock."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from plugcell.kinematics import (
    CONVENTIONS,
    angles_to_matrix,
    matrix_to_angles,
    matrix_to_pose,
    matrix_to_prj,
    matrix_to_rpy,
    matrix_to_xyz,
    matrix_to_zyz,
    pose_to_matrix,
    prj_to_matrix,
    rpy_to_matrix,
    so3_log,
    xyz_to_matrix,
    zyz_to_matrix,
)

RNG = np.random.default_rng(11)
R_RANDOM = Rotation.random(2000, random_state=5).as_matrix()

#: scipy names: uppercase = intrinsic, lowercase = extrinsic
SCIPY = {"zyz": "ZYZ", "rpy": "xyz", "xyz": "XYZ"}


@pytest.mark.parametrize("conv", ["zyz", "rpy", "xyz"])
def test_matrix_from_angles_matches_scipy(conv):
    ang = RNG.uniform(-np.pi, np.pi, (500, 3))
    R = angles_to_matrix(ang, conv)
    np.testing.assert_allclose(R, Rotation.from_euler(SCIPY[conv], ang).as_matrix(), atol=1e-14)


@pytest.mark.parametrize("conv", ["zyz", "rpy", "xyz"])
def test_matrix_round_trip_and_angles_match_scipy(conv):
    ang = matrix_to_angles(R_RANDOM, conv)
    np.testing.assert_allclose(angles_to_matrix(ang, conv), R_RANDOM, atol=1e-12)
    ref = Rotation.from_matrix(R_RANDOM).as_euler(SCIPY[conv])
    np.testing.assert_allclose(ang, ref, atol=1e-9)


def test_explicit_conventions():
    a, b, c = 0.3, -0.5, 1.1

    def rx(t):
        return Rotation.from_euler("x", t).as_matrix()

    def ry(t):
        return Rotation.from_euler("y", t).as_matrix()

    def rz(t):
        return Rotation.from_euler("z", t).as_matrix()

    np.testing.assert_allclose(zyz_to_matrix(a, b, c), rz(a) @ ry(b) @ rz(c), atol=1e-15)
    np.testing.assert_allclose(rpy_to_matrix(a, b, c), rz(c) @ ry(b) @ rx(a), atol=1e-15)
    np.testing.assert_allclose(xyz_to_matrix(a, b, c), rx(a) @ ry(b) @ rz(c), atol=1e-15)


def test_zyz_is_thesis_A4():
    """(A.4): A = atan2(R23, R13), B = atan2(√(R13²+R23²), R33), C = atan2(R32, −R31)."""
    R = R_RANDOM
    A = np.arctan2(R[:, 1, 2], R[:, 0, 2])
    B = np.arctan2(np.hypot(R[:, 0, 2], R[:, 1, 2]), R[:, 2, 2])
    C = np.arctan2(R[:, 2, 1], -R[:, 2, 0])
    np.testing.assert_allclose(matrix_to_zyz(R), np.stack([A, B, C], -1), atol=1e-15)
    assert np.all(matrix_to_zyz(R)[:, 1] >= 0)


@pytest.mark.parametrize(
    ("conv", "angles", "expect"),
    [
        ("zyz", (0.4, 0.0, 0.3), (0.7, 0.0, 0.0)),
        ("zyz", (0.4, np.pi, 0.3), (0.1, np.pi, 0.0)),
        ("rpy", (0.4, np.pi / 2, 0.3), (0.0, np.pi / 2, -0.1)),
        ("rpy", (0.4, -np.pi / 2, 0.3), (0.0, -np.pi / 2, 0.7)),
        ("xyz", (0.4, np.pi / 2, 0.3), (0.7, np.pi / 2, 0.0)),
        ("xyz", (0.4, -np.pi / 2, 0.3), (0.1, -np.pi / 2, 0.0)),
    ],
)
def test_gimbal_lock_is_deterministic(conv, angles, expect):
    R = angles_to_matrix(np.array(angles), conv)
    got = matrix_to_angles(R, conv)
    np.testing.assert_allclose(got, expect, atol=1e-7)
    np.testing.assert_allclose(angles_to_matrix(got, conv), R, atol=1e-12)


def test_near_gimbal_lock_still_round_trips():
    for conv, mid in (("zyz", 0.0), ("zyz", np.pi), ("rpy", np.pi / 2), ("xyz", -np.pi / 2)):
        for eps in (1e-6, 1e-8, 1e-10, 1e-12):
            ang = np.array([0.3, mid + (eps if mid <= 0 else -eps), -1.2])
            R = angles_to_matrix(ang, conv)
            np.testing.assert_allclose(
                angles_to_matrix(matrix_to_angles(R, conv), conv), R, atol=1e-9
            )


# --------------------------------------------------------------------------- projective
def test_prj_definition_projection_angles():
    R = R_RANDOM
    u, v, w = matrix_to_prj(R).T
    x, y, z = R[:, :, 0], R[:, :, 1], R[:, :, 2]
    np.testing.assert_allclose(np.tan(u), y[:, 2] / y[:, 1], rtol=1e-9)  # y on YZ, from Y to Z
    np.testing.assert_allclose(np.tan(v), z[:, 0] / z[:, 2], rtol=1e-9)  # z on ZX, from Z to X
    np.testing.assert_allclose(np.tan(w), x[:, 1] / x[:, 0], rtol=1e-9)  # x on XY, from X to Y


def test_prj_round_trip_inside_domain():
    R = Rotation.from_rotvec(
        RNG.normal(size=(2000, 3)) * RNG.uniform(0, 1.2, (2000, 1)) / np.sqrt(3)
    ).as_matrix()
    ang = matrix_to_prj(R)
    np.testing.assert_allclose(prj_to_matrix(*ang.T), R, atol=1e-12)
    # and from angles: matrix → angles reproduces them
    ang2 = RNG.uniform(-0.7, 0.7, (1000, 3))
    R2 = prj_to_matrix(*ang2.T)
    np.testing.assert_allclose(
        np.einsum("nij,nkj->nik", R2, R2), np.broadcast_to(np.eye(3), R2.shape), atol=1e-12
    )
    np.testing.assert_allclose(np.linalg.det(R2), 1.0, atol=1e-12)
    np.testing.assert_allclose(matrix_to_prj(R2), ang2, atol=1e-12)


def test_prj_is_the_rotation_vector_to_first_order():
    w = RNG.normal(size=(100, 3)) * 1e-5
    R = Rotation.from_rotvec(w).as_matrix()
    np.testing.assert_allclose(matrix_to_prj(R), w, atol=1e-9)
    np.testing.assert_allclose(so3_log(R), w, atol=1e-15)


def test_prj_outside_domain_raises():
    with pytest.raises(ValueError, match="domain"):
        prj_to_matrix(np.pi / 2, np.pi / 2, 0.0)  # cos u cos v cos w + sin u sin v sin w = 0
    with pytest.raises(ValueError, match="proper rotation"):
        prj_to_matrix(2.5, 2.5, 2.5)


# --------------------------------------------------------------------------- poses
@pytest.mark.parametrize("conv", CONVENTIONS)
def test_pose_round_trip(conv):
    xyz = RNG.normal(size=(100, 3))
    if conv == "prj":
        ang = RNG.uniform(-0.7, 0.7, (100, 3))
    else:
        ang = matrix_to_angles(Rotation.random(100, random_state=1).as_matrix(), conv)
    T = pose_to_matrix(xyz, ang, conv)
    assert T.shape == (100, 4, 4)
    np.testing.assert_array_equal(T[:, 3], np.tile([0, 0, 0, 1.0], (100, 1)))
    p, a = matrix_to_pose(T, conv)
    np.testing.assert_allclose(p, xyz, atol=0)
    np.testing.assert_allclose(a, ang, atol=1e-10)


def test_unknown_convention():
    with pytest.raises(ValueError, match="unknown angle convention"):
        pose_to_matrix([0, 0, 0], [0, 0, 0], "euler")
    with pytest.raises(ValueError, match=r"\(\.\.\., 3\)"):
        angles_to_matrix([0, 0], "zyz")


def test_rpy_and_xyz_are_each_others_reverse():
    """Fixed X-Y-Z (r, p, y) = intrinsic Z-Y-X (y, p, r); intrinsic XYZ differs."""
    a = RNG.uniform(-1, 1, (50, 3))
    np.testing.assert_allclose(
        rpy_to_matrix(*a.T), Rotation.from_euler("ZYX", a[:, ::-1]).as_matrix(), atol=1e-14
    )
    assert np.abs(rpy_to_matrix(*a.T) - xyz_to_matrix(*a.T)).max() > 0.1
    np.testing.assert_allclose(matrix_to_rpy(rpy_to_matrix(*a.T)), a, atol=1e-12)
    np.testing.assert_allclose(matrix_to_xyz(xyz_to_matrix(*a.T)), a, atol=1e-12)
