"""The GenericDevice service: the framework object that hosts one device.

Thesis 4.1.3.1 and 5.2.2–5.2.3.  A service holds a :class:`Participant` (its
``participant``: session, presence, partners, outbound processes) and adds the *female
adapter*, the Generic Interface (Table 5-2):

* ``Get`` → the generic state: DeviceInfo with its command catalogue, Partners;
* ``Subscribe``/``Unsubscribe`` a partner at run time (``plugcell wire``);
* ``CreateProcess`` → acknowledgement, after the process is checked and journaled;
* the notifications ``ProcessUpdate``, ``StateUpdate``, ``ConnectionUpdate``, ``Shutdown``.

A device is *composed* into a service, not derived from it: it is a
:class:`DeviceInterface` — a :class:`~plugcell.framework.declaration.Declaration`
(kind, names, catalogue: what ``StateInitialize`` declares) and the device interface
layer of Figure 5-10, the CommandDispatcher (``dispatch``), usually in front of a
driver of its device family.  ``GenericDevice(device, name, cell=…)`` hosts it: the
device reports through the service's ports of Table 5-3 (``data_feedback``,
``cmd_feedback``, ``device_state``, ``connection_state``), which the service hands it
once through the device's ``bind``; queueing, re-scheduling, notifications, partners,
discovery, the journal and the access policy are the service's.

The ProcessHandler (5.2.3.4, Figure 5-12; :mod:`plugcell.framework.scheduler`) takes
one process at a time from the
:class:`~plugcell.framework.processqueue.ProcessQueue`: it posts Running, sets the
device Busy, dispatches the command and waits — with the command's timeout — for
the command feedback; data feedback becomes ProcessUpdates.  A MultipleData
process holds the device until the StopData of the same sender (5.2.3.5), until
its sender disappears, or until its timeout.

Update sequence seen by the sender (plugcell makes every process end with exactly
one final update):

* NoData, StopData: Running → Completed | Failed
* SingleData: Running → Completed with the data | Failed  (command + data feedback in
  one notification, 5.2.1.1 b)
* MultipleData: Running → Running with data × n → Completed once the StopData of the
  same sender completes | Failed.  (In the thesis the MultipleData process reports
  Completed on its command feedback and keeps streaming; here it stays Running.)
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import threading
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any, Generic, Protocol, TypeVar

import zenoh

from plugcell.framework import codec
from plugcell.framework.data import summary
from plugcell.framework.declaration import Declaration, check_catalogue
from plugcell.framework.inbound import Inbound
from plugcell.framework.journal import Journal, JournalInUseError, NullJournal, journal_dir
from plugcell.framework.keys import DEFAULT_CELL, Presence
from plugcell.framework.messages import (
    Command,
    ConnectionStates,
    Data,
    DeviceStates,
    GenericDeviceState,
    Message,
    ProcessStates,
    ProcessUpdateNotification,
    ShutdownNotification,
)
from plugcell.framework.notifications import Notifications
from plugcell.framework.outbox import Outbox
from plugcell.framework.participant import Participant, PartnerError
from plugcell.framework.process_call import ProcessCall
from plugcell.framework.processqueue import Entry
from plugcell.framework.scheduler import DeviceError, ProcessScheduler
from plugcell.framework.security import AccessPolicy, Recipient
from plugcell.framework.transport import TransportConfig

log = logging.getLogger("plugcell.framework.service")

T = TypeVar("T")


def _deprecated(method: str) -> None:
    warnings.warn(f"GenericDevice.{method} is deprecated: use service.participant.{method} "
                  "(the participant the service holds, issue #33)", DeprecationWarning,
                  stacklevel=3)


class FeedbackPort(Generic[T]):
    """One port of Table 5-3, fed by the device interface (``post`` from any thread)."""

    def __init__(self, service: GenericDevice, handler: Callable[[T], None], name: str) -> None:
        self._service = service
        self._handler = handler
        self.name = name

    def post(self, value: T) -> None:
        """Deliver ``value`` to the service's receiver (5.2.3.2)."""
        if not self._service.call_in_loop(self._handler, value):
            raise RuntimeError(f"{self.name}.post before the service started")


