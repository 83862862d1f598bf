"""The simulated laser tracker driver: the foundation's tracker model aimed at the sim world.

A :class:`~plugcell.devices.tracker.driver.TrackerDriver` for ``plugcell serve
tracker`` (the default).  The instrument is :class:`plugcell.sim.twin.tracker.LaserTracker`
(noise, capture radius, ADM, simulated clock; docs/tracker-model.md); the reflectors
are wherever the simulated world says they are (``sim/world.py``: robot
controllers publish their T-MAC's true pose, fixed SMRs are published once).

* ``point(p)`` — the thesis's *Move*: slew the beam through ``p``; the reflector
  nearest to the new beam axis is acquired if it lies within the capture radius
  (10 mm, thesis 8.4.3), else :class:`BeamNotLockedError` names the nearest one and how
  far off the axis it is.
* ``measure(t)`` — measure the reflector on the beam with the model (6-DOF for a
  T-MAC, 3-DOF for an SMR).  A reflector the beam is locked on that has moved since
  (its robot moved) was followed continuously, as a tracker follows a moving target
  (2.3.1.1: up to 5 m/s) — the model is told with ``track``.

* ``stream(f)`` — the real-time output: :class:`~plugcell.sim.twin.tracker_stream.TrackerStream`
  (beam servo, noise at rate, latency, breaks) follows the locked reflector as the
  world publishes it (a robot that publishes its pose every interface cycle is seen
  moving), paced by the PC's clock; ``blocked`` (a callable of the stream's time)
  injects line-of-sight breaks.

The world is *asked* (a Zenoh query of every reflector's queryable) at each Move and
each measurement, so the instrument sees it as it is at that instant: a robot that
publishes its pose and then asks for a measurement is always measured where it is,
a reflector mounted on it (an SMR in its flange) is placed on that same pose
(:func:`~plugcell.sim.world.placed`), and a reflector whose publisher is gone is gone.
Time is simulated; with ``time_scale`` > 0 each call also sleeps ``elapsed ×
time_scale`` of real time.
"""

from __future__ import annotations

import asyncio
import threading
import time
from collections.abc import AsyncIterator, Callable
from typing import ClassVar

import msgspec
import numpy as np

from plugcell.devices.tracker.driver import (
    Array,
    BeamNotLockedError,
    TrackerDriverError,
    TrackerReading,
    TrackerSample,
    TrackerStatus,
)
from plugcell.framework.bus import Bus
from plugcell.sim.beam_breaks import blocked as stream_blocked
from plugcell.sim.beam_breaks import parse_beam_breaks
from plugcell.sim.twin import tracker as twin
from plugcell.sim.twin.tracker import LaserTracker
from plugcell.sim.twin.tracker_stream import StreamSpec, TrackerStream
from plugcell.sim.world import ReflectorState, WorldView, placed

__all__ = ["SimulatedTrackerDriver"]

_DECODER = msgspec.msgpack.Decoder(ReflectorState)

#: Speed at which a locked reflector is assumed to have moved between two looks at the
#: world (m/s) — a robot's TCP in a calibration or correction move; well below the
#: 5 m/s the tracker follows.
FOLLOW_SPEED_M_S = 1.0


def _beam_message(exc: twin.BeamNotLockedError) -> str:
    """The model's message in the service's vocabulary (Move, not point_at)."""
    return (
        str(exc)
        .replace("point the beam at it (point_at) first", "send Move first")
        .replace("; call point_at", "; send Move first")
    )

#: Move or a measurement with nothing to lock on: the simulated world's reflectors are
#: the T-MACs of the simulated robots (their robot services publish them), so say so.
NO_REFLECTOR = ("beam not locked: no reflector in the cell to lock on — the simulated "
                "reflectors are the simulated robots' T-MACs: start a robot in this cell "
                "first (plugcell serve robot --param sim=true)")


#: Most samples :meth:`SimulatedTrackerDriver.stream` hands over between two turns of the
#: event loop (20 ms of a 1 kHz stream): a stream that fell behind — its process was
#: starved of CPU — catches up a few samples at a time and the service's other work runs
#: between them; computing the whole backlog at once took longer the longer it was, on
#: a machine too slow to make a sample a millisecond without end.
STREAM_SAMPLES_PER_TURN = 20


