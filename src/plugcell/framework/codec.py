"""The codec of the wire format: a versioned MessagePack envelope around every message
(docs/protocol.md).

The thesis's DSS serialised messages to SOAP (5.3.2.2); here every Zenoh payload
is one MessagePack map::

    {"V": 1, "Sender": "ROBOT", "Instance": "<zenoh id>", "TimeNs": 17…,
     "Body": {"Kind": "Process", …}}

A request (``Process``, ``SubscribeRequest``, ``UnsubscribeRequest``) may carry
a signature of its sender under the optional key ``"Auth"`` (:class:`Auth`,
docs/protocol.md §3.1): the sender's certificate and a signature over
:func:`signing_input` — the cell, the recipient, the sender, its instance, the
timestamp, a random nonce, the SHA-256 of the certificate and that of the ``Body``
bytes exactly as they appear in the payload (:func:`body_bytes`).  The cryptography is in
:mod:`plugcell.framework.signing`; an envelope without ``Auth`` is unchanged, byte for
byte, and a decoder that does not know ``Auth`` ignores it.

Decoding copies no data: every ``Data`` buffer of a decoded message is a read-only
``memoryview`` into the payload (msgspec decodes ``bin`` into a ``memoryview`` field
without copying), so a 0.9 MB frame is copied once on its way in — out of the Zenoh
sample, which has no buffer interface — and never again; the views keep the payload
alive.  Encoding takes the buffers as they are (``bytes`` or views of arrays), so the
bytes on the wire are the same either way.

Decoding is strict: any malformed, truncated or mistyped input raises
:class:`WireError` with a reason fit to send back to whoever sent it, and nothing
else ever escapes the decoder (fuzz-tested).
"""

from __future__ import annotations

import hashlib
import struct
import time
from collections.abc import Callable
from typing import Annotated

import msgspec

from plugcell.framework.messages import Message, Name

#: The protocol version this implementation speaks.
VERSION = 1
#: Default largest accepted payload in bytes (a service may set its own).
DEFAULT_MAX_PAYLOAD = 64 * 1024 * 1024


#: Size of the random nonce of a signed request (bytes).
NONCE_SIZE = 16
#: Largest certificate (DER) a signed request may carry.
MAX_CERT_SIZE = 16 * 1024
#: Largest signature (an RSA-8192 signature is 1 KiB).
MAX_SIG_SIZE = 1024
#: Domain separation: the first bytes of every signing input (docs/protocol.md §3.1).
SIGNING_CONTEXT = b"plugcell-request/1\x00"

Instance = Annotated[str, msgspec.Meta(max_length=64)]


class Auth(msgspec.Struct, rename="pascal", kw_only=True):
    """The signature of a request by its sender (docs/protocol.md §3.1).

    ``cert`` is the sender's X.509 certificate (DER) issued by the cell's CA, CN = the
    sender's name; ``sig`` the signature, with that certificate's key, of
    :func:`signing_input`.  ``to_instance`` binds the request to one incarnation of
    the recipient (``""``: any).  Every key is required, so that no byte of a signed
    envelope can change without the decoder or the signature noticing.
    """

    cell: Name
    to: Name
    to_instance: Instance
    nonce: Annotated[bytes, msgspec.Meta(min_length=NONCE_SIZE, max_length=NONCE_SIZE)]
    cert: Annotated[bytes, msgspec.Meta(min_length=1, max_length=MAX_CERT_SIZE)]
    sig: Annotated[bytes, msgspec.Meta(min_length=1, max_length=MAX_SIG_SIZE)]


class Envelope(msgspec.Struct, rename="pascal", kw_only=True, omit_defaults=True):
    """Wrapper of every message: protocol version, who sent it, when, and the body."""

    v: int
    sender: Name
    instance: Instance
    time_ns: int
    body: Message
    auth: Auth | None = None
    """The sender's signature of a request (absent: unsigned)."""


class _SignedView(msgspec.Struct, rename="pascal", kw_only=True, omit_defaults=True):
    """An envelope with its body left as raw bytes: what a signature covers."""

    v: int
    sender: str
    instance: str
    time_ns: int
    body: msgspec.Raw
    auth: Auth | None = None


class _Header(msgspec.Struct, rename="pascal"):
    """Only the version: decoded on the error path to explain a failure better."""

    v: int


