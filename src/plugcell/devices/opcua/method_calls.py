"""The methods of the gateway's mirrored services: each OPC UA method call becomes a
``CreateProcess`` sent as the OPC UA user who calls (``docs/opcua.md``, "Methods").

:class:`MethodCalls` answers what the gateway's module docstring promises: no output or
the ``Data`` of a process once Completed, a process object that follows a MultipleData
stream, a Bad status and the service's reason when it fails, a ``ProcessEventType``
event for every start and end.  The gateway (:mod:`plugcell.devices.opcua.gateway`)
keeps the address space in step with the cell and hands each service's methods to
:meth:`MethodCalls.method`.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Callable
from datetime import UTC, datetime
from typing import Any

from asyncua import Server, ua

from plugcell.devices.opcua.address_space import (
    ProcessNode,
    ServiceNode,
    add_process,
    node_id,
    output_argument,
)
from plugcell.devices.opcua.arguments import ArgumentError, data_variant, input_value, option_of
from plugcell.devices.opcua.sessions import caller_name, caller_session
from plugcell.devices.opcua.users import GatewayUsers
from plugcell.framework.messages import Command, CommandTypes, ProcessStates
from plugcell.framework.participant import Participant
from plugcell.framework.process_call import ProcessCall
from plugcell.framework.transport import TransportConfig

__all__ = ["CALL_MARGIN", "MethodCalls"]

#: Seconds added to a command's own timeout for the gateway's wait on its process.
CALL_MARGIN = 5.0


class MethodCalls:
    """OPC UA method calls → plugcell processes, for the services of one gateway.

    Parameters
    ----------
    server
        The gateway's OPC UA server (it writes the process objects and emits the events).
    watcher
        The gateway's participant: it calls for anonymous sessions (when allowed) and
        names the gateway in the events of calls refused before a caller was known.
    users
        Who may log in (and whether anonymous sessions are allowed).
    transport
        How a user's participant joins the cell (with the user's certificate when the
        cell has a certificate folder).
    nodes
        The services' objects in the address space by service name (the gateway's
        dictionary, shared: a process object is added under its service's object).
    spawn
        Runs a coroutine as a task the gateway ends when it closes.
    linger
        Seconds a finished MultipleData process object stays in the address space.
    """

    def __init__(
        self,
        server: Server,
        watcher: Participant,
        users: GatewayUsers,
        transport: TransportConfig,
        nodes: dict[str, ServiceNode],
        spawn: Callable[[Any], asyncio.Task[Any]],
        linger: float = 30.0,
    ) -> None:
        self.server, self.watcher, self.users = server, watcher, users
        self.transport, self.nodes, self.linger = transport, nodes, linger
        self._spawn = spawn
        self.idx = 0
        self.event: Any = None
        """The generator of ``ProcessEventType`` events (from :meth:`open`)."""
        self._callers: dict[str, Participant] = {}
        self._caller_lock = asyncio.Lock()
        self._event_lock = asyncio.Lock()
        self._streams: dict[int, dict[int, tuple[Participant, ProcessCall]]] = {}
        """Running MultipleData processes per OPC UA session (stopped when it closes)."""

    async def open(self, idx: int) -> None:
        """Declare ``ProcessEventType`` in namespace ``idx`` and make its generator."""
        self.idx = idx
        etype = await self.server.create_custom_event_type(
            idx, "ProcessEventType", ua.ObjectIds.BaseEventType,
            [("Service", ua.VariantType.String), ("Command", ua.VariantType.String),
             ("Sender", ua.VariantType.String), ("Identifier", ua.VariantType.Int64),
             ("State", ua.VariantType.String), ("Reason", ua.VariantType.String)],
        )
        self.event = await self.server.get_event_generator(etype)

    async def close(self) -> None:
        """Leave the cell with every user's participant."""
        for caller in self._callers.values():
            with contextlib.suppress(Exception):
                await caller.close()

    async def caller(self) -> Participant:
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
                caller = Participant(user, cell=self.watcher.keys.cell, transport=transport)
                await caller.start()
                self._callers[user] = caller
        return caller

    def method(self, service: str, command: Command) -> Any:
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
            await self._emit(service, command.name, caller_name() or self.watcher.name, 0,
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
            caller = await self.caller()
        except ValueError as exc:  # a secure cell without this user's certificate
            await self._emit(service, command.name, caller_name() or self.watcher.name, 0,
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
        await self._emit(service, command.name, caller_name() or self.watcher.name, 0,
                         "Refused", reason)
        return result

    async def _start_stream(
        self, service: str, command: Command, caller: Participant, call: ProcessCall,
        count: int,
    ) -> ua.CallMethodResult:
        node = self.nodes.get(service)
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

    async def session_closed(self, session: int) -> None:
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
        event = self.event
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
