"""The cycle's reader of robot packets (rsi/reader.py) gives what ``parse_rob`` gives —
the same state or the same error — for every datagram, whether its learnt pattern read
the packet or lxml did."""

from __future__ import annotations

import random

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from rsi_testlib import mutate, rob_packet

from plugcell.devices.robot.rsi import PacketError, parse_rob
from plugcell.devices.robot.rsi.codec import RobotState
from plugcell.devices.robot.rsi.reader import RobReader

_ARRAYS = ("joints", "joints_setpoint", "tcp", "tcp_setpoint", "motor_currents", "external",
           "external_setpoint")


def outcome(read, data: bytes) -> tuple:
    """What ``read(data)`` gives, comparable: the state's fields, or the error."""
    try:
        s = read(data)
    except PacketError as exc:
        return ("error", exc.kind, str(exc))
    assert isinstance(s, RobotState)
    arrays = tuple(None if getattr(s, a) is None else getattr(s, a).tolist() for a in _ARRAYS)
    return ("state", s.ipoc, s.delay, s.signals, arrays)


def assert_same(reader: RobReader, data: bytes) -> None:
    assert outcome(reader, data) == outcome(parse_rob, data)


def learnt(packet: bytes) -> RobReader:
    reader = RobReader()
    reader(packet)
    assert (reader.fast, reader.slow) == (0, 1)
    return reader


def test_a_packet_of_the_learnt_layout_is_read_by_the_pattern_as_lxml_reads_it() -> None:
    reader = learnt(rob_packet(1000))
    for ipoc in range(1004, 1400, 4):
        data = rob_packet(ipoc, joints_deg=(ipoc / 7, -90, 90.5, 0, 45, -1e-4), delay=ipoc % 5,
                          dil=ipoc % 65536)
        assert_same(reader, data)
    assert (reader.fast, reader.slow) == (99, 1)


@pytest.mark.parametrize(("data", "fast"), [
    # XML's white space where XML ignores it: still the pattern's
    (b' <Rob Type="KUKA">\r\n <AIPos A1 = "1" A2="2" A3="3" A4="4" A5="5" A6="6" />\n'
     b'<Delay D="0"/><DiL> 5 </DiL><IPOC>8</IPOC></Rob>\n', True),
    (b'<Rob Type="KUKA"><AIPos A1="1_0" A2="+2" A3="3e1" A4=".4" A5="5." A6="-6"/>'
     b'<Delay D="2.0"/><DiL>5</DiL><IPOC>0008</IPOC></Rob>', True),
    # what the pattern leaves to lxml: entities, CDATA, comments, other quotes, layouts
    (b'<Rob Type="KUKA"><AIPos A1="&#49;" A2="2" A3="3" A4="4" A5="5" A6="6"/>'
     b'<Delay D="0"/><DiL>5</DiL><IPOC>8</IPOC></Rob>', False),
    (b'<Rob Type="KUKA"><AIPos A1=\'1\' A2="2" A3="3" A4="4" A5="5" A6="6"/>'
     b'<Delay D="0"/><DiL><![CDATA[5]]></DiL><IPOC>8</IPOC></Rob>', False),
    (b'<Rob Type="KUKA"><AIPos A1="1" A2="2" A3="3" A4="4" A5="5" A6="6"/><!-- c -->'
     b'<Delay D="0"/><DiL>5</DiL><IPOC>8</IPOC></Rob>', False),
    (b'<Rob Type="KUKA"><AIPos A1="1\t" A2="2" A3="3" A4="4" A5="5" A6="6"/>'
     b'<Delay D="0"/><DiL>5</DiL><IPOC>8</IPOC></Rob>', False),
    (b'<Rob Type="KUKA"><Delay D="0"/><AIPos A1="1" A2="2" A3="3" A4="4" A5="5" A6="6"/>'
     b'<DiL>5</DiL><IPOC>8</IPOC></Rob>', False),
    # the values parse_rob refuses: its error, word for word
    (b'<Rob Type="KUKA"><AIPos A1="inf" A2="2" A3="3" A4="4" A5="5" A6="6"/>'
     b'<Delay D="0"/><DiL>5</DiL><IPOC>8</IPOC></Rob>', False),
    (b'<Rob Type="KUKA"><AIPos A1="1e308" A2="1e308" A3="3" A4="4" A5="5" A6="6"/>'
     b'<Delay D="0"/><DiL>5</DiL><IPOC>8</IPOC></Rob>', False),  # finite; its sum is not
    (b'<Rob Type="KUKA"><AIPos A1="1" A2="2" A3="3" A4="4" A5="5" A6="6"/>'
     b'<Delay D="1.5"/><DiL>5</DiL><IPOC>8</IPOC></Rob>', False),
    (b'<Rob Type="KUKA"><AIPos A1="1" A2="2" A3="3" A4="4" A5="5" A6="6"/>'
     b'<Delay D="-1"/><DiL>nan</DiL><IPOC>8</IPOC></Rob>', False),
    (b'<Rob Type="KUKA"><AIPos A1="1" A2="2" A3="3" A4="4" A5="5" A6="6"/>'
     b'<Delay D="0"/><DiL></DiL><IPOC>8</IPOC></Rob>', False),
    (b'<Rob Type="KUKA"><AIPos A1="1" A2="2" A3="3" A4="4" A5="5" A6="6"/>'
     b'<Delay D="0"/><DiL>]]></DiL><IPOC>8</IPOC></Rob>', False),
    (b'<Rob Type="KUKA"><AIPos A1="1" A2="2" A3="3" A4="4" A5="5" A6="6"/>'
     b'<Delay D="0"/><DiL>5</DiL><IPOC>99999999999999999999</IPOC></Rob>', False),
    ('<Rob Type="KUKA"><AIPos A1="١" A2="2" A3="3" A4="4" A5="5" A6="6"/>'
     '<Delay D="0"/><DiL>5</DiL><IPOC>8</IPOC></Rob>'.encode(), False),
])
def test_the_pattern_reads_only_what_lxml_reads_the_same(data: bytes, fast: bool) -> None:
    reader = learnt(b'<Rob Type="KUKA"><AIPos A1="0" A2="0" A3="0" A4="0" A5="0" A6="0"/>'
                    b'<Delay D="0"/><DiL>0</DiL><IPOC>4</IPOC></Rob>')
    assert_same(reader, data)
    assert reader.fast == int(fast)


