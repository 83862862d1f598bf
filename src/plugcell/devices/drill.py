"""The tool service: a drilling end-effector (thesis 4.1.3.2, Figure 4-5).

One NoData command, ``Drill``: option ``"Air"`` (air blow-off on) or ``""``;
input ``Integer[2]`` = feed (mm/min), spindle speed (rpm) — what the PDL routine
sends as ``ACTIVATE TOOL #Drill#Air#550,1100``.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from plugcell.framework.messages import Command, CommandTypes, DataTypes
from plugcell.framework.service import DeviceError, GenericDevice
from plugcell.sim.drivers.drill import DrillError, SimulatedDrill


class DrillService(GenericDevice):
    """A drill (simulated unless given another controller)."""

    kind = "drill"
    default_name = "TOOL"
    vendor = "plugcell (simulated)"
    info = "Drilling end-effector with air blow-off; feed 10-2000 mm/min, speed 100-24000 rpm"
    commands = (
        Command(
            name="Drill",
            type=CommandTypes.NoData,
            success_code="OK",
            input_data_type=DataTypes.Integer,
            input_data_size=(2,),
            timeout=120.0,
            info="drill one hole; option 'Air' or ''; input: feed mm/min, speed rpm",
        ),
    )
    params: ClassVar[dict[str, type]] = {"time_scale": float, "depth_mm": float}

    def __init__(
        self,
        name: str | None = None,
        *,
        drill: SimulatedDrill | None = None,
        time_scale: float = 1.0,
        depth_mm: float = 10.0,
        **kwargs: Any,
    ) -> None:
        super().__init__(name, **kwargs)
        self.drill = drill or SimulatedDrill(depth_mm=depth_mm, time_scale=time_scale)

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
