"""The operator's hands in appendix D.1, in the simulated world: SMRs in the flange's dowel holes.

"Fix a SMR reflector in a dowel hole on the flange surface and rotate the last joint"
(D.1): a real tracker sees that SMR because it is physically there.  The simulated
robot controller publishes only its T-MAC's true pose (``services/sim/world.py``); this
helper places an SMR in each dowel hole of the same flange — the flange being where the
T-MAC truth and the twin's true PROBE say it is — and moves them with every pose the
robot publishes.  It is the test's physics (like the fixed SMRs of ``plugcell demo``),
never read by a service.
"""

from __future__ import annotations

import threading
import time
from typing import Any

import numpy as np

from plugcell.framework.bus import Bus
from plugcell.framework.keys import KeySpace
from plugcell.framework.transport import TransportConfig, open_session
from plugcell.metrology import SMR_RADIUS_HALF_INCH
from plugcell.sim.twin.appendix_d import DOWEL_HOLES
from plugcell.sim.world import ReflectorPublisher, ReflectorState, WorldView

__all__ = ["FlangeSMRs"]


class FlangeSMRs:
    """SMRs ``<ROBOT>_HOLE1`` (−y) and ``<ROBOT>_HOLE2`` (+y) in the dowel holes of a
    robot's flange (centres ``smr_offset`` above the face), following the robot."""

    def __init__(self, cell: str, robot: str, true_probe: np.ndarray,
                 smr_offset: float = SMR_RADIUS_HALF_INCH,
                 ready_timeout_s: float = 30.0) -> None:
        self.robot = robot
        self._probe_inv = np.linalg.inv(np.asarray(true_probe, dtype=float))
        self._holes = [np.r_[h[:2], h[2] + smr_offset] for h in DOWEL_HOLES]
        self._lock = threading.Lock()
        self.session: Any = open_session(TransportConfig.from_env())
        bus = Bus(self.session, KeySpace(cell))
        self._smrs = [ReflectorPublisher(bus, f"{robot}_HOLE{i + 1}", "smr")
                      for i in range(len(self._holes))]
        self.moves = 0
        self._view = WorldView(bus, on_change=self._moved)
        self._wait_for_robot(ready_timeout_s)

    def _wait_for_robot(self, timeout_s: float) -> None:
        """Return once the SMRs sit on the robot's flange.  A session opened just now
        may not have met the robot's yet (peer discovery takes a while on a loaded
        machine): the view's first look at the world then finds nobody, and a robot pose
        published before the robot's session learns of our subscriber is lost — the
        tracker would be aimed at a dowel hole with no SMR in it (CI run 20: "nearest:
        H4, 119.1 mm off the axis").  A reply from the robot proves both sessions met, and
        our subscriber was declared before the query on that link."""
        deadline = time.monotonic() + timeout_s
        while self._view.get(self.robot) is None:
            if time.monotonic() > deadline:
                self.close()
                raise TimeoutError(f"robot {self.robot}'s reflector not seen in the cell "
                                   f"within {timeout_s:g} s: no flange to put the SMRs on")
            time.sleep(0.1)

    def _moved(self, state: ReflectorState) -> None:
        if state.name != self.robot:
            return
        flange = state.matrix() @ self._probe_inv
        with self._lock:
            for smr, hole in zip(self._smrs, self._holes, strict=True):
                pose = np.eye(4)
                pose[:3, 3] = flange[:3, :3] @ hole + flange[:3, 3]
                smr.publish(pose, moving=state.moving)
            self.moves += 1

    def close(self) -> None:
        with self._lock:
            self._view.close()
            for smr in self._smrs:
                smr.close()
        self.session.close()
