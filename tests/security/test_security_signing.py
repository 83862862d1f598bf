"""Signed requests without a network: the envelope, the signer and the verifier.

Certificates come from ``plugcell certs`` (``create_ca``/``issue_certificate``); the
verifier's clock is fixed so that timestamps and validity periods are exact.  The
property test tampers with one byte of a real signed envelope: the decoder refuses it
or the verifier does — never accepted, never another exception.
"""

from __future__ import annotations

import datetime as dt
import hashlib
import itertools
import re
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import msgspec
import pytest
from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec, ed25519, rsa
from cryptography.x509.oid import NameOID
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from plugcell.framework import codec
from plugcell.framework.certificates import create_ca, issue_certificate
from plugcell.framework.messages import (
    Command,
    Data,
    DataTypes,
    Message,
    Process,
    SubscribeRequest,
    Tag,
    UnsubscribeRequest,
)
from plugcell.framework.security import AccessPolicy, PolicyError
from plugcell.framework.signing import (
    RequestSigner,
    RequestVerifier,
    SigningError,
    is_request,
    load_ca,
)

CELL, INSTANCE, TO_INSTANCE = "lab1", "18a0c2f1d3e4b5a6" + "ab" * 16, "18a0c2f1d3e4b5a7" + "cd" * 16
NOW = 1_800_000_000_000_000_000  # 2027-01-15, inside every certificate's validity


@dataclass
class Pki:
    certs: Path
    rogue: Path

    def signer(self, name: str, folder: Path | None = None) -> RequestSigner:
        folder = folder or self.certs
        return RequestSigner.load(folder / f"{name}.pem", folder / f"{name}.key")

    def verifier(self, clock: int = NOW, window_s: float = 30.0) -> RequestVerifier:
        v = RequestVerifier.load(self.certs / "ca.pem", window_s)
        v.clock = lambda: clock
        return v


@pytest.fixture(scope="module")
def pki(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Pki]:
    base = tmp_path_factory.mktemp("pki")
    certs, rogue = base / "certs", base / "rogue"
    create_ca(certs, CELL)
    for name in ("ROBOT1", "ROBOT2", "CONTROLLER"):
        issue_certificate(certs, name, days=1000)
    create_ca(rogue, "rogue")
    issue_certificate(rogue, "ROBOT1", days=1000)
    yield Pki(certs, rogue)


def process(sender: str = "ROBOT1", identifier: int = 7, data: Data | None = None) -> Process:
    return Process(
        command=Command(name="Set Base"),
        tag=Tag(sender, "TRACKER"),
        identifier=identifier,
        data=data or Data(DataTypes.Double, (6,), b"\0" * 48),
    )


def signed(
    signer: RequestSigner,
    body: Message | None = None,
    *,
    sender: str = "ROBOT1",
    time_ns: int = NOW,
    to: str = "TRACKER",
    cell: str = CELL,
    to_instance: str = TO_INSTANCE,
) -> bytes:
    return signer.encode(
        sender, INSTANCE, body if body is not None else process(sender),
        cell=cell, to=to, to_instance=to_instance, time_ns=time_ns,
    )


def verdict(verifier: RequestVerifier, payload: bytes, recipient: str = "TRACKER") -> str:
    envelope = codec.decode(payload)
    return verifier.verify(
        envelope, payload, cell=CELL, recipient=recipient, recipient_instance=TO_INSTANCE
    )


# -- the envelope ---------------------------------------------------------------------------


