"""Tracked moves of a program streamed from the PC (``MOVE LINEAR TO p WITH TRACKING``).

The robot service's streaming link (:class:`~.stream_controller.StreamController`: the PC
plans every move and streams it as whole joint commands, RSI or EGM) gives a program's
:class:`~plugcell.pdl.interfaces.TrackedMotion`: :class:`TrackedMoves` plans the straight
move as any other (:meth:`~.planned_motion.PlannedMotion.plan_move`) and streams it with
the laser tracker's correction added every cycle (the drive's ``adjust`` hook):

1. the tracker's samples come straight from the tracker service's ``Stream Measurement``
   (:class:`ServiceTrackerFeed`: a process of the robot service on the tracker, whose
   data updates arrive in this process — not relayed by anyone) in the requester's robot
   frame (the BASE and PROBE the program set, eq. 7.2: the flange pose), each with its
   acquisition time, mapped to the PC's clock (:class:`~.tracking_clocks.OneWayClock`)
   and from it to the robot's (:class:`~.tracking_clocks.CycleClock`: the PC times the
   robot's cycles were handled);
2. :class:`~plugcell.compensation.tracking.TrackingLoop` answers the Cartesian offset
   ``o = [Δp; φ]`` (F0) on the planned TCP pose ``T_p(k)`` of the cycle.  Its model —
   what predicts the TCP from the joint feedback (the residual the tracker term
   corrects) and whose inverse is the model-based feed-forward — is the robot's
   **calibrated model** when the service was given one (``--param
   calibration=PARAMS.json``: ``IdentifiedModel`` with the controller's TCP in the
   identified flange frame, at the calibration's reference payload; with the
   calibration's learned residual layer when it has one: the hybrid model of
   ``plugcell compensate``), else the
   controller's nominal model (the tracker term then corrects all of the model's
   error); which one is said in the program's console at the move's end;
3. the offset, blended in (``w = unit_ramp`` over ``ramp_s``) while the robot still
   stands at the move's start for ``settle_s`` (the loop converges before the path
   begins, and the start does not jump), becomes joints through the controller's
   Jacobian at the planned joints, ``Δq = J_n(q_p(k))⁻¹ · w·o`` — first order, exact to
   µm for the millimetres a correction is — added to the streamed ``q_p(k)``.  The
   nominal Jacobian is the right one with either model: the offset is the controller's
   (``T_c = T_n(q*)``, the nominal pose of the joints ``q*`` at which the loop's model
   puts the tool on the target), so ``J_n⁻¹ o = q* − q_p`` to first order.  At the end
   the robot stays where the correction put it (absolute mode holds the offset); the
   next move is planned from the actual joints, so nothing jumps there either.

In real time the loop runs in a thread of its own beside the link (``_Worker``): each
cycle hands it the newest state and takes the newest offset it has computed, so the
loop's cost never makes the link's answer late; its rate bounds hold in the robot's time
(a loop call ``n`` robot cycles after the last steps ``n`` cycles' worth, its speed and
acceleration bounded: :class:`~plugcell.compensation.tracking.RateLimiter`).  A loop that
fell behind (a loaded PC) takes only the newest :data:`MAX_SAMPLES_PER_CYCLE` samples of a
cycle.  In
simulated time (``realtime=False``) each cycle runs the loop (with the link in its child
process, the child waits for each cycle's correction).

With a :class:`~.move_learning.MoveLearning` (``--param learned_dir=DIR``) each tracked
move of a program learns across the program's runs: its learned file is checked before
the robot moves (a file for another move fails it with the reason), its offset is the
loop's ``learned`` feed-forward at the path's time of each cycle's planned sample, and
the move's good tracker samples — placed on the path's time by the cycles' robot times
— judge and update it after the move (:mod:`.move_learning`).

The stream holds the shared tracker for the move's duration: another robot's requests
wait in the tracker's queue until its Stop Measurement (docs/tracker-service.md).  The
tracker's term fades out where its samples stop (a beam break) and the move goes on
with the model; a move whose stream cannot start fails with the tracker's reason.

The correction is computed in the service's process, where the tracker's samples arrive.
With the link's cycle loop in a thread of the service (``--param stream_process=false``)
the drive's hook runs in the link's thread and takes the worker's newest offset; with the
link in its child process (:class:`~.stream.process.LinkProcess`, the default) the same
hook runs in a thread of the service on each cycle the child publishes, and the child
adds the newest joint correction it was handed through shared memory
(:mod:`~.stream.adjusting`) — the same semantics across the process boundary.  Either
way the side that answers the robot does not hold the newest correction between two
computed cycles (the ``n`` cycles' step of a loop that fell behind would reach the robot
in one): each robot cycle it moves what it sends towards it at the loop's bounds as
joints (:func:`wire_limits`, the loop's own limiter), in the robot's time.

Faults: a beam break or a late tracker fades the tracker's term out (the loop's
``HoldWindow``, logged at the move's end) and the move goes on with the model; a
tracker whose stream *ends* during the move (the service killed: ``TRACKER lost``, or
its process failed) holds the loop for good with that reason, the move finishes on the
model — the term fades out at its bounded rate, the robot never jumps — and then fails
with the reason (the program stops at the move's line).  :attr:`TrackedMoves.last_record`
keeps every cycle's applied Cartesian offset for the figures (its speed and acceleration).
"""

