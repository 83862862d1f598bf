"""The bookkeeping of the RSI and EGM links' fuzz tests: every datagram sent is counted by
the link — received, or dropped before it was — and only what it answered came back."""

from __future__ import annotations

import socket
from typing import Any

#: Drops of datagrams already counted as received (the others never were).
RECEIVED_DROPS = ("stale", "inconsistent")


def fuzz_socket() -> socket.socket:
    """A UDP socket on loopback with a 1 MiB receive buffer: the robot's side of a fuzz."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
    return sock


def dropped_unreceived(stats: Any) -> int:
    """Datagrams the link dropped before they counted as received (malformed, foreign …)."""
    return sum(v for k, v in stats.dropped.items() if k not in RECEIVED_DROPS)


def arrived(stats: Any) -> int:
    """Datagrams the link has counted so far: received, or dropped unreceived."""
    return stats.received + dropped_unreceived(stats)


def drain(sock: socket.socket, answers: list[bytes]) -> None:
    """Append every answer waiting on ``sock`` to ``answers`` (without blocking)."""
    sock.setblocking(False)
    while True:
        try:
            answers.append(sock.recv(65535))
        except BlockingIOError:
            break
    sock.setblocking(True)


def assert_every_datagram_accounted(stats: Any, sent: int, answers: list[bytes]) -> None:
    """Each of the ``sent`` datagrams was received or dropped; each received one was
    answered, superseded or dropped stale or inconsistent; every answer came back."""
    assert stats.received + dropped_unreceived(stats) == sent
    assert stats.received == (stats.answered + stats.superseded + stats.dropped["stale"]
                              + stats.dropped["inconsistent"])
    assert len(answers) == stats.answered
