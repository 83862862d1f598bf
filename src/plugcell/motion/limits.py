"""Speed, acceleration and jerk limits of the joints and of the tool centre point.

Robot description files carry position limits only (``joint_limits``); the dynamic
limits come from the controller's machine data (KUKA ``$VEL_AXIS_MA``,
``$RAT_MOT_ACC``; Comau ``$ARM_DATA``) and are given here explicitly, in SI units.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]

__all__ = ["CartesianLimits", "JointLimits"]


def _positive(name: str, x: ArrayLike, n: int | None) -> Array:
    a = np.array(x, dtype=float)
    if a.ndim == 0 and n is not None:
        a = np.full(n, float(a))
    if n is not None and a.shape != (n,):
        raise ValueError(f"{name}: expected {n} values (one per joint), got shape {a.shape}")
    if not np.all(np.isfinite(a)) or not np.all(a > 0.0):
        raise ValueError(f"{name}: every value must be positive and finite, got {a.tolist()}")
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class JointLimits:
    """Per-joint limits on the readings' speed, acceleration and jerk.

    Parameters
    ----------
    velocity : (n,) array_like, rad/s (m/s for a prismatic reading)
    acceleration : (n,) array_like, rad/s² (m/s²)
    jerk : (n,) array_like, rad/s³ (m/s³)
        Positive and finite; a scalar is taken for every joint when ``n`` is given
        to :meth:`uniform`.
    """

    velocity: Array
    acceleration: Array
    jerk: Array

    def __post_init__(self) -> None:
        v = _positive("velocity", self.velocity, None)
        if v.ndim != 1:
            raise ValueError(f"velocity: expected one value per joint, got shape {v.shape}")
        n = v.size
        object.__setattr__(self, "velocity", v)
        object.__setattr__(self, "acceleration", _positive("acceleration", self.acceleration, n))
        object.__setattr__(self, "jerk", _positive("jerk", self.jerk, n))

    @property
    def n(self) -> int:
        """Number of joints."""
        return int(self.velocity.size)

    @classmethod
    def uniform(cls, n: int, velocity: float, acceleration: float, jerk: float) -> JointLimits:
        """The same three limits for each of ``n`` joints (rad/s, rad/s², rad/s³)."""
        return cls(np.full(n, velocity), np.full(n, acceleration), np.full(n, jerk))

    def scaled(self, speed: float, acceleration: float = 1.0) -> JointLimits:
        """Limits times an override: velocity × ``speed``, acceleration and jerk ×
        ``acceleration`` (both fractions in (0, 1])."""
        return JointLimits(self.velocity * speed, self.acceleration * acceleration,
                           self.jerk * acceleration)


@dataclass(frozen=True)
class CartesianLimits:
    """Limits of the tool centre point along a Cartesian path.

    Parameters
    ----------
    velocity, acceleration, jerk : float
        Of the TCP's position: m/s, m/s², m/s³.
    angular_velocity, angular_acceleration, angular_jerk : float
        Of its orientation: rad/s, rad/s², rad/s³.
    """

    velocity: float
    acceleration: float
    jerk: float
    angular_velocity: float
    angular_acceleration: float
    angular_jerk: float

    def __post_init__(self) -> None:
        for name in ("velocity", "acceleration", "jerk", "angular_velocity",
                     "angular_acceleration", "angular_jerk"):
            x = getattr(self, name)
            if not (isinstance(x, (int, float)) and math.isfinite(x) and x > 0.0):
                raise ValueError(f"{name} must be positive and finite, got {x!r}")
            object.__setattr__(self, name, float(x))

    def scaled(self, speed: float, acceleration: float = 1.0) -> CartesianLimits:
        """Limits times an override (speeds × ``speed``, the rest × ``acceleration``)."""
        return CartesianLimits(
            self.velocity * speed, self.acceleration * acceleration, self.jerk * acceleration,
            self.angular_velocity * speed, self.angular_acceleration * acceleration,
            self.angular_jerk * acceleration)
