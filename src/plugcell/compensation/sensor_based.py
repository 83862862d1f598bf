"""Sensor-based error correction, thesis 6.5.2 (Figs. 6-11, 6-12), as run in 8.3.2.

Static, "move then measure" correction of the residual the model left (the second
stage of the two-stage scheme; state of the art in 3.2.2.2, Kihlman 2005).

**6-DOF loop** (:func:`correct_6dof`, a tracker with a T-MAC):

a. measure the tool pose ``x^m`` (robot base frame, via the identified BASE/PROBE);
   ``Δx = x^d ⊖ x^m`` with the project's pose-error convention (eq. B.15's rotation
   part, position at the tool point);
b. stop when ``‖Δp‖ < 0.08 mm`` and ``‖Δφ‖ < 0.05°`` (the thesis's thresholds for the
   Smart H4, set from its resolution, 6.5.2); else ``δθ = J(θ)⁻¹ Δx`` with the
   identified model's manipulator Jacobian at the current readings, and move to
   ``θ + δθ``;
c. repeat from a.

**3-DOF loop** (:func:`correct_3dof`, an SMR): ``Δp = p^d − p^m`` is handed to the
controller as a relative linear move; only the position is corrected, so the
orientation must already be good enough from the model stage (6.5.2).

Thresholds, measuring time (50 ms in 8.3.2), the iteration cap and a per-iteration
overhead (computation and communication the devices do not report — on the
thesis's C3G controller the larger part of the ~1 s per iteration, 8.3.3) are
:class:`CorrectionSettings`.  Every iteration is recorded as a
:class:`CorrectionStep`.  Anything that stops the loop early raises
:class:`~plugcell.compensation.errors.CorrectionError` with ``reason`` and the
partial :class:`CorrectionResult`: ``"sensor:<reason>"`` (e.g. ``sensor:capture``
when the tracker's beam is lost), ``"max_iterations"``, ``"joint_limit"``,
``"robot"`` (the robot refused or failed a move).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from plugcell.compensation.errors import CorrectionError, SensorError
from plugcell.compensation.model_based import joint_step
from plugcell.compensation.pose_model import PoseModel
from plugcell.compensation.protocols import (
    CartesianRobot,
    JointRobot,
    PoseSensor,
    PositionSensor,
    Reading,
)
from plugcell.kinematics.pose_error import pose_error_exact

Array = NDArray[np.float64]

__all__ = [
    "CorrectionResult",
    "CorrectionSettings",
    "CorrectionStep",
    "correct_3dof",
    "correct_6dof",
]


@dataclass(frozen=True)
class CorrectionSettings:
    """Parameters of the correction loops (defaults: thesis 6.5.2 and 8.3.2).

    The loops stop when ``‖Δp‖ < position_tol_m`` (and, 6-DOF, ``‖Δφ‖ < orientation_tol_rad``).

    Attributes
    ----------
    position_tol_m : float, m
        Position threshold (0.08 mm).
    orientation_tol_rad : float, rad
        Orientation threshold (0.05°).
    duration_s : float, s
        Integration time per measurement (50 ms).
    max_iterations : int
        Corrective moves before giving up.
    overhead_s : float, s
        Time added per corrective iteration for computation and data transfer outside
        the devices (0 by default).
    check_limits : bool
        Refuse a move that leaves the joint limits.

    Raises
    ------
    ValueError
        Non-positive thresholds or duration, negative iteration count or overhead.
    """

    position_tol_m: float = 0.08e-3
    orientation_tol_rad: float = math.radians(0.05)
    duration_s: float = 0.05
    max_iterations: int = 20
    overhead_s: float = 0.0
    check_limits: bool = True

    def __post_init__(self) -> None:
        if not (self.position_tol_m > 0 and self.orientation_tol_rad > 0):
            raise ValueError("thresholds must be > 0")
        if not self.duration_s > 0:
            raise ValueError("duration_s must be > 0")
        if self.max_iterations < 0 or self.overhead_s < 0:
            raise ValueError("max_iterations and overhead_s must be ≥ 0")


@dataclass(frozen=True, eq=False)
class CorrectionStep:
    """One iteration: a measurement and (unless it ended the loop) the move it caused.

    Attributes
    ----------
    index : int
        0 for the first measurement.
    q : (n,) array, rad
        Joint readings when measuring.
    measured : Reading
        The reading (robot base frame).
    error : (6,) or (3,) array
        ``Δx = [Δp (m); φ (rad)]`` (6-DOF) or ``Δp`` (m, 3-DOF).
    position_error_m : float, m
        ‖Δp‖.
    orientation_error_rad : float, rad
        ‖Δφ‖ (NaN for 3-DOF).
    measure_duration_s, measure_elapsed_s : float, s
        Integration time and total time of the reading.
    move : (n,) or (3,) array, or None
        The commanded increment (δθ = J⁻¹Δx, rad, or Δp, m), ``None`` if none.
    move_time_s, overhead_s : float, s
        Move time and overhead of this iteration.
    clock_s : float, s
        The loop's time at the end of the step.
    """

    index: int
    q: Array
    measured: Reading
    error: Array
    position_error_m: float
    orientation_error_rad: float
    measure_duration_s: float
    measure_elapsed_s: float
    move: Array | None
    move_time_s: float
    overhead_s: float
    clock_s: float

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready summary in mm, degrees and seconds."""
        return {
            "index": self.index,
            "position_error_mm": self.position_error_m * 1e3,
            "orientation_error_deg": (None if math.isnan(self.orientation_error_rad)
                                      else math.degrees(self.orientation_error_rad)),
            "error": self.error.tolist(),
            "measure_duration_s": self.measure_duration_s,
            "measure_elapsed_s": self.measure_elapsed_s,
            "move": None if self.move is None else self.move.tolist(),
            "move_time_s": self.move_time_s,
            "overhead_s": self.overhead_s,
            "clock_s": self.clock_s,
        }


