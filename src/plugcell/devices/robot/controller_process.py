"""A robot controller the robot service starts itself: the seam of ``sim=true``.

With ``sim=true`` the robot service runs its own controller in a child process and
connects to it over the line protocol like to any other.  The service does not know
which program that is: it is given a :class:`ControllerLauncher` (``plugcell serve
robot`` gives the simulated controller of ``plugcell.sim.controller.launcher``), calls
it with the service's name, cell and the robot's options, and starts the process it
returns.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Protocol, runtime_checkable

__all__ = ["ControllerLauncher", "ControllerProcess", "ControllerStartError"]


class ControllerStartError(RuntimeError):
    """A controller process could not be started (the message says why)."""


@runtime_checkable
class ControllerProcess(Protocol):
    """One controller process, started by the robot service and stopped at its shutdown."""

    @property
    def alive(self) -> bool:
        """The process is running."""
        ...

    async def start(self, timeout: float = 30.0) -> tuple[str, int]:
        """Start it; the (host, port) it listens on.  :class:`ControllerStartError` if it
        does not come up within ``timeout`` s."""
        ...

    async def stop(self, timeout: float = 5.0) -> None:
        """Stop it (terminate, then kill after ``timeout`` s)."""
        ...


class ControllerLauncher(Protocol):
    """Makes the :class:`ControllerProcess` of a robot service (a class, or a function)."""

    def __call__(self, *, name: str, cell: str, robot: str, payload_kg: float, speed: float,
                 seed: int, library: list[Path], transport: Any, link_baud: float,
                 dynamics: bool = False) -> ControllerProcess:
        """The (not yet started) controller of service ``name`` in ``cell`` (``dynamics``:
        its twin moves in time, the simulated controller's option)."""
        ...
