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
from pathlib import Path

from plugcell.apps.cli import CommandError
from plugcell.framework.certificates import create_ca, issue_certificate

DEFAULT_DIR = "plugcell-certs"


def configure(p: argparse.ArgumentParser) -> None:
    """Add the ``certs`` options to its parser (declared in :mod:`plugcell.apps.cli`)."""
    p.description = (
        "Create the certificate authority of a cell and the certificates of its "
        "services (CN = service name) for Zenoh mutual TLS (docs/security.md)."
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


def run_init(args: argparse.Namespace) -> int:
    if (args.dir / "ca.key").exists() and not args.force:
        raise CommandError(f"{args.dir / 'ca.key'} exists (use --force to replace the CA)")
    path = create_ca(args.dir, args.cell, args.days)
    print(f"plugcell: cell CA written to {path} (key {args.dir / 'ca.key'}, keep it offline)")
    return 0


def run_issue(args: argparse.Namespace) -> int:
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
    from plugcell.devices.opcua.certificates import certificate_paths, issue_application_certificate

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
