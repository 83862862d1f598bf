"""``plugcell opcua serve``: an OPC UA server (asyncua) that mirrors a cell live.

The gateway is a plugcell *client*: it watches the cell's presence with the
framework's public API (:meth:`Participant.services`, :meth:`Participant.events`,
:meth:`Participant.get`, :meth:`Participant.subscribe` for the state notifications)
and turns every OPC UA method call into a ``CreateProcess``
(:meth:`Participant.create_process`).  The address space is described in
:mod:`plugcell.devices.opcua.address_space`; what a call returns:

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
from datetime import UTC, datetime
from typing import Any

from asyncua import Server, ua

from plugcell.devices.opcua.address_space import (
    ProcessNode,
    ServiceNode,
    add_process,
    add_service,
    node_id,
    output_argument,
)
from plugcell.devices.opcua.arguments import ArgumentError, data_variant, input_value, option_of
from plugcell.devices.opcua.companion import Models, add_service_device, load_models
from plugcell.devices.opcua.listen import listen_url
from plugcell.devices.opcua.robots import RobotMirror, is_robot
from plugcell.devices.opcua.server_security import GatewaySecurity, configure_security
from plugcell.devices.opcua.sessions import caller_name, caller_session, capture_session_users
from plugcell.devices.opcua.users import GatewayUsers, UserBook
from plugcell.framework.messages import (
    Command,
    CommandTypes,
    ConnectionUpdateNotification,
    Message,
    ProcessStates,
    StateUpdateNotification,
)
from plugcell.framework.participant import Participant, PartnerError
from plugcell.framework.process_call import ProcessCall
from plugcell.framework.transport import TransportConfig

log = logging.getLogger("plugcell.devices.opcua")


#: Seconds added to a command's own timeout for the gateway's wait on its process.
CALL_MARGIN = 5.0


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
        self.refresh, self.linger, self.robot_poll = refresh, linger, robot_poll
        self._robots: dict[str, asyncio.Task[None]] = {}
        self.watcher = Participant(name, cell=cell, transport=self.transport)
        self.watcher.partner_listeners.append(self._partner_notified)
        self.server = Server(user_manager=self.users)  # type: ignore[arg-type]
        self.idx = 0
        self.services: dict[str, ServiceNode] = {}
        self._callers: dict[str, Participant] = {}
        self._caller_lock = asyncio.Lock()
        self._tasks: set[asyncio.Task[Any]] = set()
        self._event_lock = asyncio.Lock()
        self._event: Any = None
        self._streams: dict[int, dict[int, tuple[Participant, ProcessCall]]] = {}
        """Running MultipleData processes per OPC UA session (stopped when it closes)."""
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
        capture_session_users(server, self._session_closed)
        self.idx = await server.register_namespace(f"urn:plugcell:cell:{self.cell}")
        self.models: Models = await load_models(server, self.idx)
        self.cell_node = await server.nodes.objects.add_folder(
            ua.NodeId("Cell", self.idx), ua.QualifiedName("Cell", self.idx)
        )
        etype = await server.create_custom_event_type(
            self.idx, "ProcessEventType", ua.ObjectIds.BaseEventType,
            [("Service", ua.VariantType.String), ("Command", ua.VariantType.String),
             ("Sender", ua.VariantType.String), ("Identifier", ua.VariantType.Int64),
             ("State", ua.VariantType.String), ("Reason", ua.VariantType.String)],
        )
        self._event = await server.get_event_generator(etype)
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
        for caller in self._callers.values():
            with contextlib.suppress(Exception):
                await caller.close()
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
            lambda command: self._method(service, command),
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

    # -- calls -------------------------------------------------------------------------

    async def _caller(self) -> Participant:
        """The participant that sends the current OPC UA user's processes."""
        user = caller_name()
        if user is None:
            if not self.users.allow_anonymous:  # fail closed: never call as the gateway
                raise ValueError("the OPC UA user of this call is unknown (anonymous "
                                 "sessions are off)")
            return self.watcher
        async with self._caller_lock:
            caller = self._callers.get(user)
            if caller is None:
                transport = self.transport
                if transport.tls_dir:
                    transport = transport.for_participant(user)
                caller = Participant(user, cell=self.cell, transport=transport)
                await caller.start()
                self._callers[user] = caller
        return caller

    def _method(self, service: str, command: Command) -> Any:
        async def call(parent: ua.NodeId, *args: ua.Variant) -> ua.CallMethodResult:
            return await self._call(service, command, list(args))

        return call

    async def _call(
        self, service: str, command: Command, args: list[ua.Variant]
    ) -> ua.CallMethodResult:
        expected = 2 if command.takes_input else 1
        if len(args) > expected:
            why = (f"{command.name}: {len(args)} arguments, but it takes {expected} "
                   f"({'Option, Data' if command.takes_input else 'Option'})")
            await self._emit(service, command.name, caller_name() or self.name, 0,
                             "Refused", why)
            return _failed(command, ua.StatusCodes.BadTooManyArguments, len(args), why)
        try:
            option = option_of(args[0] if args else None, command.name)
        except ArgumentError as exc:
            return await self._refuse(service, command, 0, len(args), str(exc))
        try:
            data = input_value(args[1] if len(args) > 1 else None, command)
        except ArgumentError as exc:
            return await self._refuse(service, command, 1, len(args), str(exc))
        try:
            caller = await self._caller()
        except ValueError as exc:  # a secure cell without this user's certificate
            await self._emit(service, command.name, caller_name() or self.name, 0,
                             "Refused", str(exc))
            return _failed(command, ua.StatusCodes.BadUserAccessDenied, len(args), str(exc))
        call = await caller.create_process(
            service, command.name, option, data, timeout=command.timeout + CALL_MARGIN
        )
        if command.type is CommandTypes.MultipleData:
            return await self._start_stream(service, command, caller, call, len(args))
        await self._announce(service, command, call, ProcessStates.Running, "")
        final = await call.result()
        await self._announce(service, command, call, final.state, final.reason)
        if final.state is ProcessStates.Failed:
            return _failed(command, _failure_code(final.reason), len(args), final.reason)
        return _good(len(args), [data_variant(final.data)] if command.gives_output else [])

    async def _refuse(
        self, service: str, command: Command, index: int, count: int, reason: str
    ) -> ua.CallMethodResult:
        """BadInvalidArgument with ``reason`` as the argument's diagnostic info (and the
        ``Reason`` output)."""
        result = _failed(command, ua.StatusCodes.BadInvalidArgument, max(count, index + 1),
                         reason)
        result.InputArgumentResults[index] = ua.StatusCode(ua.StatusCodes.BadInvalidArgument)
        infos = [ua.DiagnosticInfo() for _ in result.InputArgumentResults]
        infos[index] = ua.DiagnosticInfo(AdditionalInfo=reason)
        result.InputArgumentDiagnosticInfos = infos
        await self._emit(service, command.name, caller_name() or self.name, 0,
                         "Refused", reason)
        return result

    async def _start_stream(
        self, service: str, command: Command, caller: Participant, call: ProcessCall,
        count: int,
    ) -> ua.CallMethodResult:
        node = self.services.get(service)
        if call.done and call.final is not None and call.final.state is ProcessStates.Failed:
            await self._announce(service, command, call, ProcessStates.Failed, call.final.reason)
            return _failed(command, _failure_code(call.final.reason), count, call.final.reason)
        if node is None:  # the service left meanwhile
            with contextlib.suppress(Exception):
                await caller.stop_process(call)
            return _failed(command, ua.StatusCodes.BadNoCommunication, count,
                           f"{service} left the cell")

        async def stop(parent: ua.NodeId) -> ua.CallMethodResult:
            if call.done:
                return _failed(None, ua.StatusCodes.BadInvalidState, 0,
                               f"the process {call.identifier} has already ended")
            ended = await (await caller.stop_process(call)).result()
            if ended.state is ProcessStates.Failed:
                await self._emit(service, ended.tag.recipient, caller.name, ended.identifier,
                                 "Failed", ended.reason)
                return _failed(None, _failure_code(ended.reason), 0, ended.reason)
            await finished.wait()  # State and Reason show the end when Stop returns
            return _good(0, [])

        finished = asyncio.Event()

        process = await add_process(node, command, caller.name, call.identifier, stop)
        session = caller_session()
        self._streams.setdefault(session, {})[call.identifier] = (caller, call)
        await self._announce(service, command, call, ProcessStates.Running, "")
        self._spawn(self._pump(service, command, call, process, finished))
        return _good(count, [ua.Variant(process.node.nodeid, ua.VariantType.NodeId)])

    async def _pump(
        self, service: str, command: Command, call: ProcessCall, process: ProcessNode,
        finished: asyncio.Event,
    ) -> None:
        """Follow a MultipleData process: Data, Frames, then State and Reason at its end."""
        frames = 0
        server = self.server
        async for update in call:
            if update.data is not None:
                frames += 1
                now = datetime.now(UTC)  # each frame a new sample, equal or not
                await server.write_attribute_value(
                    process.data.nodeid,
                    ua.DataValue(data_variant(update.data), SourceTimestamp=now,
                                 ServerTimestamp=now),
                )
                await server.write_attribute_value(
                    process.frames.nodeid,
                    ua.DataValue(ua.Variant(frames, ua.VariantType.UInt32)),
                )
                await asyncio.sleep(0)  # a burst of frames must not starve the server
        final = call.final
        assert final is not None
        for streams in self._streams.values():
            streams.pop(call.identifier, None)
        with contextlib.suppress(Exception):  # the service's node may be gone already
            await process.reason.write_value(ua.Variant(final.reason, ua.VariantType.String))
            await process.state.write_value(ua.Variant(final.state.value, ua.VariantType.String))
        finished.set()
        await self._announce(service, command, call, final.state, final.reason)
        await asyncio.sleep(self.linger)
        with contextlib.suppress(Exception):
            await process.node.delete(recursive=True)

    async def _session_closed(self, session: int) -> None:
        """An OPC UA session ended: stop the MultipleData processes it started."""
        for caller, call in list(self._streams.pop(session, {}).values()):
            if not call.done:
                with contextlib.suppress(Exception):
                    await caller.stop_process(call)

    async def _announce(
        self, service: str, command: Command, call: ProcessCall, state: ProcessStates,
        reason: str,
    ) -> None:
        await self._emit(service, command.name, call.tag.sender, call.identifier, state.value,
                         reason)

    async def _emit(
        self, service: str, command: str, sender: str, identifier: int, state: str, reason: str
    ) -> None:
        """One ``ProcessEventType`` event (Server object; SourceNode the service)."""
        event = self._event
        if event is None:
            return
        text = f"{service} {command} #{identifier} {sender}: {state}" + (
            f": {reason}" if reason else "")
        async with self._event_lock:
            fields = event.event
            fields.SourceNode = node_id(self.idx, service)
            fields.SourceName = service
            fields.Severity = 700 if state in ("Failed", "Refused") else 100
            fields.Service, fields.Command, fields.Sender = service, command, sender
            fields.Identifier = identifier
            fields.State, fields.Reason = state, reason
            await event.trigger(message=text)


