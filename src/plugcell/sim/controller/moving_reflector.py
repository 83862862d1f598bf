"""The T-MAC of a twin moved by a stream (RSI), published on the sim world every cycle.

The simulated tracker's real-time output follows the reflector as the world publishes
it (``sim/drivers/tracker.py``: "a robot that publishes its pose every interface cycle
is seen moving").  The exact true pose costs the twin's static physics (~9 ms a pose),
more than a 4 ms cycle, so :class:`MovingReflector` publishes, every ``period_s``,

    T = BASE · E · F_nom(θ_link) · PROBE,     E = F_true(θ_k) · F_nom(θ_k)⁻¹,

with ``E`` — the model's error at the pose, which varies slowly with it — recomputed
exactly every ``refresh_s`` at the link angles then (tens of µm off for the ~10 mm the
arm moves in 0.1 s at 100 mm/s; the same approximation as ``sim/path_run.py``).  Simulators only.
"""

from __future__ import annotations

import contextlib
import math
import threading
import time

import numpy as np

from plugcell.kinematics import forward
from plugcell.sim.controller.reflector import ReflectorTruth
from plugcell.sim.twin.dynamics import DynamicTwin

__all__ = ["MovingReflector"]


class MovingReflector:
    """Publishes a dynamic twin's T-MAC under ``name`` in ``cell`` (module docstring).

    Parameters
    ----------
    arm : DynamicTwin
        The twin (its ``link`` angles are read from this thread).
    name, cell : str
        The robot service's name (the reflector's) and the cell.
    period_s, refresh_s : float
        Publication period and the period of the exact error ``E``.
    """

    def __init__(self, arm: DynamicTwin, name: str, cell: str, period_s: float = 0.004,
                 refresh_s: float = 0.1) -> None:
        self.arm, self.period_s, self.refresh_s = arm, period_s, refresh_s
        self._desc = arm.twin.description
        self._base = arm.twin.true_base()
        self._probe = arm.twin.reveal_truth().probe
        self._truth = ReflectorTruth(name, cell, speed=math.inf)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="moving-reflector",
                                        daemon=True)
        self.published = 0

    def start(self) -> MovingReflector:
        self._thread.start()
        return self

    def pose(self, link: np.ndarray, E: np.ndarray) -> np.ndarray:
        """``BASE · E · F_nom(link) · PROBE`` (4×4, tracker frame, m)."""
        return self._base @ E @ forward(self._desc, None, link, "nominal").flange @ self._probe

    def error(self, link: np.ndarray) -> np.ndarray:
        """``E = F_true(link) · F_nom(link)⁻¹`` (4×4)."""
        nominal = forward(self._desc, None, link, "nominal").flange
        return self.arm.true_flanges(link[None])[0] @ np.linalg.inv(nominal)

    def _run(self) -> None:
        E, refreshed = None, -math.inf
        while not self._stop.wait(self.period_s):
            link = np.array(self.arm.link, dtype=float)
            now = time.monotonic()
            if E is None or now - refreshed >= self.refresh_s:
                E, refreshed = self.error(link), now
            self._truth.publish(self.pose(link, E), moving=True)
            self.published += 1

    def close(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(2.0)
        with contextlib.suppress(Exception):
            self._truth.close()
