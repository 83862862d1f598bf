"""The wire codec: a versioned MessagePack envelope around every message (docs/protocol.md).

The thesis's DSS serialised messages to SOAP (5.3.2.2); here every Zenoh payload
is one MessagePack map::

    {"V": 1, "Sender": "ROBOT", "Instance": "<zenoh id>", "TimeNs": 17…,
     "Body": {"Kind": "Process", …}}

Decoding is strict: any malformed, truncated or mistyped input raises
:class:`WireError` with a reason fit to send back to whoever sent it, and nothing
else ever escapes the decoder (fuzz-tested).
"""

from __future__ import annotations

import time
from typing import Annotated

import msgspec

from plugcell.framework.model import Message, Name

#: The protocol version this implementation speaks.
VERSION = 1
#: Default largest accepted payload in bytes (a service may set its own).
DEFAULT_MAX_PAYLOAD = 64 * 1024 * 1024


class Envelope(msgspec.Struct, rename="pascal", kw_only=True):
    """Wrapper of every message: protocol version, who sent it, when, and the body."""

    v: int
    sender: Name
    instance: Annotated[str, msgspec.Meta(max_length=64)]
    time_ns: int
    body: Message


class _Header(msgspec.Struct, rename="pascal"):
    """Only the version: decoded on the error path to explain a failure better."""

    v: int


class WireError(ValueError):
    """Bytes that are not a valid message; ``str(error)`` is the precise reason."""


_encoder = msgspec.msgpack.Encoder()
_decoder = msgspec.msgpack.Decoder(Envelope)
_header_decoder = msgspec.msgpack.Decoder(_Header)


def encode(sender: str, instance: str, body: Message) -> bytes:
    """One message ready to put on Zenoh."""
    return _encoder.encode(
        Envelope(v=VERSION, sender=sender, instance=instance, time_ns=time.time_ns(), body=body)
    )


def decode(
    payload: bytes | bytearray | memoryview, max_size: int = DEFAULT_MAX_PAYLOAD
) -> Envelope:
    """Decode and validate one message; raise :class:`WireError` with the reason."""
    if len(payload) > max_size:
        raise WireError(f"payload of {len(payload)} bytes exceeds the limit of {max_size} bytes")
    if not payload:
        raise WireError("empty payload")
    try:
        envelope = _decoder.decode(payload)
    except msgspec.DecodeError as exc:
        raise WireError(_explain(payload, exc)) from None
    except (ValueError, TypeError, OverflowError, RecursionError) as exc:  # pragma: no cover
        raise WireError(f"malformed message: {exc}") from None
    if envelope.v != VERSION:
        raise WireError(f"unsupported protocol version {envelope.v} (this side speaks {VERSION})")
    return envelope


def _explain(payload: bytes | bytearray | memoryview, exc: msgspec.DecodeError) -> str:
    try:
        version = _header_decoder.decode(payload).v
    except (msgspec.DecodeError, ValueError, TypeError, OverflowError, RecursionError):
        version = VERSION
    if version != VERSION:
        return f"unsupported protocol version {version} (this side speaks {VERSION})"
    kind = "invalid message" if isinstance(exc, msgspec.ValidationError) else "malformed message"
    return f"{kind}: {exc}"
