"""``plugcell opcua``: the cell as an OPC UA server (docs/opcua.md).

``plugcell opcua serve [--port 4840] [--cell CELL] [--users FILE] [--allow-anonymous]
[--certificate PEM --key PEM [--trust-ca PEM]]`` runs the gateway until SIGINT/SIGTERM;
``plugcell opcua hash-password`` reads a password on stdin and prints the line to put
in a users file.
"""

from __future__ import annotations

import argparse
import getpass
import logging
import sys
from pathlib import Path
from typing import Any

from plugcell.apps.cli import CommandError
from plugcell.apps.commands.cellargs import add_cell_args, cell_of, transport_of
from plugcell.framework import eventloop


def configure(p: argparse.ArgumentParser) -> None:
    """Add the ``opcua`` actions to its parser (declared in :mod:`plugcell.apps.cli`)."""
    p.description = "OPC UA (IEC 62541) for a cell: see docs/opcua.md."
    sub = p.add_subparsers(dest="opcua_command", metavar="ACTION", required=True)
    serve = sub.add_parser(
        "serve", help="run an OPC UA server mirroring the cell",
        description="Serve the cell over OPC UA: one object per service, one method per "
        "command, MultipleData processes as objects, process events.",
    )
    serve.add_argument("--host", default="127.0.0.1",
                       help="address to listen on (default 127.0.0.1; 0.0.0.0 for all)")
    serve.add_argument("--port", type=int, default=4840, help="TCP port (default 4840)")
    serve.add_argument("--name", default="OPCUA",
                       help="the gateway's participant name (sender of anonymous calls)")
    serve.add_argument("--users", type=Path, metavar="FILE",
                       help="TOML users file ([users] NAME = hash; plugcell opcua hash-password)")
    serve.add_argument("--allow-anonymous", action="store_true",
                       help="accept anonymous sessions (they call as --name)")
    serve.add_argument("--certs", type=Path, metavar="DIR",
                       help="the cell's certificate folder: use DIR/NAME.opcua.pem/.key and "
                       "trust clients of DIR/opcua-ca.pem (plugcell certs opcua NAME)")
    serve.add_argument("--certificate", type=Path, metavar="PEM",
                       help="the server's application certificate (plugcell certs opcua)")
    serve.add_argument("--key", type=Path, metavar="PEM", help="its private key")
    serve.add_argument("--trust-ca", type=Path, metavar="PEM",
                       help="accept only client certificates issued by this CA")
    serve.add_argument("--allow-insecure", action="store_true",
                       help="with a certificate, also offer SecurityPolicy None")
    serve.add_argument("--robot-poll", type=float, default=1.0, metavar="S",
                       help="seconds between reads of each robot's joints and flange pose "
                       "for its OPC 40010 variables (default 1; 0: off)")
    serve.add_argument("--log-level", default="WARNING", help="logging level (default WARNING)")
    add_cell_args(serve)
    serve.set_defaults(func=run_serve)
    hashp = sub.add_parser("hash-password",
                           help="print the users-file hash of a password read from stdin")
    hashp.add_argument("user", nargs="?", help="print a whole `USER = \"hash\"` line")
    hashp.set_defaults(func=run_hash)


def run_hash(args: argparse.Namespace) -> int:
    from plugcell.devices.opcua.users import hash_password
    from plugcell.framework.keys import check_name

    if sys.stdin.isatty():
        password = getpass.getpass("password: ")
    else:
        password = sys.stdin.readline().rstrip("\n")
    if not password:
        raise CommandError("empty password")
    text = hash_password(password)
    if args.user:
        try:
            check_name(args.user, "user name")
        except ValueError as exc:
            raise CommandError(str(exc)) from None
        print(f'{args.user} = "{text}"')
    else:
        print(text)
    return 0


def run_serve(args: argparse.Namespace) -> int:
    from plugcell.devices.opcua.gateway import CellGateway
    from plugcell.devices.opcua.listen import bind_error
    from plugcell.devices.opcua.server_security import GatewaySecurity
    from plugcell.devices.opcua.users import UserBook, UsersFileError

    logging.basicConfig(level=args.log_level.upper(), stream=sys.stderr,
                        format="%(asctime)s %(name)s %(levelname)s %(message)s")
    if args.log_level.upper() != "DEBUG":
        logging.getLogger("asyncua").setLevel(logging.ERROR)
        # a port in use: asyncua logs its traceback, then re-raises — said below in one line
        logging.getLogger("asyncua.server.server").addFilter(_not_a_start_error)
    if args.certs is not None:
        from plugcell.devices.opcua.certificates import CA_CERT, certificate_paths

        cert, key = certificate_paths(args.certs, args.name)
        args.certificate = args.certificate or cert
        args.key = args.key or key
        args.trust_ca = args.trust_ca or args.certs / CA_CERT
        if not cert.is_file():
            raise CommandError(f"no certificate {cert}: run `plugcell certs opcua {args.name} "
                               f"--dir {args.certs}`")
    if (args.certificate is None) != (args.key is None):
        raise CommandError("--certificate and --key go together")
    for path in (args.certificate, args.key, args.trust_ca):
        if path is not None and not path.is_file():
            raise CommandError(f"{path}: no such file")
    try:
        users = UserBook.load(args.users) if args.users else None
    except UsersFileError as exc:
        raise CommandError(str(exc)) from None
    try:
        gateway = CellGateway(
            cell=cell_of(args), transport=transport_of(args), host=args.host, port=args.port,
            name=args.name, users=users, allow_anonymous=args.allow_anonymous,
            security=GatewaySecurity(args.certificate, args.key, args.trust_ca,
                                     args.allow_insecure),
            robot_poll=args.robot_poll,
        )
    except ValueError as exc:
        raise CommandError(str(exc)) from None
    try:
        eventloop.run(_serve(gateway))
    except OSError as exc:
        why = bind_error(exc, gateway.host, gateway.port)
        raise CommandError(f"cannot serve at {gateway.url}: {why}") from None
    return 0


def _not_a_start_error(record: logging.LogRecord) -> bool:
    """False for asyncua's "error starting server" with an OSError (the command says why)."""
    info = record.exc_info
    return not (info and isinstance(info[1], OSError))


async def _serve(gateway: Any) -> None:
    from plugcell.apps.commands.serve import start_unless_stopped, stop_on_signals

    stop = stop_on_signals()
    if not await start_unless_stopped(gateway.start(), stop):
        return
    try:
        policy = "Basic256Sha256 SignAndEncrypt" if gateway.security.certificate else "None"
        print(f"plugcell: OPC UA gateway of cell {gateway.cell!r} at {gateway.url} "
              f"(security policy {policy})", flush=True)
        await stop.wait()
    finally:
        await gateway.close()
