"""The seam between the laser tracker service and a tracker: :class:`TrackerDriver`.

The service (``devices/tracker/service.py``) does the thesis's part of Table 7-3 — frames
per robot, eqs. (7.1)–(7.2), conversions, the queue — and asks a driver for the
three things only the instrument can do, in the *tracker* frame and SI units:

* :meth:`TrackerDriver.point` — slew the beam so that it passes through a point and
  re-establish the lock on the reflector found there (the ADM of 2.3.1.1); or fail
  with :class:`BeamNotLockedError` and the reason;
* :meth:`TrackerDriver.measure` — one measurement of the locked reflector averaged
  over a duration (a T-MAC gives a pose, an SMR a position);
* :meth:`TrackerDriver.state` — what the instrument says about itself;
* :meth:`StreamingTrackerDriver.stream` (optional) — the locked reflector's
  measurements at up to 1 kHz as they leave the instrument, each with the instrument's
  acquisition time and the PC's arrival time (:class:`TrackerSample`).

``plugcell serve tracker`` uses the simulated driver
(:class:`plugcell.sim.drivers.tracker.SimulatedTrackerDriver`: the tracker
model of the foundation aimed at the reflectors of the simulated world).  A real
tracker (e.g. a Leica AT901 through its emScon/LMF SDK) plugs in as another class
with these methods, ``--param driver=module:Class``; the service does not change.
"""

from __future__ import annotations

from collections.abc import AsyncIterator
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]

__all__ = [
    "SAMPLE_STATUSES",
    "BeamNotLockedError",
    "StreamingTrackerDriver",
    "TrackerDriver",
    "TrackerDriverError",
    "TrackerReading",
    "TrackerSample",
    "TrackerStatus",
]


class TrackerDriverError(RuntimeError):
    """The instrument cannot do what was asked; ``reason`` is a short machine code.

    Codes: ``out_of_range`` (distance, elevation or T-MAC facing), ``device`` (anything
    else the instrument reports); :class:`BeamNotLockedError` adds its own.
    """

    def __init__(self, message: str, reason: str = "device") -> None:
        super().__init__(message)
        self.reason = reason


class BeamNotLockedError(TrackerDriverError):
    """No lock on a reflector.  ``reason``: ``not_pointed`` (never aimed), ``capture``
    (no reflector within the capture radius of the beam), ``line_of_sight``,
    ``tracking_speed`` (the reflector moved faster than the tracker follows)."""


@dataclass(frozen=True)
class TrackerReading:
    """One measurement in the tracker frame.

    ``pose``: 4×4 (metres) — for a 3-DOF reflector (SMR) the rotation is the identity
    and only the position is measured (``six_dof`` False); ``duration_s``: the
    integration time; ``elapsed_s``: how long the instrument was busy (lock +
    integration + report); ``timestamp_s``: the instrument's clock at mid-integration.
    """

    pose: Array
    six_dof: bool
    duration_s: float
    elapsed_s: float
    timestamp_s: float


@dataclass(frozen=True)
class TrackerStatus:
    """What the instrument reports about itself."""

    locked: bool
    aim_point_m: tuple[float, float, float] | None
    clock_s: float
    """Instrument time (simulated for the model)."""
    busy_s: float
    """Time spent slewing and measuring since the driver connected."""
    info: str = ""


@runtime_checkable
class TrackerDriver(Protocol):
    """A laser tracker as the service needs it (module docstring).

    A driver that looks at the cell through the hosting service's transport (the
    simulated one: its reflectors are the simulated robots') also has ``attach(bus)``,
    which the tracker calls with the service's bus before :meth:`connect`.
    """

    info: str
    """Vendor and model, shown in the service's DeviceInfo."""

    async def connect(self) -> None:
        """Connect to the instrument (raise TrackerDriverError if it cannot)."""

    async def disconnect(self) -> None:
        """Release the instrument."""

    async def point(self, position_m: Array) -> float:
        """Aim the beam through ``position_m`` (tracker frame) and lock on the reflector
        there.  Returns the time it took (s).  Raises :class:`BeamNotLockedError`."""

    async def measure(self, duration_s: float) -> TrackerReading:
        """Measure the locked reflector for ``duration_s``.  Raises :class:`TrackerDriverError`."""

    def state(self) -> TrackerStatus:
        """The instrument's current status (cheap, never blocks)."""


#: A streamed sample's status: ``ok``, or why it holds no measurement (the index is the
#: status code of the service's rows, docs/tracker-service.md).
SAMPLE_STATUSES = ("ok", "line_of_sight", "tracking_speed", "out_of_range", "device")


@dataclass(frozen=True)
class TrackerSample:
    """One streamed measurement in the tracker frame (SI).

    ``pose``: 4×4 (identity rotation for a 3-DOF reflector), None unless ``status`` is
    ``ok``; ``tracker_time_s``: the instrument's clock at the middle of the sample's
    integration (its acquisition time); ``pc_time_s``: the PC's clock (``time.time()``)
    when the driver received it; ``seq``: the instrument's sample counter (a gap is a
    lost sample).
    """

    pose: Array | None
    six_dof: bool
    tracker_time_s: float
    pc_time_s: float
    status: str
    seq: int


@runtime_checkable
class StreamingTrackerDriver(TrackerDriver, Protocol):
    """A driver that can also stream (real time output of the instrument)."""

    max_stream_rate_hz: float

    def stream(self, rate_hz: float) -> AsyncIterator[TrackerSample]:
        """Samples of the locked reflector at ``rate_hz`` (1…``max_stream_rate_hz``) as
        they arrive, until the iterator is closed.  A beam break does not end it: the
        samples say so in ``status`` and the stream carries on (the instrument
        re-acquires, or the caller Moves again).  Raises :class:`BeamNotLockedError`
        before the first sample if the beam is not locked, ValueError for a bad rate."""
        ...
