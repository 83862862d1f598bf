"""A controller's side of a UDP stream played by a test: one socket on loopback that sends
to the link and reads its answers (the RSI and EGM tests' BareRobot add the messages)."""

from __future__ import annotations

import socket


class UdpRobot:
    """A UDP socket on 127.0.0.1 that talks to the link at ``link_address``.

    Parameters
    ----------
    link_address : (str, int)
        Where the link listens.
    """

    def __init__(self, link_address: tuple[str, int]) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(1.0)
        self.target = link_address

    def send(self, data: bytes) -> None:
        """One datagram to the link."""
        self.sock.sendto(data, self.target)

    def receive(self) -> bytes:
        """The next answer (within 1 s, else TimeoutError)."""
        return self.sock.recv(65535)

    def no_answer(self, wait: float = 0.05) -> bool:
        """Nothing arrives within ``wait`` seconds."""
        self.sock.settimeout(wait)
        try:
            self.sock.recv(65535)
        except TimeoutError:
            return True
        finally:
            self.sock.settimeout(1.0)
        return False

    def close(self) -> None:
        self.sock.close()