from __future__ import annotations

import asyncio
import logging
import sys
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from plugcell.compensation.pose_model import IdentifiedModel, NominalModel, PoseModel
from plugcell.compensation.tracking import TrackerMeasurement, TrackingLoop, TrackingSettings
from plugcell.devices.robot.arm_model import matrix_from_position
from plugcell.devices.robot.live_tracking import (
    HoldSpan,
    LiveTracking,
    TrackingEnd,
    identity_now,
    live_tracking_of,
)
from plugcell.devices.robot.move_learning import MoveLearning, MoveSession, program_of
from plugcell.devices.robot.poses import pose_matrix
from plugcell.devices.robot.stream.adjusting import WireLimits, WirePeaks
from plugcell.devices.robot.stream.drive import samples as planned_samples
from plugcell.devices.robot.stream.process import LinkProcess
from plugcell.devices.robot.stream.source import CycleState
from plugcell.devices.robot.tracking_clocks import CycleClock, InOrder, OneWayClock
from plugcell.kinematics import forward
from plugcell.kinematics.jacobian import jacobian_from_fk
from plugcell.motion import LIN
from plugcell.motion.profile import unit_ramp
from plugcell.pdl.interfaces import MotionError
from plugcell.pdl.values import Position

Array = NDArray[np.float64]

__all__ = ["CycleClock", "OneWayClock", "ServiceTrackerFeed", "TrackedMoves", "TrackerFeed",
           "wire_limits"]

log = logging.getLogger("plugcell.devices.robot.tracked_moves")

#: Stream Measurement's request: 1 kHz, 10 samples a message.
STREAM_RATE_HZ, STREAM_BATCH = 1000, 10
#: How long a tracked move waits for the tracker (its queue: another robot may hold it).
START_TIMEOUT_S = 60.0
#: In simulated time, how long the link's child waits for a cycle's correction (s).
SIMULATED_WAIT_S = 5.0
#: Samples the loop takes in one cycle at most, the newest (a 1 kHz stream brings 4–14 a
#: 4 ms cycle): a loop that fell behind — a loaded PC — skips to the present instead of
#: working through a backlog that costs more each cycle (the estimator's update is per
#: sample) and that is too old to correct anything (it would hold on it anyway).
MAX_SAMPLES_PER_CYCLE = 50
_STATUS = {0: "ok", 1: "line_of_sight", 2: "tracking_speed", 3: "out_of_range", 4: "device"}


class TrackerFeed(Protocol):
    """The tracker's samples for one tracked move."""

    #: Why the samples stopped for good ("" while they flow): the stream ended.
    failure: str

    def start(self) -> None:
        """Subscribe; return when the samples flow (raise MotionError: why not)."""
        ...

    def poll(self, t_robot: float, pc_time: float) -> list[TrackerMeasurement]:
        """The samples that arrived since the last poll, on the robot's clock (its time
        ``t_robot`` now, at PC time ``pc_time``), TCP poses in F0."""
        ...

    def stop(self) -> None:
        """Unsubscribe (frees the tracker)."""
        ...


