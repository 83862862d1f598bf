"""The moves a trajectory is planned from: PTP, LIN and CIRC (as KRL's and PDL's).

=======  ===========================================  =====================================
move     path                                         blend radius (``blend``)
=======  ===========================================  =====================================
PTP      straight line in joint space, all joints     joint space, rad (Euclidean norm of
         start and end together                       the joint vector's distance)
LIN      straight line of the TCP, orientation by     TCP distance, m (KRL ``C_DIS``, PDL
         slerp                                        ``$TERM_TYPE`` fly with a distance)
CIRC     circular arc of the TCP from the start        TCP distance, m
         through ``via`` to ``target``, orientation
         by slerp from start to target
=======  ===========================================  =====================================

Targets are in SI units: joint readings in radians (metres for a prismatic reading),
poses as 4×4 transforms of the TCP in the robot base frame, metres.  ``speed`` and
``acceleration`` are overrides, fractions in (0, 1] of the limits given to the planner.
``line`` is the program line the move comes from, named in errors.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]

__all__ = ["CIRC", "LIN", "PTP", "Move"]


def _fraction(name: str, x: float) -> float:
    if not (isinstance(x, (int, float)) and 0.0 < x <= 1.0):
        raise ValueError(f"{name} must be a fraction in (0, 1], got {x!r}")
    return float(x)


def _pose(name: str, T: ArrayLike) -> Array:
    a = np.array(T, dtype=float)
    if a.shape != (4, 4):
        raise ValueError(f"{name}: expected a 4×4 transform, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: values must be finite")
    R = a[:3, :3]
    if (not np.allclose(R.T @ R, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0.0
            or not np.allclose(a[3], [0.0, 0.0, 0.0, 1.0])):
        raise ValueError(f"{name}: not a rigid transform (rotation part not orthonormal "
                         "or last row not 0 0 0 1)")
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class _Common:
    blend: float = 0.0
    speed: float = 1.0
    acceleration: float = 1.0
    line: int | None = None

    def _check_common(self) -> None:
        if not (isinstance(self.blend, (int, float)) and math.isfinite(self.blend)
                and self.blend >= 0.0):
            raise ValueError(f"blend must be a finite radius ≥ 0, got {self.blend!r}")
        object.__setattr__(self, "blend", float(self.blend))
        object.__setattr__(self, "speed", _fraction("speed", self.speed))
        object.__setattr__(self, "acceleration", _fraction("acceleration", self.acceleration))


@dataclass(frozen=True, kw_only=True)
class PTP(_Common):
    """Joint move to ``target`` (readings, rad), axes synchronised.

    Parameters
    ----------
    target : (n,) array_like, rad (m for a prismatic reading)
    blend : float, rad
        Joint-space blend radius around ``target`` into the next PTP (0: stop there).
    speed, acceleration : float
        Overrides in (0, 1] of the joint limits.
    line : int, optional
        Program line, for errors.
    """

    target: Array

    def __post_init__(self) -> None:
        self._check_common()
        q = np.array(self.target, dtype=float)
        if q.ndim != 1 or not np.all(np.isfinite(q)):
            raise ValueError(f"PTP target: expected finite joint values, got {self.target!r}")
        q.setflags(write=False)
        object.__setattr__(self, "target", q)

    kind = "PTP"


@dataclass(frozen=True, kw_only=True)
class LIN(_Common):
    """Straight-line move of the TCP to ``target`` (4×4, robot base frame, m).

    Parameters
    ----------
    target : (4, 4) array_like, m
    blend : float, m
        Blend radius around ``target`` into the next LIN/CIRC (0: stop there).
    speed, acceleration, line
        As for :class:`PTP` (of the Cartesian limits).
    """

    target: Array

    def __post_init__(self) -> None:
        self._check_common()
        object.__setattr__(self, "target", _pose("LIN target", self.target))

    kind = "LIN"


@dataclass(frozen=True, kw_only=True)
class CIRC(_Common):
    """Circular move of the TCP through ``via`` (its position) to ``target``.

    Parameters
    ----------
    via : (3,) or (4, 4) array_like, m
        The auxiliary point (only its position is used, as KRL's default
        ``$CIRC_TYPE``).
    target : (4, 4) array_like, m
        End pose; the orientation turns from the start's to the target's by slerp.
    blend, speed, acceleration, line
        As for :class:`LIN`.
    """

    via: Array
    target: Array

    def __post_init__(self) -> None:
        self._check_common()
        v = np.array(self.via, dtype=float)
        if v.shape == (4, 4):
            v = _pose("CIRC via", v)[:3, 3].copy()
        if v.shape != (3,) or not np.all(np.isfinite(v)):
            raise ValueError(f"CIRC via: expected a finite point (3,) or pose (4, 4), got "
                             f"shape {v.shape}")
        v.setflags(write=False)
        object.__setattr__(self, "via", v)
        object.__setattr__(self, "target", _pose("CIRC target", self.target))

    kind = "CIRC"


Move = PTP | LIN | CIRC
