"""Calibration data: joint readings with the measured target poses (or positions).

:class:`CalibrationData` is the pure-math view of a measurement file
(:class:`plugcell.io.measurements.MeasurementSet`, read by :mod:`plugcell.io`):
SI units, rotations as matrices, no file handling here.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from plugcell.kinematics.rotations import angles_to_matrix

Array = NDArray[np.float64]

__all__ = ["CalibrationData"]


def _ro(x: ArrayLike | None) -> Array | None:
    if x is None:
        return None
    a = np.array(x, dtype=float)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class CalibrationData:
    """A calibration measurement set: joint readings and the measured target poses.

    Read-only arrays, validated on construction.

    Attributes
    ----------
    q : (N, n) array, rad
        Joint readings.
    positions : (N, 3) array, m
        Measured target positions (measurement frame).
    rotations : (N, 3, 3) array or None
        Measured orientations, ``None`` for position-only data.
    payload_kg : (N,) array, kg
        Payloads (zeros when not given).
    temperature_c : (N,) array, °C, or None
        Temperature at each pose, ``None`` when not measured.

    Raises
    ------
    ValueError
        Wrong shapes or non-finite values.
    """

    q: Array
    positions: Array
    rotations: Array | None = None
    payload_kg: Array | None = None
    temperature_c: Array | None = None

    def __post_init__(self) -> None:
        q = _ro(self.q)
        if q is None or q.ndim != 2:
            raise ValueError(f"q must be (N, n), got {None if q is None else q.shape}")
        N = q.shape[0]
        p = _ro(self.positions)
        if p is None or p.shape != (N, 3):
            raise ValueError(f"positions must be ({N}, 3), got {None if p is None else p.shape}")
        R = _ro(self.rotations)
        if R is not None and R.shape != (N, 3, 3):
            raise ValueError(f"rotations must be ({N}, 3, 3), got {R.shape}")
        m = _ro(np.zeros(N) if self.payload_kg is None else self.payload_kg)
        if m is None or m.shape != (N,):
            raise ValueError(f"payload_kg must be ({N},)")
        t = _ro(self.temperature_c)
        if t is not None and t.shape != (N,):
            raise ValueError(f"temperature_c must be ({N},), got {t.shape}")
        for name, arr in (("q", q), ("positions", p), ("rotations", R), ("payload_kg", m)):
            if arr is not None and not np.all(np.isfinite(arr)):
                raise ValueError(f"{name}: values must be finite")
        if t is not None and not np.all(np.isfinite(t)):
            bad = np.flatnonzero(~np.isfinite(t))
            raise ValueError(f"temperature_c: {bad.size} missing or non-finite value(s), first at "
                             f"pose {int(bad[0]) + 1}: a temperature column must be complete")
        object.__setattr__(self, "q", q)
        object.__setattr__(self, "positions", p)
        object.__setattr__(self, "rotations", R)
        object.__setattr__(self, "payload_kg", m)
        object.__setattr__(self, "temperature_c", t)

    @classmethod
    def from_measurements(cls, m: Any) -> CalibrationData:
        """From a :class:`~plugcell.io.measurements.MeasurementSet` (or anything with
        ``joints``, ``positions``, ``angles``, ``rotation`` and ``payload_kg``).

        Parameters
        ----------
        m : MeasurementSet
            Measurements in SI units (angles in rad, in convention ``m.rotation``).

        Returns
        -------
        CalibrationData
            Rotations ``R = R_convention(angles)`` or ``None`` without angles.
        """
        R = None if m.angles is None else angles_to_matrix(m.angles, m.rotation)
        return cls(q=m.joints, positions=m.positions, rotations=R, payload_kg=m.payload_kg,
                   temperature_c=getattr(m, "temperature_c", None))

    @classmethod
    def from_poses(cls, q: ArrayLike, poses: ArrayLike, payload_kg: ArrayLike | None = None,
                   *, position_only: bool = False) -> CalibrationData:
        """From measured poses.

        Parameters
        ----------
        q : (N, n) array_like, rad
            Joint readings.
        poses : (N, 4, 4) array_like, m
            Measured target poses.
        payload_kg : (N,) array_like, kg, optional
            Payloads.
        position_only : bool
            Drop the orientations.

        Returns
        -------
        CalibrationData
            The data set.
        """
        T = np.asarray(poses, dtype=float)
        return cls(q=q, positions=T[:, :3, 3], rotations=None if position_only else T[:, :3, :3],
                   payload_kg=payload_kg)

    def __len__(self) -> int:
        return int(self.q.shape[0])

    @property
    def six_dof(self) -> bool:
        """Whether orientations were measured."""
        return self.rotations is not None

    @property
    def rows(self) -> int:
        """Equations per pose: 6 (pose) or 3 (position)."""
        return 6 if self.six_dof else 3

    @property
    def poses(self) -> Array:
        """``(N, 4, 4)`` measured poses ``[R p; 0 1]``, m (rotation I for position-only data)."""
        T = np.broadcast_to(np.eye(4), (len(self), 4, 4)).copy()
        T[:, :3, 3] = self.positions
        if self.rotations is not None:
            T[:, :3, :3] = self.rotations
        return T

    def positions_only(self) -> CalibrationData:
        """The same poses with their measured orientations dropped (3 equations each).

        Returns
        -------
        CalibrationData
            Position-only data (temperatures are not carried over).
        """
        return CalibrationData(q=self.q, positions=self.positions, payload_kg=self.payload_kg)

    def subset(self, index: ArrayLike | slice) -> CalibrationData:
        """The poses at ``index``.

        Parameters
        ----------
        index : array_like of int or bool, or slice
            Poses to keep.

        Returns
        -------
        CalibrationData
            The subset.
        """
        return CalibrationData(
            q=self.q[index], positions=self.positions[index],
            rotations=None if self.rotations is None else self.rotations[index],
            payload_kg=self.payload_kg[index],  # type: ignore[index]
            temperature_c=None if self.temperature_c is None else self.temperature_c[index],
        )
