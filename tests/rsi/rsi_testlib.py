"""A bare robot side for the RSI link's fault tests: a UDP socket that sends ``<Rob>``
packets written here by hand and reads the answers (the independent robot side is
rsipi's EchoServer: test_rsi_rsipi.py)."""

from __future__ import annotations

import socket
import time

from plugcell.devices.robot.rsi import RsiConfig, RsiLink

AXES = ("A1", "A2", "A3", "A4", "A5", "A6")


def rob_packet(ipoc: int, joints_deg=(0.0, -90.0, 90.0, 0.0, 45.0, 0.0), delay: int = 0,
               dil: int = 0) -> bytes:
    """A ``<Rob Type="KUKA">`` packet as a controller sends it (joints in degrees)."""
    aipos = " ".join(f'{a}="{v:.4f}"' for a, v in zip(AXES, joints_deg, strict=True))
    return (f'<Rob Type="KUKA"><RIst X="445.0" Y="0.0" Z="900.0" A="180.0" B="0.0" '
            f'C="180.0"/><RSol X="445.0" Y="0.0" Z="900.0" A="180.0" B="0.0" C="180.0"/>'
            f'<AIPos {aipos}/><ASPos {aipos}/><MACur A1="1" A2="2" A3="3" A4="4" A5="5" '
            f'A6="6"/><Delay D="{delay}"/><Digout o1="0" o2="1" o3="0"/><DiL>{dil}</DiL>'
            f'<IPOC>{ipoc}</IPOC></Rob>').encode()


class BareRobot:
    """A UDP socket on loopback playing the controller, packet by packet."""

    def __init__(self, link_address: tuple[str, int]) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(1.0)
        self.target = link_address
        self.ipoc = 1_000_000

    def send(self, data: bytes) -> None:
        self.sock.sendto(data, self.target)

    def cycle(self, **kw) -> bytes:
        """Send the next packet (IPOC + 4) and return the answer."""
        self.ipoc += 4
        self.send(rob_packet(self.ipoc, **kw))
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


def local_config(**kw) -> RsiConfig:
    """A link on an ephemeral loopback port that accepts a robot on loopback."""
    return RsiConfig(robot_host="127.0.0.1", listen_host="127.0.0.1", listen_port=0, **kw)


def started(config: RsiConfig, source=None, **kw) -> RsiLink:
    link = RsiLink(config, source, **kw)
    link.start()
    return link


def wait_until(predicate, timeout: float = 2.0) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return True
        time.sleep(0.002)
    return predicate()
