"""The twin in time and the streaming tracker behind the settling-correction protocols.

:class:`DynamicCell` is one robot that moves cycle by cycle
(:class:`~plugcell.sim.twin.dynamics.DynamicTwin`: dead time, cascade servo, friction,
backlash, encoder counts, first structural modes) and one laser tracker that streams
its reflector (:class:`~plugcell.sim.twin.tracker_stream.TrackerStream`: 3 kHz internal
samples, output up to 1 kHz, latency, noise at rate, beam breaks), on one simulated
clock ``now`` (s, true time).  It hands out:

* :class:`StreamingRobot` — a :class:`~plugcell.compensation.protocols.MovingRobot`:
  ``command_joints(q, duration_s)`` plans a synchronised PTP (``plugcell.motion``,
  double-S, the joint limits below) from the last command — or, when that would be
  shorter than ``duration_s``, a quintic ramp over ``duration_s`` — and streams its
  setpoints, one per 4 ms cycle, as the controller's interpolator does; it returns at
  once with the time the interpolation ends;
* :class:`RobotFrameStream` — a :class:`~plugcell.compensation.protocols.PoseStream`:
  ``receive(wait_s)`` lets ``wait_s`` of simulated time pass (the arm steps, the
  tracker samples the moving reflector) and returns the samples that left the tracker
  meanwhile, in the robot base frame through the identified BASE/PROBE
  (:class:`~plugcell.compensation.frames.MetrologyFrames`), each stamped with its
  acquisition time on the tracker's clock.  The twin's tracker clock is the cell's
  (``StreamSpec`` without offset or drift); with a real tracker the stamps go through
  ``plugcell.metrology.timing.fit_clock_map`` first.
* :class:`StopAndGoRobot` and :class:`AveragingSensor` — the thesis's stop–measure–move
  faces (:class:`~plugcell.compensation.protocols.JointRobot`,
  :class:`~plugcell.compensation.protocols.PoseSensor`) on the same dynamic arm and
  stream, so that the iterative 6.5.2 loop (``correct_6dof``) runs on the same physics:
  a move returns after the interpolation plus a fixed settling wait; a reading is the
  mean of the stream's samples over its duration.

The true reflector pose between two cycles (the tracker samples at 3 kHz) is the
linear interpolation of the positions at the cycle ends (the rotation of the later
one); the poses are computed per cycle in batches (the static physics of the twin,
:meth:`~plugcell.sim.twin.dynamics.DynamicTwin.true_flanges`), and while the arm stays
within :data:`LINEAR_RAD` of where it last rested, to first order about that point (the
physics costs milliseconds a call; the linearisation's error is below 0.1 µm, tested).
Where nobody reads the stream (``advance(..., sample=False)``: the stop-and-go waits)
it is not simulated; the next read restarts it with the beam re-pointed.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from plugcell.compensation.errors import SensorError
from plugcell.compensation.frames import MetrologyFrames
from plugcell.compensation.protocols import Reading, StreamReading
from plugcell.kinematics.transforms import so3_exp, so3_log
from plugcell.motion import PTP, JointLimits, plan
from plugcell.sim.twin.dynamics import DynamicTwin
from plugcell.sim.twin.tracker import LaserTracker
from plugcell.sim.twin.tracker_stream import StreamSample, StreamSpec, TrackerStream

Array = NDArray[np.float64]

__all__ = ["H4_JOINT_LIMITS", "AveragingSensor", "DynamicCell", "RobotFrameStream",
           "StopAndGoRobot", "StreamingRobot"]

#: Joint speed, acceleration and jerk of a 200 kg-class robot (rad/s, /s², /s³), as
#: benchmarks/twin_path_deviation.py (our estimates for the Smart H4 class).
H4_JOINT_LIMITS = JointLimits(np.radians([100, 90, 90, 170, 120, 190]),
                              np.radians([300, 250, 300, 500, 500, 700]),
                              np.radians([2000, 1500, 2000, 4000, 4000, 5000]))

#: Largest link-angle excursion (rad) from the last rest point that the cell computes
#: the reflector's pose for to first order (module docstring).
LINEAR_RAD = 2e-4

#: How much true-pose history the cell keeps for the tracker's interpolation (s).
_HISTORY_S = 0.5


class DynamicCell:
    """A :class:`DynamicTwin` and a streaming :class:`LaserTracker` on one clock.

    Parameters
    ----------
    arm : DynamicTwin
        The robot (its static twin's truth gives the reflector: ``BASE·T6·PROBE``).
    tracker : LaserTracker
        The instrument; its beam is pointed at the reflector here.
    frames : MetrologyFrames
        The identified BASE/PROBE(/TOOL) that bring readings into the robot base frame.
    rate_hz : float
        The stream's output rate (≤ 1 kHz).
    spec : StreamSpec, optional
        The stream's dynamics (default: AT901/AT960 class).
    blocked : callable, optional
        ``blocked(t) -> bool``: the line of sight is interrupted at cell time ``t``.
    joint_limits : JointLimits
        Of the controller's PTP moves.
    seed : int
        The stream's noise.
    """

    def __init__(self, arm: DynamicTwin, tracker: LaserTracker, frames: MetrologyFrames,
                 rate_hz: float = 1000.0, *, spec: StreamSpec | None = None,
                 blocked: Callable[[float], bool] | None = None,
                 joint_limits: JointLimits = H4_JOINT_LIMITS, seed: int = 0) -> None:
        self.arm = arm
        self.tracker = tracker
        self.frames = frames
        self.joint_limits = joint_limits
        self.rate_hz, self.spec, self.blocked, self.seed = rate_hz, spec, blocked, seed
        self.cycle_s = arm.params.cycle
        self.now = 0.0
        self.cycles = 0
        self._command = arm.measured.copy()
        self._queue: list[Array] = []
        self._base = arm.twin.true_base()
        self._probe = arm.twin.reveal_truth().probe
        self._lin: tuple[Array, Array, Array, Array] | None = None
        self._times = [0.0]
        self._poses = [self._reflector(arm.link[None])[0]]
        self.streams = 0
        self._stale = False
        self.stream = self._open_stream()

    # ------------------------------------------------------------------ world
    def _open_stream(self) -> TrackerStream:
        """Point the beam at the reflector and start streaming from now."""
        self.tracker.point_at(self._poses[-1][:3, 3])
        self.streams += 1
        return TrackerStream(self.tracker, self._target, self.rate_hz, six_dof=True,
                             spec=self.spec, blocked=self.blocked, start_s=self.now,
                             seed=self.seed * 1000 + self.streams)

    def _reflector(self, link: Array) -> Array:
        """True reflector poses (tracker frame) for link angles ``(m, n)``: exact
        (:meth:`DynamicTwin.true_flanges`), or — while the arm stays within
        :data:`LINEAR_RAD` of where it last rested — to first order about that point,
        ``p = p₀ + J_p δ``, ``R = exp(J_φ δ) R₀`` (second-order error < 0.1 µm, 0.1 µrad)."""
        if self._lin is not None:
            q0, T0, Jp, Jr = self._lin
            d = link - q0
            if float(np.max(np.abs(d))) < LINEAR_RAD:
                out = np.broadcast_to(T0, (len(link), 4, 4)).copy()
                out[:, :3, 3] += d @ Jp.T
                out[:, :3, :3] = so3_exp(d @ Jr.T) @ T0[:3, :3]
                return out
        out = self._exact(link)
        if float(np.max(np.abs(link[-1] - link[0]))) < 0.25 * LINEAR_RAD:
            self._linearise(link[-1], out[-1])
        else:
            self._lin = None
        return out

    def _exact(self, link: Array) -> Array:
        return self._base @ self.arm.true_flanges(link) @ self._probe  # type: ignore[no-any-return]

    def _linearise(self, q: Array, T: Array) -> None:
        """Central differences (step 10⁻⁵ rad) of the exact pose at ``q``."""
        n, h = q.size, 1e-5
        Q = np.repeat(q[None], 2 * n, 0)
        Q[np.arange(n), np.arange(n)] += h
        Q[n + np.arange(n), np.arange(n)] -= h
        P = self._exact(Q)
        Jp = (P[:n, :3, 3] - P[n:, :3, 3]).T / (2 * h)
        Jr = np.array([so3_log(P[j, :3, :3] @ P[n + j, :3, :3].T) for j in range(n)]).T / (2 * h)
        self._lin = (q.copy(), T.copy(), Jp, Jr)

    def _target(self, t: float) -> Array:
        """True reflector pose (tracker frame) at cell time ``t``: positions interpolated
        linearly between the cycles' ends, the rotation of the later one."""
        if len(self._times) == 1:
            return self._poses[0]
        k = (t - self._times[0]) / self.cycle_s
        i = min(max(math.floor(k), 0), len(self._times) - 2)
        a = min(max(k - i, 0.0), 1.0)
        out = self._poses[i + 1].copy()
        out[:3, 3] = (1 - a) * self._poses[i][:3, 3] + a * self._poses[i + 1][:3, 3]
        return out

    def true_tool(self) -> Array:
        """The tool's true pose now in the robot base frame, through the identified frames
        (what a perfect tracker would report) — simulators only."""
        return self.frames.pose_to_robot(self._poses[-1])

    def true_tool_at(self, t: float) -> Array:
        """The tool's true pose at cell time ``t`` (within the last 0.5 s), as
        :meth:`true_tool` — simulators only."""
        return self.frames.pose_to_robot(self._target(t))

    def static_reading(self, duration_s: float = 1.0) -> Array:
        """A static tracker reading (the thesis's 1 s verification, the static
        :class:`LaserTracker` model) of the tool now, robot base frame; ``duration_s``
        passes (the stream is not sampled meanwhile)."""
        self.tracker.point_at(self._poses[-1][:3, 3])
        m = self.tracker.measure(self._poses[-1], duration_s)
        self.advance(m.elapsed_s, sample=False)
        return self.frames.pose_to_robot(m.pose)

    @property
    def command(self) -> Array:
        """The joints last commanded (the end of the current move), rad."""
        return self._command.copy()

    def advance(self, dt: float, *, sample: bool = True) -> list[StreamReading]:
        """Let ``dt`` seconds pass (whole cycles); the stream's samples that left the
        tracker meanwhile, in the robot base frame.  ``sample=False``: the arm moves, the
        stream is not read (it restarts, beam re-pointed, at the next sampled call) — to
        save the simulation's time where nobody reads it."""
        if sample and self._stale:
            self._stale = False
            self.stream = self._open_stream()
        n = max(0, math.ceil((dt - 1e-12) / self.cycle_s))
        if n:
            links = np.empty((n, self._command.size))
            for k in range(n):
                sp = self._queue.pop(0) if self._queue else self._command
                links[k] = self.arm.step(sp).link
            self._times.extend((self.cycles + k + 1) * self.cycle_s for k in range(n))
            self.cycles += n
            self._poses.extend(self._reflector(links))
            keep = int(_HISTORY_S / self.cycle_s) + 2
            if len(self._times) > keep:
                del self._times[:-keep], self._poses[:-keep]
            self.now = self.cycles * self.cycle_s
        if not sample:
            self._stale = True
            return []
        return [self._to_robot(s) for s in self.stream.advance(self.now)]

    def _to_robot(self, s: StreamSample) -> StreamReading:
        T = None if s.pose is None else self.frames.pose_to_robot(s.pose)
        return StreamReading(time_s=s.tracker_time_s, pose=T,
                             position=None if T is None else T[:3, 3].copy(), status=s.status)

    def command_joints(self, q: ArrayLike, duration_s: float = 0.0) -> float:
        """Start a synchronised PTP from the last command to ``q`` (readings, rad); the
        cell time at which the interpolation ends.  A PTP shorter than ``duration_s``
        runs as the quintic ``s(τ) = 10τ³ − 15τ⁴ + 6τ⁵`` over ``duration_s`` instead (rest
        to rest, continuous acceleration: slower than the limits allow)."""
        q = np.asarray(q, dtype=float)
        desc = self.arm.twin.description
        if q.shape != self._command.shape or not np.all(np.isfinite(q)):
            raise ValueError(f"expected {self._command.size} finite joint values, got {q!r}")
        if not bool(desc.within_limits(q)):
            raise ValueError("joint target outside the joint limits; the controller refuses it")
        start = self._queue[-1] if self._queue else self._command
        if float(np.max(np.abs(q - start))) < 1e-12:
            return self.now + len(self._queue) * self.cycle_s
        traj = plan(desc, start, [PTP(target=q)], self.joint_limits)
        if traj.duration >= duration_s:
            pts = np.asarray(traj.sample(traj.cycle_times(self.cycle_s)[1:], 0).q)
        else:
            tau = np.arange(1, math.ceil(duration_s / self.cycle_s) + 1) * self.cycle_s \
                / duration_s
            sig = np.clip(tau, 0.0, 1.0) ** 3 * (10 - 15 * tau + 6 * tau ** 2)
            pts = start + np.outer(sig, q - start)
        self._queue.extend(pts)
        self._queue.append(q.copy())
        self._command = q.copy()
        return self.now + len(self._queue) * self.cycle_s

    def robot_device(self) -> StreamingRobot:
        return StreamingRobot(self)

    def stream_device(self) -> RobotFrameStream:
        return RobotFrameStream(self)


class StreamingRobot:
    """The dynamic twin as a :class:`~plugcell.compensation.protocols.MovingRobot`."""

    def __init__(self, cell: DynamicCell) -> None:
        self.cell = cell

    def read_joints(self) -> Array:
        return self.cell.arm.measured

    def command_joints(self, q: Array, duration_s: float = 0.0) -> float:
        return self.cell.command_joints(q, duration_s)


class RobotFrameStream:
    """The tracker's stream as a :class:`~plugcell.compensation.protocols.PoseStream`."""

    def __init__(self, cell: DynamicCell) -> None:
        self.cell = cell

    def now(self) -> float:
        return self.cell.now

    def receive(self, wait_s: float) -> list[StreamReading]:
        return self.cell.advance(wait_s)


class StopAndGoRobot:
    """The thesis's robot on the dynamic twin: a move returns after the interpolation
    and a fixed settling wait (``settle_s``; ``small_settle_s`` for a corrective move
    below ``small_move_rad``), as ``TwinTiming`` counts it for the static twin."""

    def __init__(self, cell: DynamicCell, settle_s: float = 2.0, small_settle_s: float = 0.3,
                 small_move_rad: float = math.radians(0.1)) -> None:
        self.cell = cell
        self.settle_s, self.small_settle_s, self.small_move_rad = settle_s, small_settle_s, \
            small_move_rad
        self.last_interpolation_s = 0.0

    def read_joints(self) -> Array:
        return self.cell.arm.measured

    def move_joints(self, q: Array) -> float:
        t0 = self.cell.now
        travel = float(np.max(np.abs(np.asarray(q) - self.cell.command)))
        end = self.cell.command_joints(q)
        self.last_interpolation_s = end - t0
        settle = self.small_settle_s if travel < self.small_move_rad else self.settle_s
        self.cell.advance(end + settle - self.cell.now, sample=False)
        return self.cell.now - t0


class AveragingSensor:
    """A static reading from the stream: the mean pose of its samples over
    ``duration_s`` (positions averaged, rotations averaged on SO(3) about the first)."""

    def __init__(self, cell: DynamicCell) -> None:
        self.cell = cell

    def measure_pose(self, duration_s: float) -> Reading:
        t0 = self.cell.now
        got = [s for s in self.cell.advance(duration_s + self.cell.stream.spec.latency_s
                                            + 1.0 / self.cell.stream.rate_hz)
               if s.time_s >= t0]
        bad = [s.status for s in got if s.status != "ok"]
        if bad or not got:
            raise SensorError(f"the beam broke during the reading ({bad[0] if bad else 'none'})",
                              reason=bad[0] if bad else "line_of_sight")
        P = np.array([s.pose for s in got])
        R0 = P[0, :3, :3]
        w = np.mean([so3_log(R0.T @ R) for R in P[:, :3, :3]], axis=0)
        T = np.eye(4)
        T[:3, :3] = R0 @ so3_exp(w)
        T[:3, 3] = P[:, :3, 3].mean(axis=0)
        return Reading(position=T[:3, 3].copy(), pose=T, duration_s=duration_s,
                       elapsed_s=self.cell.now - t0)
