"""The process scheduler of a service: the ProcessHandler of thesis 5.2.3.4 (Figure 5-12).

It owns what happens to a process between its admission and its final update: the
:class:`~plugcell.framework.processqueue.ProcessQueue`, the one process running at a
time, the MultipleData *hold* (5.2.3.5: the device stays with one sender until that
sender's StopData, its disappearance or the command's timeout), the bound on every
wait for the device's command feedback (``Command.Timeout``), the ``Queued`` heartbeat
to senders waiting behind a hold, and the receivers of the DataFeedback and
CmdFeedback ports (5.2.3.2), which turn the device's output into ProcessUpdates.

It knows nothing of Zenoh, the journal or the wire: a :class:`ProcessScheduler` is
given four seams by its service —

* ``dispatch(command, option, data)`` — the device's CommandDispatcher
  (:meth:`DeviceInterface.dispatch <plugcell.framework.service.DeviceInterface.dispatch>`);
* ``update(entry, state, reason, data)`` — journal a ProcessUpdate, then send it
  (the service's outbox);
* ``busy(flag)`` — the device is Busy (True) / free again (False: Ready if it was Busy);
* ``heartbeat(entry, update)`` — tell a waiting sender its process is still queued
  (neither journalled nor batched).

Used from the service's event loop only.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import Awaitable, Callable
from typing import Any

from plugcell.framework.data import DataError, to_data
from plugcell.framework.messages import (
    Command,
    CommandTypes,
    Data,
    Device,
    ProcessStates,
    ProcessUpdateNotification,
)
from plugcell.framework.processqueue import Entry, ProcessQueue

log = logging.getLogger("plugcell.framework.service")

#: While a process waits in the queue its sender hears from the service at least this
#: often (a ``Queued`` ProcessUpdate, not journalled): a requester waiting behind a long
#: hold keeps waiting while the service lives, instead of timing out (docs/protocol.md).
QUEUED_HEARTBEAT_S = 2.0

#: How long :meth:`ProcessScheduler.stop` waits for the running process to end.
STOP_WAIT_S = 10.0


class DeviceError(RuntimeError):
    """Raised by a device interface: the process ends Failed with this message as reason."""


Dispatch = Callable[[Command, str, Any], Awaitable[str | None]]
Update = Callable[[Entry, ProcessStates, str, Data | None], None]


class ProcessScheduler:
    """Queue, run, hold and time out the processes of one device (module doc).

    Parameters
    ----------
    name
        The service's name (in reasons and logs).
    device
        The service's DeviceInfo; its ``commands`` give the StopData used to stop a
        stream whose sender will not.
    dispatch, update, busy, heartbeat
        The seams to the service (module doc).
    """

    def __init__(
        self,
        name: str,
        device: Device,
        *,
        dispatch: Dispatch,
        update: Update,
        busy: Callable[[bool], None],
        heartbeat: Callable[[Entry, ProcessUpdateNotification], None],
    ) -> None:
        self.name = name
        self.device = device
        self._dispatch = dispatch
        self._update = update
        self._busy = busy
        self._heartbeat = heartbeat
        self.queue = ProcessQueue()
        self.known: dict[tuple[str, int], Entry] = {}
        """Accepted processes not yet finished, by (sender, identifier)."""
        self.holder: Entry | None = None
        """The MultipleData process holding the device."""
        self.measuring: Entry | None = None
        """The process the device's data feedback belongs to."""
        self.sender = ""
        """The sender of the process being dispatched (``""`` outside a dispatch)."""
        self.stray_feedback = 0
        """Data/command feedback that arrived when no process expected it."""
        self.closing = False
        self._single_data: list[Any] = []
        self._notes: list[str] = []
        self._cmd_waiter: asyncio.Future[str] | None = None
        self._handler_task: asyncio.Task[None] | None = None
        self._heartbeat_task: asyncio.Task[None] | None = None
        self._queued = asyncio.Event()
        """Set when a process is posted: the heartbeat sleeps while the queue is empty."""

    # -- life cycle ------------------------------------------------------------------

    def admit(self) -> None:
        """Run the Queued heartbeat (on the running loop): from the moment the service
        takes processes, even before its device is connected and :meth:`start` runs
        them, a sender waiting in the queue hears that its process is still queued."""
        if self._heartbeat_task is None:
            self._heartbeat_task = asyncio.create_task(self._queued_heartbeat(),
                                                       name=f"{self.name}-queued")

    def start(self) -> None:
        """Run the ProcessHandler (and the Queued heartbeat, :meth:`admit`)."""
        self.admit()
        self._handler_task = asyncio.create_task(self._process_handler(), name=f"{self.name}-ph")

    def shut(self, reason: str) -> None:
        """Refuse to run anything more: fail the queued processes and ask the running
        one to stop, each with ``reason``."""
        self.closing = True
        for entry in self.queue.remove_if(lambda e: True):
            self.finish(entry, ProcessStates.Failed, reason)
        if self.holder is not None and not self.holder.abort_reason:
            self.holder.abort_reason = reason
        self.queue.poke()

    async def stop(self) -> None:
        """After :meth:`shut`: end the heartbeat, let the ProcessHandler end after the
        current process (bounded by :data:`STOP_WAIT_S`, then cancelled)."""
        heartbeat, self._heartbeat_task = self._heartbeat_task, None
        if heartbeat is not None:
            heartbeat.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await heartbeat
        if self._handler_task is not None:
            done, _ = await asyncio.wait({self._handler_task}, timeout=STOP_WAIT_S)
            if not done:
                self._handler_task.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await self._handler_task

    # -- what the admission and the presence of senders ask ----------------------------

    def knows(self, sender: str, identifier: int) -> bool:
        """Whether ``sender``'s process ``identifier`` is accepted and not yet finished."""
        return (sender, identifier) in self.known

    def post(self, entry: Entry) -> None:
        """Queue an admitted process (``ProcessQueue.Post`` of the CreateProcessHandler)."""
        self.known[(entry.sender, entry.identifier)] = entry
        self.queue.post(entry)
        self._queued.set()

    def sender_lost(self, name: str, instance: str) -> None:
        """A sender's incarnation left the cell: its queued processes end Failed, its
        hold is aborted."""
        gone = self.queue.remove_if(lambda e: e.sender == name and e.instance == instance)
        for entry in gone:
            self.finish(entry, ProcessStates.Failed,
                        f"sender {name} lost (liveliness) before the process started")
        holder = self.holder
        if (
            holder is not None
            and holder.sender == name
            and holder.instance == instance
            and not holder.abort_reason
        ):
            holder.abort_reason = f"sender {name} lost (liveliness token withdrawn)"
            self.queue.poke()

    def note(self, text: str) -> None:
        """A remark on the NoData/SingleData process being dispatched (its Completed
        update's reason)."""
        if text:
            self._notes.append(str(text))

    # -- the ProcessHandler (5.2.3.4, Figure 5-12) -------------------------------------

    async def _process_handler(self) -> None:
        while not self.closing:
            entry = self.queue.take_next()
            if entry is None:
                await self.queue.wait(None)
                continue
            try:
                await self._run(entry)
            except asyncio.CancelledError:
                self.finish(entry, ProcessStates.Failed, f"{self.name}: service shutting down")
                raise
            except Exception as exc:  # never let one process kill the handler
                log.exception("%s: error running %s", self.name, entry.command.name)
                self.finish(entry, ProcessStates.Failed, f"{self.name}: internal error: {exc!r}")
            finally:
                self.holder = None
                self.measuring = None
                self._busy(False)

    async def _queued_heartbeat(self) -> None:
        """Tell the senders of waiting processes, every :data:`QUEUED_HEARTBEAT_S`, that
        their process is still queued (the process's seq advances; the journal keeps
        the state changes only).  While nothing waits it sleeps until a process is
        posted: an idle service does not wake."""
        while not self.closing:
            if not len(self.queue):
                self._queued.clear()
                await self._queued.wait()
                continue
            await asyncio.sleep(QUEUED_HEARTBEAT_S)
            now = time.time_ns()
            for entry in self.queue:
                if now - entry.received_ns < QUEUED_HEARTBEAT_S * 1e9:
                    continue
                entry.seq += 1
                self._heartbeat(entry, ProcessUpdateNotification(
                    tag=entry.process.tag, identifier=entry.identifier,
                    state=ProcessStates.Queued, seq=entry.seq))

    async def _run(self, entry: Entry) -> None:
        command = entry.command
        if command.type is CommandTypes.StopData:
            self.finish(
                entry,
                ProcessStates.Failed,
                f"{command.name}: no MultipleData process of {entry.sender} is running",
            )
            return
        self.running(entry)
        if command.type is CommandTypes.MultipleData:
            await self._hold(entry)
            return
        self.measuring = entry if command.type is CommandTypes.SingleData else None
        self._single_data = []
        self._notes = []
        ok, reason = await self._execute(entry)
        self.measuring = None
        note, self._notes = "; ".join(self._notes), []
        if not ok:
            self.finish(entry, ProcessStates.Failed, reason)
        elif command.type is CommandTypes.SingleData:
            if not self._single_data:
                self.finish(
                    entry,
                    ProcessStates.Failed,
                    f"{command.name}: the device reported success but no data",
                )
                return
            try:
                data = to_data(
                    self._single_data[0],
                    command.output_data_type,
                    command.output_data_size,
                    f"{command.name} output",
                )
            except DataError as exc:
                self.finish(entry, ProcessStates.Failed, f"device produced invalid data: {exc}")
                return
            self.finish(entry, ProcessStates.Completed, note, data)
        else:
            self.finish(entry, ProcessStates.Completed, note)

    async def _execute(self, entry: Entry) -> tuple[bool, str]:
        """Dispatch one command and wait (bounded) for its command feedback."""
        command = entry.command
        waiter: asyncio.Future[str] = asyncio.get_running_loop().create_future()
        self._cmd_waiter = waiter
        self.sender = entry.sender
        try:
            async with asyncio.timeout(command.timeout):
                code = await self._dispatch(command, command.option, entry.input)
                if code is None:
                    code = await waiter
        except TimeoutError:
            return False, (
                f"{command.name}: no command feedback from the device within {command.timeout:g} s"
            )
        except DeviceError as exc:
            return False, f"{command.name}: {exc}"
        except Exception as exc:
            log.exception("%s: device interface error in %s", self.name, command.name)
            return False, f"{command.name}: device interface error: {exc!r}"
        finally:
            self._cmd_waiter = None
            self.sender = ""
        if code == command.success_code:
            return True, ""
        return False, (
            f"{command.name}: device feedback {code!r} (success code {command.success_code!r})"
        )

    async def _hold(self, entry: Entry) -> None:
        """Run a MultipleData process and hold the device until its sender's StopData (5.2.3.5)."""
        command = entry.command
        deadline = time.monotonic() + command.timeout
        self.holder = entry
        self.measuring = entry
        ok, reason = await self._execute(entry)
        if not ok:
            self.finish(entry, ProcessStates.Failed, reason)
            return
        while True:
            if entry.abort_reason:
                self.measuring = None
                await self._stop_device(entry)
                self.finish(entry, ProcessStates.Failed, entry.abort_reason)
                return
            stop = self.queue.take_stop_for(entry.sender)
            if stop is not None:
                self.running(stop)
                ok, reason = await self._execute(stop)
                self.measuring = None
                if ok:
                    self.finish(stop, ProcessStates.Completed, "")
                    self.finish(entry, ProcessStates.Completed, "")
                else:
                    self.finish(stop, ProcessStates.Failed, reason)
                    self.finish(
                        entry,
                        ProcessStates.Failed,
                        f"stopped by {stop.command.name}, which failed: {reason}",
                    )
                return
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                entry.abort_reason = (
                    f"{command.name}: held the device longer than its timeout "
                    f"of {command.timeout:g} s"
                )
                continue
            await self.queue.wait(remaining)

    async def _stop_device(self, entry: Entry) -> None:
        """Stop a MultipleData stream whose sender will not: dispatch the catalogue's StopData."""
        stops = [c for c in self.device.commands if c.type is CommandTypes.StopData]
        if not stops:
            return
        stop = stops[0]
        try:
            async with asyncio.timeout(stop.timeout):
                await self._dispatch(stop, "", None)
        except Exception as exc:
            log.warning(
                "%s: %s after %s could not stop the device: %r",
                self.name,
                stop.name,
                entry.command.name,
                exc,
            )

    # -- receivers of the feedback ports (5.2.3.2) -------------------------------------

    def on_data(self, value: Any) -> None:
        """DataFeedback receiver — the MeasurementsHandler of 5.2.3.4."""
        entry = self.measuring
        if entry is None:
            self.stray_feedback += 1
            return
        if entry.command.type is CommandTypes.SingleData:
            self._single_data.append(value)
            return
        try:
            data = to_data(
                value,
                entry.command.output_data_type,
                entry.command.output_data_size,
                f"{entry.command.name} output",
            )
        except DataError as exc:
            if not entry.abort_reason:
                entry.abort_reason = f"device produced invalid data: {exc}"
                self.queue.poke()
            return
        self._update(entry, ProcessStates.Running, "", data)

    def on_cmd(self, code: str) -> None:
        """CmdFeedback receiver — the CommandFeedbackHandler of 5.2.3.4."""
        waiter = self._cmd_waiter
        if waiter is not None and not waiter.done():
            waiter.set_result(code)
            return
        holder = self.holder
        if holder is not None and code != holder.command.success_code and not holder.abort_reason:
            holder.abort_reason = f"{holder.command.name}: device feedback {code!r} while streaming"
            self.queue.poke()
            return
        self.stray_feedback += 1

    # -- updates ---------------------------------------------------------------------

    def running(self, entry: Entry) -> None:
        """ProcessState.Post(Running) and DeviceState.Post(Busy) of the ProcessHandler."""
        self._busy(True)
        self._update(entry, ProcessStates.Running, "", None)

    def finish(
        self, entry: Entry, state: ProcessStates, reason: str, data: Data | None = None
    ) -> None:
        """The final update of ``entry`` (the process is no longer known)."""
        self.known.pop((entry.sender, entry.identifier), None)
        if reason:
            log.info(
                "%s: %s #%d from %s %s: %s",
                self.name,
                entry.command.name,
                entry.identifier,
                entry.sender,
                state.value,
                reason,
            )
        self._update(entry, state, reason, data)


__all__ = ["QUEUED_HEARTBEAT_S", "DeviceError", "ProcessScheduler"]