class ServiceTrackerFeed:
    """``Stream Measurement`` of a tracker service, opened by the robot service itself.

    Parameters
    ----------
    service : participant
        The robot service (its ``create_process``/``stop_process``; BASE and PROBE are
        the ones its program set: it is the requester).
    loop : asyncio.AbstractEventLoop
        The service's event loop (the feed is used from the program's thread).
    tracker : str
        The tracker service's name.
    tool : (4, 4) array
        The TCP in the flange frame (the controller's).
    """

    def __init__(self, service: Any, loop: asyncio.AbstractEventLoop, tracker: str,
                 tool: Array) -> None:
        self.service, self.loop, self.tracker, self.tool = service, loop, tracker, tool
        self._rows: deque[Array] = deque()
        self._lock = threading.Lock()
        self._call: Any = None
        self._task: asyncio.Task[None] | None = None
        self.tracker_clock, self.robot_clock = OneWayClock(), CycleClock()
        self._in_order = InOrder()
        self.failure = ""
        #: the ``seq`` of every data update received (each is in the tracker's journal)
        self.update_seqs: list[int] = []

    def _run(self, coro: Any, timeout: float, why: str) -> Any:
        try:
            return asyncio.run_coroutine_threadsafe(coro, self.loop).result(timeout)
        except TimeoutError:
            raise MotionError(f"{self.tracker} {why} within {timeout:g} s") from None

    def start(self) -> None:
        self._run(self._start(), START_TIMEOUT_S,
                  "Stream Measurement: no samples (the tracker held by another robot?)")

    async def _start(self) -> None:
        call = await self.service.create_process(
            self.tracker, "Stream Measurement", "tr2euler", [STREAM_RATE_HZ, STREAM_BATCH],
            timeout=3600.0)
        self._call = call
        first: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        self._task = asyncio.create_task(self._collect(call, first))
        await first

    async def _collect(self, call: Any, first: asyncio.Future[None]) -> None:
        from plugcell.framework import ProcessCall

        try:
            async for update in call:
                if update.data is None:
                    continue
                rows = np.atleast_2d(ProcessCall.array(update))
                with self._lock:
                    self._rows.extend(rows)
                    self.update_seqs.append(update.seq)
                if not first.done():
                    first.set_result(None)
            final = await call.result()
            self.failure = final.reason or f"the stream ended ({final.state.name})"
        except Exception as exc:  # the reason goes to the move
            self.failure = str(exc) or type(exc).__name__
        if not first.done():
            first.set_exception(MotionError(f"{self.tracker} Stream Measurement: "
                                            f"{self.failure}"))

    def poll(self, t_robot: float, pc_time: float) -> list[TrackerMeasurement]:
        """The samples taken before the cycle of robot time ``t_robot`` was handled at PC
        time ``pc_time``, on the robot's clock; later ones wait for a later cycle (placed
        between two cycles, a sample keeps its order whatever the robot's clock does, and
        :class:`~.tracking_clocks.InOrder` keeps it where the tracker's clock map moved
        back between two polls)."""
        self.robot_clock.see(t_robot, pc_time)
        with self._lock:
            rows, self._rows = list(self._rows), deque()
        out, later = [], []
        for r in rows:
            self.tracker_clock.see(float(r[0]), float(r[1]))
        for r in rows:
            pc = self.tracker_clock.pc(float(r[0]))
            if pc > pc_time:
                later.append(r)
                continue
            t = self._in_order(self.robot_clock.robot(pc))
            status = _STATUS.get(int(r[9]), "device")
            if status != "ok" or int(r[8]) != 1:
                out.append(TrackerMeasurement(t, None, bool(r[8]), status if status != "ok"
                                              else "no_orientation"))
                continue
            out.append(TrackerMeasurement(t, pose_matrix(r[2:8]) @ self.tool, True, "ok"))
        if later:
            with self._lock:
                self._rows.extendleft(reversed(later))
        return out

    def stop(self) -> None:
        if self._call is not None:
            self._run(self._stop(), 30.0, "Stop Measurement: the stream did not end")

    async def _stop(self) -> None:
        call, self._call = self._call, None
        if not call.done:
            stop = await self.service.stop_process(call)
            await stop.result()
        if self._task is not None:
            await self._task


class _Settled:
    """A trajectory preceded by ``before`` s of standing at its start (what the drive
    asks of it: ``setpoints``, ``duration``)."""

    def __init__(self, trajectory: Any, before: float) -> None:
        self.trajectory, self.before = trajectory, before
        self.duration = float(trajectory.duration) + before

    def setpoints(self, dt: float) -> tuple[Array, Array]:
        _, q = self.trajectory.setpoints(dt)
        q = np.vstack([np.repeat(q[:1], round(self.before / dt), 0), q])
        return np.arange(len(q)) * dt, q


