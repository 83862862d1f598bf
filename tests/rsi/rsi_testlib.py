"""A bare robot side for the RSI link's fault tests: a UDP socket that sends ``<Rob>``
packets written here by hand and reads the answers (the independent robot side is
rsipi's EchoServer: test_rsi_rsipi.py)."""

from __future__ import annotations

from childproc import wait_until  # noqa: F401  (re-exported for the link tests)
from udp_robot import UdpRobot

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


class BareRobot(UdpRobot):
    """A UDP socket on loopback playing the controller, packet by packet."""

    def __init__(self, link_address: tuple[str, int], step: int = 4) -> None:
        super().__init__(link_address)
        self.ipoc = 1_000_000
        self.step = step  # the IPOC's advance per cycle (ms)

    def cycle(self, **kw) -> bytes:
        """Send the next packet (IPOC + one cycle) and return the answer."""
        self.ipoc += self.step
        self.send(rob_packet(self.ipoc, **kw))
        return self.receive()


def local_config(**kw) -> RsiConfig:
    """A link on an ephemeral loopback port that accepts a robot on loopback."""
    return RsiConfig(robot_host="127.0.0.1", listen_host="127.0.0.1", listen_port=0, **kw)


def started(config: RsiConfig, source=None, **kw) -> RsiLink:
    link = RsiLink(config, source, **kw)
    link.start()
    return link


#: Replacements the mutator puts where a number was.
_BAD_NUMBERS = [b"nan", b"inf", b"-inf", b"1e999", b"", b"-", b"0x10", b"1,5", b"\xff\xfe",
                b"99999999999999999999999", b"-1", b"1.5.5", b" ", b"&amp;", b"1e-400"]
_JUNK = [b"<", b">", b"/>", b"</Rob>", b"<Rob>", b"<IPOC>", b"</IPOC>", b"<AIPos/>",
         b"<!DOCTYPE r [<!ENTITY a 'x'>]>", b"&a;", b"<![CDATA[x]]>", b"<!-- c -->",
         b"\x00", b"\xc3\x28", b'"', b"=", b" Type=\"KUKA\"", b"<?xml version='1.0'?>",
         b"<Sen Type=\"ImFree\">", b"<X><Y/></X>"]


#: How often each edit is chosen (oversizing rarely: it is one check).
_WEIGHTS = (3, 3, 3, 2, 3, 3, 2, 0.3, 2, 2)


def mutate(rng, packet: bytes) -> bytes:
    """One to three random edits of a valid packet (seeded ``random.Random``)."""
    data = bytearray(packet)
    for _ in range(rng.randint(1, 3)):
        op = rng.choices(range(10), weights=_WEIGHTS)[0]
        n = len(data)
        i = rng.randrange(n + 1)
        if op == 0 and n:  # flip one byte
            data[min(i, n - 1)] = rng.randrange(256)
        elif op == 1:  # delete a range
            del data[i:i + rng.randint(1, 40)]
        elif op == 2:  # insert random bytes
            data[i:i] = bytes(rng.randrange(256) for _ in range(rng.randint(1, 8)))
        elif op == 3:  # truncate
            del data[i:]
        elif op == 4:  # a number replaced by something that is none
            quote = data.find(b'"', i)
            end = data.find(b'"', quote + 1) if quote >= 0 else -1
            if end > quote >= 0:
                data[quote + 1:end] = rng.choice(_BAD_NUMBERS)
        elif op == 5:  # markup inserted
            data[i:i] = rng.choice(_JUNK)
        elif op == 6:  # a range duplicated (repeated elements)
            j = min(n, i + rng.randint(1, 80))
            data[j:j] = data[i:j]
        elif op == 7:  # oversized
            data[i:i] = b" " * rng.randint(4000, 9000)
        elif op == 8:  # a tag renamed
            lt = data.find(b"<", i)
            if lt >= 0 and lt + 2 < n:
                data[lt + 1:lt + 2] = bytes([rng.choice(b"RASIDXZ_:")])
        else:  # two ranges swapped
            j = rng.randrange(n + 1)
            a, b = sorted((i, j))
            data[a:b] = data[a:b][::-1]
    return bytes(data)
