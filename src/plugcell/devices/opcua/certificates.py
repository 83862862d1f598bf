"""OPC UA application instance certificates of a cell (OPC 10000-6 §6.2.2).

SecurityPolicy Basic256Sha256 wants RSA keys (2048–4096 bits) and certificates
signed with RSA-SHA256, while the cell's Zenoh CA of ``plugcell certs init`` is
ECDSA P-256.  So the cell's certificate folder gets a second, RSA, authority for
OPC UA, made on first use: ``opcua-ca.pem``/``opcua-ca.key`` (RSA 3072, 10 years) and
its empty revocation list ``opcua-ca.crl`` (DER; OPC UA clients such as UaExpert
want one per authority).
``plugcell certs opcua NAME`` issues ``NAME.opcua.pem``/``NAME.opcua.key`` signed by
it: RSA 2048, SHA-256, the application URI ``urn:plugcell:opcua:NAME`` (or
``--uri``) and the host names in the subject alternative name, key usages
digitalSignature, nonRepudiation, keyEncipherment, dataEncipherment, extended key
usages serverAuth and clientAuth — one certificate serves a gateway, a device
service or a client (an HMI, a test).

:func:`verify_issued` is the check a gateway makes of a client's certificate: issued
by the OPC UA authority of the cell, in its validity period.
"""

from __future__ import annotations

import datetime as dt
from pathlib import Path

from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import rsa
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

from plugcell.framework.certificates import host_names, write_file

CA_CERT, CA_KEY, CA_CRL = "opcua-ca.pem", "opcua-ca.key", "opcua-ca.crl"


def application_uri(name: str) -> str:
    """The default application URI of participant ``name``."""
    return f"urn:plugcell:opcua:{name}"


def certificate_paths(folder: Path, name: str) -> tuple[Path, Path]:
    """``NAME.opcua.pem`` and ``NAME.opcua.key`` in ``folder``."""
    return folder / f"{name}.opcua.pem", folder / f"{name}.opcua.key"


def _key_pem(key: rsa.RSAPrivateKey) -> bytes:
    return key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                             serialization.NoEncryption())


def ensure_authority(folder: Path, cell: str = "default", days: int = 3650) -> Path:
    """The OPC UA authority of the cell in ``folder`` (made if missing); its certificate."""
    if (folder / CA_CERT).is_file() and (folder / CA_KEY).is_file():
        return folder / CA_CERT
    key = rsa.generate_private_key(public_exponent=65537, key_size=3072)
    name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, f"plugcell cell {cell} OPC UA CA")])
    now = dt.datetime.now(dt.UTC)
    cert = (
        x509.CertificateBuilder().subject_name(name).issuer_name(name)
        .public_key(key.public_key()).serial_number(x509.random_serial_number())
        .not_valid_before(now - dt.timedelta(minutes=5))
        .not_valid_after(now + dt.timedelta(days=days))
        .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
        .add_extension(x509.KeyUsage(
            digital_signature=True, key_cert_sign=True, crl_sign=True, content_commitment=False,
            key_encipherment=False, data_encipherment=False, key_agreement=False,
            encipher_only=False, decipher_only=False), critical=True)
        .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()),
                       critical=False)
        .sign(key, hashes.SHA256())
    )
    write_file(folder / CA_KEY, _key_pem(key), private=True)
    write_file(folder / CA_CERT, cert.public_bytes(serialization.Encoding.PEM), private=False)
    crl = (  # empty: OPC UA applications want a revocation list for every authority
        x509.CertificateRevocationListBuilder().issuer_name(name)
        .last_update(now - dt.timedelta(minutes=5)).next_update(now + dt.timedelta(days=days))
        .add_extension(x509.AuthorityKeyIdentifier.from_issuer_public_key(key.public_key()),
                       critical=False)
        .add_extension(x509.CRLNumber(1), critical=False)
        .sign(key, hashes.SHA256())
    )
    write_file(folder / CA_CRL, crl.public_bytes(serialization.Encoding.DER), private=False)
    return folder / CA_CERT


def issue_application_certificate(
    folder: Path, name: str, hosts: list[str] | tuple[str, ...] = (), uri: str | None = None,
    days: float = 825, cell: str = "default", start: dt.datetime | None = None,
) -> Path:
    """Write ``NAME.opcua.pem``/``.key`` signed by the cell's OPC UA authority (module doc),
    valid from ``start`` (default: 5 minutes ago) for ``days``."""
    from plugcell.framework.keys import check_name

    check_name(name, "participant name")
    ensure_authority(folder, cell)
    ca_key = serialization.load_pem_private_key((folder / CA_KEY).read_bytes(), None)
    ca_cert = x509.load_pem_x509_certificate((folder / CA_CERT).read_bytes())
    key = rsa.generate_private_key(public_exponent=65537, key_size=2048)
    alt = [x509.UniformResourceIdentifier(uri or application_uri(name)), *host_names(hosts)]
    begin = start or dt.datetime.now(dt.UTC) - dt.timedelta(minutes=5)
    cert = (
        x509.CertificateBuilder()
        .subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, name),
                                 x509.NameAttribute(NameOID.ORGANIZATION_NAME, "plugcell")]))
        .issuer_name(ca_cert.subject).public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(begin).not_valid_after(begin + dt.timedelta(days=days))
        .add_extension(x509.SubjectAlternativeName(list(dict.fromkeys(alt))), critical=False)
        .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
        .add_extension(x509.KeyUsage(
            digital_signature=True, content_commitment=True, key_encipherment=True,
            data_encipherment=True, key_agreement=False, key_cert_sign=False, crl_sign=False,
            encipher_only=False, decipher_only=False), critical=True)
        .add_extension(x509.ExtendedKeyUsage(
            [ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH]), critical=False)
        .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()),
                       critical=False)
        .add_extension(x509.AuthorityKeyIdentifier.from_issuer_public_key(
            ca_cert.public_key()), critical=False)  # type: ignore[arg-type]
        .sign(ca_key, hashes.SHA256())  # type: ignore[arg-type]
    )
    cert_path, key_path = certificate_paths(folder, name)
    write_file(key_path, _key_pem(key), private=True)
    write_file(cert_path, cert.public_bytes(serialization.Encoding.PEM), private=False)
    return cert_path


def uri_of(certificate: Path) -> str | None:
    """The application URI in a certificate's subject alternative name (None if none)."""
    cert = x509.load_pem_x509_certificate(certificate.read_bytes())
    try:
        san = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    except x509.ExtensionNotFound:
        return None
    uris = san.get_values_for_type(x509.UniformResourceIdentifier)
    return uris[0] if uris else None


def verify_issued(certificate: x509.Certificate, authority: Path) -> str:
    """Why ``certificate`` is not one of the cell's (``""`` if it is): issued and signed
    by ``authority``, and valid now."""
    ca = x509.load_pem_x509_certificate(authority.read_bytes())
    if certificate.issuer != ca.subject:
        return f"issued by {certificate.issuer.rfc4514_string()}, not the cell's OPC UA CA"
    try:
        certificate.verify_directly_issued_by(ca)
    except (ValueError, TypeError, Exception) as exc:  # InvalidSignature and friends
        return f"signature of the issuer does not verify ({type(exc).__name__})"
    now = dt.datetime.now(dt.UTC)
    if not certificate.not_valid_before_utc <= now <= certificate.not_valid_after_utc:
        return "not valid now"
    return ""
