"""Signed requests: who sent a CreateProcess/Subscribe, whatever the network path.

Mutual TLS authenticates *links*; behind a Zenoh router a service sees only the
router's.  A signed request authenticates its *sender* end to end
(docs/security.md, "Signed requests"; the format is docs/protocol.md §3.1):

* the sender (:class:`RequestSigner`, built from the participant's TLS certificate
  and key — the same ``PLUGCELL_TLS_*`` settings) attaches to every request its
  certificate (DER) and a signature of :func:`~.wire.signing_input`: the cell, the
  recipient (and its instance when known), its own name and instance, the
  timestamp, a random 16-byte nonce and the SHA-256 of the body bytes;
* the recipient (:class:`RequestVerifier`, from the cell's CA file) checks that the
  certificate was issued by the cell's CA and is valid now, that its CN is the
  sender, that the request is addressed to it, that the timestamp is within
  ±``window_s`` of its clock, that the signature verifies, and that the nonce was
  not seen within the window (replay).  A service uses it when its access policy
  says ``identity = "signed"``.

Key types: what ``plugcell certs`` creates (ECDSA P-256, signed with SHA-256), and
also ECDSA P-384/P-521 (SHA-384/SHA-512), Ed25519 and RSA (PKCS#1 v1.5, SHA-256); the
algorithm follows from the certificate's key, never from the message.
"""

from __future__ import annotations

import datetime as dt
import hashlib
import os
import time
import warnings
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from cryptography import x509
from cryptography.exceptions import InvalidSignature, UnsupportedAlgorithm
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec, ed25519, padding, rsa
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

from plugcell.framework import codec
from plugcell.framework.messages import Message, Process, SubscribeRequest, UnsubscribeRequest

if TYPE_CHECKING:  # pragma: no cover
    from plugcell.framework.transport import TransportConfig

#: The messages a participant signs (those an access policy judges).
SIGNED_REQUESTS = (Process, SubscribeRequest, UnsubscribeRequest)
#: Default accepted clock difference between a request's timestamp and the recipient.
DEFAULT_WINDOW_S = 30.0
#: Verified certificates kept by fingerprint (their chain is checked once).
CERT_CACHE_SIZE = 1024


class SigningError(ValueError):
    """A certificate or key that cannot sign requests (the message says why)."""


def is_request(body: Message) -> bool:
    """True for the messages a participant signs."""
    return isinstance(body, SIGNED_REQUESTS)


def common_name(cert: x509.Certificate) -> str:
    """The CN of a certificate's subject (``""`` if none)."""
    attrs = cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)
    value = attrs[0].value if attrs else ""
    return value if isinstance(value, str) else value.decode("utf-8", "replace")


def certificate_name(path: str | Path) -> str:
    """The CN of the PEM certificate at ``path`` (``""`` if it cannot be read)."""
    try:
        return common_name(x509.load_pem_x509_certificate(Path(path).read_bytes()))
    except (OSError, ValueError):
        return ""


def _hash_for(key: Any) -> hashes.HashAlgorithm:
    size = key.curve.key_size
    return hashes.SHA256() if size <= 256 else hashes.SHA384() if size <= 384 else hashes.SHA512()


def _sign(key: Any, data: bytes) -> bytes:
    if isinstance(key, ec.EllipticCurvePrivateKey):
        return key.sign(data, ec.ECDSA(_hash_for(key)))
    if isinstance(key, ed25519.Ed25519PrivateKey):
        return key.sign(data)
    if isinstance(key, rsa.RSAPrivateKey):
        return key.sign(data, padding.PKCS1v15(), hashes.SHA256())
    raise SigningError(f"cannot sign with a {type(key).__name__}")  # pragma: no cover