class TrackedMoves:
    """``move_tracked`` for a :class:`~.planned_motion.PlannedMotion` whose drive streams
    (module docstring).

    Parameters
    ----------
    motion : PlannedMotion
        The program's arm (plans the move; its drive's ``follow`` takes ``adjust``).
    feeds : callable
        ``feeds(tracker) -> TrackerFeed`` for the tracker service named by the move.
    after : callable, optional
        Called with the move's duration when it has run (e.g. the clock's advance).
    settings : TrackingSettings, optional
        The loop's (default at the drive's cycle).
    ramp_s : float
        Blend of the correction in at the move's start (s).
    settle_s : float
        The robot stands at the start this long with the correction blending in (s).
    payload_kg : float, optional
        The payload (kg); default the calibration's reference payload (0 without one).
    realtime : bool
        True: the loop runs in a thread of its own and each cycle takes the newest offset
        it has (a real controller does not wait: the loop's cost must not make answers
        late); False: each cycle runs the loop (a controller in simulated time).
    calibration : CalibrationResult, optional
        The robot's calibration (:func:`~.calibration_file.read_calibration`): the loop's
        model (module docstring); ``None``: the controller's nominal model.
    calibration_name : str
        What to call it in the console (its file).
    say : callable, optional
        ``say(line)``: a line for the program's console (the model used, at the end).
    learning : MoveLearning, optional
        Learn each tracked move across the program's runs (:mod:`.move_learning`).
    program : callable, optional
        ``program() → (name, run)`` of the running program (None: none), the learned
        moves' keys; without it no move learns.
    live : callable, optional
        ``live() → LiveTracking`` (None: not now): publishes each move as it goes for the
        web UI's live plot (:mod:`.live_tracking`), from the service's event loop.
    """

    def __init__(self, motion: Any, feeds: Callable[[str], TrackerFeed], *,
                 after: Callable[[float], None] | None = None,
                 settings: TrackingSettings | None = None, ramp_s: float = 0.2,
                 settle_s: float = 0.5, payload_kg: float | None = None,
                 realtime: bool = True, calibration: Any = None,
                 calibration_name: str = "", say: Callable[[str], None] | None = None,
                 learning: MoveLearning | None = None,
                 program: Callable[[], tuple[str, int] | None] | None = None,
                 live: Callable[[], LiveTracking | None] | None = None) -> None:
        self.motion, self.feeds, self.after = motion, feeds, after
        #: ``live()``: the service's live display of its tracked moves (None: none)
        self.live, self._live = live, None
        self._live_count: tuple[tuple[str, int] | None, int] = (None, 0)
        #: the last move's computed cycles: ``(k, newest good tracker sample (t, x, y, z)
        #: robot s and m in F0, or None)``, beside :attr:`last_record`
        self.last_cycles: list[tuple[int, tuple[float, float, float, float] | None]] = []
        self.learning, self.program = learning, program
        #: the last move's learning (None: it did not learn) and its good tracker samples
        #: ``(t, x, y, z)`` (robot s, m in F0)
        self.last_session: MoveSession | None = None
        self.last_samples: list[tuple[float, float, float, float]] = []
        #: the last move's learned feed-forward on its cycles' path time (None: no learning)
        self._path_clock: _PathClock | None = None
        self._plan_p = np.zeros((0, 3))  # its planned TCP positions (m), one per sample
        self.settings, self.ramp_s = settings, ramp_s
        self.calibration, self.say = calibration, say
        self.payload_kg = float(payload_kg) if payload_kg is not None else \
            float(calibration.model.payload_ref_kg) if calibration is not None else 0.0
        #: which model the loop predicts with (the console's words)
        layer = getattr(calibration, "residual_model", None) is not None
        self.model_text = (f"the calibrated model ({calibration_name or 'given'}, "
                           f"{self.payload_kg:g} kg"
                           f"{', with its learned residual layer' if layer else ''})"
                           if calibration is not None else
                           "the nominal model (no calibration loaded)")
        self.settle_s, self.realtime = settle_s, realtime
        self.last_loop: TrackingLoop | None = None
        self.last_feed: TrackerFeed | None = None
        #: samples of the last move skipped by a loop that fell behind
        self.last_dropped = 0
        #: the last move's computed cycles: ``(t s, offset applied [Δp m; φ rad], loop
        #: state, its tracker term, the start's blend)`` (the rest of the offset is the
        #: model's part, zero for the nominal model but for its solver's tolerance)
        self.last_record: list[tuple[float, Array, str, Array, float]] = []
        #: the last move's bounds on the joint correction sent each robot cycle, and the
        #: largest step and change of step it sent (rad per joint: ``WirePeaks``)
        self.last_wire_limits: WireLimits | None = None
        self.last_wire_peaks: tuple[Array, Array] | None = None

    def move_tracked(self, pose: Position, tracker: str) -> float | None:
        """``MOVE LINEAR TO pose WITH TRACKING tracker``: plan, subscribe, stream with
        the correction, unsubscribe.  Returns None when ``after`` accounted for the
        move's time, else its duration (s)."""
        m = self.motion
        desc = m.description
        fk0 = forward(desc, None, np.asarray(desc.home, float), "nominal")
        tool = np.linalg.inv(fk0.flange) @ fk0.tcp
        with m._lock:
            traj = m.plan_move(LIN(target=matrix_from_position(pose), speed=m.speed))
            config = m.drive.config if isinstance(m.drive, LinkProcess) else m.drive.link.config
            cycle_s = config.cycle_s
            settings = self.settings or TrackingSettings(cycle_s=cycle_s)
            loop = self.last_loop = TrackingLoop(
                self.loop_model(tool), settings, payload_kg=self.payload_kg,
                controller=NominalModel(desc, tool))
            padded = _Settled(traj, self.settle_s)
            q_plan = planned_samples(padded, cycle_s)
            session = self.last_session = self._session(q_plan, traj, tool, cycle_s)
            feed = self.last_feed = self.feeds(tracker)
            feed.start()
            adjust, worker = self._adjust(loop, feed, cycle_s, q_plan, session)
            self._live_begin(tracker, cycle_s)
            # across the process boundary the child limits what it sends (the wire's
            # limits); in simulated time it waits for each cycle's correction (as the
            # in-process hook computes it in the cycle)
            wait: dict[str, Any] = {}
            if isinstance(m.drive, LinkProcess):
                wait["limits"] = self.last_wire_limits
                if not self.realtime:
                    wait["wait_s"] = SIMULATED_WAIT_S
            try:
                m.drive.follow(padded, adjust=adjust, **wait)
            finally:
                if worker is not None:
                    worker.close()
                failure = feed.failure  # before stop(): ending the stream is ours then
                if isinstance(m.drive, LinkProcess):
                    self.last_wire_peaks = m.drive.wire_peaks
                feed.stop()
                self._live_end(loop, failure)
            m.last = traj
        for w in loop.windows:
            log.warning("MOVE WITH TRACKING to %s: the model alone from %.3f s to %s (%s)",
                        tracker, w.start_s, "the end" if w.end_s is None else
                        f"{w.end_s:.3f} s", w.reason)
        st = loop.stats
        line = (f"MOVE WITH TRACKING {tracker}: {self.model_text}; tracker term on "
                f"{st.tracking_cycles} of {st.cycles} cycles, {len(loop.windows)} "
                f"window(s) on the model alone")
        log.info(line)
        if self.say is not None:
            self.say(line)
        if failure:
            raise MotionError(f"{tracker} stopped during the tracked move ({failure}): "
                              f"the move finished with the model alone ({self.model_text})")
        if session is not None:
            self._learn(session, len(q_plan), cycle_s)
        if self.after is None:
            return padded.duration
        self.after(padded.duration)
        return None

    def _live_begin(self, tracker: str, cycle_s: float) -> None:
        """Show the move live (:mod:`.live_tracking`), if the service does: its identity
        (the ``n``-th tracked move of the program's run) and what its cycles append.  A
        display: what fails here is logged, the move goes on."""
        self._live = None
        try:
            live = None if self.live is None else self.live()
            if live is None:
                return
            running = None if self.program is None else self.program()
            n = (self._live_count[1] if self._live_count[0] == running else 0) + 1
            self._live_count = (running, n)
            live.begin(identity_now(running, n, tracker), cycle_s,
                       round(self.settle_s / cycle_s) * cycle_s, self._plan_p,
                       self.last_record, self.last_cycles)
            self._live = live
        except Exception as exc:
            log.warning("MOVE WITH TRACKING: not shown live (%s: %s)", type(exc).__name__, exc)

    def _live_end(self, loop: TrackingLoop, failure: str) -> None:
        """The live move's last batch: the loop's counts and windows, why it failed (the
        tracker's failure, or the exception that ends the move)."""
        live, self._live = self._live, None
        if live is None:
            return
        error = sys.exc_info()[1]
        why = failure or ("" if error is None else str(error) or type(error).__name__)
        st = loop.stats
        try:
            live.end(TrackingEnd(st.cycles, st.tracking_cycles,
                                 [HoldSpan(w.start_s, w.end_s, w.reason[:512])
                                  for w in loop.windows[:1000]], self.model_text[:512],
                                 why[:512]))
        except Exception as exc:
            log.warning("MOVE WITH TRACKING: its end not shown live (%s: %s)",
                        type(exc).__name__, exc)

    def _session(self, q_plan: Array, traj: Any, tool: Array, cycle_s: float
                 ) -> MoveSession | None:
        """The move's learning (None: no learning, or no program runs), checked before the
        robot moves (MotionError: the learned file's reason)."""
        running = None if self.program is None else self.program()
        if self.learning is None or running is None:
            return None
        ends = forward(self.motion.description, None, q_plan[[0, -1]], "nominal").tcp
        return self.learning.begin(self.learning.key(*running), ends[0], ends[1],
                                   float(traj.duration), tool, self.payload_kg, cycle_s)

    def _learn(self, session: MoveSession, samples: int, cycle_s: float) -> None:
        """After the move: judge and learn from its tracker samples, say the verdict."""
        clock = self._path_clock
        rows = np.array(self.last_samples, dtype=float).reshape(-1, 4)
        if clock is None or len(clock.cycles) < 2:
            return
        inside, t = clock.path_times(rows[:, 0])
        line = session.finish(t[inside], rows[inside, 1:],
                              cycle_s * np.arange(samples) - clock.settle_s, self._plan_p, 0.0)
        if self.say is not None:
            self.say(line)

    def loop_model(self, tool: Array) -> PoseModel:
        """The loop's model (module docstring): the calibration's with the controller's
        TCP ``tool`` (flange frame, m) in its identified flange frame, or the nominal."""
        if self.calibration is None:
            return NominalModel(self.motion.description, tool)
        return IdentifiedModel(self.calibration.model, tool,
                               residual=getattr(self.calibration, "residual_model", None))

    def _adjust(self, loop: TrackingLoop, feed: TrackerFeed, cycle_s: float, q_plan: Array,
                session: MoveSession | None = None
                ) -> tuple[Callable[[CycleState, int, Array], Array], _Worker | None]:
        """The drive's hook: the loop's offset of the cycle as joints (``realtime``: the
        newest the worker has, the link's thread never waits for the loop).  The planned
        TCP poses and the controller's Jacobians at the move's samples ``q_plan`` (K+1, 6)
        are computed once, vectorised, before the move: a cycle only looks them up.  With
        a learning ``session`` its offset is the loop's feed-forward at the path's time of
        the cycle's planned sample (``k T`` less the settling), whatever the robot's clock
        did in between; the samples are placed on the path's time by the cycles'
        ``(robot time, k)`` after the move."""
        desc = self.motion.description
        ramp = unit_ramp(max(self.ramp_s, cycle_s))
        record = self.last_record = []
        kept = self.last_samples = []
        cycles = self.last_cycles = []
        self.last_dropped = 0
        clock = self._path_clock = None if session is None else _PathClock(
            session.feedforward(0.0), cycle_s, round(self.settle_s / cycle_s) * cycle_s)
        loop.learned = clock
        fk_plan = forward(desc, None, q_plan, "nominal")
        T_plan, J_plan = fk_plan.tcp, jacobian_from_fk(desc, fk_plan, "tcp")
        self._plan_p = T_plan[:, :3, 3]
        limits = self.last_wire_limits = wire_limits(loop.settings, J_plan)
        # the link in this process: its thread's hook limits what it sends (a link
        # process's child does: LinkProcess.follow's limits)
        wire = None if isinstance(self.motion.drive, LinkProcess) else limits.limiter()
        peaks = WirePeaks()
        self.last_wire_peaks = None if wire is None else (peaks.step, peaks.change)

        def planned(k: int, q_k: Array) -> tuple[Array, Array]:
            """``(T_p, J_n)`` at sample ``k`` (computed now if ``q_k`` is not the plan's)."""
            if 0 <= k < len(q_plan) and np.array_equal(q_k, q_plan[k]):
                return T_plan[k], J_plan[k]
            fk = forward(desc, None, q_k, "nominal")
            return fk.tcp, jacobian_from_fk(desc, fk, "tcp")

        def offset(state: CycleState, k: int, q_k: Array, pc: float) -> Array:
            samples = feed.poll(state.t, pc)
            if len(samples) > MAX_SAMPLES_PER_CYCLE:  # behind: the newest only (below)
                self.last_dropped += len(samples) - MAX_SAMPLES_PER_CYCLE
                samples = samples[-MAX_SAMPLES_PER_CYCLE:]
            loop.add(samples)
            cycles.append((k, _newest_good(samples)))
            if clock is not None:
                clock.see(state.t, k)
                kept.extend((m.time_s, *m.pose[:3, 3]) for m in samples
                            if m.pose is not None and m.status == "ok")
            if feed.failure and not record_held:
                loop.hold(f"tracker stopped: {feed.failure}")
                record_held.append(state.t)
            T_path = planned(k, q_k)[0]
            q_fb = state.robot.joints if state.robot.joints is not None else q_k
            out = loop.cycle(state.t, q_fb, T_path)
            blend = float(ramp.sample(k * cycle_s).s)
            o = blend * out.offset
            record.append((state.t, o, out.state, blend * out.tracker, blend))
            return o

        record_held: list[float] = []
        # in-process real time: a worker beside the link's thread; a link process has
        # its own (the pump thread of LinkProcess.follow)
        threaded = self.realtime and not isinstance(self.motion.drive, LinkProcess)
        worker = _Worker(offset) if threaded else None

        def adjust(state: CycleState, k: int, q_k: Array) -> Array:
            # when the packet was handled: the link process's stamp, or now (this is the
            # link's thread), for the robot's clock map
            pc = getattr(state.robot, "pc_time_s", None) or time.time()
            o = worker.offer(state, k, q_k, pc) if worker is not None else \
                offset(state, k, q_k, pc)
            dq = np.linalg.lstsq(planned(k, q_k)[1], o, rcond=None)[0] if np.any(o) else \
                np.zeros(len(q_k))
            if wire is None:
                return dq
            sent = peaks.add(wire.apply(dq))
            self.last_wire_peaks = (peaks.step, peaks.change)
            return sent

        return adjust, worker


