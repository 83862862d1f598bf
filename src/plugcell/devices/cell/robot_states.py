"""What the robots stream, relayed by the cell controller to its listeners: their joint
states (the 3-D view) and their tracked moves as they go (the live plot, ``live_moves.py``).

Each robot service publishes its joint state (``plugcell.devices.robot.joint_state``:
readings and link frames, several times a second); :class:`RobotStates` turns each one
into a ``robot`` event sent at once — not batched with the feed's other changes, the view
follows it live — and keeps the latest per robot for a new listener's snapshot.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import msgspec

from plugcell.devices.cell.feed import UiFeed
from plugcell.devices.cell.live_moves import LiveMoves
from plugcell.devices.robot.joint_state import decode_joint_state
from plugcell.framework.bus import Bus, Entity

__all__ = ["RobotStates", "RobotStreams"]


class RobotStates:
    """The latest ``robot`` event of each robot service; each new one to ``feed``."""

    def __init__(self, feed: UiFeed) -> None:
        self.feed = feed
        self.latest: dict[str, dict[str, Any]] = {}
        self.bad = 0
        """Payloads that were not a joint state (dropped)."""

    def on_payload(self, service: str, payload: bytes) -> None:
        """A joint state published by robot service ``service`` → a ``robot`` event
        ``{"type": "robot", "service", "robot", "q", "links", "frames", "base", "tool",
        "flange", "t_ns", "seq"}`` (SI units, as published)."""
        try:
            state = decode_joint_state(payload)
        except ValueError:  # msgspec.DecodeError
            self.bad += 1
            return
        event = {"type": "robot", "service": service, **msgspec.to_builtins(state)}
        self.latest[service] = event
        self.feed.emit(event)

    def forget(self, service: str) -> None:
        """``service`` left the cell."""
        self.latest.pop(service, None)

    def snapshot(self) -> list[dict[str, Any]]:
        """The latest event of every robot."""
        return list(self.latest.values())


class RobotStreams:
    """The robots' joint states (:class:`RobotStates`) and tracked moves
    (:class:`~plugcell.devices.cell.live_moves.LiveMoves`), each event to ``feed``."""

    def __init__(self, feed: UiFeed) -> None:
        self.states = RobotStates(feed)
        self.moves = LiveMoves(feed)

    def watch(self, bus: Bus, own: Callable[[Entity], Any]) -> None:
        """Subscribe to every robot's joint state and tracked move on ``bus``; ``own``
        keeps each subscriber (and undeclares it when the service closes)."""
        own(bus.watch_joint_states(self.states.on_payload))
        own(bus.watch_tracking(self.moves.on_payload))

    def forget(self, service: str) -> None:
        """``service`` left the cell."""
        self.states.forget(service)
        self.moves.forget(service)

    def snapshot(self) -> dict[str, list[dict[str, Any]]]:
        """``{"robots": …, "tracking": …}``: the latest of each robot, for a new listener."""
        return {"robots": self.states.snapshot(), "tracking": self.moves.snapshot()}
