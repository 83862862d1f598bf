"""The robot service's seam to its robot: what it needs of whatever runs its programs.

The robot service (:mod:`plugcell.devices.robot.service`) carries its commands — run a
program, stop it, read the arm, the kinematics, the answers to a program's ACTIVATE
strings — as the line protocol's messages (docs/controller-protocol.md) to a
:class:`RobotLink`, chosen when the service is made:

* :class:`~plugcell.devices.robot.bridge.ControllerBridge` — a controller that runs the
  programs itself, real or simulated, over TCP;
* :class:`~plugcell.devices.robot.stream_controller.StreamController` — the program runs
  on the PC and each move streams to the robot: a KUKA robot over RSI, an ABB robot over
  EGM (the PC drives).

Either calls back the service (a :class:`~plugcell.devices.robot.bridge.BridgeHandler`)
with what the robot says unasked — program started, console lines, ACTIVATE strings,
program ended, link lost — in the event loop, in order; either raises
:class:`~plugcell.devices.robot.bridge.BridgeError` when the robot cannot be reached and
:class:`~plugcell.devices.robot.bridge.ControllerError` with the reason when it refuses.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Protocol, runtime_checkable

from plugcell.devices.robot.protocol import Hello, Message, Request

__all__ = ["RobotLink"]


@runtime_checkable
class RobotLink(Protocol):
    """What the robot service uses of the link to its robot (module docstring)."""

    address: str
    """Where the robot is reached, for messages."""

    @property
    def connected(self) -> bool:
        """The robot can be talked to now."""
        ...

    @property
    def lost_reason(self) -> str:
        """Why it cannot (when not connected)."""
        ...

    def field(self, key: str, default: str = "") -> str:
        """A field of the robot's HELLO (``robot``, ``data``, ``text`` …)."""
        ...

    async def connect(self, host: str, port: int, timeout: float = 10.0) -> Hello:
        """Reach the robot at ``host:port`` within ``timeout`` s; its HELLO."""
        ...

    async def close(self) -> None:
        """Let go of the robot (a running program stops); the handler is not told."""
        ...

    def new_id(self) -> int:
        """A fresh request (and run) identifier."""
        ...

    async def send(self, *messages: Message) -> None:
        """Hand the program its answers (DATA/TEXT/RESULT, frames, stream ends), in order."""
        ...

    async def request(self, request: Request, *, before: tuple[Message, ...] = (),
                      timeout: float | None = None) -> str:
        """The text of the robot's ``OK`` to ``request`` (after ``before``)."""
        ...

    async def run(self, run_id: int, program: str, values: Mapping[str, str] | None = None,
                  timeout: float | None = None) -> str:
        """Start ``program`` as run ``run_id`` with its variables preset; its name."""
        ...