class WireError(ValueError):
    """Bytes that are not a valid message; ``str(error)`` is the precise reason."""


_encoder = msgspec.msgpack.Encoder()
_decoder = msgspec.msgpack.Decoder(Envelope)
_header_decoder = msgspec.msgpack.Decoder(_Header)
_view_decoder = msgspec.msgpack.Decoder(_SignedView)

Signer = Callable[[str, str, int, bytes], Auth]
"""``sign(sender, instance, time_ns, body_bytes) -> Auth`` (see :mod:`.signing`)."""


def encode(
    sender: str,
    instance: str,
    body: Message,
    sign: Signer | None = None,
    time_ns: int | None = None,
) -> bytes:
    """One message ready to put on Zenoh; signed by ``sign`` if given."""
    now = time.time_ns() if time_ns is None else time_ns
    if sign is None:
        return _encoder.encode(
            Envelope(v=VERSION, sender=sender, instance=instance, time_ns=now, body=body)
        )
    raw = _encoder.encode(body)
    auth = sign(sender, instance, now, raw)
    return _encoder.encode(
        _SignedView(
            v=VERSION, sender=sender, instance=instance, time_ns=now,
            body=msgspec.Raw(raw), auth=auth,
        )
    )


def attach_identifier(identifier: int) -> bytes:
    """The attachment of a published CreateProcess: its identifier (docs/protocol.md §5)."""
    return struct.pack("<Q", identifier)


def attached_identifier(attachment: object) -> int:
    """The identifier a published request carries in its attachment (0: none or bad)."""
    try:
        raw = attachment.to_bytes() if attachment is not None else b""  # type: ignore[attr-defined]
    except Exception:
        return 0
    return struct.unpack("<Q", raw)[0] if len(raw) == 8 else 0


def signing_input(
    auth: Auth, sender: str, instance: str, time_ns: int, body: bytes | memoryview
) -> bytes:
    """The bytes a request's signature covers (docs/protocol.md §3.1)::

        "plugcell-request/1" 0x00 ‖ s(Cell) ‖ s(To) ‖ s(ToInstance) ‖ s(Sender)
        ‖ s(Instance) ‖ u64(TimeNs) ‖ Nonce ‖ SHA-256(Cert) ‖ SHA-256(Body)

    ``s(x)`` is the UTF-8 of ``x`` after its length as a big-endian uint16, ``u64`` a
    big-endian uint64, ``Body`` the bytes of the ``Body`` value exactly as in the
    payload.  Raises ValueError for a timestamp outside 0 … 2⁶⁴−1.
    """
    if not 0 <= time_ns < 2**64:
        raise ValueError(f"timestamp {time_ns} outside 0 … 2**64-1")
    parts = [SIGNING_CONTEXT]
    for text in (auth.cell, auth.to, auth.to_instance, sender, instance):
        data = text.encode("utf-8")
        parts.append(struct.pack(">H", len(data)) + data)
    parts += [
        struct.pack(">Q", time_ns),
        auth.nonce,
        hashlib.sha256(auth.cert).digest(),
        hashlib.sha256(body).digest(),
    ]
    return b"".join(parts)


def body_bytes(payload: bytes | bytearray | memoryview) -> memoryview:
    """The bytes of the ``Body`` value of a payload, as sent (what a signature covers).

    Call after :func:`decode` accepted the payload; raises :class:`WireError` otherwise.
    """
    try:
        return memoryview(_view_decoder.decode(payload).body)
    except (msgspec.DecodeError, ValueError, TypeError, OverflowError, RecursionError) as exc:
        raise WireError(f"malformed message: {exc}") from None


def decode(
    payload: bytes | bytearray | memoryview, max_size: int = DEFAULT_MAX_PAYLOAD
) -> Envelope:
    """Decode and validate one message; raise :class:`WireError` with the reason.

    The message's data buffers are read-only views into ``payload`` (module docstring);
    a payload that could change under them (a ``bytearray``, a writeable view) is
    copied to ``bytes`` first.
    """
    if len(payload) > max_size:
        raise WireError(f"payload of {len(payload)} bytes exceeds the limit of {max_size} bytes")
    if not payload:
        raise WireError("empty payload")
    if type(payload) is not bytes and not (
        isinstance(payload, memoryview) and payload.readonly and type(payload.obj) is bytes
    ):
        payload = bytes(payload)
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
