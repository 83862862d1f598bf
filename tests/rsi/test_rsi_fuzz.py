"""10⁵ mutated robot packets through the RSI link on its UDP socket: no crash, every
datagram accounted for, and no answer — no correction — for anything that is not a
robot packet.  The mutator (rsi_testlib.mutate, seeded) edits valid ``<Rob>`` packets:
flipped, deleted, inserted and swapped bytes, truncation, numbers replaced by what is
none, markup, DOCTYPEs and entities, repeated elements, renamed tags, oversizing.

Whether a datagram was a robot packet is judged here with the stdlib's XML parser, not
the link's (lxml): an answer must echo the IPOC of a datagram that is well-formed XML with
a ``<Rob Type="KUKA">`` root and that IPOC."""

from __future__ import annotations

import random
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from link_fuzz import arrived, assert_every_datagram_accounted, drain, fuzz_socket
from rsi_testlib import local_config, mutate, rob_packet, started, wait_until

from plugcell.devices.robot.rsi import Correction

PACKETS = 100_000
BURST = 40  # datagrams in flight at once: well below the socket's buffer


def robot_packet_ipoc(data: bytes) -> int | None:
    """The IPOC of a datagram the stdlib's parser reads as a robot packet, else None."""
    try:
        root = ET.fromstring(data)
    except ET.ParseError:
        return None
    el = root.find("IPOC")
    if root.tag != "Rob" or root.get("Type") != "KUKA" or el is None:
        return None
    text = (el.text or "").strip()
    return int(text) if text.isascii() and text.isdigit() else None


@pytest.mark.slow
def test_a_hundred_thousand_mutated_packets(tmp_path) -> None:
    link = started(local_config(),
                   lambda s: Correction(step=np.full(6, 1e-6)))
    sock = fuzz_socket()
    rng = random.Random(37)
    sent_ok: set[int] = set()
    answers: list[bytes] = []
    try:
        ipoc = 10**6
        for start in range(0, PACKETS, BURST):
            for _ in range(min(BURST, PACKETS - start)):
                ipoc += 4
                data = mutate(rng, rob_packet(ipoc, dil=ipoc % 65536))
                seen = robot_packet_ipoc(data)
                if seen is not None:
                    sent_ok.add(seen)
                sock.sendto(data, link.address)
            sent = start + min(BURST, PACKETS - start)
            assert wait_until(lambda s=sent: arrived(link.stats()) >= s, 30.0), \
                f"{sent} sent, {link.stats()}"
            drain(sock, answers)
        # every packet received is answered, superseded or stale before the last drain
        assert wait_until(lambda: (lambda x: x.answered + x.superseded + x.dropped["stale"]
                                   + x.dropped["inconsistent"] >= x.received)(link.stats()),
                          10.0), link.stats()
        drain(sock, answers)
    finally:
        sock.close()
        link.close()
    st = link.stats()
    assert_every_datagram_accounted(st, PACKETS, answers)
    assert st.dropped["malformed"] > 50_000 and st.dropped["oversized"] > 500
    assert st.dropped["foreign"] > 50
    echoed = [int(ET.fromstring(a).find("IPOC").text) for a in answers]
    assert set(echoed) <= sent_ok  # no answer to anything that was no robot packet
    assert len(set(echoed)) == len(echoed)  # no IPOC answered twice
    # the mutants that are still robot packets reached the stream and were answered
    # (how many were superseded depends on the machine's pace)
    assert st.received > 3000 and st.answered > 100
