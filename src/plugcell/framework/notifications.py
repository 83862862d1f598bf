"""What a service publishes on its own: the notifications of the Generic Interface
(thesis Table 5-2) — ``StateUpdate``, ``ConnectionUpdate`` and ``Shutdown`` to the
subscribed partners — and the samples on each sender's process key (the outbox's
acknowledgements and updates, the scheduler's Queued heartbeats).

:class:`Notifications` belongs to one :class:`~plugcell.framework.service.GenericDevice`:
it is the receiver of the service's DeviceState and ConnectionState ports (5.2.3.2) and
keeps one Zenoh publisher per sender.  A state change is notified at the end of the
event-loop turn and only if the state then differs from the last one notified: a
process that runs within one turn (Busy → Ready) notifies nothing, as no observer could
have seen it.
"""

from __future__ import annotations

import contextlib
from datetime import UTC, datetime
from typing import Any

import zenoh

from plugcell.framework.bus import Notification
from plugcell.framework.messages import (
    ConnectionStates,
    ConnectionUpdateNotification,
    Device,
    DeviceStates,
    Message,
    StateUpdateNotification,
)
from plugcell.framework.participant import Participant

__all__ = ["Notifications"]


class Notifications:
    """The publications of one service (module docstring).

    Parameters
    ----------
    participant
        The service's participant (its bus, its envelope, its event loop).
    device
        The service's DeviceInfo, whose ``state`` and ``connection`` this writes.
    express_updates
        Send process samples without batching in Zenoh (the declaration's choice).
    """

    def __init__(self, participant: Participant, device: Device, *,
                 express_updates: bool = False) -> None:
        self.participant = participant
        self.device = device
        self.express_updates = express_updates
        self._publishers: dict[str, Any] = {}
        self._scheduled = False
        self._notified = (device.state, device.connection)

    @property
    def is_open(self) -> bool:
        """Whether the session is open (something can be sent)."""
        bus = self.participant.bus
        return bus is not None and bus.is_open

    # -- the receivers of the DeviceState and ConnectionState ports (5.2.3.2) -------------

    def device_state(self, state: DeviceStates) -> None:
        """DeviceStateHandler: write the state, notify StateUpdate (end of the turn)."""
        if state is not self.device.state:
            self.device.state = state
            self._notify_soon()

    def connection_state(self, connection: ConnectionStates) -> None:
        """ConnectionStateHandler: write the connection state, notify ConnectionUpdate."""
        if connection is not self.device.connection:
            self.device.connection = connection
            self._notify_soon()

    def _notify_soon(self) -> None:
        loop = self.participant.loop
        if not self._scheduled and loop is not None:
            self._scheduled = True
            loop.call_soon(self._notify_states)

    def _notify_states(self) -> None:
        self._scheduled = False
        device = self.device
        state, connection = device.state, device.connection
        if state is not self._notified[0] or connection is not self._notified[1]:
            device.last_updated = datetime.now(UTC)
        if state is not self._notified[0]:
            self.publish("state", StateUpdateNotification(name=device.name, state=state))
        if connection is not self._notified[1]:
            self.publish("connection",
                         ConnectionUpdateNotification(name=device.name, connection=connection))
        self._notified = (state, connection)

    # -- sending ----------------------------------------------------------------------

    def publish(self, kind: Notification, body: Message) -> None:
        """A state, connection or shutdown notification to the subscribed partners."""
        bus = self.participant.bus
        if bus is None or not bus.is_open:
            return
        with contextlib.suppress(zenoh.ZError):
            bus.notify(kind, self.device.name, self.participant.encode(body))

    def to_sender(self, sender: str, body: Message) -> None:
        """One sample for ``sender`` on its process key."""
        with contextlib.suppress(zenoh.ZError):
            self._publisher(sender).put(self.participant.encode(body))

    def _publisher(self, sender: str) -> Any:
        publisher = self._publishers.get(sender)
        if publisher is None:
            bus = self.participant.bus
            assert bus is not None
            publisher = bus.process_publisher(self.device.name, sender,
                                              express=self.express_updates)
            self._publishers[sender] = publisher
        return publisher

    def sender_left(self, name: str) -> None:
        """Drop the publisher of ``name`` (no instance of it is left in the cell)."""
        publisher = self._publishers.pop(name, None)
        if publisher is not None:
            with contextlib.suppress(zenoh.ZError):
                publisher.undeclare()

    def close(self) -> None:
        """Undeclare every publisher (the service is closing)."""
        for name in list(self._publishers):
            self.sender_left(name)