def test_unsigned_envelopes_are_unchanged_and_old_decoders_read_signed_ones(pki: Pki) -> None:
    body = process()
    plain = codec.encode("ROBOT1", INSTANCE, body, time_ns=NOW)
    assert set(msgspec.msgpack.decode(plain)) == {"V", "Sender", "Instance", "TimeNs", "Body"}
    assert codec.decode(plain).auth is None

    payload = signed(pki.signer("ROBOT1"), body)
    raw = msgspec.msgpack.decode(payload)
    assert list(raw) == ["V", "Sender", "Instance", "TimeNs", "Body", "Auth"]
    assert list(raw["Auth"]) == ["Cell", "To", "ToInstance", "Nonce", "Cert", "Sig"]
    assert raw["Body"] == msgspec.msgpack.decode(plain)["Body"]  # the body is not wrapped

    class OldEnvelope(msgspec.Struct, rename="pascal"):  # a decoder that predates Auth
        v: int
        sender: str
        instance: str
        time_ns: int
        body: Message

    old = msgspec.msgpack.decode(payload, type=OldEnvelope)
    assert old.body == body and old.sender == "ROBOT1"
    decoded = codec.decode(payload)
    assert decoded.body == body and decoded.auth is not None
    assert decoded.auth.to == "TRACKER" and decoded.auth.to_instance == TO_INSTANCE
    assert x509.load_der_x509_certificate(decoded.auth.cert).subject.rfc4514_string() == (
        "CN=ROBOT1"
    )
    # the signature covers the Body bytes exactly as they are in the payload
    assert bytes(codec.body_bytes(payload)) == msgspec.msgpack.encode(body)


def test_signing_input_layout() -> None:
    """The bytes a signature covers (docs/protocol.md §3.1), field by field."""
    auth = codec.Auth(cell="c", to="T", to_instance="", nonce=bytes(range(16)), cert=b"x",
                     sig=b"y")
    got = codec.signing_input(auth, "R", "i1", 0x0102030405060708, b"\x80")
    assert got == (
        b"plugcell-request/1\x00"
        + b"\x00\x01c" + b"\x00\x01T" + b"\x00\x00" + b"\x00\x01R" + b"\x00\x02i1"
        + bytes.fromhex("0102030405060708") + bytes(range(16)) + hashlib.sha256(b"x").digest()
        + hashlib.sha256(b"\x80").digest()
    )
    with pytest.raises(ValueError, match="timestamp"):
        codec.signing_input(auth, "R", "i1", -1, b"")


def test_the_documented_signing_example_is_exact() -> None:
    """docs/protocol.md gives a worked signing input: another implementation can check
    its bytes against it."""
    doc = (Path(__file__).resolve().parents[2] / "docs" / "protocol.md").read_text()
    section = doc[doc.index("### 3.1"):doc.index("## 4.")]
    body_hex = re.search(r"Body bytes \(hex\): `([0-9a-f ]+)`", section)
    input_hex = re.search(r"signing input \(hex\):\n\n```\n([0-9a-f \n]+)```", section)
    assert body_hex and input_hex
    body = bytes.fromhex(body_hex.group(1))
    assert msgspec.msgpack.decode(body) == {"Kind": "SubscribeRequest", "Partner": "TRACKER"}
    auth = codec.Auth(cell="lab1", to="ROBOT1", to_instance="", nonce=bytes(range(16)),
                     cert=b"-", sig=b"-")
    expected = codec.signing_input(auth, "CONTROLLER", "18a0c2f1d3e4b5a6", 1_800_000_000 * 10**9,
                                  body)
    assert bytes.fromhex(input_hex.group(1)) == expected


def test_only_requests_are_signed() -> None:
    assert is_request(process()) and is_request(SubscribeRequest(partner="A"))
    assert is_request(UnsubscribeRequest(partner="A"))
    from plugcell.framework.messages import Acknowledgement, GetRequest, ProcessStates

    assert not is_request(GetRequest())
    assert not is_request(Acknowledgement(identifier=1, state=ProcessStates.Queued))


# -- the verifier -----------------------------------------------------------------------------