def _verify(key: Any, signature: bytes, data: bytes) -> bool:
    try:
        if isinstance(key, ec.EllipticCurvePublicKey):
            key.verify(signature, data, ec.ECDSA(_hash_for(key)))
        elif isinstance(key, ed25519.Ed25519PublicKey):
            key.verify(signature, data)
        elif isinstance(key, rsa.RSAPublicKey):
            key.verify(signature, data, padding.PKCS1v15(), hashes.SHA256())
        else:
            return False
    except (InvalidSignature, ValueError, TypeError):
        return False
    return True


# -- the sender ---------------------------------------------------------------------------


@dataclass
class RequestSigner:
    """Signs a participant's requests with its certificate's private key."""

    cert_der: bytes
    key: Any
    name: str
    """The certificate's CN (a service refuses requests whose sender differs)."""

    @classmethod
    def load(cls, cert: str | Path, key: str | Path) -> RequestSigner:
        """From the PEM files of ``plugcell certs`` (the participant's TLS files)."""
        try:
            certificate = x509.load_pem_x509_certificate(Path(cert).read_bytes())
        except (OSError, ValueError) as exc:
            raise SigningError(f"cannot read the certificate {cert}: {exc}") from None
        try:
            private = serialization.load_pem_private_key(Path(key).read_bytes(), None)
        except (OSError, ValueError, TypeError) as exc:
            raise SigningError(f"cannot read the private key {key}: {exc}") from None
        return cls.from_objects(certificate, private, f"{cert} / {key}")

    @classmethod
    def from_objects(cls, cert: x509.Certificate, key: Any, where: str = "") -> RequestSigner:
        if not isinstance(
            key, ec.EllipticCurvePrivateKey | ed25519.Ed25519PrivateKey | rsa.RSAPrivateKey
        ):
            raise SigningError(f"{where}: unsupported key type {type(key).__name__}")
        public = serialization.PublicFormat.SubjectPublicKeyInfo
        der = serialization.Encoding.DER
        if key.public_key().public_bytes(der, public) != cert.public_key().public_bytes(
            der, public
        ):
            raise SigningError(f"{where}: the private key does not belong to the certificate")
        return cls(cert.public_bytes(der), key, common_name(cert))

    @classmethod
    def from_transport(cls, transport: TransportConfig) -> RequestSigner | None:
        """The signer of a participant's TLS certificate and key (None without them)."""
        if not (transport.tls_cert and transport.tls_key) or not transport.sign_requests:
            return None
        return cls.load(transport.tls_cert, transport.tls_key)

    def signer(self, cell: str, to: str, to_instance: str = "",
               nonce: bytes | None = None) -> codec.Signer:
        """The ``sign`` callback of :func:`.wire.encode` for one request."""

        def sign(sender: str, instance: str, time_ns: int, body: bytes) -> codec.Auth:
            auth = codec.Auth(
                cell=cell,
                to=to,
                to_instance=to_instance,
                nonce=nonce if nonce is not None else os.urandom(codec.NONCE_SIZE),
                cert=self.cert_der,
                sig=b"-",
            )
            auth.sig = _sign(self.key, codec.signing_input(auth, sender, instance, time_ns, body))
            return auth

        return sign

    def encode(
        self,
        sender: str,
        instance: str,
        body: Message,
        *,
        cell: str,
        to: str,
        to_instance: str = "",
        time_ns: int | None = None,
        nonce: bytes | None = None,
    ) -> bytes:
        """A signed envelope of ``body`` (what a participant sends)."""
        return codec.encode(
            sender, instance, body, self.signer(cell, to, to_instance, nonce), time_ns
        )


# -- the recipient ------------------------------------------------------------------------


@dataclass(frozen=True)
class _CertInfo:
    cn: str
    key: Any
    not_before: dt.datetime
    not_after: dt.datetime
    problem: str  # "" when issued by the cell's CA for signing


def load_ca(path: str | Path) -> tuple[x509.Certificate, ...]:
    """The CA certificates of a PEM file (a cell's ``ca.pem``; several for a rollover)."""
    try:
        certs = tuple(x509.load_pem_x509_certificates(Path(path).read_bytes()))
    except (OSError, ValueError) as exc:
        raise SigningError(f"cannot read the cell's CA {path}: {exc}") from None
    if not certs:  # pragma: no cover - load_pem_x509_certificates raises instead
        raise SigningError(f"no certificate in the cell's CA {path}")
    return certs


