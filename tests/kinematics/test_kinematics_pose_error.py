"""The pose-error convention: [p_t − p_a; vee(skew(R_t R_aᵀ − I))], translation at the TCP."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from plugcell.kinematics import (
    invert,
    pose_error,
    pose_error_exact,
    rotation_error,
    so3_exp,
    translation,
    vee,
)

RNG = np.random.default_rng(3)


def _random_T(n: int) -> np.ndarray:
    T = translation(RNG.normal(size=(n, 3)))
    T[:, :3, :3] = Rotation.random(n, random_state=2).as_matrix()
    return T


def test_small_motion_consistency():
    """T_t = [exp(φ) R_a, p_a + Δp]  ⇒  pose_error ≈ (Δp, φ) to second order."""
    Ta = _random_T(200)
    for eps in (1e-3, 1e-5):
        dp = RNG.normal(size=(200, 3)) * eps
        phi = RNG.normal(size=(200, 3)) * eps
        Tt = Ta.copy()
        Tt[:, :3, :3] = so3_exp(phi) @ Ta[:, :3, :3]
        Tt[:, :3, 3] += dp
        e = pose_error(Tt, Ta)
        np.testing.assert_array_equal(e[:, :3], Tt[:, :3, 3] - Ta[:, :3, 3])
        np.testing.assert_allclose(e[:, 3:], phi, atol=10 * eps**2)
        np.testing.assert_allclose(pose_error_exact(Tt, Ta)[:, 3:], phi, atol=1e-12)


def test_rotational_part_is_B15_and_translation_is_at_the_point():
    """B.15: ΔT = T_M T_N⁻¹ − I.  Its rotation part is ours; its translation part is the
    displacement of the point at the base origin, p_M − R_M R_Nᵀ p_N, which differs from
    our TCP displacement by ≈ φ × p_N."""
    TN = _random_T(50)
    phi = RNG.normal(size=(50, 3)) * 1e-6
    TM = TN.copy()
    TM[:, :3, :3] = so3_exp(phi) @ TN[:, :3, :3]
    TM[:, :3, 3] += RNG.normal(size=(50, 3)) * 1e-6
    dT = TM @ invert(TN) - np.eye(4)
    e = pose_error(TM, TN)
    np.testing.assert_allclose(e[:, 3:], vee(dT[:, :3, :3]), atol=1e-18)
    b15_translation = dT[:, :3, 3]
    np.testing.assert_allclose(
        b15_translation, e[:, :3] - np.cross(e[:, 3:], TN[:, :3, 3]), atol=1e-11
    )


def test_large_rotations_exact_vs_first_order():
    Ta = _random_T(100)
    w = RNG.normal(size=(100, 3))
    w *= (RNG.uniform(0.5, 3.0, 100) / np.linalg.norm(w, axis=1))[:, None]
    Tt = Ta.copy()
    Tt[:, :3, :3] = so3_exp(w) @ Ta[:, :3, :3]
    np.testing.assert_allclose(pose_error_exact(Tt, Ta)[:, 3:], w, atol=1e-10)
    th = np.linalg.norm(w, axis=1)
    # first-order φ = sin θ · axis
    np.testing.assert_allclose(
        pose_error(Tt, Ta)[:, 3:], w * (np.sin(th) / th)[:, None], atol=1e-12
    )
    np.testing.assert_allclose(rotation_error(Tt, Ta), th, atol=1e-10)
    assert pose_error(Tt[0], Ta[0]).shape == (6,)
