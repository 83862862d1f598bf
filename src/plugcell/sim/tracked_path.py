"""A tracked path on the twin, in one process and simulated time (issue 38 §2, §4).

:class:`TrackedCell` is the Smart H4 twin with a laser tracker: calibrated once from its
own campaign (model 5, :class:`~plugcell.calibration.identify.Calibrator` on
:func:`~plugcell.sim.twin.campaign.measure_poses`), then :meth:`TrackedCell.run` runs one
path, cycle by cycle, through the same pieces a real cell uses:

* the controller: :class:`~plugcell.sim.controller.rsi_robot.RsiRobot` running its own
  path (``path=``; its ``$TOOL`` the identified PROBE) on the dynamic twin, driven by
  :meth:`~plugcell.sim.controller.rsi_robot.RsiRobot.packet` /
  :meth:`~plugcell.sim.controller.rsi_robot.RsiRobot.advance` instead of its socket;
* the link's side: the ``<Rob>`` bytes parsed by the RSI codec, the correction source
  (:class:`~plugcell.devices.robot.rsi.tracking.TrackingSource`), the link's limits
  (:class:`~plugcell.devices.robot.stream.limits.OffsetLimiter`), the ``<Sen>`` bytes
  encoded and parsed back — everything but the UDP datagrams;
* the tracker: :class:`~plugcell.sim.twin.tracker_stream.TrackerStream` at 1 kHz on the
  true reflector (interpolated between cycles), its samples delivered when they leave the
  tracker (plus a fault's extra delay), mapped to the robot's clock with the given map and
  into F0 with the identified BASE and PROBE.

Time: the robot's clock is ``t = k T`` (IPOC); the twin's true time is the same. The
result (:class:`PathRun`) holds per cycle the true reflector pose (in F0 as identified:
``BASE_id⁻¹ · T_true,tracker``, the frame the taught path and the tracker's corrections
live in) and the commanded
path's pose at the same time, the offset sent and the loop's state, and the tracker's
samples (for clock alignment).  Deterministic for a given seed.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from plugcell.calibration.identify import Calibrator
from plugcell.compensation import IdentifiedModel, nominal_joints
from plugcell.compensation.tracking import (
    HoldWindow,
    IterativeLearning,
    TrackerMeasurement,
    TrackingLoop,
    TrackingSettings,
    TrackingStats,
)
from plugcell.devices.robot.rsi.codec import encode_sen, parse_rob, parse_sen
from plugcell.devices.robot.rsi.config import RsiConfig
from plugcell.devices.robot.rsi.tracking import TrackingSource
from plugcell.devices.robot.stream.limits import OffsetLimiter
from plugcell.devices.robot.stream.source import Correction, CycleState
from plugcell.kinematics import forward
from plugcell.kinematics.rotations import zyz_to_matrix
from plugcell.kinematics.transforms import invert
from plugcell.motion import CIRC, LIN, CartesianLimits, JointLimits, Trajectory, plan
from plugcell.sim.controller.rsi_robot import RsiRobot
from plugcell.sim.twin.campaign import measure_poses, working_volume_joints
from plugcell.sim.twin.dynamics import DynamicTwin
from plugcell.sim.twin.robot import RobotTwin
from plugcell.sim.twin.scenario import TwinScenario
from plugcell.sim.twin.tracker import LaserTracker
from plugcell.sim.twin.tracker_stream import StreamSample, StreamSpec, TrackerStream

Array = NDArray[np.float64]

__all__ = ["Fault", "LogFeed", "PathRun", "TrackedCell", "learn", "path_moves"]

CYCLE = 0.004
#: Start of the paths: the tool point (the T-MAC) at x, y, z (m) in the volume of the
#: calibration campaign and of thesis 8.3's lines, the flange facing the tracker (ZYZ
#: 0/90/0, as 8.3); the line runs 1 m along y, the circle (300 mm) lies in the plane z =
#: const.
START_M = (1.6, -0.5, 1.1)
FLANGE_ZYZ_DEG = (0.0, 90.0, 0.0)
JOINTS = JointLimits(np.radians([100, 90, 90, 170, 120, 190]),
                     np.radians([300, 250, 300, 500, 500, 700]),
                     np.radians([2000, 1500, 2000, 4000, 4000, 5000]))
ACCELERATION, JERK = 2.0, 20.0
#: The program waits this long at RSI_ON (the offset blends in), and after the path.
LEAD_IN_S, SETTLE_S, RAMP_S = 0.8, 0.4, 0.5


@dataclass(frozen=True)
class Fault:
    """A tracker fault during the path (times from the path's start, s).

    Attributes
    ----------
    kind : {"beam_break", "late", "killed"}
        ``beam_break``: the line of sight is blocked for ``duration_s``; ``late``: every
        sample reaches the loop ``delay_s`` late for ``duration_s``; ``killed``: the
        tracker service dies (no samples from ``start_s`` on; the client learns it
        ``delay_s`` later and holds the loop with the reason).
    """

    kind: str
    start_s: float
    duration_s: float = 0.5
    delay_s: float = 0.08

    def __post_init__(self) -> None:
        if self.kind not in ("beam_break", "late", "killed"):
            raise ValueError(f"fault kind {self.kind!r}: expected beam_break, late or killed")


@dataclass
class PathRun:
    """What one run recorded (SI, F0; arrays per robot cycle after the first)."""

    t: Array
    true_pose: Array       # (N, 4, 4) true reflector
    path_pose: Array       # (N, 4, 4) the commanded path (no correction) at the same time
    offset: Array          # (N, 6) sent (KUKA x, y, z, A, B, C)
    weight: Array          # (N,) tracker term weight
    state: list[str]
    motion: tuple[float, float]   # robot time the path starts and ends
    windows: list[HoldWindow]
    stats: TrackingStats | None
    samples: list[StreamSample] = field(default_factory=list)
    joint_feedback: Array = field(default_factory=lambda: np.zeros((0, 6)))
    joint_command: Array = field(default_factory=lambda: np.zeros((0, 6)))
    clamped: int = 0
    #: the tracker's samples as they reached the loop (robot clock, F0), every mode
    measurements: list[TrackerMeasurement] = field(default_factory=list)


def path_moves(T0: Array, shape: str, speed_m_s: float,
               size_m: float | None = None) -> tuple[list, CartesianLimits]:
    """The program's moves from ``T0``: a line along y (``size_m`` long, default 1 m), or a
    circle in the horizontal plane (two CIRCs blended; diameter ``size_m``, default
    0.3 m) through ``T0`` with its centre on +y, at ``speed_m_s``."""
    cart = CartesianLimits(speed_m_s, ACCELERATION, JERK, 1.0, 4.0, 40.0)
    p0 = T0[:3, 3]

    def at(dp: Array) -> Array:
        T = T0.copy()
        T[:3, 3] = p0 + dp
        return T

    if shape == "line":
        return [LIN(target=at(np.array([0.0, size_m or 1.0, 0.0])))], cart
    if shape == "circle":
        r = (size_m or 0.3) / 2
        return [CIRC(via=at(np.array([r, r, 0.0]))[:3, 3], target=at(np.array([0.0, 2 * r, 0.0])),
                     blend=0.02),
                CIRC(via=at(np.array([-r, r, 0.0]))[:3, 3], target=T0.copy())], cart
    raise ValueError(f"path shape {shape!r}: expected 'line' or 'circle'")


class TrackedCell:
    """The Smart H4 twin, a tracker and a calibration from a separate campaign.

    Parameters
    ----------
    seed : int
        The twin's scenario seed.
    payload_kg : float
        Payload (kg), carried in the campaign and on the paths.
    calibration_poses : int
        Poses of the campaign (model 5).
    tracker_seed : int or None
        The tracker's seed — its systematic error field, the campaign's and the paths'
        (default: ``seed``, as before).
    """

    def __init__(self, seed: int = 0, payload_kg: float = 36.0,
                 calibration_poses: int = 150, tracker_seed: int | None = None) -> None:
        self.seed, self.payload_kg = seed, payload_kg
        self.tracker_seed = seed if tracker_seed is None else tracker_seed
        self.scenario = TwinScenario(robot="smart_h4", seed=seed, payload_kg=payload_kg,
                                     tracker_seed=self.tracker_seed)
        self.twin = RobotTwin(self.scenario)
        self.tracker = LaserTracker(seed=self.tracker_seed)
        desc = self.twin.description
        rng = np.random.default_rng(seed + 1)
        q = working_volume_joints(desc, self.twin.reveal_truth().profile, calibration_poses,
                                  rng)
        ms, _ = measure_poses(self.twin, self.tracker, q)
        self.calibration = Calibrator(desc, 5).fit(ms)
        self.model = IdentifiedModel(self.calibration.model)
        self.desc_tool = dataclasses.replace(desc, tool=np.array(self.model.tool))
        T0 = np.eye(4)
        T0[:3, :3] = zyz_to_matrix(*np.radians(FLANGE_ZYZ_DEG)) @ self.model.tool[:3, :3]
        T0[:3, 3] = START_M
        q, ok, why = nominal_joints(self.model, T0)
        if not ok[0]:
            raise ValueError(f"the paths' start is out of reach: {why[0]}")
        self.q0 = q[0]

    def plan(self, shape: str, speed_mm_s: float, size_m: float | None = None) -> Trajectory:
        """The controller's program (:func:`path_moves`), planned on its nominal model
        (tool = the identified PROBE)."""
        T0 = forward(self.desc_tool, None, self.q0, "nominal").tcp
        moves, cart = path_moves(T0, shape, speed_mm_s * 1e-3, size_m)
        return plan(self.desc_tool, self.q0, moves, JOINTS, cart)

    def run(self, trajectory: Trajectory, mode: str, *,
            settings: TrackingSettings | None = None, six_dof: bool = True,
            clock: Callable[[float], float] | None = None, faults: tuple[Fault, ...] = (),
            stream_spec: StreamSpec | None = None, learning: IterativeLearning | None = None,
            stream_seed: int | None = None) -> PathRun:
        """Run ``trajectory`` once: ``mode`` ``"nominal"`` (no correction), ``"model"``
        (lead + model-based feed-forward) or ``"tracking"`` (+ the tracker term).

        ``clock`` maps the tracker's clock to the robot's (default: the identity, exact
        only for a tracker whose clock is the robot's); ``stream_spec`` the tracker's
        dynamics (its clock offset and drift among them); ``learning``: add its learned
        offset (:meth:`IterativeLearning.feedforward` from the motion's start) to the
        target (modes ``model`` and ``tracking``; learn from the run with :func:`learn`);
        ``stream_seed`` the tracker's noise (default: the cell's seed — give each run
        of a learning its own, the noise of a real tracker is fresh every run).
        """
        if mode not in ("nominal", "model", "tracking"):
            raise ValueError(f"mode {mode!r}: expected nominal, model or tracking")
        if learning is not None and mode == "nominal":
            raise ValueError("a learned offset needs the correction loop: mode model or "
                             "tracking, not nominal")
        sim = _Simulation(self, trajectory, mode, settings or TrackingSettings(), six_dof,
                          clock or (lambda x: x), faults, stream_spec or StreamSpec(),
                          learning, self.seed if stream_seed is None else stream_seed)
        return sim.run()


def learn(learning: IterativeLearning, run: PathRun) -> Array:
    """One learning update from a run of its path: the good tracker samples the loop
    received (:attr:`PathRun.measurements`) against the commanded path
    (:meth:`IterativeLearning.update`); the error on the grid (G, 3), m."""
    good = [m for m in run.measurements if m.ok]
    ts = np.array([m.time_s for m in good])
    ps = np.array([m.pose[:3, 3] for m in good]).reshape(-1, 3)
    return learning.update(ts, ps, run.t, run.path_pose[:, :3, 3], run.motion[0])


class _Simulation:
    """One run's state (TrackedCell.run)."""

    def __init__(self, cell: TrackedCell, traj: Trajectory, mode: str,
                 settings: TrackingSettings, six_dof: bool, clock: Callable[[float], float],
                 faults: tuple[Fault, ...], spec: StreamSpec,
                 learning: IterativeLearning | None, stream_seed: int) -> None:
        self.cell, self.mode, self.clock, self.faults = cell, mode, clock, faults
        self.arm = DynamicTwin(cell.twin, q0=cell.q0)
        self.config = RsiConfig(robot_host="127.0.0.1", listen_host="127.0.0.1",
                                listen_port=0, correction="cartesian", mode="absolute",
                                frame="base", timeout_packets=10_000)
        self.robot = RsiRobot(self.arm, self.config, path=traj, tool=cell.model.tool,
                              path_delay_s=LEAD_IN_S)
        self.t_start = round(LEAD_IN_S / CYCLE) * CYCLE
        self.t_end = self.t_start + traj.duration
        self.limiter = OffsetLimiter(self.config.limits, CYCLE, ("X", "Y", "Z", "A", "B", "C"),
                                     (("mm", 1e-3),) * 3 + (("deg", math.pi / 180),) * 3)
        self.loop = TrackingLoop(cell.model, settings, payload_kg=cell.payload_kg,
                                 tracking=mode == "tracking",
                                 learned=None if learning is None else
                                 learning.feedforward(self.t_start))
        self.source = TrackingSource(self.loop, ramp=RAMP_S)
        truth = cell.twin.reveal_truth()
        self.true_probe = truth.probe
        self.true_base = cell.twin.true_base()
        # F0 is the robot base frame *as identified*: the cell's one physical frame is the
        # tracker's, and the identified BASE maps it to the robot (the true base frame
        # differs from it by what the calibration cannot tell apart from BASE)
        self.to_f0 = invert(cell.model.base) @ self.true_base
        self.base_inv = invert(cell.model.base)
        self.probe_inv = invert(cell.model.probe)
        self._times = [0.0]
        self._poses = [cell.twin.true_reflector_in_tracker()]
        cell.tracker.point_at(self._poses[0][:3, 3])
        self.stream = TrackerStream(cell.tracker, self._target, 1000.0, six_dof=six_dof,
                                    spec=spec, blocked=self._blocked, seed=stream_seed)
        self.pending: list[StreamSample] = []
        self._delivered: list[TrackerMeasurement] = []
        #: without the tracker term the samples do not steer the run: the true poses are
        #: computed at its end, vectorised, and the stream replays the same cycles then
        self.live = mode == "tracking"
        self._samples: list[StreamSample] = []
        self.killed_noticed = False

    # -- the tracker's world ----------------------------------------------------------
    def _target(self, t: float) -> Array:
        """True reflector pose in the tracker frame at true time ``t`` (linear between
        the cycles; the newest cycle's pose a little beyond it)."""
        k = min(max(int(t / CYCLE), 0), len(self._times) - 1)
        T = self._poses[k].copy()
        if k + 1 < len(self._times):
            a = (t - self._times[k]) / CYCLE
            T[:3, 3] = (1 - a) * self._poses[k][:3, 3] + a * self._poses[k + 1][:3, 3]
        return T

    def _blocked(self, t: float) -> bool:
        return any(f.kind == "beam_break" and
                   self.t_start + f.start_s <= t < self.t_start + f.start_s + f.duration_s
                   for f in self.faults)

    def _deliver(self, t: float) -> list[TrackerMeasurement]:
        """Samples that reach the loop by robot time ``t`` (faults applied)."""
        new = self.stream.advance(t)
        self._samples.extend(new)
        self.pending.extend(new)
        out, keep = [], []
        for s in self.pending:
            extra, dead = 0.0, False
            for f in self.faults:
                t0 = self.t_start + f.start_s
                if f.kind == "late" and t0 <= s.available_s < t0 + f.duration_s:
                    extra = f.delay_s
                if f.kind == "killed" and s.available_s >= t0:
                    dead = True
            if dead:
                continue
            if s.available_s + extra <= t:
                out.append(self._measurement(s))
            else:
                keep.append(s)
        self.pending = keep
        return out

    def _measurement(self, s: StreamSample) -> TrackerMeasurement:
        if s.status != "ok" or s.pose is None:
            return TrackerMeasurement(self.clock(s.tracker_time_s), None, s.six_dof, s.status)
        T = self.base_inv @ s.pose @ self.probe_inv @ self.cell.model.tool
        return TrackerMeasurement(self.clock(s.tracker_time_s), T, s.six_dof, "ok")

    # -- the cycles --------------------------------------------------------------------
    def run(self) -> PathRun:
        rec: dict[str, list] = {k: [] for k in ("t", "true", "path", "off", "w", "state",
                                                "q", "cmd")}
        finish_at = self.t_end + SETTLE_S
        k, clamped = 0, 0
        live = self.live
        links: list[Array] = []
        while True:
            t = k * CYCLE
            state = parse_rob(self.robot.packet())
            if live:
                meas = self._deliver(t)
                self._delivered.extend(meas)
                self.source.add(meas)
                self._notice_kill(t)
            if self.mode != "nominal" and t >= finish_at:
                self.source.finish()
            cs = CycleState(robot=state, offset=self.limiter.offset.copy(), session=1,
                            cycle=k, t=t)
            corr = self.source.correction(cs) if self.mode != "nominal" else None
            target = np.zeros(6) if corr is None else np.asarray(corr.offset, float)
            lim = self.limiter.apply(target)
            clamped += lim.clamped
            answer = parse_sen(encode_sen(state.ipoc, "cartesian", lim.offset),
                               "cartesian").correction
            self.robot.advance(answer)
            path_k = self.robot.path_poses[self.robot.path_index]
            k += 1
            self._times.append(k * CYCLE)
            if live:
                flange = self.cell.twin.true_flange()
                self._poses.append(self.true_base @ flange @ self.true_probe)
                rec["true"].append(self.to_f0 @ flange @ self.true_probe)
            else:
                links.append(self.arm.link)
            out = self.source.last
            rec["t"].append(k * CYCLE)
            rec["path"].append(path_k)
            rec["off"].append(lim.offset)
            rec["w"].append(0.0 if out is None else out.weight)
            rec["state"].append("nominal" if out is None else out.state)
            rec["q"].append(state.joints)
            rec["cmd"].append(state.joints_setpoint)
            if (self.mode == "nominal" and t >= finish_at) or self.source.ended() or \
                    t > finish_at + 3.0:
                break
        if not live:
            rec["true"] = self._replay(np.array(links))
        return PathRun(np.array(rec["t"]), np.array(rec["true"]), np.array(rec["path"]),
                       np.array(rec["off"]), np.array(rec["w"]), rec["state"],
                       (self.t_start, self.t_end), self.loop.windows,
                       self.loop.stats if self.mode == "tracking" else None, self._samples,
                       np.array(rec["q"]), np.array(rec["cmd"]), clamped, self._delivered)

    def _replay(self, links: Array) -> Array:
        """The true poses of the cycles from their link angles (vectorised, the static
        physics :meth:`RobotTwin.true_flange` applies each cycle) and the tracker's
        stream over them, cycle by cycle as a live run delivers it; the true poses in F0.
        Exact: a sample only sees the poses up to its acquisition time."""
        flanges = self.arm.true_flanges(links) @ self.true_probe
        self._poses.extend(self.true_base @ flanges)
        for k in range(len(links)):
            self._delivered.extend(self._deliver(k * CYCLE))
        return self.to_f0 @ flanges

    def _notice_kill(self, t: float) -> None:
        for f in self.faults:
            if f.kind == "killed" and not self.killed_noticed and \
                    t >= self.t_start + f.start_s + f.delay_s:
                self.source.hold("tracker stopped: the tracker service ended mid-path")
                self.killed_noticed = True


class LogFeed:
    """A correction source for :class:`~plugcell.devices.robot.rsi.link.RsiLink` that feeds
    a :class:`~plugcell.devices.robot.rsi.tracking.TrackingSource` with the twin's true
    reflector before each answer — a perfect tracker with one cycle of age, for runs over
    the real UDP seam in real time (the robot's thread steps the arm; the reflector comes
    from its log, ``RsiRobot(record=True)``, so no state is shared between the threads).

    Parameters
    ----------
    source : TrackingSource
        What answers.
    arm : DynamicTwin
        The robot's arm (its static physics turns logged link angles into poses).
    """

    def __init__(self, source: TrackingSource, arm: DynamicTwin) -> None:
        self.source, self.arm = source, arm
        self.robot: RsiRobot | None = None
        self._probe = arm.twin.reveal_truth().probe
        self._seen = 0
        self._ipoc0: int | None = None
        #: per answered cycle: wall seconds from the samples' hand-over to the answer
        self.compute_s: list[float] = []

    def __call__(self, state: CycleState) -> Correction:
        t0 = time.perf_counter()
        if self.robot is not None:
            log = self.robot.stats().log
            new, self._seen = log[self._seen:], len(log)
            if log and self._ipoc0 is None:
                self._ipoc0 = log[0][0]
            if new:
                links = np.array([entry[2] for entry in new])
                T = self.arm.true_flanges(links) @ self._probe
                self.source.add(TrackerMeasurement((entry[0] - self._ipoc0) / 1000.0 + CYCLE,
                                                   Ti) for entry, Ti in zip(new, T, strict=True))
        corr = self.source.correction(state)
        self.compute_s.append(time.perf_counter() - t0)
        return corr