def test_a_signed_request_passes_once(pki: Pki) -> None:
    v = pki.verifier()
    payload = signed(pki.signer("ROBOT1"))
    assert verdict(v, payload) == ""
    again = verdict(v, payload)
    assert again.startswith("access denied: request of ROBOT1: replayed request (nonce ")
    assert v.remembered == 1
    # a new request (new nonce) of the same sender passes
    assert verdict(v, signed(pki.signer("ROBOT1"))) == ""
    # a wiring request too
    wiring = signed(pki.signer("CONTROLLER"), SubscribeRequest(partner="TRACKER"),
                    sender="CONTROLLER", to="ROBOT1")
    assert verdict(v, wiring, recipient="ROBOT1") == ""


def test_refusals_are_precise(pki: Pki) -> None:
    v = pki.verifier()
    r1, r2 = pki.signer("ROBOT1"), pki.signer("ROBOT2")
    unsigned = codec.encode("ROBOT1", INSTANCE, process(), time_ns=NOW)
    assert verdict(v, unsigned) == "access denied: request of ROBOT1 not signed"
    wrong_key = RequestSigner(r1.cert_der, r2.key, "ROBOT1")  # ROBOT1's certificate, ROBOT2's key
    assert verdict(v, signed(wrong_key)) == (
        "access denied: request of ROBOT1: signature does not verify")
    assert verdict(v, signed(r2)) == (
        "access denied: request of ROBOT1: certificate CN ROBOT2 is not the sender ROBOT1")
    assert verdict(v, signed(pki.signer("ROBOT1", pki.rogue))) == (
        "access denied: request of ROBOT1: certificate not issued by the cell's CA "
        "(issuer: plugcell cell rogue CA)")
    assert verdict(v, signed(r1, time_ns=NOW - 31 * 10**9)) == (
        "access denied: request of ROBOT1: timestamp 31.0 s in the past, "
        "outside the window of ±30 s")
    assert verdict(v, signed(r1, time_ns=NOW + 45 * 10**9)) == (
        "access denied: request of ROBOT1: timestamp 45.0 s in the future, "
        "outside the window of ±30 s")
    assert verdict(v, signed(r1, time_ns=NOW - 29 * 10**9)) == ""  # inside the window
    assert verdict(v, signed(r1, to="COMPUTE")) == (
        "access denied: request of ROBOT1: signed for COMPUTE in cell lab1, "
        "this is TRACKER in cell lab1")
    assert verdict(v, signed(r1, cell="lab2")).endswith(
        "signed for TRACKER in cell lab2, this is TRACKER in cell lab1")
    assert verdict(v, signed(r1, to_instance="0" * 16)) == (
        "access denied: request of ROBOT1: signed for another instance of TRACKER "
        f"({'0' * 16}; replayed across a restart?)")
    assert verdict(v, signed(r1, to_instance="")) == ""  # not bound to an instance: any
    # the sender's own claims are covered: a body changed after signing does not verify
    payload = signed(r1)
    envelope = codec.decode(payload)
    other = codec.encode("ROBOT1", INSTANCE, process(identifier=8), time_ns=NOW)
    assert v.verify(envelope, other, cell=CELL, recipient="TRACKER",
                    recipient_instance=TO_INSTANCE) == (
        "access denied: request of ROBOT1: signature does not verify")
    assert v.verify(envelope, None, cell=CELL, recipient="TRACKER",
                    recipient_instance=TO_INSTANCE).endswith("bytes are not available to "
                                                             "verify its signature")


