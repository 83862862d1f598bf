"""The simulated controller's window on the sim-only world: its T-MAC's true pose.

A real tracker sees a real T-MAC; between simulated devices that physical fact
travels on the sim-only key space of :mod:`plugcell.sim.world`.  After
every move the simulated controller publishes ``RobotTwin.true_reflector_in_tracker()``
under the robot service's name: ``moving=True`` while the move lasts (its
simulated duration divided by the speed factor, in real time), then the same pose
with ``moving=False``.  Service logic never reads it.
"""

from __future__ import annotations

import contextlib
import logging
import math
import threading

import numpy as np

from plugcell.framework.bus import Bus, TransportError
from plugcell.framework.keys import KeySpace
from plugcell.framework.transport import TransportConfig
from plugcell.sim.world import ReflectorPublisher

__all__ = ["ReflectorTruth"]

log = logging.getLogger("plugcell.sim.controller")


class ReflectorTruth:
    """Publishes one robot's T-MAC truth; ``on_move`` is a TwinArm move listener."""

    def __init__(self, name: str, cell: str, speed: float,
                 transport: TransportConfig | None = None) -> None:
        self.speed = speed
        self._bus = Bus.connect(transport or TransportConfig.from_env(), KeySpace(cell))
        self._publisher = ReflectorPublisher(self._bus, name=name, kind="tmac")
        self._lock = threading.Lock()
        self._timer: threading.Timer | None = None
        self._closed = False

    def publish(self, pose: np.ndarray, moving: bool = False) -> None:
        with contextlib.suppress(TransportError):
            self._publisher.publish(pose, moving=moving)

    def on_move(self, pose: np.ndarray, duration_s: float) -> None:
        """A move started: publish moving now, at rest when its time is up."""
        real = duration_s / self.speed if math.isfinite(self.speed) else 0.0
        with self._lock:
            if self._closed:
                return
            if self._timer is not None:
                self._timer.cancel()
                self._timer = None
            self.publish(pose, moving=True)
            if real <= 0:
                self.publish(pose, moving=False)
                return
            self._timer = threading.Timer(real, self._settled, args=(pose,))
            self._timer.daemon = True
            self._timer.start()

    def _settled(self, pose: np.ndarray) -> None:
        with self._lock:
            if not self._closed:
                self.publish(pose, moving=False)

    def close(self) -> None:
        with self._lock:
            self._closed = True
            if self._timer is not None:
                self._timer.cancel()
        with contextlib.suppress(Exception):
            self._publisher.close()
        with contextlib.suppress(Exception):
            self._bus.close()
