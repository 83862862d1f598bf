"""A simulated drilling end-effector (the TOOL of thesis 4.1.3.2, Figure 4-5).

``ACTIVATE TOOL #Drill#Air#550,1100`` drills with air blow-off at a feed of
550 mm/min and a spindle speed of 1100 rpm; drilling one hole of ``depth_mm``
takes ``depth / feed`` minutes (scaled by ``time_scale`` in simulation).
"""

from __future__ import annotations

import asyncio
from dataclasses import dataclass, field
from typing import ClassVar

from plugcell.devices.drill import FEED_MM_MIN, SPEED_RPM, DrillError


@dataclass
class SimulatedDrill:
    """The drill controller: one hole at a time (a
    :class:`~plugcell.devices.drill.DrillDriver`)."""

    params: ClassVar[dict[str, type]] = {"time_scale": float, "depth_mm": float}
    """What ``plugcell serve drill --param K=V`` sets."""

    depth_mm: float = 10.0
    time_scale: float = 1.0
    holes: list[tuple[bool, int, int]] = field(default_factory=list)

    async def drill(self, air: bool, feed: int, speed: int) -> float:
        """Drill one hole; return the (simulated) drilling time in seconds."""
        if not FEED_MM_MIN[0] <= feed <= FEED_MM_MIN[1]:
            raise DrillError(f"feed {feed} mm/min outside {FEED_MM_MIN[0]}…{FEED_MM_MIN[1]}")
        if not SPEED_RPM[0] <= speed <= SPEED_RPM[1]:
            raise DrillError(f"speed {speed} rpm outside {SPEED_RPM[0]}…{SPEED_RPM[1]}")
        seconds = self.depth_mm / feed * 60.0
        await asyncio.sleep(seconds * self.time_scale)
        self.holes.append((air, feed, speed))
        return seconds
