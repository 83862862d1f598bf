"""Which OPC UA servers ``opcua-device`` trusts: their certificates checked (OPC 10000-4 §6.1.3).

A client that sends commands to whoever answers at an address gives them to a man in
the middle; so, before the session is activated (before a user's password leaves), the
service checks the certificate the server proved it holds (its CreateSession signature):

1. **trusted**: the certificate itself is in the trust list (a pinned certificate, e.g.
   a PLC's self-signed one), or it is issued by a trusted authority — the cell's OPC UA
   CA (``<certs>/opcua-ca.pem``) or a CA of the trust folder (``--trust DIR``); the chain
   is verified with ``cryptography``'s X.509 path validation;
2. **valid now** (not expired, not yet valid);
3. **not revoked** by its issuer's revocation list (``*.crl``, the cell's
   ``opcua-ca.crl``), a list whose signature verifies;
4. **its application URI** is the one the server describes itself with (and the one
   ``server_uri`` expects, if given);
5. **its host names** (subject alternative name DNS/IP) include the endpoint's host;
6. **its key usages** are those of an OPC UA application and its extended key usage
   ``serverAuth`` (asyncua's :class:`~asyncua.crypto.validator.CertificateValidator`).

A refusal raises :class:`UntrustedServerError` whose message says which check failed and
the certificate's subject, issuer and SHA-256 fingerprint; with a trust folder the
certificate is also saved to ``DIR/rejected/<fingerprint>.der`` (the OPC UA PKI
convention: inspect it, move it to ``DIR`` to trust it).

The trust folder is either flat (certificates ``*.pem``/``*.der``/``*.crt``, revocation
lists ``*.crl``) or the OPC UA PKI layout of UaExpert and node-opcua
(``trusted/certs``, ``trusted/crl``, ``issuers/certs``, ``issuers/crl``).
"""

from __future__ import annotations

import datetime as dt
import ipaddress
import logging
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import urlsplit

from asyncua import ua
from asyncua.common.utils import ServiceError
from asyncua.crypto.validator import CertificateValidator, CertificateValidatorOptions
from cryptography import x509
from cryptography.exceptions import InvalidSignature
from cryptography.hazmat.primitives import hashes, serialization

from plugcell.devices.opcua.certificates import CA_CERT, CA_CRL
from plugcell.framework.service import DeviceError

log = logging.getLogger("plugcell.devices.opcua.device")

_CERT_SUFFIXES = (".pem", ".der", ".crt", ".cer")


class UntrustedServerError(DeviceError):
    """The server's certificate failed a check; the message says which and why."""

    def __init__(self, reason: str, status: int) -> None:
        super().__init__(reason)
        self.status = status
        """The OPC UA status code of the refusal (``BadCertificateUntrusted`` …)."""


def fingerprint(cert: x509.Certificate) -> str:
    """SHA-256 fingerprint of a certificate, ``AB:CD:…`` (as UaExpert shows it)."""
    return cert.fingerprint(hashes.SHA256()).hex(":").upper()


def _load_certificates(path: Path) -> list[x509.Certificate]:
    data = path.read_bytes()
    try:
        if b"-----BEGIN" in data:
            return x509.load_pem_x509_certificates(data)
        return [x509.load_der_x509_certificate(data)]
    except ValueError as exc:
        raise DeviceError(f"trust list: {path} is not a certificate ({exc})") from None


def _load_crl(path: Path) -> x509.CertificateRevocationList:
    data = path.read_bytes()
    try:
        if b"-----BEGIN" in data:
            return x509.load_pem_x509_crl(data)
        return x509.load_der_x509_crl(data)
    except ValueError as exc:
        raise DeviceError(f"trust list: {path} is not a revocation list ({exc})") from None


def _files(folder: Path, suffixes: tuple[str, ...]) -> list[Path]:
    if not folder.is_dir():
        return []
    return sorted(p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in suffixes)


def _ca_required(_policy: object, _cert: x509.Certificate, ext: x509.BasicConstraints | None
                 ) -> None:
    if ext is None or not ext.ca:
        raise ValueError("an issuer must be a CA (basicConstraints ca=true)")


