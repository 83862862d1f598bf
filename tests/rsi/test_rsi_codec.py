"""The RSI packets: ``<Rob>`` in (SI out of mm and degrees), ``<Sen>`` out, and every
datagram that is no robot packet refused with its kind and reason."""

from __future__ import annotations

import math
import random
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from rsi_testlib import mutate, rob_packet

from plugcell.devices.robot.rsi import PacketError, encode_sen, parse_rob
from plugcell.devices.robot.rsi.codec import CARTESIAN_AXES, JOINT_AXES


def test_a_controller_packet_reads_in_si() -> None:
    s = parse_rob(rob_packet(4208711356, joints_deg=(10, -90, 90, 0, 45, -30), delay=3,
                             dil=5))
    assert s.ipoc == 4208711356
    np.testing.assert_allclose(s.joints, np.deg2rad([10, -90, 90, 0, 45, -30]))
    np.testing.assert_allclose(s.joints_setpoint, s.joints)
    np.testing.assert_allclose(s.tcp, [0.445, 0, 0.9, math.pi, 0, math.pi])
    np.testing.assert_allclose(s.motor_currents, [1, 2, 3, 4, 5, 6])  # % as sent
    assert s.delay == 3
    assert s.signals == {"Digout": {"o1": 0.0, "o2": 1.0, "o3": 0.0}, "DiL": 5.0}
    assert s.external is None


def _r(axis: str, t: float) -> np.ndarray:
    c, s = math.cos(t), math.sin(t)
    return {"x": np.array([[1, 0, 0], [0, c, -s], [0, s, c]]),
            "y": np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]),
            "z": np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])}[axis]


def test_tcp_matrix_is_kukas_abc() -> None:
    """KUKA's A, B, C rotate about Z, then the new Y, then the new X."""
    pkt = (b'<Rob Type="KUKA"><RIst X="100" Y="-20" Z="1200" A="30" B="-15" C="170"/>'
           b'<IPOC>8</IPOC></Rob>')
    T = parse_rob(pkt).tcp_matrix()
    R = _r("z", math.radians(30)) @ _r("y", math.radians(-15)) @ _r("x", math.radians(170))
    np.testing.assert_allclose(T[:3, :3], R, atol=1e-15)
    np.testing.assert_allclose(T[:3, 3], [0.1, -0.02, 1.2])
    with pytest.raises(ValueError, match="no RIst"):
        parse_rob(b'<Rob Type="KUKA"><IPOC>8</IPOC></Rob>').tcp_matrix()


@pytest.mark.parametrize(("data", "kind", "reason"), [
    (b"x" * 5000, "oversized", "5000 bytes > 4096"),
    (b'<Rob Type="KUKA"><IPOC>1</IPOC>', "malformed", "not well-formed"),
    (b'<Rob Type="KUKA"><DiL>1</DiL></Rob>', "malformed", "no <IPOC>"),
    (b'<Rob Type="KUKA"><IPOC>-1</IPOC></Rob>', "malformed", "not a counter"),
    (b'<Rob Type="KUKA"><IPOC>12a</IPOC></Rob>', "malformed", "not a counter"),
    (b'<Rob Type="KUKA"><IPOC>99999999999999999999</IPOC></Rob>', "malformed", "out of range"),
    (b'<Rob Type="KUKA"><IPOC>1</IPOC><IPOC>2</IPOC></Rob>', "malformed", "twice"),
    (b'<Rob Type="KUKA"><DiL>1</DiL><DiL>2</DiL><IPOC>1</IPOC></Rob>', "malformed", "twice"),
    (b'<Rob Type="KUKA"><AIPos A1="1" A2="2" A3="3" A4="4" A5="5"/><IPOC>1</IPOC></Rob>',
     "malformed", "expected ['A1'"),
    (b'<Rob Type="KUKA"><RIst X="nan" Y="0" Z="0" A="0" B="0" C="0"/><IPOC>1</IPOC></Rob>',
     "malformed", "not finite"),
    (b'<Rob Type="KUKA"><DiL>1e999</DiL><IPOC>1</IPOC></Rob>', "malformed", "not finite"),
    (b'<Rob Type="KUKA"><DiL>five</DiL><IPOC>1</IPOC></Rob>', "malformed", "not a number"),
    (b'<Rob Type="KUKA"><Delay D="1.5"/><IPOC>1</IPOC></Rob>', "malformed", "no count"),
    (b'<Rob Type="KUKA"><Tech><C1/></Tech><IPOC>1</IPOC></Rob>', "malformed", "child"),
    (b'<Sen Type="ImFree"><IPOC>1</IPOC></Sen>', "foreign", "expected <Rob"),
    ('<Rob Type="KUKA"><pzؓRIst X="1"/><IPOC>1</IPOC></Rob>'.encode(), "foreign",
     "is no RSI tag"),
    ('<Rob Type="KUKA"><Digout oé="1"/><IPOC>1</IPOC></Rob>'.encode(), "foreign",
     "no RSI name"),
    (b'<Rob Type="ABB"><IPOC>1</IPOC></Rob>', "foreign", "expected <Rob"),
    (b'<!DOCTYPE Rob [<!ENTITY e "1">]><Rob Type="KUKA"><IPOC>1</IPOC></Rob>', "foreign",
     "DOCTYPE"),
    (b'<!DOCTYPE Rob [<!ENTITY e "1">]><Rob Type="KUKA"><DiL>&e;</DiL><IPOC>1</IPOC></Rob>',
     "foreign", "DOCTYPE"),
    (b'<Rob Type="KUKA">' + b"<S>1</S>" * 129 + b"<IPOC>1</IPOC></Rob>", "foreign", "130 elements"),
])
def test_what_is_no_robot_packet_is_refused_with_its_reason(data: bytes, kind: str,
                                                           reason: str) -> None:
    with pytest.raises(PacketError, match=None) as err:
        parse_rob(data)
    assert err.value.kind == kind
    assert reason in str(err.value)


