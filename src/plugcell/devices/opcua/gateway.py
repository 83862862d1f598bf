"""``plugcell opcua serve``: an OPC UA server (asyncua) that mirrors a cell live.

The gateway is a plugcell *client*: it watches the cell's presence with the
framework's public API (:meth:`Participant.services`, :meth:`Participant.events`,
:meth:`Participant.get`, :meth:`Participant.subscribe` for the state notifications)
and turns every OPC UA method call into a ``CreateProcess``
(:meth:`Participant.create_process`, in :mod:`plugcell.devices.opcua.method_calls`).
The address space is described in :mod:`plugcell.devices.opcua.address_space`; what a
call returns:

* NoData/StopData: no output; Good once the process is Completed;
* SingleData: output ``Data`` once Completed;
* MultipleData: output ``Process``, the NodeId of a process object whose ``Data``
  variable follows the stream (subscribe to it), with ``State``/``Reason`` and a
  ``Stop`` method (the service's StopData, sent by the same sender);
* every method's last output is ``Reason`` (String): empty on success;
* a process that ends Failed: a Bad status — ``BadUserAccessDenied`` for an access
  refusal, ``BadTimeout`` when the service went silent, ``BadNoCommunication`` when
  it is gone, ``BadDeviceFailure`` otherwise — with the service's reason text in the
  result's ``Reason`` output, and a ``ProcessEventType`` event with the same ``Reason``;
* an argument of the wrong type or size: ``BadInvalidArgument`` with the
  reason in the argument's diagnostic info (``AdditionalInfo``), and an event.

Every process start and end is a ``ProcessEventType`` event (emitted by the Server
object; ``SourceNode`` the service's object); the services' journals stay the record.

Who calls: each OPC UA user's processes are sent by a participant named as the user
(opened on first use), so the services' access policy (``PLUGCELL_ACL``) judges the
user and the journals record the user; an anonymous session (when allowed) calls as
the gateway itself (``--name``, default ``OPCUA``).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from typing import Any

from asyncua import Server, ua

from plugcell.devices.opcua.address_space import ServiceNode, add_service
from plugcell.devices.opcua.companion import Models, add_service_device, load_models
from plugcell.devices.opcua.listen import listen_url
from plugcell.devices.opcua.method_calls import CALL_MARGIN, MethodCalls
from plugcell.devices.opcua.robots import RobotMirror, is_robot
from plugcell.devices.opcua.server_security import GatewaySecurity, configure_security
from plugcell.devices.opcua.sessions import capture_session_users
from plugcell.devices.opcua.users import GatewayUsers, UserBook
from plugcell.framework.messages import (
    ConnectionUpdateNotification,
    Message,
    StateUpdateNotification,
)
from plugcell.framework.participant import Participant, PartnerError
from plugcell.framework.transport import TransportConfig

log = logging.getLogger("plugcell.devices.opcua")

__all__ = ["CALL_MARGIN", "CellGateway"]


class CellGateway:
    """An OPC UA server mirroring cell ``cell`` (see the module docstring).

    Parameters
    ----------
    cell, transport
        The cell to mirror and how to join it.
    host, port
        Where the OPC UA server listens (``opc.tcp://host:port/plugcell``).
    name
        The gateway's participant name (sender of anonymous calls).
    users
        Username/password users; None for none.
    allow_anonymous
        Accept anonymous sessions (off by default).
    security
        Certificate, key and accepted policies; without a certificate the server
        offers SecurityPolicy None only.
    refresh
        Seconds between refreshes of every service's Partners.
    linger
        Seconds a finished MultipleData process object stays in the address space.
    robot_poll
        Seconds between reads of each robot's joints and flange pose for the OPC 40010
        variables (:mod:`plugcell.devices.opcua.robots`); 0 turns the reads off (the
        typed robot is still there).
    """

    def __init__(
        self,
        *,
        cell: str,
        transport: TransportConfig | None = None,
        host: str = "127.0.0.1",
        port: int = 4840,
        name: str = "OPCUA",
        users: UserBook | None = None,
        allow_anonymous: bool = False,
        security: GatewaySecurity | None = None,
        refresh: float = 5.0,
        linger: float = 30.0,
        robot_poll: float = 1.0,
    ) -> None:
        self.url = listen_url(host, port)
        if users is None and not allow_anonymous:
            raise ValueError("no way to log in: give a users file (--users FILE, its lines "
                             "from plugcell opcua hash-password) or accept anonymous sessions "
                             "(--allow-anonymous)")
        self.cell = cell
        self.transport = transport or TransportConfig.from_env()
        self.host, self.port = host.strip(), port
        self.name = name
        self.users = GatewayUsers(users, allow_anonymous)
        self.security = security or GatewaySecurity()
        self.refresh, self.robot_poll = refresh, robot_poll
        self._robots: dict[str, asyncio.Task[None]] = {}
        self.watcher = Participant(name, cell=cell, transport=self.transport)
        self.watcher.partner_listeners.append(self._partner_notified)
        self.server = Server(user_manager=self.users)  # type: ignore[arg-type]
        self.idx = 0
        self.services: dict[str, ServiceNode] = {}
        self._tasks: set[asyncio.Task[Any]] = set()
        self.calls = MethodCalls(self.server, self.watcher, self.users, self.transport,
                                 self.services, self._spawn, linger)
        """The services' methods: each call a process sent as its OPC UA user."""
        self._changes: asyncio.Queue[tuple[str, str]] = asyncio.Queue()
        """``(kind, service)`` to apply in order: join, leave, state."""

    # -- life cycle ------------------------------------------------------------------

    async def start(self) -> None:
        """Join the cell, build the address space, start serving and mirroring (closed
        again if any of it fails, e.g. the port is taken)."""
        try:
            await self._start()
        except BaseException:
            await self.close()
            raise

    async def _start(self) -> None:
        await self.watcher.start()
        server = self.server
        await server.init()
        server.set_endpoint(self.url)
        server.set_server_name(f"plugcell cell {self.cell}")
        await server.set_application_uri(f"urn:plugcell:opcua:{self.cell}:{self.name}")
        await configure_security(server, self.security, self.users.allow_anonymous)
        capture_session_users(server, self.calls.session_closed)
        self.idx = await server.register_namespace(f"urn:plugcell:cell:{self.cell}")
        self.models: Models = await load_models(server, self.idx)
        self.cell_node = await server.nodes.objects.add_folder(
            ua.NodeId("Cell", self.idx), ua.QualifiedName("Cell", self.idx)
        )
        await self.calls.open(self.idx)
        events = self.watcher.events()
        for service in self.watcher.services():
            self._changes.put_nowait(("join", service))
        await server.start()
        self._spawn(self._follow_presence(events))
        self._spawn(self._apply_changes())
        self._spawn(self._refresh_partners())

    async def close(self) -> None:
        """Stop serving, end the mirror tasks and leave the cell."""
        for task in list(self._tasks):
            task.cancel()
        for task in list(self._tasks):
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await task
        with contextlib.suppress(Exception):
            await self._stop_server()
        await self.calls.close()
        await self.watcher.close()

    async def _stop_server(self) -> None:
        """``Server.stop`` without waiting out asyncua's status clock: its loop writes
        ServerStatus.CurrentTime and sleeps 1 s, and ``stop`` awaits the loop's end — up
        to a second of every SIGTERM.  Cancelled first, the rest of ``stop`` is quick."""
        iserver = self.server.iserver
        clock = getattr(iserver, "time_task", None)
        if clock is not None and not clock.done():
            clock.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await clock
        iserver.time_task = None
        await self.server.stop()

    async def __aenter__(self) -> CellGateway:
        await self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    def _spawn(self, coro: Any) -> asyncio.Task[Any]:
        task = asyncio.ensure_future(coro)
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)
        return task

    # -- mirroring the cell ------------------------------------------------------------

    async def _follow_presence(self, events: Any) -> None:
        async for event in events:
            if event.presence.role == "service":
                self._changes.put_nowait((event.kind, event.presence.name))

    def _partner_notified(self, partner: str, body: Message) -> None:
        if isinstance(body, StateUpdateNotification | ConnectionUpdateNotification):
            self._changes.put_nowait(("state", partner))

    async def _apply_changes(self) -> None:
        """Apply joins, leaves and state changes one at a time, in order."""
        while True:
            kind, service = await self._changes.get()
            try:
                if kind == "join":
                    await self._add(service)
                elif kind == "leave":
                    if not self.watcher.is_alive(service):
                        await self._remove(service)
                elif kind == "state":
                    await self._show(service)
            except Exception:  # a service that vanished meanwhile must not stop the mirror
                log.exception("opcua: %s of %s", kind, service)

    async def _add(self, service: str) -> None:
        watcher = self.watcher
        if not watcher.is_alive(service):
            return
        try:
            state, instance = await watcher.get(service)
            await watcher.subscribe(service)
        except PartnerError as exc:
            log.warning("opcua: %s joined but did not answer: %s", service, exc)
            return
        old = self.services.pop(service, None)
        if old is not None:
            if old.variables and await old.variables["Instance"].read_value() == instance:
                self.services[service] = old
                return
            await self._forget(service, old)
        partners = [p.name for p in state.partners]
        node = self.services[service] = await add_service(
            self.cell_node, self.idx, state.device_info, instance, partners,
            lambda command: self.calls.method(service, command),
        )
        device = state.device_info
        if is_robot(device):  # a MotionDeviceSystem, built (and polled) by its own task
            mirror = RobotMirror(self.server, self.models, node, device, self.watcher,
                                 self.robot_poll)
            self._robots[service] = self._spawn(mirror.run())
        else:
            node.device = await add_service_device(self.models, service, device.vendor,
                                                   device.kind, device.info)
        log.info("opcua: %s added", service)

    async def _forget(self, service: str, node: ServiceNode) -> None:
        robot = self._robots.pop(service, None)
        if robot is not None:
            robot.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await robot
        await node.delete()
        with contextlib.suppress(ua.UaStatusCodeError):  # DeviceSet.<service>, even half-made
            await self.server.get_node(ua.NodeId(f"DeviceSet.{service}", self.idx)).delete(
                recursive=True)

    async def _remove(self, service: str) -> None:
        node = self.services.pop(service, None)
        if node is not None:
            await self._forget(service, node)
            log.info("opcua: %s removed", service)

    async def _show(self, service: str, partners: list[str] | None = None) -> None:
        node = self.services.get(service)
        partner = self.watcher.partners.get(service)
        if node is None or partner is None:
            return
        if partners is None:
            partners = list(await node.variables["Partners"].read_value() or [])
        await node.show_device(partner.device, partners)

    async def _refresh_partners(self) -> None:
        while True:
            await asyncio.sleep(self.refresh)
            for service in list(self.services):
                with contextlib.suppress(PartnerError):
                    state, _ = await self.watcher.get(service, timeout=2.0)
                    await self._show(service, [p.name for p in state.partners])
