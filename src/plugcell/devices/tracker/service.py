"""The laser tracker service: Table 7-3 of the thesis, one tracker for many robots.

Commands (thesis 7.4, Table 7-3; 6-vectors are ``x, y, z`` in mm and three angles
in degrees, durations and intervals in ms):

========================  =======================  ==============  ===========  ============
command                   option                   input           output       type
========================  =======================  ==============  ===========  ============
Set Base                  rpy2tr/euler2tr/prj2tr   Double[6]       —            NoData
Set Probe                 rpy2tr/euler2tr/prj2tr   Double[6]       —            NoData
Move                      (rpy2tr/euler2tr/prj2tr) Double[6]       —            NoData
Single Measurement        tr2rpy/tr2euler/tr2prj   Integer[1]      Double[6]    SingleData
Continuous Measurement    tr2rpy/tr2euler/tr2prj   Integer[1]      Double[6]    MultipleData
Stop Measurement          —                        —               —            StopData
Stream Measurement        tr2rpy/tr2euler/tr2prj   Integer[2]      Double[n,11] MultipleData
========================  =======================  ==============  ===========  ============

* **Per robot.**  BASE, PROBE and the angle convention belong to the requester (the
  process's sender, or whom a routed process is for): two robots sharing the tracker
  each get measurements in their own frame, eq. (7.2), ``BASE⁻¹ · T · PROBE⁻¹``.
* **Move** (8.4.2): every robot "must send a command Move ... provided with their
  instant positions before any measurement can take place": the beam is aimed where
  eq. (7.1), ``BASE · T · PROBE``, puts the robot's reflector and re-locks by ADM, or
  the process fails with the reason (nothing within the capture radius, and which
  reflector is nearest).
* **One at a time, through the queue** (8.4.3): a robot holding the tracker with
  Continuous Measurement keeps it until its Stop Measurement; the others' processes
  wait their turn in the FIFO queue (the framework's re-scheduling, 5.2.3.5).  A
  holder that dies is stopped by the framework and the queue moves on.
* **Stream Measurement** (issue 38): the instrument's real-time output, RATE samples a
  second (≤ 1 kHz), PER_MESSAGE of them in each data update (``n`` rows of
  :data:`STREAM_COLUMNS`: each sample's own acquisition time on the tracker's clock and
  arrival time on the PC's, pose, status, number), straight to the requester — a
  correction loop in another process subscribes to it; a beam break does not end it
  (rows say so); Stop Measurement or the requester's disappearance does.
* **Routing** (9.3): option clauses ``; to=SERVICE:Command:Option`` send every
  measurement on to another service as well (``devices/tracker/routing.py``).

The instrument is behind :class:`~plugcell.devices.tracker.driver.TrackerDriver`, given
to the device: ``plugcell serve tracker`` hands it the simulated one
(:class:`plugcell.sim.drivers.tracker.SimulatedTrackerDriver`, ``--param seed=S``,
``--param time_scale=X``); ``--param driver=module:Class`` plugs in another.
"""

from __future__ import annotations

import asyncio
import contextlib
import importlib
import logging
from typing import Any, ClassVar

import numpy as np

from plugcell.devices.tracker.driver import TrackerDriver, TrackerDriverError, TrackerStatus
from plugcell.devices.tracker.frames import FrameError, RequesterFrames
from plugcell.devices.tracker.routing import Routing
from plugcell.devices.tracker.streaming import STREAM_COLUMNS, stream_request, stream_samples
from plugcell.framework.declaration import Declaration
from plugcell.framework.messages import Command, CommandTypes, DataTypes
from plugcell.framework.service import DeviceError, GenericDevice

log = logging.getLogger("plugcell.devices.tracker.service")

#: Longest measuring time of a Single Measurement and longest Continuous interval (ms).
MAX_DURATION_MS = 60_000
#: Shortest Continuous Measurement interval (ms): the tracker's 1 kHz output (Table 2-2).
MIN_INTERVAL_MS = 1

SIX = (6,)
_VECTOR = "x, y, z mm; 3 angles deg"

__all__ = ["STREAM_COLUMNS", "TrackerService", "load_driver"]


def load_driver(spec: str, **kwargs: Any) -> TrackerDriver:
    """A driver from ``module:Class`` (constructed with ``kwargs``)."""
    module_name, sep, attr = spec.partition(":")
    if not sep:
        raise ValueError(f"driver {spec!r}: expected 'sim' or module:Class")
    try:
        cls = getattr(importlib.import_module(module_name), attr)
    except (ImportError, AttributeError) as exc:
        raise ValueError(f"cannot load tracker driver {spec!r}: {exc}") from None
    if not isinstance(cls, type):
        raise ValueError(f"{spec} is not a class")
    try:
        driver = cls(**kwargs)
    except Exception as exc:
        raise ValueError(f"cannot construct tracker driver {spec}: {exc}") from None
    if not isinstance(driver, TrackerDriver):
        raise ValueError(f"{spec} is not a TrackerDriver (point, measure, state, ...)")
    return driver