def test_certificate_validity_and_kind(pki: Pki, tmp_path: Path) -> None:
    r1 = pki.signer("ROBOT1")
    late = NOW + 2000 * 86400 * 10**9  # after the certificate's 1000 days
    assert "certificate of ROBOT1 not valid now" in verdict(
        pki.verifier(clock=late), signed(r1, time_ns=late))
    early = 10**18  # 2001: before it
    assert "certificate of ROBOT1 not valid now" in verdict(
        pki.verifier(clock=early), signed(r1, time_ns=early))
    # the CA's own certificate and key: not a participant's certificate
    ca = RequestSigner.load(pki.certs / "ca.pem", pki.certs / "ca.key")
    assert verdict(pki.verifier(), signed(ca, sender="CA")).endswith(
        "certificate of plugcell cell lab1 CA is a CA certificate, not a participant's")
    # garbage in the certificate field
    bad = codec.Auth(cell=CELL, to="TRACKER", to_instance="", nonce=b"\0" * 16,
                    cert=b"\x30\x03\x02\x01\x01", sig=b"x")
    envelope = codec.Envelope(v=1, sender="ROBOT1", instance=INSTANCE, time_ns=NOW,
                             body=process(), auth=bad)
    payload = msgspec.msgpack.encode(envelope)
    assert verdict(pki.verifier(), payload).startswith(
        "access denied: request of ROBOT1: bad certificate (")


def _leaf(folder: Path, name: str, key: object, usage: x509.KeyUsage | None = None) -> bytes:
    ca_key = serialization.load_pem_private_key((folder / "ca.key").read_bytes(), None)
    ca = x509.load_pem_x509_certificate((folder / "ca.pem").read_bytes())
    now = dt.datetime.fromtimestamp(NOW / 1e9, dt.UTC)
    builder = (
        x509.CertificateBuilder()
        .subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, name)]))
        .issuer_name(ca.subject)
        .public_key(key.public_key())  # type: ignore[attr-defined]
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - dt.timedelta(days=1))
        .not_valid_after(now + dt.timedelta(days=1))
    )
    if usage is not None:
        builder = builder.add_extension(usage, critical=True)
    return builder.sign(ca_key, hashes.SHA256()).public_bytes(  # type: ignore[arg-type]
        serialization.Encoding.DER)


@pytest.mark.parametrize("kind", ["ed25519", "rsa", "p384"])
def test_other_key_types_sign_and_verify(pki: Pki, kind: str) -> None:
    key = {
        "ed25519": lambda: ed25519.Ed25519PrivateKey.generate(),
        "rsa": lambda: rsa.generate_private_key(65537, 2048),
        "p384": lambda: ec.generate_private_key(ec.SECP384R1()),
    }[kind]()
    der = _leaf(pki.certs, "ROBOT1", key)
    signer = RequestSigner.from_objects(x509.load_der_x509_certificate(der), key)
    assert verdict(pki.verifier(), signed(signer)) == ""
    other = ec.generate_private_key(ec.SECP256R1())
    with pytest.raises(SigningError, match="does not belong to the certificate"):
        RequestSigner.from_objects(x509.load_der_x509_certificate(der), other)


def test_key_usage_without_digital_signature_is_refused(pki: Pki) -> None:
    key = ec.generate_private_key(ec.SECP256R1())
    usage = x509.KeyUsage(digital_signature=False, content_commitment=False,
                          key_encipherment=False, data_encipherment=False, key_agreement=True,
                          key_cert_sign=False, crl_sign=False, encipher_only=False,
                          decipher_only=False)
    der = _leaf(pki.certs, "ROBOT1", key, usage)
    signer = RequestSigner(der, key, "ROBOT1")
    assert verdict(pki.verifier(), signed(signer)).endswith(
        "certificate of ROBOT1 is not for digital signatures (key usage)")


def test_signer_and_ca_files_errors(pki: Pki, tmp_path: Path) -> None:
    with pytest.raises(SigningError, match="cannot read the certificate"):
        RequestSigner.load(tmp_path / "none.pem", pki.certs / "ROBOT1.key")
    with pytest.raises(SigningError, match="cannot read the private key"):
        RequestSigner.load(pki.certs / "ROBOT1.pem", tmp_path / "none.key")
    with pytest.raises(SigningError, match="does not belong"):
        RequestSigner.load(pki.certs / "ROBOT1.pem", pki.certs / "ROBOT2.key")
    with pytest.raises(SigningError, match="cannot read the cell's CA"):
        load_ca(tmp_path / "none.pem")
    assert len(load_ca(pki.certs / "ca.pem")) == 1