class SimulatedTrackerDriver:
    """The tracker model behind the TrackerDriver seam (module docstring).

    ``bus``: the service's transport (its cell's world is looked at through it), given
    here or by :meth:`attach` before :meth:`connect` (``plugcell serve tracker`` makes the
    driver before the service: the tracker attaches the bus of the service it runs in);
    ``tracker``: the instrument model (default ``LaserTracker(seed=seed)``);
    ``time_scale``: real seconds slept per simulated second (0: none);
    ``query_timeout_s``: bound of one look at the world;
    ``beam_breaks``: line-of-sight breaks of every stream, ``START:DURATION[,…]`` in
    seconds from the stream's start (:mod:`plugcell.sim.beam_breaks`; a fault to inject:
    ``plugcell serve tracker --param beam_breaks=1.0:0.5``), unless ``blocked`` is given.
    """

    info = "simulated Leica AT901-MR with T-MAC (plugcell.sim.twin.tracker model)"
    params: ClassVar[dict[str, type]] = {"seed": int, "time_scale": float,
                                         "beam_breaks": str}
    """What ``plugcell serve tracker --param K=V`` sets."""

    def __init__(
        self,
        bus: Bus | None = None,
        *,
        tracker: LaserTracker | None = None,
        seed: int = 0,
        time_scale: float = 0.0,
        query_timeout_s: float = 2.0,
        stream_spec: StreamSpec | None = None,
        blocked: Callable[[float], bool] | None = None,
        beam_breaks: str = "",
    ) -> None:
        if not (time_scale >= 0 and np.isfinite(time_scale)):
            raise ValueError(f"time_scale must be >= 0, got {time_scale}")
        if beam_breaks and blocked is None:
            try:
                breaks = parse_beam_breaks(beam_breaks.split(","))
            except ValueError as exc:
                raise ValueError(f"beam_breaks {exc}") from None
            blocked = stream_blocked(breaks)
        self.bus = bus
        self.model = tracker if tracker is not None else LaserTracker(seed=seed)
        self.time_scale = float(time_scale)
        self.query_timeout_s = query_timeout_s
        self._lock = threading.Lock()  # guards the model; never held across a wait
        self._target: str | None = None
        self._target_position: Array | None = None
        self._lost = ""
        """The reflector the lock was lost on when it vanished ("" if none): until the
        next Move, measurements fail with its name."""
        self._busy_s = 0.0
        self.stream_spec = stream_spec if stream_spec is not None else StreamSpec(
            clock_drift_ppm=20.0)  # a crystal's ±20 ppm (estimate)
        self.blocked = blocked
        """Line-of-sight breaks of streams, ``blocked(t)`` with ``t`` the stream's time (s)."""
        self._streams = 0

    def attach(self, bus: Bus) -> None:
        """Look at the cell's world through ``bus`` (the tracker service's)."""
        self.bus = bus

    @property
    def _world_bus(self) -> Bus:
        if self.bus is None:
            raise TrackerDriverError("the simulated tracker sees no cell: attach a bus first",
                                     "device")
        return self.bus

    @property
    def max_stream_rate_hz(self) -> float:
        return self.stream_spec.max_rate_hz

    # -- TrackerDriver --------------------------------------------------------------------

    async def connect(self) -> None:
        await self._world()  # fails early if the session is unusable

    async def disconnect(self) -> None:
        self._target = None

    async def point(self, position_m: Array) -> float:
        world = await self._world()
        with self._lock:
            try:
                dt = self.model.point_at(np.asarray(position_m, dtype=float))
            except ValueError as exc:
                raise TrackerDriverError(f"cannot aim the beam: {exc}") from None
            self._busy_s += dt
            self._target, self._target_position, self._lost = None, None, ""
            nearest = self._nearest(world)
            radius = self.model.spec.capture_radius_m
            if nearest is None:
                raise BeamNotLockedError(NO_REFLECTOR, reason="capture")
            offset, state = nearest
            if offset > radius:
                raise BeamNotLockedError(
                    f"beam not locked: no reflector within the {radius * 1e3:.1f} mm capture "
                    f"radius of the beam (nearest: {state.name}, {offset * 1e3:.1f} mm off the "
                    "axis); check BASE, PROBE and the robot pose given to Move",
                    reason="capture",
                )
            self._target = state.name
            self._target_position = state.matrix()[:3, 3]
        await self._sleep(dt)
        return dt

    async def measure(self, duration_s: float) -> TrackerReading:
        world = await self._world()
        with self._lock:
            if self._target is not None and self._target not in world:
                gone, self._target = self._target, None  # e.g. its robot was switched off
                self._lost = gone
                raise BeamNotLockedError(
                    f"beam not locked: the reflector {gone} the beam was locked on is gone; "
                    "send Move again", reason="line_of_sight")
            if self._lost:
                raise BeamNotLockedError(
                    f"beam not locked: the reflector {self._lost} the beam was locked on is "
                    "gone; send Move again", reason="line_of_sight")
            self._follow(world)
            if self.model.aim_point is None:
                raise BeamNotLockedError(
                    "beam not locked: the beam has not been pointed at a reflector; "
                    "send Move first",
                    reason="not_pointed",
                )
            nearest = self._nearest(world)
            if nearest is None:
                raise BeamNotLockedError(NO_REFLECTOR, reason="capture")
            state = nearest[1]
            six_dof = state.kind == "tmac"
            pose = state.matrix()
            try:
                m = self.model.measure(pose if six_dof else pose[:3, 3], duration_s,
                                       mode="6dof" if six_dof else "3dof")
            except twin.BeamNotLockedError as exc:
                self._target = None
                raise BeamNotLockedError(_beam_message(exc), reason=exc.reason) from None
            except twin.TargetOutOfRangeError as exc:
                raise TrackerDriverError(str(exc), reason="out_of_range") from None
            except (twin.TrackerError, ValueError) as exc:
                raise TrackerDriverError(f"{state.name}: {exc}") from None
            self._target, self._target_position = state.name, pose[:3, 3]
            self._busy_s += m.elapsed_s
        if m.pose is not None:
            measured = m.pose
        else:
            measured = np.eye(4)
            measured[:3, 3] = m.position
        await self._sleep(m.elapsed_s)
        return TrackerReading(pose=measured, six_dof=six_dof, duration_s=m.duration_s,
                              elapsed_s=m.elapsed_s, timestamp_s=m.timestamp_s)

    async def stream(self, rate_hz: float) -> AsyncIterator[TrackerSample]:
        spec = self.stream_spec
        if not (np.isfinite(rate_hz) and 1.0 <= rate_hz <= spec.max_rate_hz):
            raise ValueError(f"stream rate {rate_hz} Hz outside 1…{spec.max_rate_hz:g} Hz")
        seen = await asyncio.to_thread(self._query)  # as published: mounts kept
        world = placed(seen)
        with self._lock:
            self._follow(world)
            name = self._target
            if name is None or name not in world:
                raise BeamNotLockedError("beam not locked: send Move first",
                                         reason="not_pointed")
            six_dof = world[name].kind == "tmac"
        view = WorldView(self._world_bus.direct())

        def target(_t: float) -> np.ndarray | None:
            # the view's latest states over the first look's, placed together
            state = placed({**seen, **view.all()}).get(name)
            return None if state is None else state.matrix()

        origin = time.monotonic()
        with self._lock:
            self._streams += 1
            clock = self.model.clock_s
            try:
                stream = TrackerStream(
                    self.model, target, rate_hz, six_dof=six_dof, seed=self._streams,
                    spec=StreamSpec(**{**spec.__dict__, "clock_offset_s": clock}),
                    blocked=self.blocked)
            except twin.BeamNotLockedError as exc:
                view.close()
                raise BeamNotLockedError(_beam_message(exc), reason=exc.reason) from None
        try:
            while True:
                # a few at a time, the loop turning between: a process starved of CPU
                # catches up on its backlog without blocking the service it runs in
                for sample in stream.advance(time.monotonic() - origin,
                                             STREAM_SAMPLES_PER_TURN):
                    yield TrackerSample(pose=sample.pose, six_dof=sample.six_dof,
                                        tracker_time_s=sample.tracker_time_s,
                                        pc_time_s=time.time(), status=sample.status,
                                        seq=sample.seq)
                await asyncio.sleep(max(0.0, stream.next_time() - (time.monotonic() - origin)))
        finally:
            view.close()
            last = target(0.0)
            with self._lock:  # the beam stays on the reflector it streamed, if still locked
                locked = stream.locked and last is not None
                self._target = name if locked else None
                self._target_position = last[:3, 3] if locked and last is not None else None

    def state(self) -> TrackerStatus:
        with self._lock:
            aim = self.model.aim_point
            return TrackerStatus(
                locked=self.model.locked,
                aim_point_m=None if aim is None else (float(aim[0]), float(aim[1]), float(aim[2])),
                clock_s=self.model.clock_s,
                busy_s=self._busy_s,
                info=f"locked on {self._target}" if self._target else "",
            )

    # -- the world --------------------------------------------------------------------------

    async def _world(self) -> dict[str, ReflectorState]:
        """One look: every reflector placed in the tracker frame."""
        return placed(await asyncio.to_thread(self._query))

    def _query(self) -> dict[str, ReflectorState]:
        found: dict[str, ReflectorState] = {}
        for payload in self._world_bus.query_reflectors(self.query_timeout_s):
            try:
                state = _DECODER.decode(payload)
            except msgspec.DecodeError:
                continue  # not ours to judge: a malformed sim message is ignored
            if state.name not in found or state.seq >= found[state.name].seq:
                found[state.name] = state
        return found

    def _follow(self, world: dict[str, ReflectorState]) -> None:
        """The locked reflector moved since we last looked: the beam followed it."""
        if self._target is None or self._target_position is None:
            return
        state = world.get(self._target)
        if state is None:
            return
        pose = state.matrix()
        distance = float(np.linalg.norm(pose[:3, 3] - self._target_position))
        if distance > 0.0:
            self.model.track(pose[:3, 3], distance / FOLLOW_SPEED_M_S)
            self._target_position = pose[:3, 3]

    def _nearest(self, world: dict[str, ReflectorState]) -> tuple[float, ReflectorState] | None:
        """The reflector nearest to the beam axis (the locked one wins a tie)."""
        best: tuple[float, int, ReflectorState] | None = None
        for state in world.values():
            offset = self.model.beam_offset(state.matrix()[:3, 3])
            rank = (offset, 0 if state.name == self._target else 1, state)
            if best is None or rank[:2] < best[:2]:
                best = rank
        return None if best is None else (best[0], best[2])

    async def _sleep(self, simulated_s: float) -> None:
        if self.time_scale > 0:
            await asyncio.sleep(simulated_s * self.time_scale)
