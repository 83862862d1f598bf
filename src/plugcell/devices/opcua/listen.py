"""Where the gateway's OPC UA server listens: ``--host`` and ``--port`` checked, as a URL.

:func:`listen_url` turns a host and a port into ``opc.tcp://HOST:PORT/plugcell``, or
raises ValueError with one line naming the likely mistake — a port, a URL or a path in
the host (``--host 127.0.0.1:4850``), a port out of range — so that asyncua never
sees an address it would fail on with a traceback.  :func:`bind_error` says in one
line why a valid address could not be bound (in use, not this machine's, unknown).
"""

from __future__ import annotations

import errno
import ipaddress
import re
import socket

__all__ = ["PATH", "bind_error", "listen_url"]

#: The path of the gateway's endpoint URL.
PATH = "/plugcell"
_LABEL = re.compile(r"(?!-)[A-Za-z0-9-]{1,63}(?<!-)\Z")
_HOST_PORT = re.compile(r"(?P<host>[^:\[\]]*|\[[^\]]*\]):(?P<port>\d+)\Z")


def _is_host_name(text: str) -> bool:
    """A DNS host name (RFC 1123): dot-separated labels of letters, digits and inner '-'."""
    name = text[:-1] if text.endswith(".") else text
    return 0 < len(name) <= 253 and all(_LABEL.match(label) for label in name.split("."))


def _address(host: str) -> ipaddress.IPv4Address | ipaddress.IPv6Address | None:
    try:
        return ipaddress.ip_address(host)
    except ValueError:
        return None


def listen_url(host: str, port: int) -> str:
    """``opc.tcp://HOST:PORT/plugcell`` for a host name or IP address and a TCP port.

    Parameters
    ----------
    host : str
        A host name (``localhost``), an IPv4 address (``127.0.0.1``; ``0.0.0.0`` for all)
        or an IPv6 address (``::1``, written ``[::1]`` in the URL).
    port : int
        TCP port, 1…65535.

    Returns
    -------
    str
        The endpoint URL.

    Raises
    ------
    ValueError
        One line naming the likely mistake, e.g. ``--host takes a host name or address,
        not a port: give the port with --port (--host 127.0.0.1 --port 4850)``.
    """
    if isinstance(port, bool) or not isinstance(port, int) or not 1 <= port <= 65535:
        raise ValueError(f"--port {port!r}: a TCP port is 1…65535")
    text = host.strip() if isinstance(host, str) else ""
    if not text:
        raise ValueError("--host is empty: give a host name or address (127.0.0.1; 0.0.0.0 "
                         "for every interface)")
    shown = text if len(text) <= 80 else text[:79] + "…"
    if "://" in text:
        raise ValueError(f"--host {shown!r} is a URL: --host takes a host name or address, "
                         "the port goes to --port (--host 127.0.0.1 --port 4840)")
    address = _address(text.strip("[]") if text.startswith("[") else text)
    if address is not None:
        return (f"opc.tcp://[{address}]:{port}{PATH}" if address.version == 6
                else f"opc.tcp://{address}:{port}{PATH}")
    pair = _HOST_PORT.match(text)
    if pair:
        name = pair["host"] or "127.0.0.1"
        raise ValueError(f"--host {shown!r} holds a port: --host takes a host name or address; "
                         f"give the port with --port (--host {name} --port {pair['port']})")
    if "/" in text:
        raise ValueError(f"--host {shown!r} holds a path: --host takes a host name or "
                         "address (the endpoint's path is always /plugcell)")
    if not _is_host_name(text):
        raise ValueError(f"--host {shown!r} is not a host name or an IP address (letters, "
                         "digits, '-' and '.'; e.g. localhost, 127.0.0.1, 0.0.0.0)")
    return f"opc.tcp://{text}:{port}{PATH}"


def bind_error(exc: OSError, host: str, port: int) -> str:
    """Why ``host:port`` could not be listened on, in one line naming what to do."""
    if isinstance(exc, socket.gaierror):
        return f"unknown host {host!r} ({exc.strerror or exc}): give a name this machine resolves"
    code = exc.errno
    if code == errno.EADDRINUSE:
        return (f"port {port} on {host} is in use (another OPC UA server or gateway?): stop "
                "it, or choose another port with --port")
    if code == errno.EADDRNOTAVAIL:
        return (f"{host} is not an address of this machine: give one of its addresses, "
                "127.0.0.1, or 0.0.0.0 for every interface")
    if code == errno.EACCES:
        return f"no permission to listen on port {port}: ports below 1024 need privileges"
    return f"cannot listen on {host}:{port}: {exc.strerror or exc}"
