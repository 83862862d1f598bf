"""The robot service's ExternalProcessHandler (thesis 5.2.3.6, Figures 5-14 and 5-15).

"When the robot service receives a string (e.g. "ACTIVATE CAMERA #SnapShot##500")
from the robot program, it searches in the list state.Partners for the device
given the name (e.g. "CAMERA") then searches in the list DeviceInfo.Commands of
the corresponding device for the command given the name (e.g. "SnapShot")" and
sends the CreateProcess; the ProcessUpdates come back to the program as the
handshake of 4.1.3.2 — ``ext_cmd_result``, the data variables, and last
``ext_cmd_finished``.

One ACTIVATE at a time, in the order the program wrote them (the program has one
set of handshake variables).  Per command type (5.2.1, Figure 5-15):

* **NoData**, **StopData** — RESULT when the process is Completed or Failed;
* **SingleData** — the data (``DATA``/``TEXT``) and RESULT together;
* **MultipleData** — RESULT TRUE as soon as the stream runs (the command feedback),
  then every data feedback as a ``FRAME`` (data variables only, no handshake: a
  program reads a frame with ``ext_cmd_count := 0`` … ``WAIT FOR ext_cmd_count >
  0``), and ``STREAMEND FALSE`` if the stream fails on its own.  The program's
  StopData command ends forwarding at once, then stops the stream.

Every failure reaches the program as ``RESULT FALSE`` with the reason in
``ext_cmd_message`` — a garbled string, a device that is not a partner, a command
it does not have, data that does not fit the command's declared type and size, a
partner that fails or dies mid-command — and nothing waits unbounded: every
partner call is bounded by the command's timeout.  When a program ends, its
pending requests are dropped and the streams it left running are stopped.
``ROBOT`` (and the service's own name) addresses the robot service itself — the
CALC routine of 8.3.2 delegates the joint increment that way.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from plugcell.devices.robot.activate import ActivateString
from plugcell.devices.robot.bridge import BridgeError, ControllerError
from plugcell.devices.robot.data import DataTextError, data_from_text, result_data
from plugcell.devices.robot.protocol import Message, Result, StreamEnd
from plugcell.framework.messages import Command, CommandTypes, ProcessStates
from plugcell.framework.process_call import ProcessCall
from plugcell.framework.service import DeviceError

if TYPE_CHECKING:
    from plugcell.devices.robot.service import RobotService

__all__ = ["CALL_MARGIN_S", "SELF_ALIAS", "ExternalProcessHandler"]

log = logging.getLogger("plugcell.devices.robot.service")

#: The device name by which a program addresses its own robot service.
SELF_ALIAS = "ROBOT"
#: A partner call may take the command's timeout plus this (queueing, network).
CALL_MARGIN_S = 10.0
#: How long stopping a stream a finished program left running may take.
STOP_TIMEOUT_S = 10.0

Outcome = tuple[bool, Any, str]


@dataclass
class _Request:
    """One line of a program: an ACTIVATE string, or a garbled line and why."""

    run: int
    activate: ActivateString | None
    garbled: str = ""
    stream: _Stream | None = None


@dataclass
class _Stream:
    """A MultipleData process started by a program, forwarding its frames."""

    run: int
    device: str
    command: str
    call: ProcessCall
    forwarding: bool = True
    stopped: bool = False
    """The program's own StopData completed: the partner needs no other."""
    ready: asyncio.Event = field(default_factory=asyncio.Event)


