"""CreateProcess through the publication door (docs/protocol.md §5, "Two doors").

A requester publishes its Process on ``svc/<recipient>/create/<sender>`` with the
identifier as the sample's attachment; the recipient acknowledges on the sender's
process key, in one sample with the first updates.  A recipient that only has the
queryable (a foreign implementation) is still served through the query.  Every bad
request gets a Failed acknowledgement with the reason — to the right process even
when the request cannot be read — and the service keeps serving.
"""

from __future__ import annotations

import asyncio
import random
import threading
import time

import pytest
from framework_testlib import cell_with, collect, run, states
from hypothesis import given, settings
from hypothesis import strategies as st
from zenoh.handlers import Callback

from plugcell.framework import codec
from plugcell.framework.journal import read_journal
from plugcell.framework.messages import (
    Acknowledgement,
    Command,
    Process,
    ProcessStates,
    ProcessUpdateNotification,
    Tag,
    process_acks,
)

pytestmark = pytest.mark.timeout(60)

Q, C, F = ProcessStates.Queued, ProcessStates.Completed, ProcessStates.Failed


class AckTap:
    """Acknowledgements published on one process key, as they travel."""

    def __init__(self, participant, key: str) -> None:
        self.acks: list[Acknowledgement] = []
        self._lock = threading.Lock()
        self._sub = participant.session.declare_subscriber(key, Callback(self._on, indirect=False))

    def _on(self, sample) -> None:
        acks = process_acks(codec.decode(sample.payload.to_bytes()).body)
        with self._lock:
            self.acks.extend(acks)

    async def next(self, count: int, timeout: float = 5.0) -> Acknowledgement:
        deadline = time.monotonic() + timeout
        while len(self.acks) < count:
            assert time.monotonic() < deadline, "no acknowledgement on the process key"
            await asyncio.sleep(0.005)
        return self.acks[count - 1]

    def close(self) -> None:
        self._sub.undeclare()


def _process(identifier: int, sender: str = "A", recipient: str = "DEV") -> Process:
    return Process(command=Command(name="Measure"), tag=Tag(sender, recipient),
                   identifier=identifier)


def test_bad_published_requests_are_acknowledged_failed_to_the_right_process(tmp_path):
    async def body():
        async with cell_with(tmp_path, "A", max_payload=20_000) as (dev, a):
            tap = AckTap(a, dev.participant.keys.process("DEV", "A"))
            door = dev.participant.keys.request("DEV", "A")

            async def publish(payload: bytes, identifier: int | None) -> Acknowledgement:
                seen = len(tap.acks)
                attachment = codec.attach_identifier(identifier) if identifier else None
                a.session.put(door, payload, attachment=attachment)
                return await tap.next(seen + 1)

            ack = await publish(b"\xc1\xc1", 77)
            assert (ack.identifier, ack.state) == (77, F)
            assert ack.reason.startswith("malformed message")
            ack = await publish(b"\x93\x01", None)  # no attachment: identifier unknown
            assert (ack.identifier, ack.state) == (0, F) and "invalid message" in ack.reason
            ack = await publish(b"\0" * 30_000, 78)
            assert (ack.identifier, ack.state) == (78, F)
            assert "exceeds the limit of 20000 bytes" in ack.reason
            good = codec.encode("A", a.instance, _process(4242))
            ack = await publish(good, 4242)
            assert (ack.identifier, ack.state, ack.instance) == (4242, Q, dev.participant.instance)
            dup = await publish(good, 4242)
            assert dup.state is F and "4242" in dup.reason  # reused: refused, with the id
            # seeded garbage: always a Failed acknowledgement, with a reason, to its id
            rng = random.Random(5)
            for i in range(200):
                junk = rng.randbytes(rng.randint(1, 64))
                ack = await publish(junk, 10_000 + i)
                assert (ack.identifier, ack.state) == (10_000 + i, F) and ack.reason
            tap.close()
            assert (await (await a.create_process("DEV", "Measure")).result()).state is C

    run(body())


def test_a_request_published_under_another_senders_key_is_refused(tmp_path):
    async def body():
        async with cell_with(tmp_path, "A", "B") as (dev, a, b):
            tap_b = AckTap(a, dev.participant.keys.process("DEV", "B"))
            forged = codec.encode("A", a.instance, _process(9))  # A's envelope, B's key
            a.session.put(dev.participant.keys.request("DEV", "B"), forged,
                          attachment=codec.attach_identifier(9))
            ack = await tap_b.next(1)
            assert ack.state is F and "differs from the sender B of the request key" in ack.reason
            # a key whose last chunk cannot be a sender name: journaled, nobody answered
            a.session.put(dev.participant.keys.request("DEV", "-x"), forged)
            await asyncio.sleep(0.3)
            rejected = [r for r in read_journal([dev.journal.path]) if r.get("rejected")]
            assert any("invalid sender name '-x'" in r["reason"] for r in rejected)
            tap_b.close()
            assert (await (await b.create_process("DEV", "Measure")).result()).state is C

    run(body())