@dataclass
class ServerTrust:
    """The trust list of ``opcua-device`` and the checks of a server certificate.

    Parameters
    ----------
    certificates
        Trusted certificates: authorities (their issued certificates are trusted) and
        pinned server certificates (trusted as they are).
    crls
        Revocation lists; each applies to the certificates its issuer signed.
    endpoint
        The endpoint URL the service connects to (its host is checked, step 5).
    expected_uri
        The application URI the server must have ("" for any the certificate and the
        server agree on).
    rejected
        Where refused certificates are saved (None: not saved).
    """

    certificates: list[x509.Certificate]
    crls: list[x509.CertificateRevocationList]
    endpoint: str
    expected_uri: str = ""
    rejected: Path | None = None
    sources: list[str] = field(default_factory=list)
    """Where the trust list came from (named in a refusal)."""

    @classmethod
    def load(cls, endpoint: str, *, cell_certs: Path | None = None, trust: Path | None = None,
             expected_uri: str = "") -> ServerTrust:
        """The trust list of the cell's certificate folder and/or a trust folder."""
        certs: list[x509.Certificate] = []
        crls: list[x509.CertificateRevocationList] = []
        sources = []
        if cell_certs is not None and (cell_certs / CA_CERT).is_file():
            certs += _load_certificates(cell_certs / CA_CERT)
            if (cell_certs / CA_CRL).is_file():
                crls.append(_load_crl(cell_certs / CA_CRL))
            sources.append(str(cell_certs / CA_CERT))
        if trust is not None:
            if not trust.is_dir():
                raise DeviceError(f"trust list: {trust} is not a folder")
            pki = (trust / "trusted").is_dir() or (trust / "issuers").is_dir()
            folders = ([trust / "trusted" / "certs", trust / "issuers" / "certs"] if pki
                       else [trust])
            crl_folders = ([trust / "trusted" / "crl", trust / "issuers" / "crl"] if pki
                           else [trust])
            for folder in folders:
                for path in _files(folder, _CERT_SUFFIXES):
                    certs += _load_certificates(path)
            for folder in crl_folders:
                for path in _files(folder, (".crl",) if not pki else (".crl", ".der", ".pem")):
                    crls.append(_load_crl(path))
            sources.append(str(trust))
        if not certs:
            where = " and ".join(sources) or "nothing given"
            raise DeviceError(
                f"no trusted certificate to check the server of {endpoint} against ({where}): "
                "give the cell's certificates (--param certs=DIR with opcua-ca.pem) or "
                "--trust DIR with the server's certificate or its CA")
        return cls(certs, crls, endpoint, expected_uri,
                   (trust / "rejected") if trust is not None else None, sources)

    # -- the checks ----------------------------------------------------------------

    async def __call__(self, cert: x509.Certificate,
                       description: ua.ApplicationDescription) -> None:
        """asyncua's ``Client.certificate_validator``: refuse with :class:`UntrustedServerError`."""
        try:
            await self.check(cert, description)
        except UntrustedServerError as exc:
            self._save_rejected(cert)
            log.error("refused the server of %s: %s", self.endpoint, exc)
            raise

    async def check(self, cert: x509.Certificate,
                    description: ua.ApplicationDescription) -> None:
        """Steps 1–6 of the module docstring, in order; :class:`UntrustedServerError` on failure."""
        who = (f"the server certificate of {self.endpoint} ({cert.subject.rfc4514_string()}, "
               f"issued by {cert.issuer.rfc4514_string()}, SHA-256 {fingerprint(cert)})")
        issuer = self._trusted_issuer(cert)
        if issuer is None:
            raise UntrustedServerError(
                f"{who} is not trusted: neither in the trust list nor issued by a trusted "
                f"authority (trust list: {', '.join(self.sources)})",
                ua.StatusCodes.BadCertificateUntrusted)
        now = dt.datetime.now(dt.UTC)
        if cert.not_valid_after_utc < now:
            raise UntrustedServerError(
                f"{who} expired on {cert.not_valid_after_utc:%Y-%m-%d %H:%M} UTC",
                ua.StatusCodes.BadCertificateTimeInvalid)
        if cert.not_valid_before_utc > now:
            raise UntrustedServerError(
                f"{who} is valid only from {cert.not_valid_before_utc:%Y-%m-%d %H:%M} UTC",
                ua.StatusCodes.BadCertificateTimeInvalid)
        for crl in self.crls:
            if (crl.issuer == issuer.subject and crl.is_signature_valid(issuer.public_key())
                    and crl.get_revoked_certificate_by_serial_number(cert.serial_number)):
                raise UntrustedServerError(f"{who} is revoked by its issuer's revocation list",
                                      ua.StatusCodes.BadCertificateRevoked)
        san = _alt_names(cert)
        uris = san.get_values_for_type(x509.UniformResourceIdentifier) if san else []
        said = description.ApplicationUri
        if said not in uris:
            raise UntrustedServerError(
                f"{who} names the application URI {', '.join(uris) or '(none)'}, but the "
                f"server says it is {said}", ua.StatusCodes.BadCertificateUriInvalid)
        if self.expected_uri and self.expected_uri not in uris:
            raise UntrustedServerError(
                f"{who} is the application {', '.join(uris)}, not the expected "
                f"{self.expected_uri} (server_uri)", ua.StatusCodes.BadCertificateUriInvalid)
        host = urlsplit(self.endpoint).hostname or ""
        names = _host_names(san)
        if not _host_matches(host, names):
            raise UntrustedServerError(
                f"{who} is for the hosts {', '.join(names) or '(none)'}, not {host} of the "
                "endpoint", ua.StatusCodes.BadCertificateHostNameInvalid)
        usage = CertificateValidator(CertificateValidatorOptions.KEY_USAGE
                                     | CertificateValidatorOptions.EXT_KEY_USAGE
                                     | CertificateValidatorOptions.PEER_SERVER)
        try:
            await usage.validate(cert, description)
        except ServiceError as exc:
            name = ua.StatusCode(exc.code).name
            raise UntrustedServerError(
                f"{who} is not an OPC UA server's certificate: its key usages or extended key "
                f"usage (serverAuth), or the server's application type, do not fit ({name})",
                exc.code) from None

    def _trusted_issuer(self, cert: x509.Certificate) -> x509.Certificate | None:
        """The trusted certificate that vouches for ``cert`` (itself if pinned), or None."""
        der = cert.public_bytes(serialization.Encoding.DER)
        for trusted in self.certificates:
            if trusted.public_bytes(serialization.Encoding.DER) == der:
                return trusted
        authorities = [c for c in self.certificates if _is_ca(c)]
        if not authorities:
            return None
        policy = (
            x509.verification.PolicyBuilder()
            .store(x509.verification.Store(authorities))
            .extension_policies(
                ca_policy=x509.verification.ExtensionPolicy.permit_all().require_present(
                    x509.BasicConstraints, x509.verification.Criticality.AGNOSTIC,
                    _ca_required),
                ee_policy=x509.verification.ExtensionPolicy.permit_all())
        )
        try:
            chain = policy.build_client_verifier().verify(cert, []).chain
        except x509.verification.VerificationError:
            now = dt.datetime.now(dt.UTC)
            if cert.not_valid_before_utc <= now <= cert.not_valid_after_utc:
                return None
            # out of its validity (step 2 names that): still say whether a trusted
            # authority signed it
            for authority in authorities:
                try:
                    cert.verify_directly_issued_by(authority)
                except (ValueError, TypeError, InvalidSignature):
                    continue
                return authority
            return None
        return chain[1] if len(chain) > 1 else chain[0]

    def _save_rejected(self, cert: x509.Certificate) -> None:
        if self.rejected is None:
            return
        try:
            self.rejected.mkdir(parents=True, exist_ok=True)
            path = self.rejected / f"{fingerprint(cert).replace(':', '')[:40]}.der"
            path.write_bytes(cert.public_bytes(serialization.Encoding.DER))
        except OSError as exc:
            log.warning("could not save the refused certificate in %s: %s", self.rejected, exc)


def _is_ca(cert: x509.Certificate) -> bool:
    try:
        return bool(cert.extensions.get_extension_for_class(x509.BasicConstraints).value.ca)
    except x509.ExtensionNotFound:
        return False


def _alt_names(cert: x509.Certificate) -> x509.SubjectAlternativeName | None:
    try:
        return cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    except x509.ExtensionNotFound:
        return None


def _host_names(san: x509.SubjectAlternativeName | None) -> list[str]:
    if san is None:
        return []
    ips = [str(ip) for ip in san.get_values_for_type(x509.IPAddress)]
    return [*san.get_values_for_type(x509.DNSName), *ips]


def _host_matches(host: str, names: Iterable[str]) -> bool:
    """Whether the endpoint's host is one of the certificate's names (an IP compared as
    an address, a DNS name case-insensitively)."""
    try:
        address = ipaddress.ip_address(host)
    except ValueError:
        return host.lower().rstrip(".") in {n.lower().rstrip(".") for n in names}
    for name in names:
        try:
            if ipaddress.ip_address(name) == address:
                return True
        except ValueError:
            continue
    return False