class ExternalProcessHandler:
    """Turns a program's ACTIVATE strings into CreateProcess and answers the program."""

    def __init__(self, service: RobotService) -> None:
        self.service = service
        self.run = 0
        """The run whose lines arrive now (``EVENT STARTED``); 0 if none was announced."""
        self._live: set[int] = set()
        self._queue: asyncio.Queue[_Request] = asyncio.Queue()
        self._worker: asyncio.Task[None] | None = None
        self._current: tuple[_Request, asyncio.Task[None]] | None = None
        self._streams: dict[str, _Stream] = {}
        self._background: set[asyncio.Task[Any]] = set()
        self.answered = 0

    # ------------------------------------------------------------------ life cycle
    def start(self) -> None:
        if self._worker is None:
            self._worker = asyncio.create_task(self._work(), name="external-process-handler")

    async def close(self) -> None:
        self._drop(None, "the robot service is shutting down")
        worker, self._worker = self._worker, None
        if worker is not None:
            worker.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await worker
        if self._background:
            await asyncio.wait(self._background, timeout=STOP_TIMEOUT_S)
        for task in list(self._background):
            task.cancel()

    # ------------------------------------------------------------------ from the controller
    def submit(self, activate: ActivateString) -> None:
        """An ACTIVATE string of the current run."""
        self._queue.put_nowait(_Request(self.run, activate))

    def submit_garbled(self, reason: str) -> None:
        """A line that could not be read: the program gets RESULT FALSE with the reason."""
        self._queue.put_nowait(_Request(self.run, None, reason))

    def started(self, run: int) -> None:
        self.run = run
        self._live.add(run)

    def ended(self, run: int) -> None:
        """Run ``run`` ended: drop what it still waits for, stop the streams it left."""
        self._live.discard(run)
        if self.run == run:
            self.run = 0
        self._drop(run, f"run {run} ended")

    def lost(self) -> None:
        """The controller connection is gone: nothing can be answered any more."""
        self._live.clear()
        self.run = 0
        while not self._queue.empty():
            self._queue.get_nowait()
        self._drop(None, "connection to the controller lost")

    def _answerable(self, run: int) -> bool:
        return run == 0 or run in self._live

    def _drop(self, run: int | None, why: str) -> None:
        current = self._current
        if current is not None and (run is None or current[0].run == run):
            current[1].cancel()
        for stream in list(self._streams.values()):
            if run is None or stream.run == run:
                stream.forwarding = False
                if stream.call.final is None and not stream.stopped:
                    log.info("%s: stopping %s %s (%s)", self.service.name, stream.device,
                             stream.command, why)
                    self._spawn(self._stop_partner(stream))

    def _spawn(self, coro: Any) -> None:
        task = asyncio.create_task(coro)
        self._background.add(task)
        task.add_done_callback(self._background.discard)

    # ------------------------------------------------------------------ the worker
    async def _work(self) -> None:
        while True:
            request = await self._queue.get()
            if not self._answerable(request.run):
                continue
            task = asyncio.create_task(self._handle(request))
            self._current = (request, task)
            try:
                await asyncio.wait({task})
            except asyncio.CancelledError:
                task.cancel()
                raise
            finally:
                self._current = None

    async def _handle(self, request: _Request) -> None:
        try:
            try:
                ok, output, message = await self._execute(request)
            except asyncio.CancelledError:
                raise
            except Exception as exc:  # never leave the program waiting
                log.exception("%s: error handling %s", self.service.name, request.activate)
                ok, output, message = False, None, f"robot service error: {exc!r}"
            await self._answer(request.run, ok, output, message)
            self.answered += 1
        finally:  # the stream's frames may follow its RESULT now
            if request.stream is not None:
                request.stream.ready.set()

    async def _execute(self, request: _Request) -> Outcome:
        if request.activate is None:
            return False, None, f"garbled line: {request.garbled}"
        a = request.activate
        service = self.service
        if a.device in (service.name, SELF_ALIAS):
            return await self._own(a)
        partner = service.host.participant.partners.get(a.device)
        if partner is None:
            wired = ", ".join(sorted(service.host.participant.partners)) or "none"
            return False, None, (f"{a.device} is not a partner of {service.name} "
                                 f"(partners: {wired}); wire it: plugcell wire "
                                 f"{service.name} {a.device}")
        command = partner.device.command(a.command)
        if command is None:
            known = ", ".join(c.name for c in partner.device.commands) or "none"
            return False, None, f"{a.device} has no command {a.command!r} (commands: {known})"
        try:
            data = data_from_text(a.data, command, a.device)
        except DataTextError as exc:
            return False, None, str(exc)
        stream = self._streams.get(a.device)
        if command.type is CommandTypes.StopData and stream is not None:
            stream.forwarding = False  # no frame may follow the program's StopData
        if command.type is CommandTypes.MultipleData and stream is not None:
            return False, None, (f"{a.device} {stream.command} is still streaming to this robot: "
                                 f"stop it first")
        call = await service.host.participant.create_process(
            a.device, command.name, a.option, data, timeout=command.timeout + CALL_MARGIN_S)
        if command.type is CommandTypes.MultipleData:
            return await self._start_stream(request, a, command, call)
        final = await call.result()
        if final.state is not ProcessStates.Completed:
            return False, None, _failure(a, final.reason)
        if command.type is CommandTypes.StopData and stream is not None:
            stream.stopped = True  # its final update may still be on its way
        output = call.array(final) if command.type is CommandTypes.SingleData else None
        return True, output, final.reason  # the device's note on a success, usually ""

    async def _own(self, a: ActivateString) -> Outcome:
        """A command of the robot service itself (``ACTIVATE ROBOT #JointIncrement##…``)."""
        service = self.service
        command = service.host.device.command(a.command)
        if command is None:
            known = ", ".join(c.name for c in service.declaration.commands)
            return False, None, f"{a.device} has no command {a.command!r} (commands: {known})"
        try:
            data = data_from_text(a.data, command, a.device)
            output = await service.perform(command, a.option, data)
        except DataTextError as exc:
            return False, None, str(exc)
        except (DeviceError, ControllerError, BridgeError) as exc:
            return False, None, f"{a.device} {command.name}: {exc}"
        return True, output, ""

    async def _start_stream(self, request: _Request, a: ActivateString, command: Command,
                            call: ProcessCall) -> Outcome:
        try:
            first = await anext(call)
        except StopAsyncIteration:  # pragma: no cover - the final update was consumed
            first = call.final
        assert first is not None
        if first.state is ProcessStates.Failed:
            return False, None, _failure(a, first.reason)
        if first.state is ProcessStates.Completed:
            return True, None, ""
        stream = _Stream(request.run, a.device, command.name, call)
        self._streams[a.device] = stream
        request.stream = stream
        self._spawn(self._forward(stream, first))
        return True, None, ""

    async def _forward(self, stream: _Stream, update: Any) -> None:
        """Frames of a MultipleData process → ``FRAME`` lines, until it ends."""
        await stream.ready.wait()
        capacity, text_capacity = self.service.capacities()
        noted = False
        try:
            while True:
                live = stream.forwarding and self._answerable(stream.run)
                if update.data is not None and live:
                    frame, note = result_data(stream.call.array(update), capacity,
                                              text_capacity, frame=True)
                    if frame is not None:
                        await self._send(frame)
                    elif not noted:
                        noted = True
                        log.info("%s: frames of %s %s not forwarded: %s", self.service.name,
                                 stream.device, stream.command, note)
                if update.state.final:
                    if update.state is ProcessStates.Failed and live:
                        reason = _failure(ActivateString(stream.device, stream.command),
                                          update.reason)
                        await self._send(StreamEnd(False, reason))
                    return
                update = await anext(stream.call)
        except StopAsyncIteration:
            return
        finally:
            if self._streams.get(stream.device) is stream:
                del self._streams[stream.device]

    async def _stop_partner(self, stream: _Stream) -> None:
        """Send the partner's StopData for a stream whose program is gone."""
        partner = self.service.host.participant.partners.get(stream.device)
        stops = [c.name for c in (partner.device.commands if partner else ())
                 if c.type is CommandTypes.StopData]
        if not stops:
            return
        with contextlib.suppress(Exception):
            call = await self.service.host.participant.create_process(stream.device, stops[0],
                                                     timeout=STOP_TIMEOUT_S)
            await call.result()

    # ------------------------------------------------------------------ answering
    async def _answer(self, run: int, ok: bool, output: Any, message: str) -> None:
        if not self._answerable(run):
            return
        messages: list[Message] = []
        if ok and output is not None:
            capacity, text_capacity = self.service.capacities()
            data, note = result_data(output, capacity, text_capacity)
            if data is not None:
                messages.append(data)
            message = message or note
        messages.append(Result(ok, message))
        await self._send(*messages)

    async def _send(self, *messages: Message) -> None:
        try:
            await self.service.bridge.send(*messages)
        except BridgeError as exc:
            log.info("%s: answer not delivered: %s", self.service.name, exc)


def _failure(a: ActivateString, reason: str) -> str:
    """``TOOL Drill: <reason>`` (without repeating a reason's own command prefix)."""
    reason = reason or "failed"
    if reason.startswith(f"{a.command}:"):
        return f"{a.device} {reason}"
    return f"{a.device} {a.command}: {reason}"
