"""``plugcell certs``: a cell's certificate authority and one certificate per participant.

``plugcell certs init [--dir DIR] [--cell CELL]`` creates ``ca.pem`` and ``ca.key``
(ECDSA P-256, 10 years); ``plugcell certs issue NAME... [--dir DIR] [--host H]...``
creates ``NAME.pem`` and ``NAME.key`` for each participant, CN = NAME (what the
service's access policy checks), valid for TLS server and client use, with the
subject alternative names ``localhost``, ``127.0.0.1`` and every ``--host``.
Private keys are written mode 0600.  See docs/security.md.
"""

from __future__ import annotations

import argparse
import datetime as dt
import ipaddress
import os
from pathlib import Path
from typing import Any

DEFAULT_DIR = "plugcell-certs"


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "certs",
        help="create a cell's CA and per-service TLS certificates",
        description="Create the certificate authority of a cell and the certificates of its "
        "services (CN = service name) for Zenoh mutual TLS (docs/security.md).",
    )
    sub = p.add_subparsers(dest="certs_command", metavar="ACTION", required=True)
    init = sub.add_parser("init", help="create the cell CA (ca.pem, ca.key)")
    init.add_argument("--dir", type=Path, default=Path(DEFAULT_DIR), help="output folder")
    init.add_argument("--cell", default="default", help="cell name (in the CA's CN)")
    init.add_argument("--days", type=int, default=3650, help="validity (days)")
    init.add_argument("--force", action="store_true", help="overwrite an existing CA")
    init.set_defaults(func=run_init)
    issue = sub.add_parser("issue", help="issue NAME.pem/NAME.key signed by the cell CA")
    issue.add_argument("names", nargs="+", metavar="NAME", help="participant names (the CN)")
    issue.add_argument("--dir", type=Path, default=Path(DEFAULT_DIR), help="CA/output folder")
    issue.add_argument(
        "--host",
        action="append",
        default=[],
        help="DNS name or IP address the participant listens on (repeatable)",
    )
    issue.add_argument("--days", type=int, default=825, help="validity (days)")
    issue.set_defaults(func=run_issue)

    opc = sub.add_parser(
        "opcua",
        help="issue OPC UA application certificates NAME.opcua.pem/.key (RSA, Basic256Sha256)",
        description="Issue OPC UA application instance certificates signed by the cell's OPC "
        "UA authority (opcua-ca.pem, RSA, made on first use): for `plugcell opcua serve`, "
        "`plugcell serve opcua-device` and OPC UA clients (docs/opcua.md).",
    )
    opc.add_argument("names", nargs="+", metavar="NAME", help="application names (the CN)")
    opc.add_argument("--dir", type=Path, default=Path(DEFAULT_DIR), help="CA/output folder")
    opc.add_argument("--host", action="append", default=[],
                     help="DNS name or IP address of the application (repeatable)")
    opc.add_argument("--uri", help="application URI (one NAME only; default "
                     "urn:plugcell:opcua:NAME)")
    opc.add_argument("--cell", default="default", help="cell name (in a new CA's CN)")
    opc.add_argument("--days", type=int, default=825, help="validity (days)")
    opc.set_defaults(func=run_opcua)


def write_file(path: Path, data: bytes, private: bool) -> None:
    """Write ``data`` to ``path`` (mode 0600 if ``private``, else 0644), folders made."""
    path.parent.mkdir(parents=True, exist_ok=True)
    flags = os.O_WRONLY | os.O_CREAT | os.O_TRUNC
    fd = os.open(path, flags, 0o600 if private else 0o644)
    with os.fdopen(fd, "wb") as f:
        f.write(data)


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
    alt: list[x509.GeneralName] = []
    for host in ("localhost", "127.0.0.1", *hosts):
        try:
            alt.append(x509.IPAddress(ipaddress.ip_address(host)))
        except ValueError:
            alt.append(x509.DNSName(host))
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


def run_init(args: argparse.Namespace) -> int:
    from plugcell.cli import CommandError

    if (args.dir / "ca.key").exists() and not args.force:
        raise CommandError(f"{args.dir / 'ca.key'} exists (use --force to replace the CA)")
    path = create_ca(args.dir, args.cell, args.days)
    print(f"plugcell: cell CA written to {path} (key {args.dir / 'ca.key'}, keep it offline)")
    return 0


def run_issue(args: argparse.Namespace) -> int:
    from plugcell.cli import CommandError

    if not (args.dir / "ca.key").exists():
        raise CommandError(f"no CA in {args.dir}: run `plugcell certs init --dir {args.dir}`")
    for name in args.names:
        try:
            path = issue_certificate(args.dir, name, args.host, args.days)
        except ValueError as exc:
            raise CommandError(str(exc)) from None
        print(f"plugcell: {name}: {path} and {args.dir / (name + '.key')}")
    return 0


def run_opcua(args: argparse.Namespace) -> int:
    from plugcell.cli import CommandError
    from plugcell.opcua.certificates import certificate_paths, issue_application_certificate

    if args.uri and len(args.names) > 1:
        raise CommandError("--uri names one application: give one NAME with it")
    for name in args.names:
        try:
            path = issue_application_certificate(args.dir, name, args.host, args.uri,
                                                 args.days, args.cell)
        except ValueError as exc:
            raise CommandError(str(exc)) from None
        print(f"plugcell: {name}: {path} and {certificate_paths(args.dir, name)[1]}")
    return 0
