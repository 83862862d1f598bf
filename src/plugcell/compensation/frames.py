"""Measurements into the robot base frame with the identified BASE and PROBE (thesis 6.5.2).

"Notice in both cases, measurements from the global metrology system are expressed
in the robot base frame, thanks to the BASE and PROBE transformations already
identified in the calibration process" (6.5.2; in 8.3.2 both are loaded into the
tracker service).  The tracker reads the reflector in its own frame,
``T_meas = BASE · T_flange · PROBE`` (eq. 6.23), so the tool pose in the robot base
frame is::

    T_tool = BASE⁻¹ · T_meas · PROBE⁻¹ · TOOL

(``TOOL`` = the tool point in the flange frame; ``TOOL = PROBE`` — the default, the
T-MAC itself is compensated — gives ``BASE⁻¹ · T_meas``).  A position-only reading
(SMR) is the reflector's position: ``p_tool = BASE⁻¹ · p_meas``, valid when the
tool point is the reflector.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from plugcell.compensation.protocols import Reading
from plugcell.kinematics.transforms import invert

Array = NDArray[np.float64]

__all__ = ["MetrologyFrames", "RawSensor", "RobotFrameSensor"]


def _transform(x: ArrayLike, name: str) -> Array:
    T = np.array(x, dtype=float)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise ValueError(f"{name}: expected a finite 4x4 transform, got shape {T.shape}")
    T.setflags(write=False)
    return T


@dataclass(frozen=True, eq=False)
class MetrologyFrames:
    """Identified BASE, PROBE and TOOL: ``T_tool = BASE⁻¹ · T_meas · PROBE⁻¹ · TOOL``.

    Attributes
    ----------
    base : (4, 4) array, m
        BASE, the robot base in the sensor frame.
    probe : (4, 4) array, m
        PROBE, the reflector in the flange frame.
    tool : (4, 4) array, m
        TOOL, the tool point in the flange frame (default: PROBE).

    Raises
    ------
    ValueError
        A transform that is not a finite 4×4 matrix.
    """

    base: Array
    probe: Array
    tool: Array = field(default=None)  # type: ignore[assignment]

    def __post_init__(self) -> None:
        object.__setattr__(self, "base", _transform(self.base, "base"))
        object.__setattr__(self, "probe", _transform(self.probe, "probe"))
        tool = self.probe if self.tool is None else _transform(self.tool, "tool")
        object.__setattr__(self, "tool", tool)
        object.__setattr__(self, "_base_inv", invert(self.base))
        object.__setattr__(self, "_probe_to_tool", invert(self.probe) @ tool)

    @property
    def tool_is_probe(self) -> bool:
        """Whether TOOL equals PROBE (to 1e-12), so positions locate the tool point."""
        return bool(np.allclose(self.tool, self.probe, atol=1e-12))

    def pose_to_robot(self, T_meas: ArrayLike) -> Array:
        """Tool pose in the robot base frame, ``T_tool = BASE⁻¹ · T_meas · PROBE⁻¹ · TOOL``.

        Parameters
        ----------
        T_meas : (..., 4, 4) array_like, m
            Reflector poses in the sensor frame.

        Returns
        -------
        (..., 4, 4) array, m
            Tool poses in the robot base frame.
        """
        return self._base_inv @ np.asarray(T_meas, dtype=float) @ self._probe_to_tool  # type: ignore[attr-defined,no-any-return]

    def position_to_robot(self, p_meas: ArrayLike) -> Array:
        """Reflector position in the robot base frame, ``p = BASE⁻¹ · p_meas``.

        Parameters
        ----------
        p_meas : (..., 3) array_like, m
            Reflector positions in the sensor frame.

        Returns
        -------
        (..., 3) array, m
            The positions in the robot base frame.
        """
        Bi = self._base_inv  # type: ignore[attr-defined]
        p = np.asarray(p_meas, dtype=float)
        return p @ Bi[:3, :3].T + Bi[:3, 3]  # type: ignore[no-any-return]

    def robot_to_sensor(self, T_tool: ArrayLike) -> Array:
        """Where the reflector should be, in the sensor frame, for tool poses in the robot
        base frame (to point a tracker at a target before moving there).

        ``T_meas = BASE · T_tool · TOOL⁻¹ · PROBE``, the inverse of :meth:`pose_to_robot`.

        Parameters
        ----------
        T_tool : (..., 4, 4) array_like, m
            Tool poses in the robot base frame.

        Returns
        -------
        (..., 4, 4) array, m
            Reflector poses in the sensor frame.
        """
        return self.base @ np.asarray(T_tool, dtype=float) @ invert(self._probe_to_tool)  # type: ignore[attr-defined,no-any-return]


class RawSensor(Protocol):
    """A metrology device reading the reflector in its own frame."""

    def measure(self, duration_s: float, mode: str) -> Reading:
        """One reading of the reflector in the sensor's own frame.

        Parameters
        ----------
        duration_s : float, s
            Averaging time.
        mode : {"6dof", "3dof"}
            Pose or position.

        Returns
        -------
        Reading
            Position (m) and, for ``"6dof"``, pose (4, 4), m.
        """
        ...


@dataclass(eq=False)
class RobotFrameSensor:
    """A :class:`RawSensor` seen through :class:`MetrologyFrames`: implements
    :class:`~plugcell.compensation.protocols.PoseSensor` and ``PositionSensor``.

    Attributes
    ----------
    sensor : RawSensor
        The device, reading in its own frame.
    frames : MetrologyFrames
        BASE, PROBE and TOOL used to bring readings into the robot base frame.
    """

    sensor: RawSensor
    frames: MetrologyFrames

    def measure_pose(self, duration_s: float) -> Reading:
        """Tool pose in the robot base frame, ``BASE⁻¹ · T_meas · PROBE⁻¹ · TOOL``.

        Parameters
        ----------
        duration_s : float, s
            Averaging time.

        Returns
        -------
        Reading
            ``pose`` (4, 4) and ``position`` (3,), m, robot base frame.

        Raises
        ------
        ValueError
            The sensor returned no orientation.
        """
        r = self.sensor.measure(duration_s, "6dof")
        if r.pose is None:
            raise ValueError("the sensor returned no orientation for a 6-DOF reading")
        T = self.frames.pose_to_robot(r.pose)
        return Reading(position=T[:3, 3].copy(), pose=T, duration_s=r.duration_s,
                       elapsed_s=r.elapsed_s)

    def measure_position(self, duration_s: float) -> Reading:
        """Reflector position in the robot base frame, ``p = BASE⁻¹ · p_meas``.

        Parameters
        ----------
        duration_s : float, s
            Averaging time.

        Returns
        -------
        Reading
            ``position`` (3,), m, robot base frame; ``pose`` None.

        Raises
        ------
        ValueError
            TOOL is not PROBE (a position locates the reflector only).
        """
        if not self.frames.tool_is_probe:
            raise ValueError("a position-only reading locates the reflector: the tool point "
                             "must be the reflector (TOOL = PROBE)")
        r = self.sensor.measure(duration_s, "3dof")
        p = self.frames.position_to_robot(r.position)
        return Reading(position=p, pose=None, duration_s=r.duration_s, elapsed_s=r.elapsed_s)