def wire_limits(settings: TrackingSettings, jacobians: Array) -> WireLimits:
    """The bounds on the joint correction sent each robot cycle: the loop's own bounds
    on the offset's rate, as joints, along the move.

    The offset ``o`` moves at most at ``v_o = [v_c + v_l] × 3 + [ω_c] × 3`` (the tracker
    term's speed bounds, ``max_speed_m_s`` and ``max_speed_rad_s``, plus the lead's
    ``max_lead_speed_m_s`` when the loop leads; the same sums for the accelerations), and
    ``Δq = J⁻¹ o``, so per joint ``|Δq̇_i| ≤ Σ_j |J⁻¹_ij| v_o,j``::

        v_q,i = max_k Σ_j |J_k⁻¹|_ij v_o,j,     a_q,i = max_k Σ_j |J_k⁻¹|_ij a_o,j

    over the move's samples ``k``: what the loop computes every cycle passes the wire's
    limiter unchanged (but for its lag behind a moving target), what it computed for a
    cycle ``n`` after its last (a loaded machine) reaches the robot at these rates.

    Parameters
    ----------
    settings : TrackingSettings
        The loop's.
    jacobians : ndarray, shape (K+1, 6, 6)
        The controller's TCP Jacobians ``J_k`` at the move's samples (m/rad, rad/rad).

    Returns
    -------
    WireLimits
        At the loop's cycle, rad/s and rad/s² per joint.
    """
    s = settings
    lead = s.lead_s > 0
    v = np.r_[[s.max_speed_m_s + lead * s.max_lead_speed_m_s] * 3, [s.max_speed_rad_s] * 3]
    a = np.r_[[s.max_accel_m_s2 + lead * s.max_lead_accel_m_s2] * 3,
              [s.max_accel_rad_s2] * 3]
    inv = np.abs(np.linalg.pinv(np.asarray(jacobians, dtype=float)))
    return WireLimits(s.cycle_s, (inv @ v).max(axis=0), (inv @ a).max(axis=0))