def test_a_new_layout_is_learnt_and_an_oversized_packet_refused() -> None:
    reader = learnt(b'<Rob Type="KUKA"><IPOC>4</IPOC></Rob>')
    other = b'<Rob Type="KUKA"><Digout o1="1" o2="0"/><IPOC>8</IPOC></Rob>'
    assert_same(reader, other)
    assert (reader.fast, reader.slow) == (0, 2)
    assert_same(reader, other.replace(b"8", b"12"))
    assert reader.fast == 1
    small = RobReader(max_bytes=40)
    small(b'<Rob Type="KUKA"><IPOC>4</IPOC></Rob>')
    with pytest.raises(PacketError, match="bytes > 40") as err:
        small(b'<Rob Type="KUKA"><IPOC>4</IPOC>     </Rob>')
    assert err.value.kind == "oversized"


_ELEMENTS = {
    "RIst": ("X", "Y", "Z", "A", "B", "C"), "AIPos": ("A1", "A2", "A3", "A4", "A5", "A6"),
    "EIPos": ("E1", "E2", "E3", "E4", "E5", "E6"), "Digout": ("o1", "o2"), "Delay": ("D",),
    "DiL": None, "Tech": None,
}
_number = st.one_of(st.integers(-10**6, 10**6).map(str),
                    st.floats(-1e6, 1e6, allow_nan=False).map(lambda v: f"{v:.6g}"),
                    st.sampled_from(["nan", "-inf", "1e999", "", " 1 ", "x", "1_0", "٣"]))
_space = st.sampled_from(["", " ", "\n", "\r\n\t"])


@st.composite
def packets(draw, tags: list[str]) -> bytes:
    """A ``<Rob>`` of the elements ``tags`` in that order, with drawn values and spaces."""
    parts = ['<Rob Type="KUKA">']
    for tag in tags:
        parts.append(draw(_space))
        if tag == "IPOC":
            parts.append(f"<IPOC>{draw(st.integers(0, 2**64))}</IPOC>")
        elif _ELEMENTS[tag] is None:
            parts.append(f"<{tag}>{draw(_number)}</{tag}>")
        else:
            names = " ".join(f'{a}{draw(_space)}="{draw(_number)}"' for a in _ELEMENTS[tag])
            parts.append(f"<{tag} {names}{draw(_space)}/>")
    parts.append("</Rob>" + draw(_space))
    return "".join(parts).encode()


@settings(deadline=None, max_examples=300)  # a loaded machine is slow, not wrong
@given(st.data())
def test_any_packet_after_any_layout_reads_as_parse_rob_reads_it(data) -> None:
    tags = [*data.draw(st.lists(st.sampled_from(sorted(_ELEMENTS)), unique=True)), "IPOC"]
    tags = data.draw(st.permutations(tags))
    reader = RobReader()
    for _ in range(4):  # the first one that reads teaches the layout
        assert_same(reader, data.draw(packets(tags)))


@settings(deadline=None)  # a loaded machine is slow, not wrong
@given(st.integers(0, 2**32))
def test_mutated_packets_read_as_parse_rob_reads_them(seed: int) -> None:
    rng = random.Random(seed)
    reader = learnt(rob_packet(4))
    for k in range(40):
        data = mutate(rng, rob_packet(8 + 4 * k, dil=k))
        assert_same(reader, data)
        reader(rob_packet(4))  # back to the controller's layout, as a stream would be
    np.testing.assert_equal(reader(rob_packet(12)).joints, parse_rob(rob_packet(12)).joints)
