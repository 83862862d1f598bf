"""Fixtures of the motion tests: the robots and the limits of a 200 kg-class arm."""

from __future__ import annotations

import numpy as np
import pytest

from plugcell.motion import CartesianLimits, JointLimits


@pytest.fixture(scope="session")
def jl() -> JointLimits:
    return JointLimits(np.radians([120, 115, 120, 190, 180, 260]),
                       np.radians([400, 350, 400, 600, 600, 800]),
                       np.radians([3000, 2500, 3000, 5000, 5000, 7000]))


@pytest.fixture(scope="session")
def cl() -> CartesianLimits:
    return CartesianLimits(1.0, 4.0, 40.0, 2.0, 8.0, 80.0)
