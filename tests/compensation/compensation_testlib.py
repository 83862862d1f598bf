"""Helpers of the compensation tests."""

from __future__ import annotations

import numpy as np

from plugcell.calibration.model import ErrorModel
from plugcell.kinematics import RobotDescription


def perturbed_error_model(desc: RobotDescription, seed: int = 1, family: str = "loop",
                          payload: bool = True) -> ErrorModel:
    """Model 5 (or the serial family) with every parameter perturbed at a realistic size."""
    em = ErrorModel.create(desc, family, gravity=True, payload=payload, payload_ref_kg=36.0)
    rng = np.random.default_rng(seed)
    scale = np.array([5e-4 if p.unit == "m" else 5e-4 if p.kind in ("gravity", "payload")
                      else np.radians(0.05) for p in em.space])
    return em.with_values(scale * rng.standard_normal(len(em.space)))
