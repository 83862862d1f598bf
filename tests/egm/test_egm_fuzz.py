"""10⁵ mutated EgmRobot messages through the EGM link on its UDP socket: no crash, every
datagram accounted for, and no answer — no target — for anything that is not a robot's
message.  The mutator (egm_testlib.mutate, seeded) edits valid messages: flipped,
deleted, inserted, duplicated and swapped bytes, truncation, endless varints, oversizing.

Whether a datagram was a robot's message is judged here by protobuf's generated parser
alone (header with seqno, six feedback joints), not by the link's checks: an answer must
echo the seqno of such a datagram."""

from __future__ import annotations

import random

import numpy as np
import pytest
from egm_testlib import local_config, mutate, robot_message, started, wait_until
from link_fuzz import arrived, assert_every_datagram_accounted, drain, fuzz_socket

from plugcell.devices.robot.egm import Correction
from plugcell.devices.robot.egm.messages import egm_pb2

PACKETS = 100_000
BURST = 50  # datagrams in flight at once: well below the socket's buffer
SESSION = 500  # datagrams per session


def robot_seqno(data: bytes) -> tuple[int, list[float]] | None:
    """The seqno and joints (deg) of a datagram protobuf reads as a robot's, else None."""
    msg = egm_pb2.EgmRobot()
    try:
        msg.ParseFromString(data)
    except Exception:
        return None
    if not msg.header.HasField("seqno") or len(msg.feedBack.joints.joints) != 6:
        return None
    return msg.header.seqno, list(msg.feedBack.joints.joints)


@pytest.mark.slow
def test_a_hundred_thousand_mutated_messages() -> None:
    # a short CommTimeout: between bursts the session ends, so a mutant's huge seqno
    # does not leave the rest stale
    link = started(local_config(comm_timeout_s=0.02),
                   lambda s: Correction(step=np.full(6, 1e-5)))
    sock = fuzz_socket()
    rng = random.Random(37)
    valid: dict[int, list[float]] = {}
    answers: list[bytes] = []

    try:
        seqno = 0
        for start in range(0, PACKETS, BURST):
            for _ in range(min(BURST, PACKETS - start)):
                seqno += 1
                data = mutate(rng, robot_message(seqno))
                seen = robot_seqno(data)
                if seen is not None:
                    valid.setdefault(seen[0], seen[1])
                sock.sendto(data, link.address)
            sent = start + min(BURST, PACKETS - start)
            assert wait_until(lambda s=sent: arrived(link.stats()) >= s, 10.0), \
                f"{sent} sent, {link.stats()}"
            if sent % SESSION == 0:
                assert link.wait(lambda lk: not lk.streaming, 2.0)  # the session ended
            drain(sock, answers)
        drain(sock, answers)
    finally:
        sock.close()
        link.close()
    st = link.stats()
    assert_every_datagram_accounted(st, PACKETS, answers)
    assert st.dropped["malformed"] > 10_000 and st.dropped["oversized"] > 50
    assert st.dropped["foreign"] > 100
    for a in answers:
        m = egm_pb2.EgmSensor()
        m.ParseFromString(a)
        assert m.header.seqno in valid  # no answer to anything that was no robot message
        assert len(m.planned.joints.joints) == 6 and all(
            abs(v) <= 3600 for v in m.planned.joints.joints)
    # valid mutants were answered (how many were superseded depends on the machine's pace)
    assert st.answered > 100
    assert st.sessions >= PACKETS // SESSION
