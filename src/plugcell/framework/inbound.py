"""The inbound doors of a service: Subscribe and CreateProcess, and the admission of
each request (thesis 5.2.3.4, the CreateProcessHandler).

:class:`Inbound` belongs to one :class:`~plugcell.framework.service.GenericDevice`: it
decodes a request, authenticates and authorises it with the service's access policy
(on its :class:`~plugcell.framework.security.Recipient` value), checks it
(:mod:`plugcell.framework.admission`), journals it, acknowledges it through the
service's outbox and hands an admitted process to its scheduler.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from typing import TYPE_CHECKING, Any

import msgspec
import zenoh

from plugcell.framework import codec
from plugcell.framework.admission import (
    check_envelope,
    check_input,
    check_process,
    decode_request,
)
from plugcell.framework.data import summary
from plugcell.framework.keys import check_name
from plugcell.framework.messages import (
    Acknowledgement,
    Command,
    Process,
    ProcessStates,
    SubscribeRequest,
    SubscribeResponse,
    UnsubscribeRequest,
)
from plugcell.framework.participant import PartnerError
from plugcell.framework.processqueue import Entry
from plugcell.framework.signing import RequestVerifier, SigningError

if TYPE_CHECKING:
    from plugcell.framework.service import GenericDevice

log = logging.getLogger("plugcell.framework.service")

Answer = zenoh.Query | str
"""Where a CreateProcess is acknowledged: its query, or the sender that published it."""

__all__ = ["Answer", "Inbound"]


class Inbound:
    """Subscribe and CreateProcess of one service (module docstring)."""

    def __init__(self, service: GenericDevice) -> None:
        self.service = service
        self._verifier: RequestVerifier | None = None

    def decode_query(self, query: zenoh.Query) -> tuple[codec.Envelope, bytes] | str:
        """The request of ``query`` and its bytes (a signature covers them), or why not."""
        return self.decode_request(query.payload)

    def decode_request(self, payload: zenoh.ZBytes | None) -> tuple[codec.Envelope, bytes] | str:
        """A request's envelope and its bytes, or why not (admission step 1)."""
        service = self.service
        return decode_request(payload, service.max_payload, service.name)

    def request_verifier(self) -> RequestVerifier:
        """The checker of signed requests (``identity = "signed"``), from the cell's CA
        of this service's transport (``PLUGCELL_TLS_CA``/``PLUGCELL_TLS_DIR``)."""
        service = self.service
        window = service.access.signature_window
        verifier = self._verifier
        if verifier is None or verifier.window_s != window:
            if not service.participant.transport.tls_ca:
                raise SigningError(
                    f"{service.name}: identity = 'signed' needs the cell's CA "
                    "(PLUGCELL_TLS_CA or PLUGCELL_TLS_DIR)"
                )
            verifier = RequestVerifier.load(service.participant.transport.tls_ca, window)
            self._verifier = verifier
        return verifier

    def role_of(self, sender: str) -> str | None:
        """``"service"`` or ``"client"`` if ``sender`` is live as one, else None."""
        for role in ("service", "client"):
            if self.service.participant.is_alive(sender, role):  # type: ignore[arg-type]
                return role
        return None

    def on_subscribe(self, query: zenoh.Query) -> None:
        service = self.service
        decoded = self.decode_query(query)
        if isinstance(decoded, str):
            service.reply(query, SubscribeResponse(ok=False, reason=decoded))
            return
        envelope, raw = decoded
        body = envelope.body
        if not isinstance(body, SubscribeRequest | UnsubscribeRequest):
            service.reply(
                query,
                SubscribeResponse(
                    ok=False, reason=f"expected SubscribeRequest, got {type(body).__name__}"
                ),
            )
            return
        # journaled below
        refused = service.access.check_wire(service.recipient, envelope, body.partner, raw)
        if refused:
            with contextlib.suppress(Exception):
                what = type(body).__name__
                service.journal.record_rejection(envelope.sender, None, what, 0, refused)
                service.journal.commit()
            service.reply(query, SubscribeResponse(ok=False, reason=refused))
            return
        asyncio.get_running_loop().create_task(self._subscribe_for(query, body))

    async def _subscribe_for(
        self, query: zenoh.Query, body: SubscribeRequest | UnsubscribeRequest
    ) -> None:
        service = self.service
        if isinstance(body, UnsubscribeRequest):
            found = await service.participant.unsubscribe(body.partner)
            reason = "" if found else f"{body.partner} was not a partner of {service.name}"
            service.reply(query, SubscribeResponse(ok=found, reason=reason))
            return
        try:
            device = await service.participant.subscribe(body.partner)
        except PartnerError as exc:
            service.reply(query, SubscribeResponse(ok=False, reason=str(exc)))
        except Exception as exc:  # always answer: the asker waits for it
            log.exception("%s: subscribing to %s", service.name, body.partner)
            service.reply(query, SubscribeResponse(ok=False, reason=f"{body.partner}: {exc!r}"))
        else:
            service.reply(query, SubscribeResponse(ok=True, partner=device))

    def on_create(self, query: zenoh.Query) -> None:
        """CreateProcess through the queryable: the acknowledgement is the reply."""
        self.create(query.payload, query)

    def on_request(self, sender: str, sample: zenoh.Sample) -> None:
        """CreateProcess published on ``svc/<name>/create/<sender>``: the acknowledgement
        goes to ``<sender>`` on its process key, in one sample with the first updates."""
        service = self.service
        try:
            check_name(sender, "sender name")
        except ValueError as exc:  # nobody to answer: journal it only
            size = len(sample.payload) if sample.payload is not None else 0
            with contextlib.suppress(Exception):
                service.journal.record_rejection(None, None, None, size, str(exc))
                service.journal.commit()
            return
        self.create(sample.payload, sender, codec.attached_identifier(sample.attachment))

    def create(self, payload: zenoh.ZBytes | None, answer: Answer, attached: int = 0) -> None:
        """CreateProcessHandler (5.2.3.4): admit (framework/admission.py: decode,
        authenticate, check, authorise, journal), acknowledge, enqueue.

        ``answer`` is where the acknowledgement goes: the query (queryable door) or
        the name of the sender that published the request (publication door, whose
        ``attached`` identifier acknowledges even a request that cannot be read).
        """
        service = self.service
        received = time.time_ns()
        size = len(payload) if payload is not None else 0
        decoded = (
            self.decode_request(payload)
            if not service.closing
            else f"{service.name}: service shutting down"
        )
        if isinstance(decoded, str):
            sender = answer if isinstance(answer, str) else None
            self._reject(answer, decoded, size, sender, attached or None)
            return
        envelope, raw = decoded
        published_by = answer if isinstance(answer, str) else None
        invalid = check_envelope(envelope, published_by)
        if invalid:
            self._reject(answer, invalid, size, published_by or envelope.sender)
            return
        process = envelope.body
        assert isinstance(process, Process)
        sender, identifier = process.tag.sender, process.identifier
        unauthenticated = service.access.authenticate(service.recipient, envelope, raw)
        if unauthenticated:  # a rejection: nothing is recorded under the claimed name
            self._reject(answer, unauthenticated, size, sender, identifier, process.command.name)
            return
        command, array, reason = self._judge(envelope, process)
        if service.scheduler.knows(sender, identifier):
            self._reject(answer, f"duplicate identifier {identifier} from {sender}", size,
                         sender, identifier, process.command.name)
            return
        state = ProcessStates.Failed if reason else ProcessStates.Queued
        try:
            service.journal.record_process(
                sender=sender,
                identifier=identifier,
                sender_instance=envelope.instance,
                recipient_instance=service.participant.instance,
                command=process.command.name,
                option=process.command.option,
                command_type=command.type.value if command else "",
                input_summary=summary(process.data),
                received_ns=received,
                state=state.value,
                reason=reason,
            )
        except Exception as exc:  # DuplicateProcessError: an identifier reused
            service.journal.commit()
            self._reject(answer, f"cannot journal process {identifier} from {sender}: {exc}",
                         size, sender, identifier, process.command.name)
            return
        ack = Acknowledgement(identifier=identifier, state=state, reason=reason,
                              instance=service.participant.instance)
        if not reason:
            assert command is not None
            command = msgspec.structs.replace(command, option=process.command.option)
            entry = Entry(
                process=msgspec.structs.replace(process, command=command),
                command=command,
                instance=envelope.instance,
                received_ns=received,
                input=array,
            )
            service.scheduler.post(entry)
        # after the post: a process the handler starts (or ends) in this turn of the
        # loop shares the acknowledgement's commit and sample
        service.outbox.acknowledge(answer, ack)

    def _judge(self, envelope: codec.Envelope, process: Process
               ) -> tuple[Command | None, Any, str]:
        """Check and authorise an authenticated process: its command in the catalogue,
        its checked input (an array or None) and the reason to refuse it ("" if none;
        refusals are journaled with it)."""
        service = self.service
        reason = check_process(service.name, service.device, envelope, process, service.departed)
        if not reason:  # access control
            reason = service.access.authorize_create(service.recipient, envelope, process)
        command = service.device.command(process.command.name)
        array = None
        if not reason and command is not None:
            array, reason = check_input(command, process)
        return command, array, reason

    def _reject(
        self,
        answer: Answer,
        reason: str,
        size: int,
        sender: str | None = None,
        identifier: int | None = None,
        command: str | None = None,
    ) -> None:
        """Journal a refused request; acknowledge it Failed with the reason (at the flush)."""
        service = self.service
        with contextlib.suppress(Exception):
            service.journal.record_rejection(sender, identifier, command, size, reason)
        service.outbox.acknowledge(answer, Acknowledgement(
            identifier=identifier or 0,
            state=ProcessStates.Failed,
            reason=reason,
            instance=service.participant.instance,
        ))
