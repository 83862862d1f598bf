"""Helpers shared by the kinematics tests."""

from __future__ import annotations

import numpy as np

from plugcell.kinematics import GeometricParameters, RobotDescription


def random_configs(desc: RobotDescription, n: int, seed: int) -> np.ndarray:
    """``n`` configurations drawn uniformly inside the joint and coupled limits."""
    rng = np.random.default_rng(seed)
    lo, hi = desc.joint_limits[:, 0], desc.joint_limits[:, 1]
    out = np.empty((0, desc.n_readings))
    while len(out) < n:
        q = lo + rng.random((2 * n, desc.n_readings)) * (hi - lo)
        out = np.concatenate([out, q[desc.within_limits(q)]])
    return out[:n]


def perturbed_params(desc: RobotDescription, seed: int, scale: float = 1.0) -> GeometricParameters:
    """Nominal parameters with thesis-sized errors (~1 mm, ~0.1°) on every entry."""
    rng = np.random.default_rng(seed)
    p = desc.nominal_parameters()
    n = p.n_links
    return p.replace(
        theta=p.theta + scale * rng.normal(0, 2e-3, n),
        d=p.d + scale * rng.normal(0, 1e-3, n),
        a=p.a + scale * rng.normal(0, 1e-3, n),
        alpha=p.alpha + scale * rng.normal(0, 2e-3, n),
        beta=p.beta + scale * np.array([2e-3 if lk.hayati else 0.0 for lk in desc.links]),
    )
