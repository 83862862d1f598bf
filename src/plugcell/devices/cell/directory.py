"""The services and clients of the cell as the cell controller knows them (Figure 7-9).

Discovery — the controller follows the presence of every participant, keeps a record
of each service (alive or, once it has left, dead), fetches its state, subscribes to
it and refreshes all of them every few seconds — and the wires it asks services for:
each :class:`~plugcell.devices.cell.wiring.Wire` is asked of its service
(``ask_subscribe``), and the wanted ones are re-applied as soon as both of their
services are (back) in the cell (:class:`~plugcell.devices.cell.wiring.WiringKeeper`).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import AsyncIterator, Callable
from typing import Any

from plugcell.devices.cell.feed import UiFeed
from plugcell.devices.cell.monitor import ProcessMonitor
from plugcell.devices.cell.robot_states import RobotStreams
from plugcell.devices.cell.tasks import describe_command
from plugcell.devices.cell.wiring import Wire, WiringKeeper, wires_in_place
from plugcell.framework.keys import Presence
from plugcell.framework.messages import Device, GenericDeviceState
from plugcell.framework.participant import Participant, PartnerError, PresenceEvent

log = logging.getLogger("plugcell.devices.cell.service")

#: Seconds between two rounds of Get to every service (partners, i.e. the wiring).
REFRESH_PERIOD = 1.5

__all__ = ["REFRESH_PERIOD", "CellDirectory", "ServiceRecord"]


class ServiceRecord:
    """A service as the controller knows it (alive or not)."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.alive = False
        self.instance = ""
        self.device: Device | None = None
        self.partners: list[str] = []
        self.first_seen = time.time_ns()
        self.joined_ns = 0
        self.left_ns = 0

    def to_json(self, controller: str) -> dict[str, Any]:
        d = self.device
        return {
            "name": self.name,
            "alive": self.alive,
            "controller": self.name == controller,
            "instance": self.instance,
            "kind": d.kind if d else "",
            "vendor": d.vendor if d else "",
            "info": d.info if d else "",
            "state": d.state.value if d else "Unknown",
            "connection": d.connection.value if d else "Unknown",
            "commands": [describe_command(c) for c in d.commands] if d else [],
            "partners": list(self.partners),
            "joinedNs": self.joined_ns,
            "leftNs": self.left_ns,
        }