def _newest_good(samples: list[TrackerMeasurement]
                 ) -> tuple[float, float, float, float] | None:
    """``(t, x, y, z)`` of the newest sample with a pose (robot s, m), None if none."""
    for m in reversed(samples):
        if m.pose is not None and m.status == "ok":
            return (m.time_s, *m.pose[:3, 3].tolist())
    return None


class _PathClock:
    """A learned move's cycles on the path's time (s from the motion's start): cycle ``k``
    commands the planned sample ``k``, at path time ``k T − settle_s``.

    Called with a robot time (as :class:`TrackingLoop` calls its ``learned``) it answers
    the learned offset ``u`` at the path time of the cycle last seen; after the move
    :meth:`path_times` places the tracker's samples on the path's time by the cycles'
    ``(robot time, k)`` — whatever the robot's clock did between them.
    """

    def __init__(self, learned: Callable[[float], Array], cycle_s: float,
                 settle_s: float) -> None:
        self.learned, self.cycle_s, self.settle_s = learned, cycle_s, settle_s
        self.k = 0
        #: ``(robot t, k)`` of each computed cycle
        self.cycles: list[tuple[float, int]] = []

    def see(self, t: float, k: int) -> None:
        """Cycle ``k`` at robot time ``t`` is being computed."""
        self.k = k
        self.cycles.append((t, k))

    def __call__(self, t: float) -> Array:
        return self.learned(self.k * self.cycle_s - self.settle_s)

    def path_times(self, robot_t: Array) -> tuple[NDArray[np.bool_], Array]:
        """The samples within the cycles seen (mask) and their path times (s)."""
        km = np.array(self.cycles, dtype=float).reshape(-1, 2)
        km = km[np.concatenate([[True], np.diff(km[:, 0]) > 0])]
        inside = (robot_t >= km[0, 0]) & (robot_t <= km[-1, 0])
        return inside, np.interp(robot_t, km[:, 0], km[:, 1]) * self.cycle_s - self.settle_s


