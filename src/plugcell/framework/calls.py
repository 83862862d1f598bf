"""The processes a participant created and waits on: the ExternalProcessHandler of
thesis 5.2.3.6, the requester side.

``create`` looks the command up in the partner's catalogue, converts the data to the
declared type and size, sends ``CreateProcess`` — published on the partner's request key
when the partner takes published requests, else through its queryable — and returns a
:class:`~plugcell.framework.process_call.ProcessCall`, which the participant's
subscription to its process key then feeds (acknowledgements and updates) through the
call's public interface (``acknowledge``, ``receive``, ``fail``).
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import msgspec
import zenoh

from plugcell.framework import codec
from plugcell.framework.data import DataError, to_data
from plugcell.framework.keys import check_name
from plugcell.framework.messages import (
    Acknowledgement,
    Command,
    CommandTypes,
    Data,
    Process,
    Tag,
    process_acks,
    process_updates,
)
from plugcell.framework.process_call import ProcessCall

if TYPE_CHECKING:
    from plugcell.framework.participant import Participant

__all__ = ["Calls", "PartnerError"]

log = logging.getLogger("plugcell.framework")


class PartnerError(RuntimeError):
    """A partner could not be reached or refused; the message is the reason."""


def _text(raw: bytes) -> str:
    return raw.decode("utf-8", "replace")


class Calls:
    """The outbound processes of one participant (module docstring)."""

    def __init__(self, participant: Participant) -> None:
        self.participant = participant
        self._calls: dict[tuple[str, int], ProcessCall] = {}
        self.publishes_requests = True
        """False for a participant whose certificate has another name (see
        :meth:`request_door`)."""
        self._doors: dict[str, Any] = {}
        """Publishers of CreateProcess requests, per partner (:meth:`request_door`)."""
        self._last_id = 0

    def fail_all(self, reason: str) -> None:
        """End every process still waiting, Failed with ``reason`` (the participant closes)."""
        for call in list(self._calls.values()):
            call.fail(reason)
        self._calls.clear()

    def close_doors(self) -> None:
        """Undeclare the request publishers."""
        for door in self._doors.values():
            door.undeclare()

    async def create(
        self,
        partner: str,
        command: str,
        option: str = "",
        data: Any = None,
        *,
        timeout: float = 10.0,
        check: bool = True,
    ) -> ProcessCall:
        """Create a process at ``partner`` and return it once acknowledged.

        Subscribes to ``partner`` first if needed.  With ``check`` (default) the
        command and data are checked against the partner's catalogue here, with
        the same reasons the recipient would give; ``check=False`` sends as-is
        (``data`` must then be a :class:`Data` or None) and lets the recipient judge.
        A process that cannot be created is returned already Failed — this
        method does not raise for bad input or a missing partner.
        """
        p = self.participant
        assert p.bus is not None, "create_process before start()"
        identifier = self._next_identifier()
        call = ProcessCall(p.name, partner, command, identifier, timeout,
                           asyncio.get_running_loop())
        try:
            process = await self._make_process(
                partner, command, option, data, identifier, check, timeout
            )
        except (PartnerError, DataError, ValueError) as exc:
            call.fail(str(exc))
            return call
        self._calls[(partner, identifier)] = call
        call.sent_ns = time.perf_counter_ns()
        payload = p.encode(process, to=partner)
        door = self.request_door(partner)
        if door is not None:  # the partner takes published requests: ack on the process key
            try:
                door.put(payload, attachment=codec.attach_identifier(identifier))
            except zenoh.ZError as exc:
                call.fail(f"cannot send CreateProcess to {partner}: {exc}")
        else:
            p.bus.query("create", partner, payload, *self._ack_handlers(call),
                        timeout=timeout)
        await call.acknowledged()
        if call.final is not None:
            self._calls.pop((partner, identifier), None)
        return call

    async def _make_process(
        self,
        partner: str,
        command: str,
        option: str,
        data: Any,
        identifier: int,
        check: bool,
        timeout: float,
    ) -> Process:
        p = self.participant
        check_name(partner, "service name")
        if not check:
            known = p.partners.get(partner)
            cmd = (known.device.command(command) if known else None) or Command(name=command)
            if data is not None and not isinstance(data, Data):
                raise DataError("check=False needs data as a Data buffer or None")
            return Process(
                command=msgspec.structs.replace(cmd, option=option),
                tag=Tag(p.name, partner),
                identifier=identifier,
                data=data,
            )
        if partner not in p.partners:
            await p.subscribe(partner, timeout)
        device = p.partners[partner].device
        cmd = device.command(command)
        if cmd is None:
            known = ", ".join(c.name for c in device.commands) or "none"
            raise PartnerError(f"unknown command {command!r} for {partner} (commands: {known})")
        typed = to_data(data, cmd.input_data_type, cmd.input_data_size, f"{cmd.name} input")
        return Process(
            command=msgspec.structs.replace(cmd, option=option),
            tag=Tag(p.name, partner),
            identifier=identifier,
            data=typed,
        )

    def request_door(self, partner: str) -> Any:
        """The publisher of requests to ``partner`` if ``partner`` subscribes to them
        (Zenoh's matching status, known locally), else None: use the queryable.

        Also None for a participant whose certificate has another name: a secure
        cell's Zenoh ACL drops such publications silently, while the queryable door
        brings back the service's precise refusal.
        """
        p = self.participant
        if not self.publishes_requests:  # the cell's ACL would drop them unanswered
            return None
        door = self._doors.get(partner)
        if door is None:
            assert p.bus is not None
            door = p.bus.request_door(partner, p.name)
            self._doors[partner] = door
        return door if door.matching_status.matching else None

    def _on_ack(self, call: ProcessCall, ack: Acknowledgement, instance: str) -> None:
        call.acknowledge(ack, instance)
        if call.final is not None:
            self._calls.pop((call.partner, call.identifier), None)

    def _ack_handlers(
        self, call: ProcessCall
    ) -> tuple[Callable[[Any], None], Callable[[Any], None]]:
        """The reply and done handlers of a CreateProcess sent through the queryable."""
        p = self.participant

        def reply(r: Any) -> None:
            if r.ok is None:
                text = _text(r.err.payload.to_bytes()) if r.err else "error reply"
                call.fail(f"{call.partner} answered CreateProcess with an error: {text}")
                return
            try:
                envelope = codec.decode(r.ok.payload.to_bytes())
            except codec.WireError as exc:
                call.fail(f"bad acknowledgement from {call.partner}: {exc}")
                return
            if isinstance(envelope.body, Acknowledgement):
                self._on_ack(call, envelope.body, envelope.instance)
            else:
                call.fail(
                    f"bad acknowledgement from {call.partner}: {type(envelope.body).__name__}"
                )

        asked = time.monotonic()

        def done(_: Any) -> None:
            if call.ack is None:
                waited = time.monotonic() - asked
                if not p.is_alive(call.partner):
                    reason = (f"unknown device {call.partner!r}: no service answered in cell "
                              f"{p.keys.cell!r}")
                elif waited < call.timeout - 0.5:  # the query ended early: no one replied
                    reason = (f"{call.partner} did not answer CreateProcess (no reply after "
                              f"{waited * 1e3:.0f} ms; the service may be stopping)")
                else:
                    reason = f"no acknowledgement from {call.partner} within {call.timeout:g} s"
                call.fail(reason)
                self._calls.pop((call.partner, call.identifier), None)

        return reply, done

    def on_process_update(self, sample: zenoh.Sample) -> None:
        p = self.participant
        try:
            envelope = codec.decode(sample.payload.to_bytes())
        except codec.WireError as exc:
            log.warning("%s: bad ProcessUpdate on %s: %s", p.name, sample.key_expr, exc)
            return
        for ack in process_acks(envelope.body):
            call = self._calls.get((envelope.sender, ack.identifier))
            if call is not None:
                self._on_ack(call, ack, envelope.instance)
        for update in process_updates(envelope.body):
            call = self._calls.get((envelope.sender, update.identifier))
            if call is None:
                continue
            if call.instance and envelope.instance and envelope.instance != call.instance:
                # another incarnation of the name (two at once, briefly, until the
                # younger withdraws — both hear a published request): not our process
                continue
            call.receive(update, envelope.instance)
            if call.final is not None:
                self._calls.pop((envelope.sender, update.identifier), None)

    async def stop(
        self, call: ProcessCall, command: str | None = None, timeout: float | None = None
    ) -> ProcessCall:
        """Send the StopData command that ends ``call`` (a MultipleData process).

        ``command`` defaults to the first StopData command of the partner's catalogue.
        """
        p = self.participant
        if command is None:
            partner = p.partners.get(call.partner)
            stops = [
                c.name
                for c in (partner.device.commands if partner else ())
                if c.type is CommandTypes.StopData
            ]
            if not stops:
                raise PartnerError(f"{call.partner} has no StopData command")
            command = stops[0]
        return await self.create(
            call.partner, command, timeout=timeout if timeout is not None else call.timeout
        )

    def fail_partner(self, partner: str, instance: str | None, reason: str) -> None:
        for key, call in list(self._calls.items()):
            if call.partner == partner and (instance is None or call.instance in ("", instance)):
                call.fail(reason)
                self._calls.pop(key, None)

    def _next_identifier(self) -> int:
        self._last_id = max(self._last_id + 1, time.time_ns())
        return self._last_id
