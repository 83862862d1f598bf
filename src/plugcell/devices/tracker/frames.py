"""The frames of one requester of the laser tracker: BASE, PROBE and its angle convention.

Thesis 7.4, eqs. (7.1)–(7.2)::

    T = BASE · T_n^0 · PROBE            (7.1)  where the tracker finds the reflector
    T_n^0 = BASE⁻¹ · T · PROBE⁻¹        (7.2)  a measurement in the robot frame

and Table 7-3's conversions between a 4×4 matrix and the robot's 6-vector
``x, y, z`` (mm), three angles (degrees):

========  ========  ===========  ======================================================
option    option    convention   angles (plugcell.kinematics.rotations)
========  ========  ===========  ======================================================
rpy2tr    tr2rpy    ``rpy``      roll-pitch-yaw about fixed X, Y, Z: Rz(y)·Ry(p)·Rx(r)
euler2tr  tr2euler  ``zyz``      Euler Z-Y-Z (Comau): Rz(A)·Ry(B)·Rz(C)
prj2tr    tr2prj    ``prj``      projective angles (defined in rotations.py)
========  ========  ===========  ======================================================

The option words are the tracker's (thesis Table 7-3, on the wire); this module maps
them to the convention names of :mod:`plugcell.kinematics.rotations` and converts with
:func:`plugcell.io.units.pose_from_robot` / :func:`~plugcell.io.units.robot_from_pose`
(the one units boundary), raising :class:`FrameError`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from plugcell.io.units import ROBOT_CONVENTION, UnitsError, pose_from_robot, robot_from_pose
from plugcell.kinematics.transforms import invert

Array = NDArray[np.float64]

#: The convention of a requester that has not said otherwise: Comau's (thesis 7.4).
DEFAULT_CONVENTION = ROBOT_CONVENTION
#: The tracker's option word for each convention (Table 7-3).
OPTION_WORDS = {"rpy": "rpy", "zyz": "euler", "prj": "prj"}
TO_MATRIX = {f"{word}2tr": c for c, word in OPTION_WORDS.items()}
FROM_MATRIX = {f"tr2{word}": c for c, word in OPTION_WORDS.items()}

__all__ = [
    "DEFAULT_CONVENTION",
    "FROM_MATRIX",
    "OPTION_WORDS",
    "TO_MATRIX",
    "FrameError",
    "RequesterFrames",
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


def _pose(v: ArrayLike, convention: str) -> Array:
    """:func:`~plugcell.io.units.pose_from_robot`, its error a :class:`FrameError`."""
    try:
        return pose_from_robot(v, convention)
    except UnitsError as exc:
        raise FrameError(str(exc)) from None


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
        self.base = _pose(v, convention)
        self.convention = convention

    def set_probe(self, v: ArrayLike, option: str) -> None:
        """Set Probe: the reflector (T-MAC) frame in the flange frame F_n."""
        convention = self.input_convention(option)
        self.probe = _pose(v, convention)
        self.convention = convention

    def reflector(self, robot_pose: ArrayLike, option: str = "") -> Array:
        """Eq. (7.1): where the reflector is (tracker frame, 4×4 m) for a robot pose 6-vector."""
        T = _pose(robot_pose, self.input_convention(option))
        return self.base @ T @ self.probe

    def to_robot(self, measured: ArrayLike) -> Array:
        """Eq. (7.2): a measurement (tracker frame, 4×4 m) in the robot frame."""
        M = np.asarray(measured, dtype=float)
        return invert(self.base) @ M @ invert(self.probe)

    def measurement(self, measured: ArrayLike, option: str = "") -> Array:
        """Eq. (7.2) then the conversion of Table 7-3: the 6-vector the robot receives."""
        return robot_from_pose(self.to_robot(measured), self.output_convention(option))
