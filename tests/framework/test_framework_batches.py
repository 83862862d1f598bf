"""Batched notifications and the once-per-turn acknowledgement (docs/protocol.md, "Batches").

A burst of frames a device produces in one event-loop turn reaches its requester
in a few samples (``ProcessUpdateBatch``) instead of one per frame, every frame
whole and in order; no batch carries more than ``BATCH_BYTES`` of data; every
receiver of process updates (the requester, ``process_updates``) reads both forms.
"""

from __future__ import annotations

import threading

import msgspec
import pytest
from framework_testlib import cell_with, collect, run, states
from hypothesis import given, settings
from hypothesis import strategies as st
from zenoh.handlers import Callback

from plugcell.framework import codec
from plugcell.framework import outbox as outbox_module
from plugcell.framework.journal import read_journal
from plugcell.framework.messages import (
    Acknowledgement,
    Data,
    DataTypes,
    ProcessStates,
    ProcessUpdateBatch,
    ProcessUpdateNotification,
    Tag,
    process_updates,
)

pytestmark = pytest.mark.timeout(60)

R, C = ProcessStates.Running, ProcessStates.Completed


class Tap:
    """A raw Zenoh subscriber on one process key: the samples as they travel."""

    def __init__(self, participant, key: str) -> None:
        self.bodies: list = []
        self._lock = threading.Lock()
        self._sub = participant.session.declare_subscriber(key, Callback(self._on, indirect=False))

    def _on(self, sample) -> None:
        body = codec.decode(sample.payload.to_bytes()).body
        with self._lock:
            self.bodies.append(body)

    def close(self) -> None:
        self._sub.undeclare()


async def _stream_burst(tmp_path, frames: int):
    """``frames`` values emitted in one turn by DEV's stream for A; what A and a tap saw."""
    async with cell_with(tmp_path, "A") as (dev, a):
        tap = Tap(a, dev.participant.keys.process("DEV", "A"))
        stream = await a.create_process("DEV", "Stream")
        await dev.interface.started.wait()
        for i in range(frames):  # one event-loop turn: one flush
            dev.interface.emit(float(i))
        stop = await a.create_process("DEV", "Stop")
        assert (await stop.result()).state is C
        updates = await collect(stream)
        tap.close()
        journal = read_journal([tmp_path / "journal" / "DEV.sqlite"])
        return updates, list(tap.bodies), stream, journal


def test_a_burst_of_frames_travels_in_a_few_batches_whole_and_in_order(tmp_path):
    updates, bodies, stream, journal = run(_stream_burst(tmp_path, 500))
    assert states(updates) == [R] * 501 + [C]
    assert [stream.array(u)[0] for u in updates[1:501]] == [float(i) for i in range(500)]
    assert [u.seq for u in updates] == list(range(1, 503))  # no gap, nothing skipped
    frames = [u for b in bodies for u in process_updates(b) if u.data is not None]
    assert len(frames) == 500
    batches = [b for b in bodies if isinstance(b, ProcessUpdateBatch)]
    assert batches, "the burst went out one sample per frame"
    assert len(bodies) < 20  # 500 frames + Running + Completed + Stop's own updates
    # every update is journaled, batched or not
    rows = {p["command"]: p for p in journal}
    assert [u["seq"] for u in rows["Stream"]["updates"]] == list(range(1, 503))


def test_no_batch_carries_more_than_the_limit(tmp_path, monkeypatch):
    monkeypatch.setattr(outbox_module, "BATCH_BYTES", 20)  # 8-byte frames: 2 per batch
    updates, bodies, stream, _ = run(_stream_burst(tmp_path, 41))
    assert [stream.array(u)[0] for u in updates[1:42]] == [float(i) for i in range(41)]
    sizes = [
        sum(len(u.data.buffer) for u in process_updates(b) if u.data is not None)
        for b in bodies
    ]
    assert max(sizes) <= 20
    assert sum(1 for b in bodies if isinstance(b, ProcessUpdateBatch)) >= 20


def test_a_frame_larger_than_the_limit_travels_alone(tmp_path, monkeypatch):
    monkeypatch.setattr(outbox_module, "BATCH_BYTES", 4)  # every 8-byte frame is too big
    updates, bodies, stream, _ = run(_stream_burst(tmp_path, 10))
    assert [stream.array(u)[0] for u in updates[1:11]] == [float(i) for i in range(10)]
    data_bodies = [b for b in bodies if any(u.data is not None for u in process_updates(b))]
    assert all(isinstance(b, ProcessUpdateNotification) for b in data_bodies)
    assert len(data_bodies) == 10


def test_a_requester_reads_a_batch_it_did_not_expect_in_one_piece(tmp_path):
    """Updates for unknown processes inside a batch are skipped, the known ones delivered."""

    async def body():
        async with cell_with(tmp_path, "A") as (dev, a):
            stream = await a.create_process("DEV", "Stream")
            first = await anext(stream)  # the Running of the stream itself
            tag = Tag("A", "DEV")
            stray = ProcessUpdateNotification(tag=tag, identifier=1, state=R, seq=1)
            frame = ProcessUpdateNotification(
                tag=tag, identifier=stream.identifier, state=R, seq=2,
                data=Data(DataTypes.Double, (1,), b"\x00" * 8),
            )
            payload = codec.encode("DEV", dev.participant.instance,
                                   ProcessUpdateBatch(updates=[stray, frame]))
            a.session.put(dev.participant.keys.process("DEV", "A"), payload)  # as DEV would
            second = await anext(stream)
            assert (first.seq, second.seq) == (1, 2) and stream.array(second)[0] == 0.0
            stop = await a.create_process("DEV", "Stop")
            assert (await stop.result()).state is C

    run(body())


_updates = st.lists(
    st.builds(
        ProcessUpdateNotification,
        tag=st.just(Tag("A", "DEV")),
        identifier=st.integers(1, 2**62),
        state=st.sampled_from(list(ProcessStates)),
        data=st.none() | st.binary(max_size=64).map(
            lambda b: Data(DataTypes.Byte, (len(b),), b)),
        reason=st.text(max_size=20),
        seq=st.integers(0, 2**31),
    ),
    min_size=1,
    max_size=20,
)


@settings(max_examples=200, deadline=None)
@given(_updates)
def test_process_updates_reads_a_batch_as_its_updates_in_order(updates):
    body = codec.decode(codec.encode("DEV", "i", ProcessUpdateBatch(updates=updates))).body
    assert process_updates(body) == updates
    single = codec.decode(codec.encode("DEV", "i", updates[0])).body
    assert process_updates(single) == [updates[0]]
    assert process_updates(Acknowledgement(identifier=1, state=ProcessStates.Queued)) == []


def test_a_batch_of_the_wrong_things_is_refused_with_the_reason():
    raw = msgspec.msgpack.encode(
        {"V": 1, "Sender": "DEV", "Instance": "i", "TimeNs": 1,
         "Body": {"Kind": "ProcessUpdateBatch", "Updates": [{"Kind": "GetRequest"}]}}
    )
    with pytest.raises(codec.WireError, match="invalid message"):
        codec.decode(raw)