def test_replay_cache_forgets_what_the_window_refuses_anyway(pki: Pki) -> None:
    signer = pki.signer("ROBOT1")
    v = pki.verifier(window_s=1.0)
    now = NOW
    v.clock = lambda: now
    for i in range(3000):
        now = NOW + i * 10**6  # 1 ms apart: about 1000 nonces inside the 1 s window
        assert verdict(v, signed(signer, time_ns=now)) == ""
    assert v.remembered <= 2100


def test_policy_identity_signed_and_window() -> None:
    p = AccessPolicy.from_mapping({"identity": "signed", "signature_window": 5})
    assert p.identity == "signed" and p.signature_window == 5.0
    assert AccessPolicy.from_mapping({}).signature_window == 30.0
    for bad in (0, -1, 4000, "30", True):
        with pytest.raises(PolicyError, match="signature_window must be seconds"):
            AccessPolicy.from_mapping({"signature_window": bad})
    with pytest.raises(PolicyError, match="identity must be 'none', 'tls' or 'signed'"):
        AccessPolicy.from_mapping({"identity": "cert"})


# -- tampering ------------------------------------------------------------------------------


_TAMPER_PAYLOADS: dict[str, bytes] = {}


def _sample(pki: Pki) -> dict[str, bytes]:
    if not _TAMPER_PAYLOADS:
        signer = pki.signer("ROBOT1")
        _TAMPER_PAYLOADS["process"] = signed(signer)
        _TAMPER_PAYLOADS["subscribe"] = signed(
            pki.signer("CONTROLLER"), SubscribeRequest(partner="COMPUTE"), sender="CONTROLLER")
    return _TAMPER_PAYLOADS


@settings(max_examples=600, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(which=st.sampled_from(["process", "subscribe"]), where=st.floats(0, 1, exclude_max=True),
       new=st.integers(0, 255), cut=st.booleans())
def test_tampering_with_any_byte_is_never_accepted(
    pki: Pki, which: str, where: float, new: int, cut: bool
) -> None:
    """Change one byte (or cut the payload there): decoding fails with WireError, or the
    verifier refuses with a reason; nothing else escapes."""
    original = _sample(pki)[which]
    i = int(where * len(original))
    if cut:
        tampered = original[:i]
    else:
        if original[i] == new:
            new ^= 0xFF
        tampered = original[:i] + bytes([new]) + original[i + 1:]
    try:
        envelope = codec.decode(tampered)
    except codec.WireError:
        return
    verifier = pki.verifier()  # fresh: the original was never seen
    recipient = "TRACKER"
    reason = verifier.verify(envelope, tampered, cell=CELL, recipient=recipient,
                             recipient_instance=TO_INSTANCE)
    assert reason.startswith("access denied: "), (i, new, cut)
    assert "cannot verify" not in reason, reason  # a refusal for a reason, not an exception


def test_tampering_every_byte_exhaustively(pki: Pki) -> None:
    """Every position of a signed Process, its low bit, high bit or all bits flipped:
    none is accepted."""
    original = _sample(pki)["process"]
    started = time.perf_counter()
    refused_by = {"decoder": 0, "verifier": 0}
    for i, mask in itertools.product(range(len(original)), (0x01, 0x80, 0xFF)):
        tampered = original[:i] + bytes([original[i] ^ mask]) + original[i + 1:]
        try:
            envelope = codec.decode(tampered)
        except codec.WireError:
            refused_by["decoder"] += 1
            continue
        reason = pki.verifier().verify(envelope, tampered, cell=CELL, recipient="TRACKER",
                                       recipient_instance=TO_INSTANCE)
        assert reason.startswith("access denied: ") and "cannot verify" not in reason, i
        refused_by["verifier"] += 1
    assert sum(refused_by.values()) == 3 * len(original)
    assert refused_by["verifier"] > 0 and time.perf_counter() - started < 60