@dataclass
class RequestVerifier:
    """Checks the signature of requests addressed to one service (thread: its loop)."""

    cas: tuple[x509.Certificate, ...]
    window_s: float = DEFAULT_WINDOW_S
    clock: Callable[[], int] = time.time_ns
    _certs: dict[bytes, _CertInfo] = field(default_factory=dict, repr=False)
    _nonces: dict[bytes, int] = field(default_factory=dict, repr=False)
    _prune_at: int = field(default=1024, repr=False)

    @classmethod
    def load(cls, ca: str | Path, window_s: float = DEFAULT_WINDOW_S) -> RequestVerifier:
        return cls(load_ca(ca), window_s)

    def verify(
        self,
        envelope: codec.Envelope,
        payload: bytes | bytearray | memoryview | None,
        *,
        cell: str,
        recipient: str,
        recipient_instance: str,
    ) -> str:
        """``""`` if ``envelope`` (decoded from ``payload``) is a valid signed request
        of its sender to ``recipient``; else the reason of the refusal."""
        sender = envelope.sender
        auth = envelope.auth
        if auth is None:
            return f"access denied: request of {sender} not signed"
        who = f"access denied: request of {sender}"
        if auth.cell != cell or auth.to != recipient:
            return (
                f"{who}: signed for {auth.to} in cell {auth.cell}, "
                f"this is {recipient} in cell {cell}"
            )
        if auth.to_instance and auth.to_instance != recipient_instance:
            return (
                f"{who}: signed for another instance of {recipient} ({auth.to_instance}; "
                f"replayed across a restart?)"
            )
        try:
            return self._verify(envelope, auth, payload, recipient)
        except Exception as exc:  # a request must never crash its recipient  # pragma: no cover
            return f"{who}: cannot verify: {exc!r}"

    def _verify(
        self,
        envelope: codec.Envelope,
        auth: codec.Auth,
        payload: bytes | bytearray | memoryview | None,
        recipient: str,
    ) -> str:
        sender = envelope.sender
        who = f"access denied: request of {sender}"
        now = self.clock()
        info = self._certificate(auth.cert)
        if info.problem:
            return f"{who}: {info.problem}"
        now_dt = dt.datetime.fromtimestamp(now / 1e9, dt.UTC)
        if not info.not_before <= now_dt <= info.not_after:
            return (
                f"{who}: certificate of {info.cn} not valid now "
                f"(valid {info.not_before:%Y-%m-%d %H:%M} … {info.not_after:%Y-%m-%d %H:%M} UTC)"
            )
        if info.cn != sender:
            return f"{who}: certificate CN {info.cn} is not the sender {sender}"
        window_ns = int(self.window_s * 1e9)
        offset = envelope.time_ns - now
        if abs(offset) > window_ns:
            when = "in the past" if offset < 0 else "in the future"
            return (
                f"{who}: timestamp {abs(offset) / 1e9:.1f} s {when}, "
                f"outside the window of ±{self.window_s:g} s"
            )
        if payload is None:
            return f"{who}: the request's bytes are not available to verify its signature"
        try:
            data = codec.signing_input(
                auth, sender, envelope.instance, envelope.time_ns, codec.body_bytes(payload)
            )
        except (codec.WireError, ValueError) as exc:  # pragma: no cover - decode() passed
            return f"{who}: cannot verify: {exc}"
        if not _verify(info.key, auth.sig, data):
            return f"{who}: signature does not verify"
        seen = self._nonces.get(auth.nonce)
        if seen is not None and seen >= now:
            return f"{who}: replayed request (nonce {auth.nonce.hex()} already seen)"
        self._remember(auth.nonce, envelope.time_ns + window_ns, now)
        return ""

    def _remember(self, nonce: bytes, expires_ns: int, now: int) -> None:
        self._nonces[nonce] = expires_ns
        if len(self._nonces) >= self._prune_at:
            self._nonces = {n: t for n, t in self._nonces.items() if t >= now}
            self._prune_at = max(1024, 2 * len(self._nonces))

    @property
    def remembered(self) -> int:
        """How many nonces the replay cache holds."""
        return len(self._nonces)

    def _certificate(self, der: bytes) -> _CertInfo:
        fingerprint = hashlib.sha256(der).digest()
        info = self._certs.get(fingerprint)
        if info is None:
            info = self._check_certificate(der)
            if len(self._certs) >= CERT_CACHE_SIZE:
                self._certs.clear()
            self._certs[fingerprint] = info
        return info

    def _check_certificate(self, der: bytes) -> _CertInfo:
        epoch = dt.datetime.fromtimestamp(0, dt.UTC)
        try:
            # hostile DER makes cryptography warn (a non-positive serial, a bad attribute
            # length …) and raise (ValueError, InvalidVersion, UnsupportedAlgorithm …)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                cert = x509.load_der_x509_certificate(der)
                cn = common_name(cert)
                key = cert.public_key()
                span = (cert.not_valid_before_utc, cert.not_valid_after_utc)
                problem = _issued_by(cert, self.cas) or _usable_for_signing(cert)
        except Exception as exc:
            return _CertInfo("", None, epoch, epoch, f"bad certificate ({exc})")
        if not problem and not isinstance(
            key, ec.EllipticCurvePublicKey | ed25519.Ed25519PublicKey | rsa.RSAPublicKey
        ):
            problem = f"unsupported key type {type(key).__name__} in the certificate of {cn}"
        if not problem:  # the CA's own validity bounds its certificates'
            ca = _issuer(cert, self.cas)
            assert ca is not None
            span = (max(span[0], ca.not_valid_before_utc), min(span[1], ca.not_valid_after_utc))
        return _CertInfo(cn, key, span[0], span[1], problem)


