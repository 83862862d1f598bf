"""A free port on loopback, for the processes a simulated cell starts on one machine (the
twin's robot side, a router, a gateway) and the tests and benchmarks that start them."""

from __future__ import annotations

import socket

#: protocol → socket type
_KINDS = {"tcp": socket.SOCK_STREAM, "udp": socket.SOCK_DGRAM}


def free_port(protocol: str = "tcp") -> int:
    """A port on 127.0.0.1 that was free a moment ago: the one the OS gives a socket bound
    to port 0 (another process may take it before it is used again).

    Parameters
    ----------
    protocol : {"tcp", "udp"}
        The port's protocol.

    Returns
    -------
    int
        The port number (1–65535).

    Raises
    ------
    ValueError
        ``protocol`` is neither ``"tcp"`` nor ``"udp"``.
    """
    if protocol not in _KINDS:
        raise ValueError(f"protocol: expected 'tcp' or 'udp', got {protocol!r}")
    with socket.socket(socket.AF_INET, _KINDS[protocol]) as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])