@dataclass(frozen=True, eq=False)
class CorrectionResult:
    """The record of one correction: every :class:`CorrectionStep`, whether the
    thresholds were met, and the final joint readings.

    Attributes
    ----------
    mode : str
        ``"6dof"`` or ``"3dof"``.
    target : (4, 4) array, m
        Target tool pose in the robot base frame (position only for 3-DOF).
    settings : CorrectionSettings
        The settings used.
    steps : tuple of CorrectionStep
        Every iteration.
    converged : bool
        The thresholds were met.
    reason : str
        ``""`` or why the loop stopped (``"max_iterations"``, ``"sensor:…"``, …).
    q_final : (n,) array, rad, or None
        Joint readings at the last measurement.
    """

    mode: str
    target: Array
    settings: CorrectionSettings
    steps: tuple[CorrectionStep, ...] = field(default=())
    converged: bool = False
    reason: str = ""
    q_final: Array | None = None

    @property
    def iterations(self) -> int:
        """Corrective moves made (the thesis's "iterations", 8.3.3)."""
        return sum(1 for s in self.steps if s.move is not None)

    @property
    def measurements(self) -> int:
        """Number of measurements taken."""
        return len(self.steps)

    @property
    def time_s(self) -> float:
        """Total time of the loop: measurements, moves and overheads (s)."""
        return self.steps[-1].clock_s if self.steps else 0.0

    @property
    def final_position_error_m(self) -> float:
        """‖Δp‖ of the last measurement (m; NaN without one)."""
        return self.steps[-1].position_error_m if self.steps else math.nan

    @property
    def final_orientation_error_rad(self) -> float:
        """‖Δφ‖ of the last measurement (rad; NaN without one or for 3-DOF)."""
        return self.steps[-1].orientation_error_rad if self.steps else math.nan

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready summary with every step (mm, degrees, seconds)."""
        return {
            "mode": self.mode, "converged": self.converged, "reason": self.reason,
            "iterations": self.iterations, "measurements": self.measurements,
            "time_s": self.time_s, "steps": [s.as_dict() for s in self.steps],
        }


class _Loop:
    """Bookkeeping shared by both loops: steps, clock, early-exit errors."""

    def __init__(self, mode: str, target: Array, settings: CorrectionSettings) -> None:
        self.mode, self.target, self.settings = mode, target, settings
        self.steps: list[CorrectionStep] = []
        self.clock = 0.0

    def result(self, converged: bool, reason: str, q: Array | None) -> CorrectionResult:
        return CorrectionResult(self.mode, self.target, self.settings, tuple(self.steps),
                                converged, reason, q)

    def fail(self, message: str, reason: str, q: Array | None) -> CorrectionError:
        return CorrectionError(message, reason=reason, result=self.result(False, reason, q))

    def measure(self, fn: Any, q: Array) -> Reading:
        try:
            r: Reading = fn(self.settings.duration_s)
        except SensorError as exc:
            raise self.fail(f"measurement failed after {len(self.steps)} readings: {exc}",
                            f"sensor:{exc.reason}", q) from exc
        self.clock += r.elapsed_s
        return r

    def move(self, fn: Any, arg: Array, q: Array) -> float:
        try:
            t = float(fn(arg))
        except CorrectionError:
            raise
        except Exception as exc:
            raise self.fail(f"the robot could not make the corrective move: {exc}", "robot",
                            q) from exc
        self.clock += t + self.settings.overhead_s
        return t

    def record(self, q: Array, r: Reading, error: Array, ep: float, er: float,
               move: Array | None, t_move: float) -> None:
        self.steps.append(CorrectionStep(
            index=len(self.steps), q=q.copy(), measured=r, error=error, position_error_m=ep,
            orientation_error_rad=er, measure_duration_s=r.duration_s,
            measure_elapsed_s=r.elapsed_s, move=move, move_time_s=t_move,
            overhead_s=self.settings.overhead_s if move is not None else 0.0,
            clock_s=self.clock,
        ))


def _target_pose(T: ArrayLike) -> Array:
    T = np.asarray(T, dtype=float)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise ValueError(f"target: expected a finite 4x4 pose, got shape {T.shape}")
    return T


def correct_6dof(
    robot: JointRobot,
    sensor: PoseSensor,
    model: PoseModel,
    target: ArrayLike,
    settings: CorrectionSettings | None = None,
    *,
    payload_kg: float = 0.0,
) -> CorrectionResult:
    """The 6-DOF loop of 6.5.2 (Fig. 6-11, module docstring) towards a tool pose.

    Repeat: measure ``x^m``, ``Δx = x^d ⊖ x^m`` (exact log-map pose error), stop when
    ``‖Δp‖ < position_tol_m`` and ``‖Δφ‖ < orientation_tol_rad``, else
    ``δθ = J(θ)⁻¹ Δx`` (pseudo-inverse if J is not square or singular) and move to
    ``θ + δθ``.

    Parameters
    ----------
    robot : JointRobot
        Reads joints and makes the corrective moves.
    sensor : PoseSensor
        Measures the tool pose in the robot base frame.
    model : PoseModel
        Supplies ``J(θ)`` (the identified model) and the joint limits.
    target : (4, 4) array_like, m
        Desired tool pose in the robot base frame.
    settings : CorrectionSettings, optional
        Thresholds, timing and limits (default: the thesis's).
    payload_kg : float, kg
        Payload for the model's Jacobian.

    Returns
    -------
    CorrectionResult
        The record, once the thresholds are met.

    Raises
    ------
    CorrectionError
        The loop stopped early (sensor failure, iteration cap, joint limit, robot
        failure), with the partial result.
    ValueError
        A malformed target or a reading without a pose.
    """
    s = settings or CorrectionSettings()
    Td = _target_pose(target)
    loop = _Loop("6dof", Td, s)
    desc = model.description
    k = 0
    while True:
        q = np.asarray(robot.read_joints(), dtype=float)
        r = loop.measure(sensor.measure_pose, q)
        if r.pose is None:
            raise ValueError("a PoseSensor returned a reading without a pose")
        dx = pose_error_exact(Td, r.pose)
        ep, er = float(np.linalg.norm(dx[:3])), float(np.linalg.norm(dx[3:]))
        if ep < s.position_tol_m and er < s.orientation_tol_rad:
            loop.record(q, r, dx, ep, er, None, 0.0)
            return loop.result(True, "", q)
        if k >= s.max_iterations:
            loop.record(q, r, dx, ep, er, None, 0.0)
            raise loop.fail(
                f"thresholds not met after {k} corrective moves: ‖Δp‖ = {ep * 1e3:.3f} mm, "
                f"‖Δφ‖ = {math.degrees(er):.4f}°", "max_iterations", q)
        dq = joint_step(model.evaluate(q, payload_kg)[1][0], dx)
        q_new = q + dq
        if s.check_limits and not bool(desc.within_limits(q_new)):
            loop.record(q, r, dx, ep, er, None, 0.0)
            raise loop.fail("the corrective move would leave the joint limits", "joint_limit", q)
        t = loop.move(robot.move_joints, q_new, q)
        loop.record(q, r, dx, ep, er, dq, t)
        k += 1


def correct_3dof(
    robot: CartesianRobot,
    sensor: PositionSensor,
    target_position: ArrayLike,
    settings: CorrectionSettings | None = None,
) -> CorrectionResult:
    """The 3-DOF loop of 6.5.2 (Fig. 6-12): relative moves along ``Δp = p^d − p^m`` until
    ``‖Δp‖ < position_tol_m``.

    Parameters
    ----------
    robot : CartesianRobot
        Reads joints and makes the relative linear moves.
    sensor : PositionSensor
        Measures the tool point in the robot base frame.
    target_position : (3,) array_like, m
        Desired position in the robot base frame.
    settings : CorrectionSettings, optional
        Threshold, timing (default: the thesis's).

    Returns
    -------
    CorrectionResult
        The record, once the threshold is met.

    Raises
    ------
    CorrectionError
        The loop stopped early (sensor failure, iteration cap, robot failure).
    ValueError
        A malformed target.
    """
    s = settings or CorrectionSettings()
    pd = np.asarray(target_position, dtype=float)
    if pd.shape != (3,) or not np.all(np.isfinite(pd)):
        raise ValueError(f"target_position: expected a finite 3-vector, got {pd.shape}")
    Td = np.eye(4)
    Td[:3, 3] = pd
    loop = _Loop("3dof", Td, s)
    k = 0
    while True:
        q = np.asarray(robot.read_joints(), dtype=float)
        r = loop.measure(sensor.measure_position, q)
        dp = pd - r.position
        ep = float(np.linalg.norm(dp))
        if ep < s.position_tol_m:
            loop.record(q, r, dp, ep, math.nan, None, 0.0)
            return loop.result(True, "", q)
        if k >= s.max_iterations:
            loop.record(q, r, dp, ep, math.nan, None, 0.0)
            raise loop.fail(f"threshold not met after {k} relative moves: ‖Δp‖ = "
                            f"{ep * 1e3:.3f} mm", "max_iterations", q)
        t = loop.move(robot.move_relative, dp, q)
        loop.record(q, r, dp, ep, math.nan, dp.copy(), t)
        k += 1