def test_the_acknowledgement_and_a_short_process_arrive_in_one_sample(tmp_path):
    async def body():
        async with cell_with(tmp_path, "A") as (dev, a):
            samples: list = []
            sub = a.session.declare_subscriber(
                dev.participant.keys.process("DEV", "A"),
                Callback(lambda s: samples.append(codec.decode(s.payload.to_bytes()).body),
                         indirect=False))
            call = await a.create_process("DEV", "Measure")
            assert states(await collect(call)) == [C]
            await asyncio.sleep(0.1)
            sub.undeclare()
            assert len(samples) == 1  # Acknowledgement + Completed with the data
            batch = samples[0]
            assert [x.identifier for x in batch.acks] == [call.identifier]
            assert [u.state for u in batch.updates] == [C]

    run(body())


def test_a_recipient_with_only_the_queryable_is_served_through_it(tmp_path):
    """A foreign service that implements only the queryable of protocol.md §7."""

    async def body():
        async with cell_with(tmp_path, "A") as (dev, a):
            _queryable, subscriber = dev._create_doors
            subscriber.undeclare()  # what a queryable-only implementation looks like
            await asyncio.sleep(0.3)
            call = await a.create_process("DEV", "Measure")
            assert call.ack.state is Q and call.ack.instance == dev.participant.instance
            assert (await call.result()).state is C
            assert not a.calls.request_door("DEV")  # no subscriber matches: the query was used

    run(body())


def test_updates_from_another_incarnation_of_the_name_are_not_ours(tmp_path):
    """While two services briefly share a name both hear a published request; the
    requester follows the incarnation that acknowledged it, not the other one."""

    async def body():
        async with cell_with(tmp_path, "A") as (dev, a):
            stream = await a.create_process("DEV", "Stream")
            first = await anext(stream)
            assert stream.instance == dev.participant.instance
            impostor = ProcessUpdateNotification(
                tag=Tag("A", "DEV"), identifier=stream.identifier, state=F, seq=9,
                reason="DEV: a service named DEV is already running")
            a.session.put(dev.participant.keys.process("DEV", "A"),
                          codec.encode("DEV", "f" * 16 + "other", impostor))
            await asyncio.sleep(0.3)
            assert stream.final is None  # the other incarnation's Failed was not taken
            dev.interface.emit(5.0)
            frame = await anext(stream)
            assert (first.seq, frame.seq, stream.array(frame)[0]) == (1, 2, 5.0)
            stop = await a.create_process("DEV", "Stop")
            assert (await stop.result()).state is C
            assert (await stream.result()).state is C

    run(body())


def test_every_waiter_of_an_acknowledgement_is_woken_by_it():
    from plugcell.framework.process_call import ProcessCall

    async def body():
        loop = asyncio.get_running_loop()
        call = ProcessCall("A", "DEV", "Work", 5, timeout=30.0, loop=loop)
        waiters = [asyncio.create_task(call.acknowledged()) for _ in range(3)]
        await asyncio.sleep(0)
        started = loop.time()
        call.acknowledge(Acknowledgement(identifier=5, state=Q, instance="i"), "i")
        acks = await asyncio.wait_for(asyncio.gather(*waiters), 2.0)
        assert [a.state for a in acks] == [Q, Q, Q] and loop.time() - started < 1.0
        assert call._ack_waiters == []

    run(body())


class _Attachment:
    def __init__(self, raw: bytes) -> None:
        self.raw = raw

    def to_bytes(self) -> bytes:
        return self.raw


class _Unreadable:
    def to_bytes(self) -> bytes:
        raise ValueError("not bytes")


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=16), st.integers(0, 2**64 - 1))
def test_the_attached_identifier_reads_any_attachment(raw, identifier):
    """8 bytes little-endian is an identifier; anything else (or nothing) is 0."""
    assert codec.attached_identifier(_Attachment(codec.attach_identifier(identifier))) == identifier
    expected = int.from_bytes(raw, "little") if len(raw) == 8 else 0
    assert codec.attached_identifier(_Attachment(raw)) == expected
    assert codec.attached_identifier(None) == 0
    assert codec.attached_identifier(_Unreadable()) == 0