def _good(count: int, outputs: list[ua.Variant]) -> ua.CallMethodResult:
    """A Good result: ``outputs`` and an empty ``Reason``."""
    result = ua.CallMethodResult()
    result.StatusCode = ua.StatusCode(ua.StatusCodes.Good)
    result.InputArgumentResults = [ua.StatusCode() for _ in range(count)]
    result.OutputArguments = [*outputs, ua.Variant("", ua.VariantType.String)]
    return result


def _failed(command: Command | None, code: int, count: int, reason: str
            ) -> ua.CallMethodResult:
    """A Bad result whose ``Reason`` output says why (``command`` None: a process's Stop).

    The status code is for every client; the reason text travels as the method's last
    output argument (a status code has no text; asyncua's method callbacks cannot reach
    the response's DiagnosticInfos), Null in the place of the other outputs."""
    declared = len(output_argument(command)) if command is not None else 1
    result = ua.CallMethodResult()
    result.StatusCode = ua.StatusCode(code)
    result.InputArgumentResults = [ua.StatusCode() for _ in range(count)]
    result.OutputArguments = [*(ua.Variant() for _ in range(declared - 1)),
                              ua.Variant(reason, ua.VariantType.String)]
    return result


def _failure_code(reason: str) -> int:
    """The status code of a Failed process, from its reason (module docstring)."""
    if reason.startswith("access denied"):
        return ua.StatusCodes.BadUserAccessDenied
    if "lost (liveliness" in reason or "shut down" in reason or "unknown device" in reason:
        return ua.StatusCodes.BadNoCommunication
    if reason.startswith(("no acknowledgement", "no update")):
        return ua.StatusCodes.BadTimeout
    return ua.StatusCodes.BadDeviceFailure
