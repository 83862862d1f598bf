"""The frames of one requester of the laser tracker: BASE, PROBE and its angle convention.

Thesis 7.4, eqs. (7.1)–(7.2)::

    T = BASE · T_n^0 · PROBE            (7.1)  where the tracker finds the reflector
    T_n^0 = BASE⁻¹ · T · PROBE⁻¹        (7.2)  a measurement in the robot frame

and Table 7-3's conversions between a 4×4 matrix and the robot's 6-vector
``x, y, z`` (mm), three angles (degrees):

========  ========  ===================================================
option    option    angles (plugcell.kinematics.rotations)
========  ========  ===================================================
rpy2tr    tr2rpy    roll-pitch-yaw about fixed X, Y, Z: Rz(y)·Ry(p)·Rx(r)
euler2tr  tr2euler  Euler Z-Y-Z (Comau): Rz(A)·Ry(B)·Rz(C)
prj2tr    tr2prj    projective angles (defined in rotations.py)
========  ========  ===================================================

Pure functions on numpy arrays; inside they work in metres and radians.  The
conversions themselves are :mod:`plugcell.io.units` (the one units boundary); this module
names them as the tracker's options do and raises :class:`FrameError`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from plugcell.io.units import CONVENTIONS, UnitsError, pose_from_robot, robot_from_pose
from plugcell.metrology import invert_transform

Array = NDArray[np.float64]

#: The convention of a requester that has not said otherwise: Comau's (thesis 7.4).
DEFAULT_CONVENTION = "euler"
TO_MATRIX = {f"{k}2tr": k for k in CONVENTIONS}
FROM_MATRIX = {f"tr2{k}": k for k in CONVENTIONS}

__all__ = [
    "CONVENTIONS",
    "DEFAULT_CONVENTION",
    "FROM_MATRIX",
    "TO_MATRIX",
    "FrameError",
    "RequesterFrames",
    "matrix_from_vector",
    "vector_from_matrix",
]


class FrameError(ValueError):
    """A 6-vector or option that cannot be converted; the message is the reason."""


def _convention(option: str, table: dict[str, str], default: str) -> str:
    if not option:
        return default
    try:
        return table[option]
    except KeyError:
        raise FrameError(
            f"unknown option {option!r}: use {', '.join(table)} (or none for {default})"
        ) from None


def matrix_from_vector(v: ArrayLike, convention: str) -> Array:
    """``x, y, z`` (mm), three angles (deg) → 4×4 (metres): rpy2tr / euler2tr / prj2tr."""
    try:
        return pose_from_robot(v, convention)
    except UnitsError as exc:
        raise FrameError(str(exc)) from None


def vector_from_matrix(T: ArrayLike, convention: str) -> Array:
    """4×4 (metres) → ``x, y, z`` (mm), three angles (deg): tr2rpy / tr2euler / tr2prj."""
    return robot_from_pose(T, convention)


@dataclass
class RequesterFrames:
    """BASE, PROBE and the angle convention of one requester (a robot), eq. (7.1).

    Each robot sharing the tracker has its own (thesis 8.4.2): the service keeps one
    per requester.  Both frames start as the identity — the robot frame is the
    tracker frame and measurements come out raw, as calibration needs them (8.2.2).
    """

    base: Array = field(default_factory=lambda: np.eye(4))
    probe: Array = field(default_factory=lambda: np.eye(4))
    convention: str = DEFAULT_CONVENTION

    def input_convention(self, option: str) -> str:
        """The convention of an input 6-vector: option ``rpy2tr``… or the requester's."""
        return _convention(option, TO_MATRIX, self.convention)

    def output_convention(self, option: str) -> str:
        """The convention of an output 6-vector: option ``tr2rpy``… or the requester's."""
        return _convention(option, FROM_MATRIX, self.convention)

    def set_base(self, v: ArrayLike, option: str) -> None:
        """Set Base: the robot base frame F0 in the tracker frame."""
        convention = self.input_convention(option)
        self.base = matrix_from_vector(v, convention)
        self.convention = convention

    def set_probe(self, v: ArrayLike, option: str) -> None:
        """Set Probe: the reflector (T-MAC) frame in the flange frame F_n."""
        convention = self.input_convention(option)
        self.probe = matrix_from_vector(v, convention)
        self.convention = convention

    def reflector(self, robot_pose: ArrayLike, option: str = "") -> Array:
        """Eq. (7.1): where the reflector is (tracker frame, 4×4 m) for a robot pose 6-vector."""
        T = matrix_from_vector(robot_pose, self.input_convention(option))
        return self.base @ T @ self.probe

    def to_robot(self, measured: ArrayLike) -> Array:
        """Eq. (7.2): a measurement (tracker frame, 4×4 m) in the robot frame."""
        M = np.asarray(measured, dtype=float)
        return invert_transform(self.base) @ M @ invert_transform(self.probe)

    def measurement(self, measured: ArrayLike, option: str = "") -> Array:
        """Eq. (7.2) then the conversion of Table 7-3: the 6-vector the robot receives."""
        return vector_from_matrix(self.to_robot(measured), self.output_convention(option))
