"""A participant of a cell: Zenoh session, presence, partners and outbound processes.

This is the *male adapter* side of every service (thesis 4.1.3.1, Figure 4-3):
the dynamic array of partners (``genericPort``/``genericNotify`` of 5.2.3.3) and
the outbound message handling of 5.2.3.6 — subscribing to a partner fetches its
DeviceInfo with ``Get``, ``create_process`` looks the command up in the partner's
catalogue, converts the data to the declared type and size, sends
``CreateProcess`` and returns a :class:`ProcessCall` (:mod:`plugcell.framework.calls`
keeps those calls).  A plain client (the CLI, a
script, a test) is a participant without the inbound side; a service
(:class:`~plugcell.framework.service.GenericDevice`) *holds* one (its ``participant``)
and adds the inbound side through two seams: ``declare``, run before the token goes
live, and :attr:`Participant.presence_listeners`.

Presence uses Zenoh liveliness tokens: a participant that dies without a
``Shutdown`` is noticed (its token disappears), its partners are removed and the
processes waiting on it end Failed with the reason.

Threading: all state lives in one asyncio event loop.  Zenoh callbacks only post
to a :class:`~plugcell.framework.port.Port`, whose items the loop hands to
:meth:`Participant._handle` in order.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import logging
import os
import re
import socket
import time
import weakref
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from typing import Any

import zenoh

from plugcell.framework import codec
from plugcell.framework.bus import Bus, QueryDoor
from plugcell.framework.calls import Calls, PartnerError
from plugcell.framework.keys import DEFAULT_CELL, KeySpace, Presence, Role, check_name
from plugcell.framework.memory import tune_allocator
from plugcell.framework.messages import (
    Device,
    GenericDeviceState,
    GetRequest,
    Message,
    ProcessUpdateNotification,
    ShutdownNotification,
    SubscribeRequest,
    SubscribeResponse,
    UnsubscribeRequest,
    process_updates,
)
from plugcell.framework.port import Port
from plugcell.framework.process_call import ProcessCall
from plugcell.framework.signing import RequestSigner, certificate_name, is_request
from plugcell.framework.transport import TransportConfig

log = logging.getLogger("plugcell.framework")

#: How long ``create_process`` waits for an unknown partner to appear before failing.
DISCOVERY_GRACE = 1.0


@dataclass
class Partner:
    """One entry of the Partners array (Table 5-1) with its notification subscriber."""

    device: Device
    instance: str
    subscriber: Any = None


@dataclass(frozen=True)
class PresenceEvent:
    """A participant joined or left the cell (``kind`` is ``"join"`` or ``"leave"``)."""

    kind: str
    presence: Presence


class PresenceEvents:
    """The join/leave events of a cell, from the :meth:`Participant.events` call on.

    An async iterator.  The participant holds it weakly: a stream that its owner
    drops — iterated or not, left by ``break`` or never started — stops collecting
    events as soon as it is garbage; :meth:`aclose` ends it explicitly.
    """

    def __init__(self) -> None:
        self._queue: asyncio.Queue[PresenceEvent | None] = asyncio.Queue()
        self._closed = False

    def _put(self, event: PresenceEvent) -> None:
        if not self._closed:
            self._queue.put_nowait(event)

    def __aiter__(self) -> PresenceEvents:
        return self

    async def __anext__(self) -> PresenceEvent:
        event = None if self._closed else await self._queue.get()
        if event is None:
            raise StopAsyncIteration
        return event

    async def aclose(self) -> None:
        """Stop collecting and end the iteration, a waiting one included (what was
        collected and not taken is dropped)."""
        self._closed = True
        waiting, self._queue = self._queue, asyncio.Queue()
        waiting.put_nowait(None)  # ends an __anext__ that waits on it

    def __len__(self) -> int:
        """Events collected and not yet taken."""
        return self._queue.qsize()


@dataclass
class _Pending:
    replies: list[Any] = field(default_factory=list)
    done: asyncio.Future[None] | None = None


_client_numbers = itertools.count(1)


def default_client_name(prefix: str = "client") -> str:
    """A unique name for a client: ``<prefix>-<host>-<pid>`` (``-<n>`` after the first)."""
    host = re.sub(r"[^A-Za-z0-9_.\-]", "-", socket.gethostname())[:24] or "host"
    n = next(_client_numbers)
    return f"{prefix}-{host}-{os.getpid()}" + (f"-{n}" if n > 1 else "")


class Participant:
    """Everything that takes part in a cell: a client, or the participant a service
    (:class:`~plugcell.framework.service.GenericDevice`) holds — then with ``role``
    ``"service"`` (its presence token says so) and ``declare``, awaited by :meth:`start`
    once the session is open and presence followed, before the token goes live."""

    def __init__(
        self,
        name: str | None = None,
        *,
        cell: str = DEFAULT_CELL,
        transport: TransportConfig | None = None,
        role: Role = "client",
        declare: Callable[[], Awaitable[None]] | None = None,
    ) -> None:
        self.name = check_name(name or default_client_name(), "participant name")
        self.role: Role = role
        self._declare = declare
        self.keys = KeySpace(cell)
        self.transport = transport or TransportConfig.from_env()
        self.instance = ""
        self.partners: dict[str, Partner] = {}
        self.alive: dict[tuple[str, str], set[str]] = {}
        """``(role, name)`` → live instances, from liveliness tokens."""
        self.bus: Bus | None = None
        """The transport adapter (framework/bus.py), from :meth:`start`."""
        self._loop: asyncio.AbstractEventLoop | None = None
        self._port: Port[tuple[Callable[[Any], None], Any]] | None = None
        self._entities: list[Any] = []
        self._token: Any = None
        self.calls = Calls(self)
        """The processes this participant created and waits on (framework/calls.py)."""
        self.partner_listeners: list[Callable[[str, Message], None]] = []
        """Told ``(partner, body)`` of each partner's StateUpdate/ConnectionUpdate, once
        Partners is current (a cell controller or gateway showing the cell)."""
        self.presence_listeners: list[Callable[[Presence, bool], None]] = []
        """Told ``(presence, joined)`` of each join and leave of the cell, once
        :attr:`alive` (and, on a leave, Partners and the waiting processes) are current
        (a service refuses a second one of its name, forgets a sender that left)."""
        self._presence_changed = asyncio.Event()
        self._watchers: weakref.WeakSet[PresenceEvents] = weakref.WeakSet()
        self._closed = False
        self._started = False
        self.signer: RequestSigner | None = None
        """Signs this participant's requests (set at :meth:`start` from the transport's
        certificate and key, unless set before; docs/security.md, "Signed requests")."""

    # -- life cycle ----------------------------------------------------------------------

    async def start(self) -> None:
        """Open the session, watch presence, run ``declare`` (if given), then go live."""
        tune_allocator()  # large frames reuse memory instead of faulting in fresh pages
        self._loop = asyncio.get_running_loop()
        self._port = Port(self._loop, self._handle)
        if self.signer is None:
            self.signer = RequestSigner.from_transport(self.transport)
            if self.signer is not None and self.signer.name != self.name:
                log.warning(
                    "%s: signing requests with the certificate of %s: services that check "
                    "signatures will refuse them (give this participant the name %s)",
                    self.name, self.signer.name, self.signer.name,
                )
        cert = self.transport.tls_cert
        self.calls.publishes_requests = not cert or certificate_name(cert) == self.name
        self.bus = bus = await asyncio.to_thread(
            Bus.connect, self.transport, self.keys, self._port.post)
        # incarnation id: start time first, so instances of one name order by age
        self.instance = f"{time.time_ns():016x}{bus.zid}"
        self._entities.append(bus.follow_processes(self.name, self.calls.on_process_update))
        self._entities.append(bus.watch_presence(self._on_presence))
        if self._declare is not None:
            await self._declare()
        self._token = bus.announce(self.role, self.name, self.instance)
        self._started = True

    @property
    def session(self) -> zenoh.Session | None:
        """The raw Zenoh session (None before :meth:`start`) — for tests that inject
        what no participant would send; plugcell itself goes through :attr:`bus`."""
        return self.bus.session if self.bus is not None else None

    @property
    def loop(self) -> asyncio.AbstractEventLoop | None:
        """The event loop this participant lives on (None before :meth:`start`)."""
        return self._loop

    @property
    def started(self) -> bool:
        """Whether :meth:`start` went through (its token went live)."""
        return self._started

    def own(self, entity: Any) -> Any:
        """Keep a Zenoh declaration until :meth:`close` undeclares it; return it."""
        self._entities.append(entity)
        return entity

    async def close(self) -> None:
        """Fail what still waits, withdraw the token and close the session."""
        if self._closed:
            return
        self._closed = True
        self.calls.fail_all(f"{self.name} is closing")
        bus = self.bus
        if bus is not None:
            with contextlib.suppress(zenoh.ZError):
                if self._token is not None:
                    self._token.undeclare()
                for partner in self.partners.values():
                    if partner.subscriber is not None:
                        partner.subscriber.undeclare()
                self.calls.close_doors()
                for entity in reversed(self._entities):
                    entity.undeclare()
            await asyncio.to_thread(bus.close)
        self.partners.clear()
        if self._port is not None:
            self._port.close()

    async def __aenter__(self) -> Participant:
        await self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    # -- plumbing --------------------------------------------------------------------------

    def _handle(self, items: list[tuple[Callable[[Any], None], Any]]) -> None:
        """Run the handler of each item the Zenoh callbacks posted, in order."""
        for handler, item in items:
            try:
                handler(item)
            except Exception:  # a bad message must not stop the participant
                log.exception("%s: error handling %s", self.name, handler.__name__)

    def encode(self, body: Message, to: str = "") -> bytes:
        """The envelope of ``body``; a request to service ``to`` is signed when this
        participant has a :attr:`signer` (bound to ``to``'s instance when it is known)."""
        if to and self.signer is not None and is_request(body):
            sign = self.signer.signer(self.keys.cell, to, self._instance_of(to))
            return codec.encode(self.name, self.instance, body, sign)
        return codec.encode(self.name, self.instance, body)

    def _instance_of(self, service: str) -> str:
        """The one live instance of ``service`` known here (else ``""``: any)."""
        live = self.alive.get(("service", service), set())
        partner = self.partners.get(service)
        if partner is not None and live == {partner.instance}:
            return partner.instance
        return next(iter(live)) if len(live) == 1 and partner is None else ""

    async def _query(
        self,
        door: QueryDoor,
        name: str,
        body: Message | None,
        timeout: float,
        *,
        everyone: bool = False,
        to: str = "",
    ) -> list[codec.Envelope | str]:
        """Query service ``name``'s ``door``; each reply decoded, or the error text of a
        bad one."""
        assert self.bus is not None and self._loop is not None
        pending = _Pending(done=self._loop.create_future())

        def done(_: Any) -> None:
            if pending.done is not None and not pending.done.done():
                pending.done.set_result(None)

        self.bus.query(door, name, self.encode(body, to) if body is not None else None,
                       pending.replies.append, done, timeout=timeout, everyone=everyone)
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(asyncio.shield(pending.done), timeout + 1.0)  # type: ignore[arg-type]
        out: list[codec.Envelope | str] = []
        for reply in list(pending.replies):
            if reply.ok is None:
                out.append(_text(reply.err.payload.to_bytes()) if reply.err else "error reply")
                continue
            try:
                out.append(codec.decode(reply.ok.payload.to_bytes()))
            except codec.WireError as exc:
                out.append(str(exc))
        return out

    # -- presence ------------------------------------------------------------------------

    def _on_presence(self, presence: Presence, joined: bool) -> None:
        key = (presence.role, presence.name)
        if joined:
            self.alive.setdefault(key, set()).add(presence.instance)
            event = PresenceEvent("join", presence)
        else:
            instances = self.alive.get(key, set())
            instances.discard(presence.instance)
            if not instances:
                self.alive.pop(key, None)
            event = PresenceEvent("leave", presence)
            self._on_left(presence)
        for listener in self.presence_listeners:
            listener(presence, joined)
        self._presence_changed.set()
        for watcher in list(self._watchers):
            watcher._put(event)

    def _on_left(self, presence: Presence) -> None:
        """A participant's token disappeared: drop it as a partner, fail what waits on it."""
        if presence.role != "service":
            return
        partner = self.partners.get(presence.name)
        reason = f"service {presence.name} lost (liveliness token withdrawn)"
        if partner is not None and partner.instance == presence.instance:
            self._drop_partner(presence.name)
        self.calls.fail_partner(presence.name, presence.instance, reason)

    def services(self) -> list[str]:
        """Names of the services currently alive in the cell."""
        return sorted(name for role, name in self.alive if role == "service")

    def is_alive(self, name: str, role: Role = "service") -> bool:
        return (role, name) in self.alive

    async def wait_for(self, name: str, timeout: float = 10.0, role: Role = "service") -> bool:
        """Wait until ``name`` is alive in the cell; False after ``timeout`` seconds."""
        return await self._wait_presence(name, role, True, timeout)

    async def wait_gone(self, name: str, timeout: float = 10.0, role: Role = "service") -> bool:
        """Wait until no instance of ``name`` is alive; False after ``timeout`` seconds."""
        return await self._wait_presence(name, role, False, timeout)

    async def _wait_presence(self, name: str, role: Role, alive: bool, timeout: float) -> bool:
        deadline = time.monotonic() + timeout
        while self.is_alive(name, role) is not alive:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                return False
            self._presence_changed.clear()
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self._presence_changed.wait(), remaining)
        return True

    def events(self) -> PresenceEvents:
        """Join/leave events from this call on (iterate in a task; stop by breaking out).

        The events are collected from the call, not from the first iteration: nothing
        that happens before the iterating task first runs is missed.  Dropping the
        stream — or :meth:`PresenceEvents.aclose` — stops the collecting.
        """
        stream = PresenceEvents()
        self._watchers.add(stream)
        return stream

    # -- generic interface of others -------------------------------------------------------

    async def get(self, name: str, timeout: float = 5.0) -> tuple[GenericDeviceState, str]:
        """``Get`` on service ``name``: its generic state and the answering instance."""
        check_name(name, "service name")
        replies = await self._query("get", name, GetRequest(), timeout)
        for reply in replies:
            if isinstance(reply, codec.Envelope) and isinstance(reply.body, GenericDeviceState):
                return reply.body, reply.instance
        if replies:
            raise PartnerError(f"{name}: bad answer to Get: {replies[0]}")
        raise PartnerError(f"unknown device {name!r}: no such service in cell {self.keys.cell!r}")

    async def list_services(self, timeout: float = 3.0) -> list[GenericDeviceState]:
        """Ask every service of the cell for its generic state (one wildcard Get)."""
        replies = await self._query("get", "*", GetRequest(), timeout, everyone=True)
        states = [
            r.body
            for r in replies
            if isinstance(r, codec.Envelope) and isinstance(r.body, GenericDeviceState)
        ]
        return sorted(states, key=lambda s: s.device_info.name)

    async def subscribe(self, partner: str, timeout: float = 5.0) -> Device:
        """Subscribe to ``partner`` (4.1.3.1): Get its DeviceInfo, add it to Partners."""
        check_name(partner, "partner name")
        if partner == self.name:
            raise PartnerError(f"{self.name} cannot subscribe to itself")
        if not self.is_alive(partner):
            await self.wait_for(partner, min(timeout, DISCOVERY_GRACE))
        state, instance = await self.get(partner, timeout)
        assert self.bus is not None
        old = self.partners.pop(partner, None)
        if old is not None and old.subscriber is not None:
            old.subscriber.undeclare()
        subscriber = self.bus.follow_notifications(partner, self._on_notification)
        self.partners[partner] = Partner(state.device_info, instance, subscriber)
        return state.device_info

    async def unsubscribe(self, partner: str) -> bool:
        """Drop ``partner`` from Partners; its pending processes end Failed."""
        found = self._drop_partner(partner)
        self.calls.fail_partner(partner, None, f"{self.name} unsubscribed from {partner}")
        return found

    def _drop_partner(self, name: str) -> bool:
        partner = self.partners.pop(name, None)
        if partner is None:
            return False
        if partner.subscriber is not None:
            with contextlib.suppress(zenoh.ZError):
                partner.subscriber.undeclare()
        return True

    def _on_notification(self, sample: zenoh.Sample) -> None:
        try:
            envelope = codec.decode(sample.payload.to_bytes())
        except codec.WireError as exc:
            log.warning("%s: bad notification on %s: %s", self.name, sample.key_expr, exc)
            return
        body = envelope.body
        partner = self.partners.get(envelope.sender)
        if isinstance(body, ShutdownNotification):
            reason = f"service {body.name} shut down" + (f": {body.reason}" if body.reason else "")
            if partner is not None and partner.instance == envelope.instance:
                self._drop_partner(envelope.sender)
            self.calls.fail_partner(envelope.sender, envelope.instance, reason)
        elif partner is not None:
            self.on_partner_notification(envelope.sender, body)

    def on_partner_notification(self, partner: str, body: Message) -> None:
        """A StateUpdate/ConnectionUpdate of a partner: keep its DeviceInfo current, then
        tell each of :attr:`partner_listeners`."""
        p = self.partners.get(partner)
        if p is None:
            return
        state = getattr(body, "state", None)
        connection = getattr(body, "connection", None)
        if state is not None:
            p.device.state = state
        if connection is not None:
            p.device.connection = connection
        for listener in self.partner_listeners:
            listener(partner, body)

    async def ask_subscribe(
        self, service: str, partner: str, subscribe: bool = True, timeout: float = 10.0
    ) -> SubscribeResponse:
        """Make ``service`` subscribe to (or drop) ``partner`` at run time (``plugcell wire``)."""
        body: Message = (
            SubscribeRequest(partner=partner) if subscribe else UnsubscribeRequest(partner=partner)
        )
        replies = await self._query("subscribe", service, body, timeout, to=service)
        for reply in replies:
            if isinstance(reply, codec.Envelope) and isinstance(reply.body, SubscribeResponse):
                return reply.body
        if replies:
            return SubscribeResponse(ok=False, reason=f"bad answer from {service}: {replies[0]}")
        return SubscribeResponse(
            ok=False,
            reason=f"unknown device {service!r}: no such service in cell {self.keys.cell!r}",
        )

    # -- outbound processes (5.2.3.6; framework/calls.py) ---------------------------------

    async def create_process(
        self,
        partner: str,
        command: str,
        option: str = "",
        data: Any = None,
        *,
        timeout: float = 10.0,
        check: bool = True,
    ) -> ProcessCall:
        """Create a process at ``partner`` and return it once acknowledged
        (:meth:`Calls.create <plugcell.framework.calls.Calls.create>`)."""
        return await self.calls.create(partner, command, option, data, timeout=timeout,
                                       check=check)

    async def stop_process(
        self, call: ProcessCall, command: str | None = None, timeout: float | None = None
    ) -> ProcessCall:
        """Send the StopData command that ends ``call`` (a MultipleData process).

        ``command`` defaults to the first StopData command of the partner's catalogue.
        """
        return await self.calls.stop(call, command, timeout)


    def watch_processes(
        self, handler: Callable[[str, ProcessUpdateNotification], None]
    ) -> Any:
        """Follow every ProcessUpdate of the cell, whoever sent the process (a cell
        controller's monitor, thesis 7.6): ``handler(service, update)`` runs on the event
        loop for each update.  Returns the Zenoh subscriber: ``undeclare()`` it to stop
        (a participant's own declarations end with it)."""
        assert self.bus is not None, "watch_processes before start()"

        def on_sample(service: str, sample: zenoh.Sample) -> None:
            try:
                envelope = codec.decode(sample.payload.to_bytes())
            except codec.WireError:
                return
            for update in process_updates(envelope.body):
                handler(service, update)

        return self.bus.watch_processes(on_sample)



def _text(raw: bytes) -> str:
    return raw.decode("utf-8", "replace")