def test_an_external_entity_is_never_fetched(tmp_path) -> None:
    secret = tmp_path / "secret.txt"
    secret.write_text("42")
    data = (f'<!DOCTYPE Rob [<!ENTITY x SYSTEM "file://{secret}">]>'
            '<Rob Type="KUKA"><DiL>&x;</DiL><IPOC>1</IPOC></Rob>').encode()
    with pytest.raises(PacketError):
        parse_rob(data)


def _sen(data: bytes) -> ET.Element:
    root = ET.fromstring(data)  # the stdlib's parser, not the codec's
    assert root.tag == "Sen"
    return root


def test_joint_answer_in_degrees_echoes_the_ipoc() -> None:
    q = np.deg2rad([0.01, -0.02, 0.5, 0, 1e-4, -3])
    root = _sen(encode_sen(4208711356, "joint", q, {"DiO": 5, "Stop": 0}, "ImFree"))
    assert root.get("Type") == "ImFree"
    assert root.find("IPOC").text == "4208711356"
    ak = root.find("AKorr")
    np.testing.assert_allclose([float(ak.get(a)) for a in JOINT_AXES],
                               [0.01, -0.02, 0.5, 0, 1e-4, -3], atol=5e-7)
    assert root.find("DiO").text == "5"
    assert root.find("Stop").text == "0"
    assert root.find("RKorr") is None


def test_cartesian_answer_in_mm_and_degrees() -> None:
    c = np.array([0.001, -0.0002, 0.05, *np.deg2rad([0.1, -0.2, 0.3])])
    root = _sen(encode_sen(12, "cartesian", c, sentype="Plugcell"))
    assert root.get("Type") == "Plugcell"
    rk = root.find("RKorr")
    np.testing.assert_allclose([float(rk.get(a)) for a in CARTESIAN_AXES],
                               [1, -0.2, 50, 0.1, -0.2, 0.3], atol=5e-7)


_finite = st.floats(-1e5, 1e5, allow_nan=False)


@settings(deadline=None)  # a loaded machine is slow, not wrong
@given(ipoc=st.integers(0, (1 << 63) - 1),
       joints=st.lists(st.floats(-400, 400, allow_nan=False), min_size=6, max_size=6),
       delay=st.integers(0, 10**6), dil=st.integers(0, 65535))
def test_any_controller_packet_reads_back(ipoc, joints, delay, dil) -> None:
    s = parse_rob(rob_packet(ipoc, joints_deg=joints, delay=delay, dil=dil))
    assert (s.ipoc, s.delay, s.signals["DiL"]) == (ipoc, delay, dil)
    np.testing.assert_allclose(s.joints, np.deg2rad(joints), atol=np.deg2rad(5e-5))


@settings(deadline=None)  # a loaded machine is slow, not wrong
@given(st.binary(max_size=600))
def test_random_bytes_are_a_packet_error_or_a_packet(data: bytes) -> None:
    try:
        parse_rob(data)
    except PacketError as exc:
        assert exc.kind in ("malformed", "oversized", "foreign")


@settings(deadline=None)  # a loaded machine is slow, not wrong
@given(st.integers(0, 2**32), st.data())
def test_mutated_packets_are_a_packet_error_or_a_packet(seed: int, data) -> None:
    rng = random.Random(seed)
    base = rob_packet(data.draw(st.integers(0, 2**40)))
    for _ in range(20):
        try:
            s = parse_rob(mutate(rng, base))
        except PacketError as exc:
            assert exc.kind in ("malformed", "oversized", "foreign")
        else:
            assert isinstance(s.ipoc, int) and s.ipoc >= 0
            for v in (s.joints, s.tcp, s.joints_setpoint, s.tcp_setpoint):
                assert v is None or np.all(np.isfinite(v))