class _Worker:
    """Runs the loop beside the link (real time): :meth:`offer` hands it the newest cycle
    and returns the newest offset it has computed (zeros before the first), at once."""

    def __init__(self, offset: Callable[[CycleState, int, Array, float], Array]) -> None:
        self.offset = offset
        self._latest: tuple[CycleState, int, Array, float] | None = None
        self._result = np.zeros(6)
        self._cond = threading.Condition()
        self._stop = False
        self.failure: BaseException | None = None
        self.cycles = 0
        self._thread = threading.Thread(target=self._run, name="tracking-loop", daemon=True)
        self._thread.start()

    def offer(self, state: CycleState, k: int, q_k: Array, pc: float) -> Array:
        with self._cond:
            if self.failure is not None:
                raise MotionError(f"the tracking loop failed: {self.failure}")
            self._latest = (state, k, q_k, pc)
            self._cond.notify()
            return self._result

    def _run(self) -> None:
        while True:
            with self._cond:
                while self._latest is None and not self._stop:
                    self._cond.wait()
                if self._stop:
                    return
                job, self._latest = self._latest, None
            try:
                out = self.offset(*job)
            except Exception as exc:  # the next offer fails the move with it
                with self._cond:
                    self.failure = exc
                return
            with self._cond:
                self._result = out
                self.cycles += 1

    def close(self) -> None:
        with self._cond:
            self._stop = True
            self._cond.notify()
        self._thread.join(5.0)


def tracked_moves_for(controller: Any) -> Callable[[Position, str], float | None]:
    """The ``move_tracked`` of a streaming robot link (the hook of
    :class:`~.stream_controller.StreamController`): the tracker's samples through the link's
    robot service (``controller.handler.host``, in its event loop), the move's time on the
    program's clock, each move shown live on the service's bus (:mod:`.live_tracking`)."""

    def feeds(tracker: str) -> TrackerFeed:
        loop = controller.event_loop
        if loop is None:
            raise MotionError("not connected")
        desc = controller.description
        fk = forward(desc, None, np.asarray(desc.home, float), "nominal")
        # the robot device's host holds the participant that opens the tracker's stream
        return ServiceTrackerFeed(controller.handler.host.participant, loop, tracker,
                                  np.linalg.inv(fk.flange) @ fk.tcp)

    return TrackedMoves(controller.motion, feeds, after=controller.clock.advance,
                        calibration=controller.calibration,
                        calibration_name=controller.calibration_name,
                        say=controller.say, learning=controller.move_learning,
                        program=program_of(controller),
                        live=live_tracking_of(lambda: controller.handler.host,
                                              lambda: controller.event_loop)).move_tracked
