"""The operator's hands in appendix D.1, in the simulated world: SMRs in the flange's dowel holes.

"Fix a SMR reflector in a dowel hole on the flange surface and rotate the last joint"
(D.1): a real tracker sees that SMR because it is physically there.  The simulated
robot controller publishes only its T-MAC's true pose (``sim/world.py``); this helper
fixes an SMR in each dowel hole of the same flange — *mounted* on the robot's T-MAC,
at ``PROBE⁻¹ · hole`` in its frame (the twin's true PROBE), published once — and the
tracker places them on the T-MAC's pose of the same look at the world
(:func:`plugcell.sim.world.placed`).  It is the test's physics (like the fixed SMRs of
``plugcell demo``), never read by a service.

Before, the helper re-published the holes from its own process whenever the robot's
pose reached it: under load that came after the tracker had measured, the circle got
the previous pose twice, its points stopped being in angular order and the fitted
normal took an arbitrary sign — PROBE 282 mm / 180° off (CI runs 25, 27 and of
2026-11-28).
"""

from __future__ import annotations

import contextlib
import time
from typing import Any

import numpy as np

from plugcell.framework.bus import Bus
from plugcell.framework.keys import KeySpace
from plugcell.framework.transport import TransportConfig, open_session
from plugcell.metrology import SMR_RADIUS_HALF_INCH
from plugcell.sim.twin.appendix_d import DOWEL_HOLES
from plugcell.sim.world import ReflectorPublisher, WorldView

__all__ = ["FlangeSMRs"]


class FlangeSMRs:
    """SMRs ``<ROBOT>_HOLE1`` (−y) and ``<ROBOT>_HOLE2`` (+y) in the dowel holes of a
    robot's flange (centres ``smr_offset`` above the face), mounted on its T-MAC."""

    def __init__(self, cell: str, robot: str, true_probe: np.ndarray,
                 smr_offset: float = SMR_RADIUS_HALF_INCH,
                 ready_timeout_s: float = 30.0) -> None:
        self.robot = robot
        probe_inv = np.linalg.inv(np.asarray(true_probe, dtype=float))
        self.session: Any = open_session(TransportConfig.from_env())
        bus = Bus(self.session, KeySpace(cell))
        self._view = WorldView(bus)
        self._smrs: list[ReflectorPublisher] = []
        try:
            self._wait_for_robot(ready_timeout_s)
            for i, h in enumerate(DOWEL_HOLES):
                hole = np.eye(4)
                hole[:3, 3] = np.r_[h[:2], h[2] + smr_offset]
                smr = ReflectorPublisher(bus, f"{robot}_HOLE{i + 1}", "smr", mount=robot)
                smr.publish(probe_inv @ hole)
                self._smrs.append(smr)
        except BaseException:
            self.close()
            raise

    def _wait_for_robot(self, timeout_s: float) -> None:
        """Return once the robot's T-MAC is seen.  A session opened just now may not have
        met the cell's yet (peer discovery takes a while on a loaded machine); a reply
        from the robot proves it has (CI run 20: "nearest: H4, 119.1 mm off the axis")."""
        deadline = time.monotonic() + timeout_s
        while self._view.get(self.robot) is None:
            if time.monotonic() > deadline:
                raise TimeoutError(f"robot {self.robot}'s reflector not seen in the cell "
                                   f"within {timeout_s:g} s: no flange to put the SMRs on")
            time.sleep(0.1)

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self._view.close()
        for smr in self._smrs:
            smr.close()
        self.session.close()
