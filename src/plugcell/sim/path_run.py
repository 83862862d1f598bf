"""A path run on the twin with the laser tracker in the loop (``plugcell path run``).

The pieces are the ones a real cell has, over the same seams:

* the **robot** is the twin's KUKA RSI side (:class:`~.controller.rsi_robot.RsiRobot`):
  a simulated controller that runs the path by itself — the path file's points as LIN
  moves (:mod:`plugcell.motion`, the robot's nominal model) — and takes relative-to-path
  Cartesian corrections (``RKorr``, absolute mode, base frame) from plugcell's
  :class:`~plugcell.devices.robot.rsi.link.RsiLink` over UDP on the loopback, every 4 ms;
* the **tracker** is the streaming model (:class:`~.twin.tracker_stream.TrackerStream`,
  1 kHz, latency, noise, servo lag, beam breaks) aimed at the twin's T-MAC — its *true*
  pose, from the dynamic twin's link angles through the static physics;
* the **loop** is :class:`~plugcell.compensation.tracking.TrackingLoop` (the estimator
  and the law: model feed-forward, tracker term, fades at beam breaks, hold windows) as
  the link's correction source (:class:`~plugcell.devices.robot.rsi.tracking.
  TrackingSource`: blended in and out at the path's ends), held to the link's limits
  (clamped: the robot never jumps).  A segment whose ``tracking`` is 0 runs with the
  model alone (the tracker term fades out), as does the whole path with
  ``tracking=False`` — the comparison.

The robot's clock is the controller's IPOC (``t = k·T``); the tracker's clock is the
simulation's (no offset, no drift: the alignment of clocks is measured elsewhere,
:mod:`plugcell.metrology.timing`).  BASE and PROBE are the twin's true ones (a cell whose
frames are calibrated).  Accuracy is judged against the twin's true TCP
(:func:`plugcell.metrology.path_accuracy.segment_accuracy`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from plugcell.calibration.result import CalibrationResult
from plugcell.compensation.pose_model import IdentifiedModel, NominalModel, PoseModel
from plugcell.compensation.tracking import (
    HoldWindow,
    TrackerMeasurement,
    TrackingLoop,
    TrackingSettings,
)
from plugcell.devices.robot.rsi import RsiConfig, RsiLink
from plugcell.devices.robot.rsi.config import CorrectionLimits
from plugcell.devices.robot.rsi.tracking import TrackingSource
from plugcell.devices.robot.stream.source import Correction, CycleState
from plugcell.io.path_files import PathFile
from plugcell.kinematics import RobotDescription, forward, inverse
from plugcell.metrology.path_accuracy import PathAccuracy, segment_accuracy
from plugcell.motion import LIN, CartesianLimits, JointLimits, Trajectory, TrajectoryError, plan
from plugcell.sim.controller.rsi_robot import RsiRobot
from plugcell.sim.twin.dynamics import DynamicTwin
from plugcell.sim.twin.scenario import TwinScenario
from plugcell.sim.twin.tracker import LaserTracker
from plugcell.sim.twin.tracker_stream import StreamSpec, TrackerStream

Array = NDArray[np.float64]

__all__ = ["PathRun", "PathRunOptions", "plan_path", "run_path"]

#: Joint limits of a 200 kg-class robot (benchmarks/twin_path_deviation.py).
JOINTS = JointLimits(np.radians([100, 90, 90, 170, 120, 190]),
                     np.radians([300, 250, 300, 500, 500, 700]),
                     np.radians([2000, 1500, 2000, 4000, 4000, 5000]))
#: TCP acceleration (m/s²) and jerk (m/s³) of the LIN moves.
ACCELERATION, JERK = 2.0, 20.0


@dataclass(frozen=True)
class PathRunOptions:
    """How a path is run on the twin.

    Attributes
    ----------
    robot, payload_kg, seed : the twin (:class:`~.twin.scenario.TwinScenario`).
    tracking : bool
        The tracker corrects (False: it only measures, for comparison).
    rate_hz : float
        The tracker's output rate.
    six_dof : bool
        T-MAC (position and orientation) or SMR (position only: the measured TCP takes
        the orientation the loop's model predicts at the joint feedback).
    beam_breaks : sequence of (start s, duration s)
        The line of sight is interrupted then (times from the path's start).
    tracker_lost_at : float, optional
        The tracker stops sending at this time from the path's start (a tracker gone).
    silence_s : float
        After this long without any sample the tracker is taken as gone: the correction
        ramps out and the run ends with the reason.
    settle_s, rest_s : float
        The robot stands still before the path (the loop converges) and after it.
    ramp_s : float
        Blend in and out of the correction.
    max_offset_mm, max_speed_mm_s : float
        The link's limits of the correction (clamped).
    timeout_packets : int
        The controller's ``Timeout`` (late answers before RSI stops).
    settings : TrackingSettings, optional
        The loop's settings (default: :class:`TrackingSettings` at the stream's cycle).
    stream_seed : int, optional
        The seed of the tracker's measurement noise (default: ``seed``): the same robot
        and instrument, fresh noise — each run of a repeated path its own, as a real
        tracker's noise is fresh every run.
    """

    robot: str = "smart_h4"
    payload_kg: float = 36.0
    seed: int = 0
    tracking: bool = True
    rate_hz: float = 1000.0
    six_dof: bool = True
    beam_breaks: tuple[tuple[float, float], ...] = ()
    tracker_lost_at: float | None = None
    silence_s: float = 0.5
    settle_s: float = 0.5
    rest_s: float = 0.3
    ramp_s: float = 0.2
    max_offset_mm: float = 5.0
    max_speed_mm_s: float = 50.0
    timeout_packets: int = 1000
    settings: TrackingSettings | None = None
    stream_seed: int | None = None

    def __post_init__(self) -> None:
        if not (np.isfinite(self.rate_hz) and 1.0 <= self.rate_hz <= 1000.0):
            raise ValueError(f"rate {self.rate_hz:g} Hz outside 1…1000 Hz (the tracker's "
                             "output rate)")
        if not (np.isfinite(self.payload_kg) and self.payload_kg >= 0):
            raise ValueError(f"payload must be ≥ 0 kg, got {self.payload_kg:g}")
        if self.tracker_lost_at is not None and not (np.isfinite(self.tracker_lost_at)
                                                     and self.tracker_lost_at >= 0):
            raise ValueError(f"tracker lost at {self.tracker_lost_at:g} s: expected a time "
                             "≥ 0 s after the path's start")


@dataclass
class PathRun:
    """What a run gave: accuracy, windows, traces (robot clock, path start at 0)."""

    accuracy: PathAccuracy
    windows: list[HoldWindow]
    ended: str
    duration_s: float
    cycles: int
    late: int
    clamped: int
    samples_ok: int
    samples_lost: int
    traces: dict[str, Array] = field(repr=False, default_factory=dict)
    #: The path's motion (s) and the robot time it started at (s, the robot's clock).
    motion_s: float = 0.0
    start_s: float = 0.0


def plan_path(desc: RobotDescription, path: PathFile) -> tuple[Array, Trajectory]:
    """The start joints (nominal IK of the first point) and the LIN moves through the rest.

    Without angles in the file every point keeps the start's orientation, which is the
    TCP's at the robot's home pose.  Each segment's speed is a fraction of the fastest.

    Raises
    ------
    ValueError
        The first point out of reach, or a move the planner refuses (with its reason).
    """
    home = np.asarray(desc.home, dtype=float)
    poses = np.array(path.poses, copy=True)
    if not path.oriented:
        poses[:, :3, :3] = forward(desc, None, home, "nominal").tcp[:3, :3]
    ik = inverse(desc, None, poses[0], seed=home, target="tcp", raise_errors=False)
    if not ik.converged:
        raise ValueError(f"line {path.lines[0]}: the first point is out of the robot's reach")
    top = float(np.max(path.speeds))
    moves = [LIN(target=poses[i + 1], speed=float(path.speeds[i] / top),
                 line=int(path.lines[i + 1])) for i in range(path.n_segments)]
    cart = CartesianLimits(top, ACCELERATION, JERK, 1.0, 4.0, 40.0)
    try:
        return ik.q, plan(desc, ik.q, moves, JOINTS, cart)
    except TrajectoryError as exc:
        raise ValueError(f"line {path.lines[0]}: {exc}" if "the start" in str(exc)
                         else str(exc)) from None


class _Padded:
    """The controller's program: stand ``before`` s, run the trajectory, stand ``after`` s
    (what :class:`RsiRobot` asks of a path: its setpoints at the cycle)."""

    def __init__(self, trajectory: Trajectory, before: float, after: float) -> None:
        self.trajectory, self.before, self.after = trajectory, before, after

    def setpoints(self, dt: float) -> tuple[Array, Array]:
        _, q = self.trajectory.setpoints(dt)
        pre, post = round(self.before / dt), round(self.after / dt)
        q = np.vstack([np.repeat(q[:1], pre, 0), q, np.repeat(q[-1:], post, 0)])
        return np.arange(len(q)) * dt, q


class _TruthTwin(DynamicTwin):
    """The dynamic twin that keeps its T-MAC's true pose (tracker frame) after every cycle
    for the tracker model to see — simulators only.

    The static physics costs ~9 ms a pose, too much for every 4 ms cycle; the model's
    error ``E(q) = F_true(q) · F_nom(q)⁻¹`` varies slowly with the pose, so it is computed
    in one batch at every ``every``-th cycle of the program and the flange taken as
    ``E(q_k) · F_nom(link)`` of the link angles now (µm off for the millimetres a
    correction moves the arm).  :meth:`true_tcp` gives the exact poses afterwards.
    """

    def __init__(self, scenario: TwinScenario, q0: Array, program: Array,
                 every: int = 10) -> None:
        super().__init__(scenario, q0=q0)
        truth = self.twin.reveal_truth()
        self.base, self.probe = truth.base, truth.probe
        self._desc = self.twin.description
        ref = program[::every]
        self._every = every
        self._E = self.true_flanges(ref) @ np.linalg.inv(
            forward(self._desc, None, ref, "nominal").flange)
        self.links: list[Array] = [self.link]
        self.truth: list[Array] = [self._reflector(self.link, 0)]

    def _reflector(self, link: Array, k: int) -> Array:
        E = self._E[min(round(k / self._every), len(self._E) - 1)]
        flange = E @ forward(self._desc, None, link, "nominal").flange
        return self.base @ flange @ self.probe

    def step(self, command: object):  # type: ignore[override]
        state = super().step(command)  # type: ignore[arg-type]
        self.links.append(state.link)
        self.truth.append(self._reflector(state.link, self.cycle))
        return state

    def true_tcp(self, tool: Array, n: int) -> Array:
        """The exact true TCP poses (base frame) after cycles ``1…n`` (n, 4, 4)."""
        return self.true_flanges(np.array(self.links[1:n + 1])) @ tool

    def reflector_at(self, t: float, cycle_s: float) -> Array:
        """The T-MAC's true pose at ``t`` (s, robot clock), linear between cycles."""
        truth = self.truth
        x = min(max(t / cycle_s, 0.0), len(truth) - 1.0)
        i = min(int(x), len(truth) - 2) if len(truth) > 1 else 0
        w = x - i
        if len(truth) == 1 or w <= 0.0:
            return truth[i]
        T = truth[i].copy()
        T[:3, 3] = (1 - w) * truth[i][:3, 3] + w * truth[i + 1][:3, 3]
        return T


class _Frames:
    """A tracker sample (reflector pose, tracker frame) as the TCP's pose in F0, eq. (7.2)
    with the tool: ``T_tcp = BASE⁻¹ · T · PROBE⁻¹ · tool``.

    A 3-DoF sample (SMR: a position, its rotation the identity) takes the reflector's
    orientation the loop's model predicts at the joint feedback ``q``:
    ``R = rot(model(q) · tool⁻¹ · PROBE)`` — the tracker sees no rotation, so the TCP's
    position is the reflector's moved by the lever arm turned as the model says.
    """

    def __init__(self, base: Array, probe: Array, tool: Array, model: PoseModel,
                 payload_kg: float) -> None:
        self.base_inv = np.linalg.inv(base)
        self.to_tcp = np.linalg.inv(probe) @ tool
        self.tool_to_probe = np.linalg.inv(tool) @ probe
        self.model, self.payload_kg = model, payload_kg
        self._q: Array | None = None
        self._R = np.eye(3)

    def tcp(self, pose: Array, six_dof: bool, q: Array | None) -> Array | None:
        """The TCP (4×4, F0, m) of a sample's ``pose``; None for a 3-DoF sample before any
        joint feedback."""
        T = self.base_inv @ pose
        if not six_dof:
            if q is None:
                return None
            if self._q is None or not np.array_equal(q, self._q):
                self._q = q.copy()
                T_model = self.model.evaluate(q, self.payload_kg)[0][0]
                self._R = (T_model @ self.tool_to_probe)[:3, :3]
            T[:3, :3] = self._R
        return T @ self.to_tcp


class _Cycle:
    """The link's source each cycle: new tracker samples into the loop, then its offset."""

    def __init__(self, arm: _TruthTwin, robot_T: float, ipoc0: int, ipoc_step: int,
                 stream: TrackerStream, source: TrackingSource, frames: _Frames,
                 tracked: NDArray[np.bool_], options: PathRunOptions, t_end: float) -> None:
        self.arm, self.T, self.ipoc0, self.ipoc_step = arm, robot_T, ipoc0, ipoc_step
        self.stream, self.source, self.frames, self.tracked = stream, source, frames, tracked
        self.options, self.t_end = options, t_end
        self.ended = ""
        self.t_heard = -np.inf
        self.measured: list[tuple[float, Array]] = []
        self.states: dict[int, str] = {}

    def _samples(self, t: float, q: Array | None) -> list[TrackerMeasurement]:
        lost = self.options.tracker_lost_at
        if lost is not None and t >= self.options.settle_s + lost:
            return []  # the tracker is gone: nothing arrives
        out = []
        for s in self.stream.advance(t):
            tcp = None if s.pose is None else self.frames.tcp(s.pose, s.six_dof, q)
            if tcp is not None:
                self.measured.append((s.true_time_s, tcp[:3, 3].copy()))
            out.append(TrackerMeasurement(s.true_time_s, tcp, s.six_dof, s.status))
        return out

    def correction(self, state: CycleState) -> Correction:
        k = (state.robot.ipoc - self.ipoc0) // self.ipoc_step
        t = k * self.T
        joints = state.robot.joints
        samples = self._samples(t, None if joints is None else np.asarray(joints, float))
        if samples or self.t_heard == -np.inf:  # silence counts from the first cycle
            self.t_heard = t
        self.source.add(samples)
        loop = self.source.loop
        loop.tracking = self.options.tracking and bool(self.tracked[min(k, len(self.tracked) - 1)])
        silent = t - self.t_heard
        if not self.ended and silent > self.options.silence_s:
            self.ended = (f"tracker silent for {silent:.3f} s (more than "
                          f"{self.options.silence_s:g} s): the path went on with the model "
                          "alone")
            self.source.hold("tracker silent")
        if t >= self.t_end:
            self.source.finish()
        corr = self.source.correction(state)
        self.states[k] = loop.state if loop.tracking else \
            "model" if not self.options.tracking else "off"
        return corr


def _setup(path: PathFile, options: PathRunOptions, T: float
           ) -> tuple[_TruthTwin, Trajectory, _Padded, Array]:
    scenario = TwinScenario(robot=options.robot, seed=options.seed,
                            payload_kg=options.payload_kg)
    desc = DynamicTwin(scenario).twin.description
    q0, trajectory = plan_path(desc, path)
    program = _Padded(trajectory, options.settle_s, options.rest_s)
    arm = _TruthTwin(scenario, q0, program.setpoints(T)[1])
    fk = forward(desc, None, q0, "nominal")
    return arm, trajectory, program, np.linalg.inv(fk.flange) @ fk.tcp


def _link_config(options: PathRunOptions) -> RsiConfig:
    mm = 1e-3
    deg = np.pi / 180
    limits = CorrectionLimits((options.max_speed_mm_s * mm * 0.004,) * 3 + (0.02 * deg,) * 3,
                              (options.max_offset_mm * mm,) * 3 + (1.0 * deg,) * 3,
                              (options.max_speed_mm_s * mm,) * 3 + (5.0 * deg,) * 3, "clamp")
    return RsiConfig(robot_host="127.0.0.1", listen_host="127.0.0.1", listen_port=0,
                     correction="cartesian", mode="absolute", frame="base",
                     timeout_packets=options.timeout_packets, limits=limits)


def _blocked(options: PathRunOptions) -> Callable[[float], bool]:
    breaks = [(options.settle_s + t0, options.settle_s + t0 + d)
              for t0, d in options.beam_breaks]
    return lambda t: any(a <= t < b for a, b in breaks)


def run_path(path: PathFile, options: PathRunOptions | None = None,
             progress: Callable[[float], None] | None = None,
             calibration: CalibrationResult | None = None,
             learned: Callable[[float], ArrayLike] | None = None) -> PathRun:
    """Run ``path`` on the twin with the tracker in the loop (module docstring).

    Parameters
    ----------
    path : PathFile
        The path (``plugcell.io.path_files``).
    options : PathRunOptions, optional
    progress : callable, optional
        Called with the fraction of the run done (0…1), about every 0.1 s.
    calibration : CalibrationResult, optional
        The robot's calibration (``plugcell calibrate``'s PARAMS.json): the loop's model
        is :class:`~plugcell.compensation.pose_model.IdentifiedModel` (with its residual
        layer if any) at the path's TCP, and the tracker's samples come into F0 through
        its identified BASE and PROBE.  Without: the controller's nominal model and the
        twin's true BASE and PROBE (the tracker term then corrects all of the model's
        millimetres).
    learned : callable, optional
        ``u(t)``: a learned offset (3,) (m, F0) at robot time ``t`` added to the loop's
        target (:class:`~plugcell.compensation.tracking.TrackingLoop`'s ``learned``; the
        motion starts at robot time ``options.settle_s``), e.g.
        :meth:`~plugcell.compensation.tracking.IterativeLearning.feedforward`.

    Returns
    -------
    PathRun
        Accuracy per segment and window, the windows, the traces (path start at 0 s).

    Raises
    ------
    ValueError
        A path the planner refuses, or a calibration of another robot, with the reason.
    """
    o = options or PathRunOptions()
    config = _link_config(o)
    T = config.cycle_s
    arm, trajectory, program, tool = _setup(path, o, T)
    times, q_prog = program.setpoints(T)
    moves = trajectory.sample(np.clip(times - o.settle_s, 0.0, None), 0).move
    on_path = (times >= o.settle_s) & (times <= o.settle_s + trajectory.duration)
    tracked = np.where(on_path, path.tracking[np.clip(moves, 0, path.n_segments - 1)], False)
    tracked[times < o.settle_s] = True  # converge before the path starts
    tracker = LaserTracker(seed=o.seed)
    tracker.point_at(arm.reflector_at(0.0, T)[:3, 3])
    stream = TrackerStream(tracker, lambda t: arm.reflector_at(t, T), o.rate_hz,
                           six_dof=o.six_dof, spec=StreamSpec(), blocked=_blocked(o),
                           seed=o.seed if o.stream_seed is None else o.stream_seed)
    model, frames = _model(arm, tool, o, calibration)
    settings = o.settings or TrackingSettings(cycle_s=T, max_correction_m=o.max_offset_mm * 1e-3)
    loop = TrackingLoop(model, settings, payload_kg=o.payload_kg, tracking=o.tracking,
                        controller=NominalModel(arm.twin.description, tool),  # its $TOOL
                        learned=learned)
    source = TrackingSource(loop, ramp=o.ramp_s)
    t_end = o.settle_s + trajectory.duration
    with RsiLink(config) as link:
        robot = RsiRobot(arm, dataclasses.replace(config, listen_port=link.address[1]),
                         path=program, record=True, lockstep_s=1.0)  # type: ignore[arg-type]
        cycle = _Cycle(arm, T, 1_000_000, config.ipoc_step, stream, source, frames, tracked, o,
                       t_end)
        robot.start()
        ended = _follow(link, robot, cycle, times[-1], progress)
        robot.stop()
        stats = link.stats()
    run = _result(path, o, arm, robot, loop, cycle, q_prog, tracked, moves, on_path, tool,
                  ended or cycle.ended, stats)
    run.motion_s, run.start_s = float(trajectory.duration), float(o.settle_s)
    return run


def _model(arm: _TruthTwin, tool: Array, o: PathRunOptions,
           calibration: CalibrationResult | None) -> tuple[PoseModel, _Frames]:
    """The loop's model and the tracker's frames: the calibration's, or the nominal model
    with the twin's true BASE and PROBE."""
    if calibration is None:
        model: PoseModel = NominalModel(arm.twin.description, tool)
        return model, _Frames(arm.base, arm.probe, tool, model, o.payload_kg)
    em = calibration.model
    robot = em.structure.source.name
    if robot != arm.twin.description.name:
        raise ValueError(f"the calibration is of the robot {robot!r}, the path runs on "
                         f"{arm.twin.description.name!r}")
    # the TCP in the identified flange frame: placed by its offset from the T-MAC (a
    # property of the end effector, measured on it; the twin's is exact), as the flange
    # frame itself is only known up to what the identified PROBE absorbed
    tool_id = em.probe() @ np.linalg.inv(arm.probe) @ tool
    model = IdentifiedModel(em, tool_id, residual=calibration.residual_model)
    return model, _Frames(model.base, model.probe, tool_id, model, o.payload_kg)


def _follow(link: RsiLink, robot: RsiRobot, cycle: _Cycle, total_s: float,
            progress: Callable[[float], None] | None) -> str:
    """Stream the offset until it has ramped out and the robot's program has ended; the
    reason if the stream failed ('' otherwise)."""
    import concurrent.futures

    # simulated time: the run takes as long as the machine needs; this only catches a hang
    timeout = 60.0 + 0.25 * total_s / link.config.cycle_s
    with concurrent.futures.ThreadPoolExecutor(1) as pool:
        done = pool.submit(link.follow, cycle.correction, cycle.source.ended, timeout)
        while not done.done():
            if progress is not None:
                progress(min(robot.stats().cycles * link.config.cycle_s / total_s, 1.0))
            concurrent.futures.wait([done], timeout=0.1)
        try:
            done.result()
        except (TimeoutError, RuntimeError) as exc:
            return str(exc)
    if not link.wait(lambda lk: robot.path_done or robot.stopped is not None, timeout):
        return f"the robot's program did not end within {timeout:g} s"
    if progress is not None:
        progress(1.0)
    return robot.stopped or ""


def _states(cycle: _Cycle, n: int) -> NDArray[np.str_]:
    """Each cycle's state: the loop's (``tracking``, ``holding``, ``acquiring``,
    ``model``), ``off`` where the segment asks for no tracking or no correction ran."""
    return np.array([cycle.states.get(k, "off") for k in range(n)], dtype=str)


def _result(path: PathFile, o: PathRunOptions, arm: _TruthTwin, robot: RsiRobot,
            loop: TrackingLoop, cycle: _Cycle, q_prog: Array, tracked: NDArray[np.bool_],
            moves: NDArray[np.intp], on_path: NDArray[np.bool_], tool: Array, ended: str,
            stats: object) -> PathRun:
    T = robot.config.cycle_s
    log = robot.stats().log
    n = min(len(log), len(q_prog), len(arm.truth) - 1)
    desc = arm.twin.description
    # the true TCP in the cell's F0: the robot base frame as the cell knows it, through
    # the BASE it measures with (the identified one with a calibration: the paths are
    # where the tracker puts them)
    actual = (cycle.frames.base_inv @ arm.base @ arm.true_tcp(tool, n))[:, :3, 3]
    commanded = forward(desc, None, q_prog[:n], "nominal").tcp[:, :3, 3]
    offsets = np.array([entry[3] for entry in log[:n]])
    segment = np.where(on_path[:n], moves[:n], -1)
    states = _states(cycle, n)
    points = path.poses[:, :3, 3]
    accuracy = segment_accuracy(actual, commanded, points, segment, states, T)
    t = np.arange(n) * T - o.settle_s
    measured = np.array([[ts - o.settle_s, *x] for ts, x in cycle.measured]) \
        if cycle.measured else np.zeros((0, 4))
    traces = {"t": t, "commanded": commanded, "corrected": commanded + offsets[:, :3],
              "actual": actual, "measured": measured, "segment": segment,
              "state": states}
    windows = [HoldWindow(w.start_s - o.settle_s,
                          None if w.end_s is None else w.end_s - o.settle_s, w.reason)
               for w in loop.windows]
    return PathRun(accuracy, windows, ended, float(n * T), n, robot.stats().delay,
                   int(getattr(stats, "clamped", 0)), loop.stats.samples_used,
                   loop.stats.samples_bad, traces)