def _issuer(cert: x509.Certificate, cas: Iterable[x509.Certificate]) -> x509.Certificate | None:
    for ca in cas:
        try:
            cert.verify_directly_issued_by(ca)
        except (ValueError, TypeError, InvalidSignature, UnsupportedAlgorithm):
            continue
        return ca
    return None


def _issued_by(cert: x509.Certificate, cas: Iterable[x509.Certificate]) -> str:
    if _issuer(cert, cas) is not None:
        return ""
    issuer = ", ".join(
        str(a.value) for a in cert.issuer.get_attributes_for_oid(NameOID.COMMON_NAME)
    ) or cert.issuer.rfc4514_string()
    return f"certificate not issued by the cell's CA (issuer: {issuer})"


def _usable_for_signing(cert: x509.Certificate) -> str:
    cn = common_name(cert)
    try:
        constraints = cert.extensions.get_extension_for_class(x509.BasicConstraints).value
        if constraints.ca:
            return f"certificate of {cn} is a CA certificate, not a participant's"
    except x509.ExtensionNotFound:
        pass
    try:
        usage = cert.extensions.get_extension_for_class(x509.KeyUsage).value
        if not usage.digital_signature:
            return f"certificate of {cn} is not for digital signatures (key usage)"
    except x509.ExtensionNotFound:
        pass
    try:
        purposes = cert.extensions.get_extension_for_class(x509.ExtendedKeyUsage).value
        if ExtendedKeyUsageOID.CLIENT_AUTH not in purposes:
            return f"certificate of {cn} is not for client authentication (extended key usage)"
    except x509.ExtensionNotFound:
        pass
    return ""


__all__ = [
    "DEFAULT_WINDOW_S",
    "SIGNED_REQUESTS",
    "RequestSigner",
    "RequestVerifier",
    "SigningError",
    "common_name",
    "is_request",
    "load_ca",
]