class CellDirectory:
    """The records of the cell's services and clients, kept current, and the wires asked
    for (module docstring), through the controller's ``participant`` (presence, Get,
    partners, wiring requests).  ``log(level, text)`` writes the controller's activity
    log; ``spawn(coro)`` runs a task the controller cancels when it closes."""

    def __init__(self, participant: Participant, *, feed: UiFeed, keeper: WiringKeeper,
                 monitor: ProcessMonitor, robots: RobotStreams,
                 log: Callable[[str, str], None], spawn: Callable[[Any], Any]) -> None:
        self.participant = participant
        self.feed = feed
        self.keeper = keeper
        self.monitor = monitor
        self.robots = robots
        self._log = log
        self._spawn = spawn
        self.records: dict[str, ServiceRecord] = {}
        self.clients: set[str] = set()
        self.refresh_now = asyncio.Event()
        """Set to refresh at once (a wiring was loaded)."""
        self._reapplying = asyncio.Lock()

    # -- discovery ---------------------------------------------------------------------

    async def follow(self, events: AsyncIterator[PresenceEvent]) -> None:
        """Presence events from before the controller started listed ``alive`` on."""
        async for event in events:
            self.presence(event.presence, joined=event.kind == "join")

    def presence(self, presence: Presence, *, joined: bool) -> None:
        """A participant joined or left the cell."""
        participant = self.participant
        if presence.role == "client":
            if joined:
                self.clients.add(presence.name)
            elif not participant.is_alive(presence.name, "client"):
                self.clients.discard(presence.name)
            self.feed.cell_changed()
            return
        record = self.records.get(presence.name)
        if record is None:
            record = self.records[presence.name] = ServiceRecord(presence.name)
        if joined:
            if record.alive and record.instance == presence.instance:
                return
            record.alive, record.instance = True, presence.instance
            record.joined_ns, record.left_ns = time.time_ns(), 0
            if presence.name != participant.name:
                self._log("info", f"{presence.name} joined the cell")
            self.keeper.reset_backoff(presence.name)
            self._spawn(self._adopt(presence.name))
        elif not participant.is_alive(presence.name):
            record.alive = False
            record.left_ns = time.time_ns()
            record.partners = []
            for lost in self.monitor.service_lost(presence.name):
                self.feed.process_changed(lost.key)
            for other in self.records.values():
                if presence.name in other.partners:
                    other.partners.remove(presence.name)
            self.robots.forget(presence.name)
            self._log("warning", f"{presence.name} left the cell")
        self.feed.cell_changed()

    async def _adopt(self, name: str) -> None:
        """A service appeared: fetch its state, subscribe to it, re-apply its wires."""
        try:
            state, _ = await self.participant.get(name, 3.0)
        except PartnerError as exc:
            self._log("error", f"{name}: {exc}")
            return
        self._update_record(state)
        if name != self.participant.name:
            try:
                await self.participant.subscribe(name, 3.0)
            except PartnerError as exc:
                self._log("error", f"cannot subscribe to {name}: {exc}")
        await self.reapply()
        self.feed.cell_changed()

    def _update_record(self, state: GenericDeviceState) -> None:
        info = state.device_info
        record = self.records.get(info.name)
        if record is None or not self.participant.is_alive(info.name):
            return
        partners = sorted(p.name for p in state.partners)
        if record.device is None or record.partners != partners or _differs(record.device, info):
            self.feed.cell_changed()
        record.device, record.partners = info, partners

    def partner_changed(self, partner: str) -> None:
        """A partner's StateUpdate/ConnectionUpdate (recorded in the service's Partners)."""
        record = self.records.get(partner)
        p = self.participant.partners.get(partner)
        if record is not None and p is not None:
            record.device = p.device
            self.feed.cell_changed()

    async def refresh_loop(self) -> None:
        """:meth:`refresh` every :data:`REFRESH_PERIOD` s, or at once when asked."""
        while True:
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self.refresh_now.wait(), REFRESH_PERIOD)
            self.refresh_now.clear()
            try:
                await self.refresh()
            except Exception:  # never let the loop die
                log.exception("%s: refresh failed", self.participant.name)

    def seen(self) -> None:
        """Take every participant the service knows to be alive (events missed)."""
        for (role, name), instances in list(self.participant.alive.items()):
            for instance in instances:
                self.presence(Presence(role, name, instance), joined=True)  # type: ignore[arg-type]

    async def refresh(self) -> None:
        """Get every service (partners = the wiring), then re-apply missing wires."""
        self.seen()
        for name, record in list(self.records.items()):
            if record.alive and not self.participant.is_alive(name):
                self.presence(Presence("service", name, record.instance), joined=False)
        for state in await self.participant.list_services(1.0):
            self._update_record(state)
        await self.reapply()

    # -- wires -------------------------------------------------------------------------

    def alive_set(self) -> set[str]:
        """The live services whose state is known."""
        return {n for n, r in self.records.items() if r.alive and r.device is not None}

    def partner_sets(self) -> dict[str, set[str]]:
        """Each live service's partners."""
        return {n: set(r.partners) for n, r in self.records.items() if r.alive}

    def wiring_now(self) -> list[Wire]:
        """The wires in place between the services of the cell (the controller's own left out)."""
        return wires_in_place({name: record.partners for name, record in self.records.items()
                               if record.alive and name != self.participant.name})

    async def ask(self, wire: Wire, subscribe: bool) -> tuple[bool, str]:
        """Ask ``wire``'s service to subscribe to (or drop) its partner: (ok, reason)."""
        participant = self.participant
        if wire.service == participant.name:
            return False, f"{participant.name} is the cell controller; wire other services"
        response = await participant.ask_subscribe(wire.service, wire.partner, subscribe, 5.0)
        record = self.records.get(wire.service)
        if response.ok and record is not None:
            if subscribe and wire.partner not in record.partners:
                record.partners = sorted([*record.partners, wire.partner])
            if not subscribe and wire.partner in record.partners:
                record.partners = [p for p in record.partners if p != wire.partner]
            self.feed.cell_changed()
        return response.ok, response.reason

    async def reapply(self) -> None:
        """Ask again for every wanted wire that is missing while both services are here."""
        async with self._reapplying:  # one round at a time: no wire is asked for twice
            results = await self.keeper.reapply(
                self.alive_set(), self.partner_sets(), lambda w: self.ask(w, True))
            for w, ok, reason in results:
                if ok:
                    self._log("info", f"re-applied {w}")
                else:
                    self._log("error", f"cannot re-apply {w}: {reason}")
            if results:
                self.feed.cell_changed()


def _differs(a: Device, b: Device) -> bool:
    return (a.state, a.connection, a.commands, a.info) != (b.state, b.connection, b.commands,
                                                           b.info)

