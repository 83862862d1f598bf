"""Stream Measurement: the tracker's real-time output as rows of data updates (issue 38).

The driver (:class:`~plugcell.devices.tracker.driver.StreamingTrackerDriver`) yields
samples as they leave the instrument; the service puts ``per_message`` of them in each
data update of the requester's MultipleData process — straight to the requester, not
through a robot service (thesis 9.3).  Each row keeps its sample's own times, so a
consumer (a correction loop in another process) never confuses when a pose was
*measured* with when it *arrived*:

======  ================  =====================================================
column  name              meaning
======  ================  =====================================================
0       tracker_time_s    the instrument's clock at the middle of the integration
1       pc_time_s         the PC's clock (``time.time()``) when the driver got it
2–4     x, y, z           position, mm, in the requester's robot frame (eq. 7.2)
5–7     a, b, c           angles, degrees, in the option's convention
8       six_dof           1 for a T-MAC pose, 0 for an SMR (angles: identity)
9       status            index in ``SAMPLE_STATUSES``: 0 ok, 1 line of sight,
                          2 tracking speed, 3 out of range, 4 device; x…c NaN if ≠ 0
10      seq               the instrument's sample number (a gap is a lost sample)
======  ================  =====================================================
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from plugcell.devices.tracker.driver import (
    SAMPLE_STATUSES,
    StreamingTrackerDriver,
    TrackerDriver,
    TrackerDriverError,
    TrackerSample,
)
from plugcell.devices.tracker.frames import RequesterFrames
from plugcell.framework.service import DeviceError

__all__ = ["MAX_PER_MESSAGE", "STREAM_COLUMNS", "stream_request", "stream_row",
           "stream_samples"]

#: Most samples in one data update.
MAX_PER_MESSAGE = 100
#: The columns of a row (module docstring).
STREAM_COLUMNS = ("tracker_time_s", "pc_time_s", "x", "y", "z", "a", "b", "c", "six_dof",
                  "status", "seq")


def stream_request(driver: TrackerDriver | None, data: Any) -> tuple[float, int]:
    """``[RATE Hz, PER_MESSAGE]`` checked against the driver → (rate, per_message)."""
    values = np.asarray(data).reshape(-1)
    if values.size != 2:
        raise DeviceError(f"expected [RATE Hz, PER_MESSAGE], got {values.size} numbers")
    rate, per_message = int(values[0]), int(values[1])
    if not isinstance(driver, StreamingTrackerDriver):
        info = getattr(driver, "info", type(driver).__name__)
        raise DeviceError(f"the tracker driver ({info}) cannot stream")
    top = float(driver.max_stream_rate_hz)
    if not 1 <= rate <= top:
        raise DeviceError(f"rate {rate} Hz outside 1…{top:g} Hz (the tracker's output rate)")
    if not 1 <= per_message <= MAX_PER_MESSAGE:
        raise DeviceError(f"{per_message} samples per message outside 1…{MAX_PER_MESSAGE}")
    return float(rate), per_message


def stream_row(frames: RequesterFrames, option: str, sample: TrackerSample) -> list[float]:
    """One row (module docstring) of ``sample`` for the requester with ``frames``."""
    status = (SAMPLE_STATUSES.index(sample.status) if sample.status in SAMPLE_STATUSES
              else len(SAMPLE_STATUSES) - 1)
    if sample.pose is None or status != 0:
        vector = [float("nan")] * 6
    else:
        vector = [float(v) for v in frames.measurement(sample.pose, option)]
    return [sample.tracker_time_s, sample.pc_time_s, *vector, float(sample.six_dof),
            float(status), float(sample.seq)]


async def stream_samples(driver: StreamingTrackerDriver, frames: RequesterFrames, option: str,
                         rate_hz: float, per_message: int, post: Callable[[Any], None],
                         fail: Callable[[str], None]) -> None:
    """The FeedbackReceiver of Stream Measurement: ``post`` an ``(per_message, 11)`` array as
    soon as that many samples arrived; ``fail`` with the reason if the driver cannot go on.
    Runs until cancelled (Stop Measurement, or the requester gone)."""
    samples = driver.stream(rate_hz)
    rows: list[list[float]] = []
    try:
        async for sample in samples:
            rows.append(stream_row(frames, option, sample))
            if len(rows) >= per_message:
                post(np.asarray(rows, dtype=float))
                rows = []
    except (TrackerDriverError, ValueError) as exc:
        fail(str(exc))  # ends the process with this reason
    finally:
        await samples.aclose()  # type: ignore[attr-defined]
