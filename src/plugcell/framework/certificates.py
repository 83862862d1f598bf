"""A cell's certificate authority (ECDSA P-256) and the certificates of its participants.

:func:`create_ca` makes ``ca.pem``/``ca.key`` (10 years); :func:`issue_certificate`
makes ``NAME.pem``/``NAME.key`` signed by it, CN = NAME (what a service's access policy
checks), valid for TLS server and client use, with the subject alternative names
``localhost``, ``127.0.0.1`` and the given hosts; :func:`write_file` writes private keys
mode 0600.  ``plugcell certs`` is the command line over these (docs/security.md);
:mod:`plugcell.devices.opcua.certificates` adds the RSA authority OPC UA needs.
"""

from __future__ import annotations

import datetime as dt
import ipaddress
import os
from collections.abc import Iterable
from pathlib import Path
from typing import Any


def write_file(path: Path, data: bytes, private: bool) -> None:
    """Write ``data`` to ``path`` (mode 0600 if ``private``, else 0644), folders made."""
    path.parent.mkdir(parents=True, exist_ok=True)
    flags = os.O_WRONLY | os.O_CREAT | os.O_TRUNC
    fd = os.open(path, flags, 0o600 if private else 0o644)
    with os.fdopen(fd, "wb") as f:
        f.write(data)


def host_names(hosts: Iterable[str]) -> list[Any]:
    """Subject alternative names of a certificate: ``localhost``, ``127.0.0.1`` and
    ``hosts`` (each an IP address if it parses as one, else a DNS name)."""
    from cryptography import x509

    alt: list[x509.GeneralName] = []
    for host in ("localhost", "127.0.0.1", *hosts):
        try:
            alt.append(x509.IPAddress(ipaddress.ip_address(host)))
        except ValueError:
            alt.append(x509.DNSName(host))
    return alt


def create_ca(folder: Path, cell: str = "default", days: int = 3650) -> Path:
    """Write ``ca.pem``/``ca.key`` into ``folder``; return the certificate's path."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import NameOID

    key = ec.generate_private_key(ec.SECP256R1())
    name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, f"plugcell cell {cell} CA")])
    now = dt.datetime.now(dt.UTC)
    cert = (
        x509.CertificateBuilder()
        .subject_name(name)
        .issuer_name(name)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - dt.timedelta(minutes=5))
        .not_valid_after(now + dt.timedelta(days=days))
        .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
        .add_extension(
            x509.KeyUsage(
                digital_signature=True,
                key_cert_sign=True,
                crl_sign=True,
                content_commitment=False,
                key_encipherment=False,
                data_encipherment=False,
                key_agreement=False,
                encipher_only=False,
                decipher_only=False,
            ),
            critical=True,
        )
        .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()), critical=False)
        .sign(key, hashes.SHA256())
    )
    write_file(
        folder / "ca.key",
        key.private_bytes(
            serialization.Encoding.PEM,
            serialization.PrivateFormat.PKCS8,
            serialization.NoEncryption(),
        ),
        private=True,
    )
    write_file(folder / "ca.pem", cert.public_bytes(serialization.Encoding.PEM), private=False)
    return folder / "ca.pem"


def issue_certificate(
    folder: Path, name: str, hosts: list[str] | tuple[str, ...] = (), days: int = 825
) -> Path:
    """Write ``NAME.pem``/``NAME.key`` signed by ``folder/ca.*``; return the certificate."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

    from plugcell.framework.keys import check_name

    check_name(name, "participant name")
    ca_key = serialization.load_pem_private_key((folder / "ca.key").read_bytes(), None)
    ca_cert = x509.load_pem_x509_certificate((folder / "ca.pem").read_bytes())
    key = ec.generate_private_key(ec.SECP256R1())
    alt = host_names(hosts)
    now = dt.datetime.now(dt.UTC)
    cert = (
        x509.CertificateBuilder()
        .subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, name)]))
        .issuer_name(ca_cert.subject)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - dt.timedelta(minutes=5))
        .not_valid_after(now + dt.timedelta(days=days))
        .add_extension(x509.SubjectAlternativeName(list(dict.fromkeys(alt))), critical=False)
        .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
        .add_extension(
            x509.ExtendedKeyUsage(
                [ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH]
            ),
            critical=False,
        )
        .sign(ca_key, hashes.SHA256())  # type: ignore[arg-type]
    )
    write_file(
        folder / f"{name}.key",
        key.private_bytes(
            serialization.Encoding.PEM,
            serialization.PrivateFormat.PKCS8,
            serialization.NoEncryption(),
        ),
        private=True,
    )
    write_file(folder / f"{name}.pem", cert.public_bytes(serialization.Encoding.PEM), private=False)
    return folder / f"{name}.pem"