class DeviceInterface(Protocol):
    """The device side of a service (Figure 5-10, the "Camera Interface"): what a device
    family implements and the framework hosts — a :class:`Declaration` and the
    CommandDispatcher.  A device does not subclass the framework: a
    :class:`GenericDevice` is made *with* one and hands itself to :meth:`bind`.

    Optional methods (looked up when present): ``async connect()`` and
    ``async disconnect()`` — open and close the link to the device at start (once the
    service is live in the cell) and at shutdown (after the last process), the service
    then reporting Online, Offline; ``async prepare_close()`` — end what the device runs
    on its own before the service stops taking and running processes; and
    ``on_partner_notification(partner, body)`` — a partner's StateUpdate or
    ConnectionUpdate (after the service has recorded it).
    """

    declaration: Declaration

    def bind(self, service: GenericDevice) -> None:
        """Take the service that hosts this device: its feedback ports (``data_feedback``,
        ``cmd_feedback``, ``device_state``, ``connection_state``), ``sender``, ``note``
        and, for a device that creates processes itself, its ``participant``."""

    async def dispatch(self, command: Command, option: str, data: Any) -> str | None:
        """CommandDispatcher: send ``command`` to the device.

        ``data`` is the checked input (an n-D numpy array of the declared type and
        size, or None).  Return the device's command feedback code (compared with
        ``command.success_code``), or None if the device will post it later on the
        service's ``cmd_feedback``.  Report data on its ``data_feedback``.  Raise
        :class:`DeviceError` to fail the process with a reason.  For a MultipleData
        command, start the stream and return; the StopData command stops it.
        """
        ...


