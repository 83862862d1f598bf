"""The simulated controller's window on the sim-only world: its T-MAC's true pose.

A real tracker sees a real T-MAC; between simulated devices that physical fact
travels on the sim-only key space of :mod:`plugcell.sim.world`.  After
every move the simulated controller publishes ``RobotTwin.true_reflector_in_tracker()``
under the robot service's name: ``moving=True`` while the move lasts (its
simulated duration divided by the speed factor, in real time), then the same pose
with ``moving=False``.  An arm that moves in time (:class:`~plugcell.sim.twin.dynamics.
DynamicTwin`) is published *as it moves* by a :class:`ReflectorFeed`: its true pose at
most ``rate_hz`` times a second while its link angles change, then once at rest.  Service
logic never reads it.  Such an arm's truth also answers every look at the world
(``current``): a tracker's query gets the pose at that instant.
"""

from __future__ import annotations

import contextlib
import logging
import math
import threading
from collections.abc import Callable

import numpy as np

from plugcell.framework.bus import Bus, TransportError
from plugcell.framework.keys import KeySpace
from plugcell.framework.transport import TransportConfig
from plugcell.sim.twin.dynamics import DynamicTwin
from plugcell.sim.world import ReflectorPublisher

__all__ = ["ReflectorFeed", "ReflectorTruth"]

log = logging.getLogger("plugcell.sim.controller")


class ReflectorTruth:
    """Publishes one robot's T-MAC truth; ``on_move`` is a TwinArm move listener."""

    def __init__(self, name: str, cell: str, speed: float,
                 transport: TransportConfig | None = None,
                 current: Callable[[], np.ndarray] | None = None) -> None:
        self.speed = speed
        self._bus = Bus.connect(transport or TransportConfig.from_env(), KeySpace(cell))
        self._publisher = ReflectorPublisher(self._bus, name=name, kind="tmac", current=current)
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


class ReflectorFeed:
    """Publishes the T-MAC truth of an arm that moves in time, while it moves.

    A thread looks at the arm every ``1/rate_hz`` seconds: if any link-side angle moved
    by more than ``rest_rad`` since the last publication, it publishes
    ``RobotTwin.true_reflector_in_tracker()`` with ``moving=True``; the first look that
    finds the arm still publishes it once more with ``moving=False``.  The static physics
    of one pose costs milliseconds (gravity through the closed loop, link bending), so
    the feed runs beside the arm's cycle, not in it.

    Parameters
    ----------
    truth : ReflectorTruth
        Where to publish (the cell's sim-only world, under the robot's name).
    arm : DynamicTwin
        The arm (its ``link`` angles and its static twin's truth are read).
    rate_hz : float
        Largest publication rate while moving (Hz, real time).
    rest_rad : float
        Link-angle change below which the arm counts as still (rad).
    """

    def __init__(self, truth: ReflectorTruth, arm: DynamicTwin, rate_hz: float = 25.0,
                 rest_rad: float = 1e-7) -> None:
        if not (math.isfinite(rate_hz) and rate_hz > 0):
            raise ValueError(f"the reflector feed's rate must be positive, not {rate_hz}")
        self.truth, self.arm = truth, arm
        self.period = 1.0 / rate_hz
        self.rest_rad = rest_rad
        self.published = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> ReflectorFeed:
        """Publish where the arm stands now, then follow it (a daemon thread)."""
        self._thread = threading.Thread(target=self._run, name="reflector-feed", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(5.0)

    def _run(self) -> None:
        last: np.ndarray | None = None  # the link angles last published
        at_rest = False
        while True:
            link = self.arm.link
            moved = last is not None and float(np.max(np.abs(link - last))) > self.rest_rad
            if moved or not at_rest:
                self.truth.publish(self.arm.twin.true_reflector_in_tracker(), moving=moved)
                self.published += 1
                at_rest, last = not moved, link
            if self._stop.wait(self.period):
                return
