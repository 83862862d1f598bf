"""A stand-in for a real tracker driver (e.g. one over a vendor SDK): what the seam needs."""

from __future__ import annotations

import numpy as np

from plugcell.devices.tracker.driver import BeamNotLockedError, TrackerReading, TrackerStatus


class ScriptedDriver:
    """Reports a fixed reflector pose; records where it was asked to point."""

    info = "scripted tracker (tests)"
    reflector = np.eye(4)

    def __init__(self) -> None:
        self.pointed: list[np.ndarray] = []
        self.connected = False

    async def connect(self) -> None:
        self.connected = True

    async def disconnect(self) -> None:
        self.connected = False

    async def point(self, position_m: np.ndarray) -> float:
        self.pointed.append(np.array(position_m))
        if np.linalg.norm(position_m - self.reflector[:3, 3]) > 0.010:
            raise BeamNotLockedError("beam not locked: nothing there", reason="capture")
        return 0.1

    async def measure(self, duration_s: float) -> TrackerReading:
        if not self.pointed:
            raise BeamNotLockedError("beam not locked: never pointed", reason="not_pointed")
        return TrackerReading(self.reflector.copy(), True, duration_s, duration_s, 0.0)

    def state(self) -> TrackerStatus:
        return TrackerStatus(locked=bool(self.pointed), aim_point_m=None, clock_s=0.0, busy_s=0.0)


class NotADriver:
    """Constructible, but without the TrackerDriver methods."""