class TrackerService:
    """The laser tracker of Table 7-3, shared by many robots (module docstring); the
    device a :class:`~plugcell.framework.service.GenericDevice` hosts, in front of a
    :class:`~plugcell.devices.tracker.driver.TrackerDriver`."""

    declaration = Declaration(
        kind="tracker",
        default_name="TRACKER",
        vendor="plugcell",
        info="Laser tracker (thesis Table 7-3): per-robot BASE/PROBE, Move, measurements",
        commands=(
        Command(
            name="Set Base", type=CommandTypes.NoData,
            input_data_type=DataTypes.Double, input_data_size=SIX,
            info=f"BASE: robot base frame in the tracker frame ({_VECTOR}); "
                 "option rpy2tr | euler2tr | prj2tr",
        ),
        Command(
            name="Set Probe", type=CommandTypes.NoData,
            input_data_type=DataTypes.Double, input_data_size=SIX,
            info=f"PROBE: reflector frame in the flange frame ({_VECTOR}); "
                 "option rpy2tr | euler2tr | prj2tr",
        ),
        Command(
            name="Move", type=CommandTypes.NoData,
            input_data_type=DataTypes.Double, input_data_size=SIX, timeout=30.0,
            info=f"aim the beam at BASE·T·PROBE for the robot pose T ({_VECTOR}) and lock on "
                 "the reflector there (eq. 7.1)",
        ),
        Command(
            name="Single Measurement", type=CommandTypes.SingleData,
            input_data_type=DataTypes.Integer, input_data_size=(1,),
            output_data_type=DataTypes.Double, output_data_size=SIX, timeout=120.0,
            info=f"one measurement averaged over DURATION ms, in the robot frame ({_VECTOR}, "
                 "eq. 7.2); option tr2rpy | tr2euler | tr2prj [; to=SERVICE:Command:Option]",
        ),
        Command(
            name="Continuous Measurement", type=CommandTypes.MultipleData,
            input_data_type=DataTypes.Integer, input_data_size=(1,),
            output_data_type=DataTypes.Double, output_data_size=SIX, timeout=3600.0,
            info="a measurement every INTERVAL ms (each averaged over the interval) until "
                 "Stop Measurement; options as Single Measurement",
        ),
        Command(name="Stop Measurement", type=CommandTypes.StopData,
                info="end this requester's Continuous or Stream Measurement and release the "
                     "tracker"),
        Command(
            name="Stream Measurement", type=CommandTypes.MultipleData,
            input_data_type=DataTypes.Integer, input_data_size=(2,),
            output_data_type=DataTypes.Double, output_data_size=(-1, len(STREAM_COLUMNS)),
            timeout=3600.0,
            info="the real-time output: [RATE Hz (1-1000), PER_MESSAGE (1-100)]; rows "
                 + ", ".join(STREAM_COLUMNS) + " (times s, mm, deg; status 0 ok, 1 line of "
                 "sight, 2 tracking speed, 3 out of range, 4 device) until Stop Measurement; "
                 "option tr2rpy | tr2euler | tr2prj",
        ),
    ))
    params: ClassVar[dict[str, type]] = {"driver": str}
    """``driver=module:Class``: another driver than the one ``plugcell serve`` gives."""

    def __init__(self, driver: TrackerDriver | str) -> None:
        if isinstance(driver, str):
            driver = load_driver(driver)
        self.driver: TrackerDriver = driver
        self.service: GenericDevice | None = None
        self.routing = Routing(self.handle)
        """Who each process is for, and where its measurements go (tracker/routing.py)."""
        self.frames: dict[str, RequesterFrames] = {}
        """BASE, PROBE and angle convention of each requester (robot) by name."""
        self.beam_for: str | None = None
        """The requester whose Move the beam is locked for (None: no Move yet)."""
        self.aims: dict[str, np.ndarray] = {}
        """Where each requester's last successful Move aimed the beam (tracker frame, m)."""
        self._stream: asyncio.Task[None] | None = None

    def bind(self, service: GenericDevice) -> None:
        self.service = service
        self.routing.bind(service)

    @property
    def requester(self) -> str:
        """The participant the running process is for (tracker/routing.py)."""
        return self.routing.requester

    # -- connection -----------------------------------------------------------------------

    async def connect(self) -> None:
        assert self.service is not None
        attach = getattr(self.driver, "attach", None)
        if attach is not None:  # a driver that sees the cell through the service's bus
            attach(self.service.participant.bus)
        await self.driver.connect()
        self.service.device.vendor = self.driver.info

    async def disconnect(self) -> None:
        await self._stop_stream()
        await self.driver.disconnect()

    def status(self) -> TrackerStatus:
        """The instrument's status."""
        return self.driver.state()

    async def dispatch(self, command: Command, option: str, data: Any) -> str | None:
        """Through the routing: the requester, then :meth:`handle`, then the routes."""
        return await self.routing.dispatch(command, option, data)

    # -- the device interface (Figure 5-10) -----------------------------------------------

    def frames_of(self, requester: str) -> RequesterFrames:
        """The frames of ``requester`` (identity BASE/PROBE until it sets them)."""
        return self.frames.setdefault(requester, RequesterFrames())

    async def handle(self, command: Command, option: str, data: Any) -> str:
        """CommandDispatcher of Table 7-3, for :attr:`requester`."""
        assert self.service is not None
        name, output = self.service.name, self.routing.data_feedback
        try:
            match command.name:
                case "Set Base":
                    self.frames_of(self.requester).set_base(data, option)
                case "Set Probe":
                    self.frames_of(self.requester).set_probe(data, option)
                case "Move":
                    target = self.frames_of(self.requester).reflector(data, option)
                    self.beam_for = None
                    self.aims.pop(self.requester, None)
                    await self.driver.point(target[:3, 3])
                    self.beam_for = self.requester
                    self.aims[self.requester] = target[:3, 3]
                case "Single Measurement":
                    await self._reaim()
                    duration = _milliseconds(data, "duration", 1)
                    frames = self.frames_of(self.requester)
                    frames.output_convention(option)  # refuse a bad option before measuring
                    reading = await self.driver.measure(duration)
                    output.post(frames.measurement(reading.pose, option))
                case "Continuous Measurement":
                    await self._reaim()
                    interval = _milliseconds(data, "interval", MIN_INTERVAL_MS)
                    frames = self.frames_of(self.requester)
                    frames.output_convention(option)
                    self._stream = asyncio.create_task(
                        self._measure_continuously(frames, option, interval),
                        name=f"{name}-continuous",
                    )
                case "Stream Measurement":
                    await self._reaim()
                    rate, per_message = stream_request(self.driver, data)
                    frames = self.frames_of(self.requester)
                    frames.output_convention(option)
                    self._stream = asyncio.create_task(
                        stream_samples(self.driver, frames, option, rate, per_message,
                                       output.post, self.service.cmd_feedback.post),
                        name=f"{name}-stream",
                    )
                case "Stop Measurement":
                    await self._stop_stream()
                case _:
                    raise DeviceError(f"unknown command {command.name}")
        except FrameError as exc:
            raise DeviceError(str(exc)) from None
        except TrackerDriverError as exc:
            raise DeviceError(str(exc)) from None
        return "OK"

    async def _reaim(self) -> None:
        """Measure only the reflector of the requester's own Move (7.4).  If another
        requester's Move took the beam since, aim it back where this requester's last
        Move put it first — one robot's measurement never measures another's reflector,
        and two robots taking turns cannot starve each other."""
        owner = self.beam_for
        if owner is None or owner == self.requester:
            return
        aim = self.aims.get(self.requester)
        if aim is None:
            raise DeviceError(f"the beam is pointed for {owner}; send Move first")
        self.beam_for = None
        await self.driver.point(aim)  # BeamNotLockedError: the reflector is not there now
        self.beam_for = self.requester

    async def _measure_continuously(self, frames: RequesterFrames, option: str,
                                    interval_s: float) -> None:
        """The FeedbackReceiver of Continuous Measurement: one measurement per interval.

        Each measurement integrates over the interval (the 50 ms readings of the
        correction loop, 8.3.2); a lost beam ends the stream with the reason.
        """
        assert self.service is not None
        output, cmd_feedback = self.routing.data_feedback, self.service.cmd_feedback
        time_scale = getattr(self.driver, "time_scale", 0.0)  # a model's; real time: 0
        loop = asyncio.get_running_loop()
        next_time = loop.time()
        while True:
            try:
                reading = await self.driver.measure(interval_s)
            except TrackerDriverError as exc:
                cmd_feedback.post(str(exc))  # ends the process with this reason
                return
            output.post(frames.measurement(reading.pose, option))
            next_time += max(interval_s * time_scale, 0.002)
            await asyncio.sleep(max(0.0, next_time - loop.time()))

    async def _stop_stream(self) -> None:
        stream, self._stream = self._stream, None
        if stream is not None:
            stream.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await stream


def _milliseconds(data: Any, what: str, minimum: int) -> float:
    value = int(np.asarray(data).reshape(-1)[0])
    if not minimum <= value <= MAX_DURATION_MS:
        raise DeviceError(f"{what} {value} ms outside {minimum}…{MAX_DURATION_MS} ms")
    return value / 1000.0