class GenericDevice:
    """The service that hosts one device (module docstring): ``GenericDevice(device)``.

    It owns the participant (:attr:`participant`: session, presence, partners, outbound
    processes), the scheduler, the outbox, the journal, the access policy and the
    inbound doors (:class:`~plugcell.framework.inbound.Inbound`); the device (a
    :class:`DeviceInterface`) brings its declaration and its dispatcher.  Not meant to
    be subclassed.
    """

    def __init__(
        self,
        interface: DeviceInterface,
        name: str | None = None,
        *,
        cell: str = DEFAULT_CELL,
        transport: TransportConfig | None = None,
        journal: bool | Path = True,
        max_payload: int = codec.DEFAULT_MAX_PAYLOAD,
        access: AccessPolicy | None = None,
    ) -> None:
        declaration = interface.declaration
        if not isinstance(declaration, Declaration):
            raise TypeError(f"{type(interface).__name__}.declaration is not a Declaration")
        participant = Participant(declaration.name(name), cell=cell, transport=transport,
                                  role="service", declare=self._declare)
        participant.transport = participant.transport.for_participant(participant.name)
        participant.presence_listeners.append(self._on_presence)
        self.participant = participant
        """This service as a participant of the cell: session (``bus``), presence
        (``alive``, ``events()``, ``wait_for``), ``partners``, and the processes it creates
        itself (``create_process``, ``stop_process``) — what a device that sends processes
        (the robot, the cell controller) uses."""
        self.name = participant.name
        """The service's name in the cell."""
        self.cell = participant.keys.cell
        """The cell it serves in."""
        self.interface = interface
        """The device this service hosts (its declaration and dispatcher)."""
        self.declaration = declaration
        self.access = access if access is not None else AccessPolicy.from_env()
        """Who may create processes here and wire this service (docs/security.md)."""
        self.device = declaration.device_info(self.name)
        """Its DeviceInfo (Table 5-1), with the current state and connection."""
        self.max_payload = max_payload
        self._journal_setting = journal
        self.journal: Journal | NullJournal = NullJournal()
        self.scheduler = ProcessScheduler(
            self.name, self.device, update=self._update, busy=self._busy,
            heartbeat=self._heartbeat,
            # looked up per call: a test may replace dispatch on the device
            dispatch=lambda command, option, data: self.interface.dispatch(
                command, option, data))
        """Queue, holds, heartbeats and timeouts of the processes (framework/scheduler.py)."""
        # the ports of Table 5-3
        self.data_feedback: FeedbackPort[Any] = FeedbackPort(
            self, self.scheduler.on_data, "DataFeedback")
        self.cmd_feedback: FeedbackPort[str] = FeedbackPort(
            self, self.scheduler.on_cmd, "CmdFeedback")
        self.notifications = Notifications(participant, self.device,
                                           express_updates=declaration.express_updates)
        """StateUpdate, ConnectionUpdate, Shutdown; each sender's process samples."""
        self.device_state: FeedbackPort[DeviceStates] = FeedbackPort(
            self, self.notifications.device_state, "DeviceState")
        self.connection_state: FeedbackPort[ConnectionStates] = FeedbackPort(
            self, self.notifications.connection_state, "ConnectionState")
        self._loop_thread = 0
        self.departed: set[str] = set()
        """Incarnations of senders that have left (their late requests are refused)."""
        self._closing = False
        self.outbox = Outbox(self.name, commit=lambda: self.journal.commit(),
                             reply=self.reply, publish=self.notifications.to_sender,
                             is_open=lambda: self.notifications.is_open)
        """Acknowledgements and updates of this turn of the loop (framework/outbox.py)."""
        self._create_doors: list[Any] = []
        """The queryable ``svc/<name>/create`` and the subscriber ``svc/<name>/create/*``."""
        self.conflict = ""
        """Why this service withdrew because another one has its name (else empty)."""
        self.stopped = asyncio.Event()
        """Set once the service has shut down (by :meth:`close` or a name conflict)."""
        self.recipient = Recipient(self.name, self.cell)
        """This service as its access policy sees it (complete once it has started)."""
        self.inbound = Inbound(self)
        """Its doors Subscribe and CreateProcess, and the admission of each request."""
        listener = getattr(interface, "on_partner_notification", None)
        if listener is not None:  # the device shows its partners' states
            participant.partner_listeners.append(listener)
        interface.bind(self)

    # -- what the device uses ---------------------------------------------------------------

    @property
    def sender(self) -> str:
        """Who asked for the process being dispatched (its sender's participant name).

        Set while the device's ``dispatch`` runs a process from the queue; ``""`` when
        the framework itself calls it (e.g. to stop the stream of a sender that
        disappeared).  Devices that keep per-requester state (the tracker's BASE and
        PROBE, the compute service's workspaces) key it by this name.
        """
        return self.scheduler.sender

    @property
    def closing(self) -> bool:
        """Whether the service is shutting down (or has shut down)."""
        return self._closing

    @property
    def stray_feedback(self) -> int:
        """Data/command feedback that arrived when no process expected it."""
        return self.scheduler.stray_feedback

    def call_in_loop(self, fn: Callable[..., Any], *args: Any) -> bool:
        """Run ``fn(*args)`` on the service's event loop: at once when called there, else
        scheduled thread-safely (so device threads can feed the service).  False when the
        service has not started; a call after the loop closed is dropped (the service is
        gone)."""
        loop = self.participant.loop
        if loop is None:
            return False
        if threading.get_ident() == self._loop_thread:
            fn(*args)
        else:
            with contextlib.suppress(RuntimeError):  # loop closed: the service is gone
                loop.call_soon_threadsafe(fn, *args)
        return True

    def note(self, text: str) -> None:
        """Remark on the NoData or SingleData process being dispatched — a warning its
        sender should see although the process succeeds (e.g. "target 3 lies outside the
        calibrated region").  The notes (joined by ``"; "``) become the ``reason`` of the
        process's ``Completed`` update, which is otherwise empty; a Failed process keeps
        its own reason."""
        self.scheduler.note(text)

    def own(self, entity: Any) -> Any:
        """Keep a Zenoh declaration of the device (a publisher, a subscriber) until the
        service closes, which undeclares it; returns ``entity``."""
        return self.participant.own(entity)

    async def create_process(self, partner: str, command: str, option: str = "",
                             data: Any = None, **options: Any) -> ProcessCall:
        """Deprecated: ``service.participant.create_process`` (issue #33)."""
        _deprecated("create_process")
        return await self.participant.create_process(partner, command, option, data,
                                                     **options)

    async def stop_process(self, call: ProcessCall, command: str | None = None,
                           timeout: float | None = None) -> ProcessCall:
        """Deprecated: ``service.participant.stop_process`` (issue #33)."""
        _deprecated("stop_process")
        return await self.participant.stop_process(call, command, timeout)

    # -- life cycle ----------------------------------------------------------------------

    async def start(self) -> None:
        """Go live in the cell, connect the device, run the ProcessHandler."""
        self._loop_thread = threading.get_ident()
        self.outbox.loop = asyncio.get_running_loop()
        try:
            await self.participant.start()
            # processes sent while the device connects wait in the queue, and their
            # senders hear the Queued heartbeat (a controller may take its time)
            self.scheduler.admit()
            connect = getattr(self.interface, "connect", None)
            if connect is not None:
                await connect()
            self.connection_state.post(ConnectionStates.Online)
        except BaseException:
            await self.close()
            raise
        self.scheduler.start()

    async def _declare(self) -> None:
        """Refuse a duplicate name, open the journal, declare the Generic Interface."""
        participant = self.participant
        bus = participant.bus
        assert bus is not None
        if self.access.identity == "signed":
            self.inbound.request_verifier()  # no CA: refuse to start, with the reason
        if (await self._query_live_instances()
                or participant.alive.get(("service", self.name))):
            raise PartnerError(
                f"a service named {self.name} is already running in cell {self.cell!r}"
            )
        self._open_journal()
        self.recipient = Recipient(
            name=self.name, cell=self.cell, instance=participant.instance,
            identities=bus.link_identities, role_of=self.inbound.role_of,
            verifier=self.inbound.request_verifier)
        """This service as its access policy sees it (framework/security.py)."""
        participant.own(bus.serve("get", self.name, self._on_get))
        participant.own(bus.serve("subscribe", self.name, self.inbound.on_subscribe))
        # undeclared first when the service closes (no new process), not with the rest
        self._create_doors = [
            bus.serve("create", self.name, self.inbound.on_create),
            bus.take_requests(self.name, self.inbound.on_request),
        ]

    def _open_journal(self) -> None:
        if not self._journal_setting:
            return
        folder = (
            self._journal_setting
            if isinstance(self._journal_setting, Path)
            else journal_dir(self.cell)
        )
        try:
            self.journal = Journal(folder / f"{self.name}.sqlite", self.name)
        except JournalInUseError as exc:
            raise PartnerError(
                f"a service named {self.name} is already running on this host ({exc})"
            ) from None
        recovered = self.journal.recover(
            f"interrupted: {self.name} stopped before the process finished"
        )
        if recovered:
            log.warning(
                "%s: %d unfinished processes of a previous run marked Failed", self.name, recovered
            )

    async def _query_live_instances(self) -> list[Presence]:
        """The live instances of this service's name (another one already running?)."""
        bus, loop = self.participant.bus, self.participant.loop
        assert bus is not None and loop is not None
        done = loop.create_future()
        found: list[Presence] = []

        def on_done(_: Any) -> None:
            if not done.done():
                done.set_result(None)

        bus.find_service(self.name, found.append, on_done, timeout=1.0)
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(done, 3.0)
        return found

    async def close(self, reason: str = "service shutting down") -> None:
        """Shutdown: refuse new processes, fail queued ones, stop the running one,
        notify ``Shutdown`` (5.2.3.6), withdraw the token, close the journal."""
        if self._closing:  # a close is already under way (or done)
            await self.stopped.wait()
            return
        self._closing = True
        prepare = getattr(self.interface, "prepare_close", None)
        if prepare is not None:  # the device ends what it runs on its own first
            with contextlib.suppress(Exception):
                await prepare()
        for door in self._create_doors:
            with contextlib.suppress(zenoh.ZError):
                door.undeclare()
        self._create_doors = []
        self.scheduler.shut(f"{self.name}: {reason}")
        await self.scheduler.stop()  # after the current process (bounded by its timeout)
        if self.participant.bus is not None and self.participant.started:
            with contextlib.suppress(Exception):
                disconnect = getattr(self.interface, "disconnect", None)
                if disconnect is not None:
                    await disconnect()
                self.connection_state.post(ConnectionStates.Offline)
            self.notifications.publish(
                "shutdown", ShutdownNotification(name=self.name, reason=reason))
        self.outbox.flush()
        self.notifications.close()
        # nothing is journaled after the last flush: release the journal (and its
        # lock) before the token goes, so a successor started on our leave can open it
        self.journal.close()
        await self.participant.close()
        self.stopped.set()

    async def __aenter__(self) -> GenericDevice:
        await self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    # -- inbound: Get, Subscribe, CreateProcess (Table 5-2) ----------------------------

    def reply(self, query: zenoh.Query, body: Message) -> None:
        """Answer ``query`` with ``body`` (then drop it)."""
        with contextlib.suppress(zenoh.ZError):
            query.reply(query.key_expr, self.participant.encode(body))
        query.drop()

    def generic_state(self) -> GenericDeviceState:
        """The generic state (Table 5-1): DeviceInfo and Partners."""
        return GenericDeviceState(
            device_info=self.device,
            partners=[p.device for p in self.participant.partners.values()],
        )

    def _on_get(self, query: zenoh.Query) -> None:
        self.reply(query, self.generic_state())

    # -- presence of senders -------------------------------------------------------------

    def _on_presence(self, presence: Presence, joined: bool) -> None:
        """The participant's presence listener: a name conflict on a join, a departed
        sender on a leave."""
        if joined:
            self._on_joined(presence)
        else:
            self._on_left(presence)

    def _on_joined(self, presence: Presence) -> None:
        """Two live services with one name: the younger withdraws (the older keeps serving)."""
        instance = self.participant.instance
        if (
            presence.role == "service"
            and presence.name == self.name
            and presence.instance != instance
            and presence.instance < instance
            and self.participant.started  # before that, _declare refuses to start instead
            and not self._closing
        ):
            self.conflict = (
                f"a service named {self.name} is already running in cell {self.cell!r}"
            )
            log.error("%s: %s; withdrawing", self.name, self.conflict)
            asyncio.get_running_loop().create_task(self.close(self.conflict))

    def _on_left(self, presence: Presence) -> None:
        """A sender left (after the participant dropped it as a partner): refuse its late
        requests, end its MultipleData hold, drop its publisher."""
        self.departed.add(presence.instance)
        self.scheduler.sender_lost(presence.name, presence.instance)
        if not self.participant.is_alive(presence.name, presence.role):
            self.notifications.sender_left(presence.name)

    # -- the scheduler's seams (framework/scheduler.py) ----------------------------------

    def _busy(self, busy: bool) -> None:
        """The scheduler's seam: Busy while a process runs, Ready after (if it was Busy)."""
        if busy:
            self.notifications.device_state(DeviceStates.Busy)
        elif self.device.state is DeviceStates.Busy:
            self.notifications.device_state(DeviceStates.Ready)

    def _heartbeat(self, entry: Entry, update: ProcessUpdateNotification) -> None:
        """The scheduler's seam: a Queued update straight to its sender (no journal,
        no batch)."""
        if self.notifications.is_open:
            self.notifications.to_sender(entry.sender, update)

    def _update(self, entry: Entry, state: ProcessStates, reason: str, data: Data | None) -> None:
        """ProcessStateHandler: journal the ProcessUpdate, then send it (the outbox)."""
        entry.seq += 1
        update = ProcessUpdateNotification(
            tag=entry.process.tag,
            identifier=entry.identifier,
            state=state,
            data=data,
            reason=reason,
            seq=entry.seq,
        )
        if self.journal.enabled:
            self.journal.record_update(
                entry.sender, entry.identifier, entry.seq, state.value, reason, summary(data)
            )
        self.outbox.update(entry, update)


__all__ = [
    "Declaration", "DeviceError", "DeviceInterface", "FeedbackPort", "GenericDevice",
    "check_catalogue",
]
