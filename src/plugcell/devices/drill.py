"""The tool service: a drilling end-effector (thesis 4.1.3.2, Figure 4-5).

One NoData command, ``Drill``: option ``"Air"`` (air blow-off on) or ``""``;
input ``Integer[2]`` = feed (mm/min), spindle speed (rpm) — what the PDL routine
sends as ``ACTIVATE TOOL #Drill#Air#550,1100``.  The drill itself is behind
:class:`DrillDriver` (``plugcell serve drill`` gives it the simulated one,
:class:`plugcell.sim.drivers.drill.SimulatedDrill`).
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

from plugcell.framework.declaration import Declaration
from plugcell.framework.messages import Command, CommandTypes, DataTypes
from plugcell.framework.service import DeviceError, GenericDevice

#: The feeds (mm/min) and spindle speeds (rpm) the drill takes.
FEED_MM_MIN = (10, 2000)
SPEED_RPM = (100, 24000)


class DrillError(RuntimeError):
    """The drill refused or failed a request (its reason is the message)."""


@runtime_checkable
class DrillDriver(Protocol):
    """The seam between :class:`DrillService` and a drilling end-effector."""

    async def drill(self, air: bool, feed: int, speed: int) -> float:
        """Drill one hole at ``feed`` mm/min and ``speed`` rpm (air blow-off on if
        ``air``); return the drilling time in seconds, or raise :class:`DrillError`."""
        ...


class DrillService:
    """A drill behind a :class:`DrillDriver` (the device a
    :class:`~plugcell.framework.service.GenericDevice` hosts)."""

    declaration = Declaration(
        kind="drill",
        default_name="TOOL",
        vendor="plugcell (simulated)",
        info="Drilling end-effector with air blow-off; feed 10-2000 mm/min, speed 100-24000 "
             "rpm",
        commands=(
        Command(
            name="Drill",
            type=CommandTypes.NoData,
            success_code="OK",
            input_data_type=DataTypes.Integer,
            input_data_size=(2,),
            timeout=120.0,
            info="drill one hole; option 'Air' or ''; input: feed mm/min, speed rpm",
        ),
    ))

    def __init__(self, driver: DrillDriver) -> None:
        self.drill = driver

    def bind(self, service: GenericDevice) -> None:
        """The drill reports only its command feedback (the code it returns)."""

    async def dispatch(self, command: Command, option: str, data: np.ndarray | None) -> str:
        """CommandDispatcher of the drill interface."""
        if option not in ("Air", ""):
            raise DeviceError(f"unknown option {option!r}: use 'Air' or ''")
        assert data is not None
        feed, speed = (int(v) for v in data)
        try:
            await self.drill.drill(option == "Air", feed, speed)
        except DrillError as exc:
            raise DeviceError(str(exc)) from exc
        return "OK"
