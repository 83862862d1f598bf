"""Admission of a request: small checks, each returning the reason it fails ("" passes).

A CreateProcess reaching a service goes through, in this order (the
CreateProcessHandler of thesis 5.2.3.4,
:meth:`Inbound.create <plugcell.framework.inbound.Inbound.create>`):

1. :func:`decode_request` — present, within the size limit, a valid envelope;
2. :func:`check_envelope` — sent by the participant whose key it came on, a Process;
3. authentication — the access policy (:meth:`AccessPolicy.authenticate`);
4. :func:`check_process` — addressed here, tagged by its sender, from a sender not
   known to be gone, a command of the catalogue;
5. authorisation — the access policy (:meth:`AccessPolicy.authorize_create`);
6. :func:`check_input` — the input data of the declared type and size;
7. the journal — a duplicate identifier is refused, the process recorded.

Steps 1–3 and a duplicate *reject* the request (nothing is recorded under the claimed
name: only the rejection is journaled); a reason from steps 4–6 makes a process that is
journaled and acknowledged ``Failed``.  The checks are pure: they read the request and
what they are given, and change nothing.
"""

from __future__ import annotations

from typing import Any

from plugcell.framework import codec
from plugcell.framework.data import DataError, check_data, from_data
from plugcell.framework.messages import Command, Device, Process


def decode_request(payload: Any, max_payload: int, owner: str
                   ) -> tuple[codec.Envelope, bytes] | str:
    """``(envelope, its bytes)`` of a request (a Zenoh payload, or None), or why not."""
    size = len(payload) if payload is not None else 0
    if size == 0:
        return "empty request"
    if size > max_payload:
        return f"payload of {size} bytes exceeds the limit of {max_payload} bytes of {owner}"
    raw = payload.to_bytes()
    try:
        return codec.decode(raw, max_payload), raw
    except codec.WireError as exc:
        return str(exc)


def check_envelope(envelope: codec.Envelope, published_by: str | None) -> str:
    """The envelope's sender is who published it (``published_by``: the sender named by
    the request key; None for a query), and it carries a Process."""
    if published_by is not None and envelope.sender != published_by:
        return (f"envelope sender {envelope.sender} differs from the sender {published_by} "
                "of the request key")
    if not isinstance(envelope.body, Process):
        return f"expected a Process, got {type(envelope.body).__name__}"
    return ""


def check_process(owner: str, device: Device, envelope: codec.Envelope, process: Process,
                  departed: set[str]) -> str:
    """Addressed to ``owner``, tagged by the envelope's sender, from an instance not
    known to have left (``departed``), a command of ``device``'s catalogue."""
    if process.tag.recipient != owner:
        return f"process addressed to {process.tag.recipient}, this is {owner}"
    if process.tag.sender != envelope.sender:
        return (f"tag sender {process.tag.sender} differs from the envelope sender "
                f"{envelope.sender}")
    if envelope.instance and envelope.instance in departed:
        return f"sender {envelope.sender} (instance {envelope.instance}) is already gone"
    if device.command(process.command.name) is None:
        known = ", ".join(c.name for c in device.commands) or "none"
        return f"unknown command {process.command.name!r} for {owner} (commands: {known})"
    return ""


def check_input(command: Command, process: Process) -> tuple[Any, str]:
    """``(input array or None, "")`` for input data of ``command``'s declared type and
    size, else ``(None, reason)``."""
    try:
        check_data(process.data, command.input_data_type, command.input_data_size,
                   f"{command.name} input")
        return from_data(process.data), ""
    except DataError as exc:
        return None, str(exc)
