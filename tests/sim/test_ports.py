"""plugcell.sim.ports.free_port: a loopback port of the protocol asked for, free to bind."""

from __future__ import annotations

import socket

import pytest

from plugcell.sim.ports import free_port


@pytest.mark.parametrize(("protocol", "kind"), [("tcp", socket.SOCK_STREAM),
                                                ("udp", socket.SOCK_DGRAM)])
def test_the_port_given_can_be_bound_on_loopback(protocol: str, kind: int) -> None:
    port = free_port(protocol)
    assert 0 < port < 65536
    with socket.socket(socket.AF_INET, kind) as sock:
        sock.bind(("127.0.0.1", port))
        assert sock.getsockname()[1] == port


def test_tcp_is_the_default() -> None:
    port = free_port()
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", port))


def test_an_unknown_protocol_is_refused_by_name() -> None:
    with pytest.raises(ValueError, match="protocol: expected 'tcp' or 'udp', got 'sctp'"):
        free_port("sctp")
