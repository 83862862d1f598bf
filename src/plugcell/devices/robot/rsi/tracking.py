"""The tracker's correction loop as an RSI correction source (mode (b), issue 38).

:class:`TrackingSource` plugs a :class:`~plugcell.compensation.tracking.TrackingLoop`
into an :class:`~.link.RsiLink` configured for Cartesian corrections (``RKorr``) in
absolute mode in the base frame, while the controller runs its own path.  Each cycle it
reads from the robot's packet

* ``AIPos`` — the joint feedback ``q(t)`` (``t``: the session's IPOC clock);
* ``RSol`` — the corrected set-point, from which the path's own pose is recovered by
  removing the offset in force, ``p_p = p − o_xyz``, ``R_p = R_oᵀ R`` with
  ``R_o = Rz(A)·Ry(B)·Rx(C)`` (docs/kuka-rsi.md: the controller applies
  ``p = p_p + o_xyz``, ``R = R_o·R_p``);

asks the loop for its offset ``[Δp; φ]``, converts the rotation vector to KUKA's A, B,
C (``R_o = exp(φ)``) and hands it to a :class:`~..stream.source.PathOffset`, which
blends it in at the start and out at :meth:`finish` (jerk-limited) before the link's own
limits.  Tracker samples come from any thread through :meth:`add`.

API note: ``TrackingSource(loop, ramp=0.5, record=False)``; ``add(measurements)``;
``correction(state)`` (what the link calls); ``finish()``; ``ended(state)``;
``hold(reason)``; ``records`` (per cycle ``(t, CycleOutput, blend)`` when ``record``).
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
from numpy.typing import NDArray

from plugcell.compensation.tracking import CycleOutput, TrackerMeasurement, TrackingLoop
from plugcell.kinematics.rotations import matrix_to_rpy, rpy_to_matrix
from plugcell.kinematics.transforms import so3_exp

from ..stream.source import Correction, CycleState, PathOffset
from .config import RsiConfig

Array = NDArray[np.float64]

__all__ = ["TrackingSource", "check_tracking_config", "kuka_pose", "path_pose"]


def check_tracking_config(config: RsiConfig) -> None:
    """Refuse a stream the source cannot drive.

    Raises
    ------
    ValueError
        Not Cartesian, not absolute or not in the base frame (named).
    """
    if config.correction != "cartesian" or config.mode != "absolute" or config.frame != "base":
        raise ValueError("tracking corrections are absolute Cartesian offsets in the base "
                         f"frame; the link is configured for {config.mode} "
                         f"{config.correction} corrections in the {config.frame} frame")


def kuka_pose(xyzabc: Array) -> Array:
    """4×4 pose of x, y, z (m) and KUKA's A, B, C (rad): ``R = Rz(A)·Ry(B)·Rx(C)``."""
    T = np.eye(4)
    T[:3, :3] = rpy_to_matrix(xyzabc[5], xyzabc[4], xyzabc[3])
    T[:3, 3] = xyzabc[:3]
    return T


def path_pose(setpoint: Array, offset: Array) -> Array:
    """The path's own pose from the corrected set-point ``RSol`` and the offset in force.

    Parameters
    ----------
    setpoint : (6,) array
        ``RSol``: x, y, z (m), A, B, C (rad).
    offset : (6,) array
        The absolute base-frame offset the set-point carries (m, rad: A, B, C).

    Returns
    -------
    (4, 4) array
        ``(p − o_xyz, R_oᵀ R)``.
    """
    T = kuka_pose(setpoint)
    Ro = rpy_to_matrix(offset[5], offset[4], offset[3])
    T[:3, 3] -= offset[:3]
    T[:3, :3] = Ro.T @ T[:3, :3]
    return T


class TrackingSource:
    """A tracked path's correction source for RSI (module docstring).

    Parameters
    ----------
    loop : TrackingLoop
        The estimator and law (its ``cycle_s`` the stream's cycle).
    ramp : float
        Blend in and out of the whole offset (s).
    finish_at : float, optional
        Start blending out this many seconds after the first cycle.
    record : bool
        Keep every cycle's ``(t, CycleOutput, blend)`` in :attr:`records`.
    """

    def __init__(self, loop: TrackingLoop, *, ramp: float = 0.5,
                 finish_at: float | None = None, record: bool = False) -> None:
        self.loop = loop
        self.path_offset = PathOffset(self._goal, ramp=ramp, finish_at=finish_at)
        self.record = record
        self.records: list[tuple[float, CycleOutput, float]] = []
        self.last: CycleOutput | None = None

    def add(self, measurements: Iterable[TrackerMeasurement]) -> None:
        """Tracker samples for the loop (thread-safe; robot clock, F0)."""
        self.loop.add(measurements)

    def hold(self, reason: str) -> None:
        """The tracker is gone for good: the model alone from now (the window says why)."""
        self.loop.hold(reason)

    def finish(self) -> None:
        """Blend the offset out from the next cycle (thread-safe)."""
        self.path_offset.finish()

    def ended(self, state: CycleState | None = None) -> bool:
        """The blend out is over (a ``done`` for the link's ``follow``)."""
        return self.path_offset.ended(state)

    def correction(self, state: CycleState) -> Correction:
        """This cycle's absolute offset (what the link calls).

        Parameters
        ----------
        state : CycleState
            The cycle: the packet must carry ``AIPos`` and ``RSol``.

        Returns
        -------
        Correction
            ``offset = b · [Δp; A, B, C]``.
        """
        corr = self.path_offset.correction(state)
        if self.record and self.last is not None:
            self.records.append((state.t, self.last, self.path_offset.blend))
        return corr

    def _goal(self, state: CycleState) -> Array:
        robot = state.robot
        if robot.joints is None or robot.tcp_setpoint is None:
            raise ValueError("tracking needs the controller's AIPos and RSol in its packets")
        Tp = path_pose(np.asarray(robot.tcp_setpoint, float), np.asarray(state.offset, float))
        out = self.loop.cycle(state.t, robot.joints, Tp)
        self.last = out
        roll, pitch, yaw = matrix_to_rpy(so3_exp(out.offset[3:]))
        return np.array([*out.offset[:3], yaw, pitch, roll])
