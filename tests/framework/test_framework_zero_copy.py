"""Large frames without copies (issue 20, §2): what the data path copies, and what not.

* receiving: a decoded message's buffers are read-only views into the payload, and
  :func:`from_data` a read-only numpy view of one — the frame is never copied after it
  left the Zenoh sample;
* sending: :func:`to_data` of a read-only array is a view of it, so the encoded payload
  is the only copy Python makes; a writeable array is copied (its owner may reuse it);
* the journal keeps a summary text of a frame, never its bytes;
* the bytes on the wire are the same whichever way a buffer is held, and every data type
  arrives with exactly the values that were sent.
"""

from __future__ import annotations

import sqlite3
import tracemalloc

import numpy as np
import pytest
from framework_testlib import run, unique_cell
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from plugcell.apps.bench.device import bench_service
from plugcell.framework import codec
from plugcell.framework.data import (
    DTYPES,
    VIEW_MIN_BYTES,
    DataError,
    check_data,
    from_data,
    summary,
    to_data,
)
from plugcell.framework.journal import Journal
from plugcell.framework.messages import (
    Data,
    DataTypes,
    ProcessStates,
    ProcessUpdateBatch,
    ProcessUpdateNotification,
    Tag,
    process_updates,
)
from plugcell.framework.participant import Participant

pytestmark = pytest.mark.timeout(120)

NUMERIC = [DataTypes.Boolean, DataTypes.Byte, DataTypes.Integer, DataTypes.Double]
FRAME = (480, 640, 3)  # the 0.9 MB frame of the transport benchmark


def _update(data: Data | None, seq: int = 1) -> ProcessUpdateNotification:
    return ProcessUpdateNotification(
        tag=Tag("A", "DEV"), identifier=7, state=ProcessStates.Running, data=data, seq=seq
    )


def _read_only(arr: np.ndarray) -> np.ndarray:
    arr = np.array(arr)  # own copy, C order
    arr.flags.writeable = False
    return arr


_numeric_arrays = st.sampled_from(NUMERIC).flatmap(
    lambda t: st.tuples(
        st.just(t), hnp.arrays(DTYPES[t], hnp.array_shapes(min_dims=1, max_dims=4, max_side=7))
    )
)


@settings(max_examples=200, deadline=None)
@given(_numeric_arrays, st.booleans())
def test_numbers_arrive_as_sent_as_views_into_the_payload(case, read_only):
    """Every numeric type, any shape: the same wire bytes as a copied buffer gives, the
    same values back, and the array received is a read-only view of the payload."""
    data_type, arr = case
    if read_only:
        arr = _read_only(arr)
    declared = tuple(-1 for _ in arr.shape)
    data = to_data(arr, data_type, declared)
    payload = codec.encode("DEV", "i", _update(data), time_ns=1)
    reference = Data(data_type, arr.shape, np.ascontiguousarray(arr).tobytes())
    assert payload == codec.encode("DEV", "i", _update(reference), time_ns=1)  # byte-identical

    received = codec.decode(payload).body.data
    check_data(received, data_type, declared)
    back = from_data(received)
    assert back.dtype == DTYPES[data_type] and back.shape == arr.shape
    np.testing.assert_array_equal(back, arr)
    assert not back.flags.writeable
    if arr.size:
        assert isinstance(received.buffer, memoryview) and received.buffer.readonly
        assert received.buffer.obj is payload
        assert np.shares_memory(back, np.frombuffer(payload, np.uint8))


@settings(max_examples=100, deadline=None)
@given(st.lists(st.text(max_size=10), min_size=1, max_size=6))
def test_strings_arrive_as_sent(items):
    data = to_data(items, DataTypes.String, (len(items),))
    received = codec.decode(codec.encode("DEV", "i", _update(data))).body.data
    check_data(received, DataTypes.String, (-1,))
    assert from_data(received).tolist() == items


@pytest.mark.parametrize("data_type", NUMERIC)
def test_a_read_only_array_is_sent_from_its_own_memory(data_type):
    shape = (64, VIEW_MIN_BYTES // 64)
    arr = _read_only(np.ones(shape, DTYPES[data_type]))
    data = to_data(arr, data_type, shape)
    assert isinstance(data.buffer, memoryview) and data.buffer.readonly
    assert len(data.buffer) == arr.nbytes and data.buffer.format == "B"
    assert np.shares_memory(np.frombuffer(data.buffer, np.uint8), arr)
    check_data(data, data_type, shape)


def test_a_small_array_is_copied_a_copy_being_cheaper_than_a_view():
    arr = _read_only(np.ones(VIEW_MIN_BYTES - 1, np.uint8))
    assert type(to_data(arr, DataTypes.Byte, ()).buffer) is bytes


def test_a_writeable_array_is_copied_so_its_owner_may_reuse_it():
    frame = np.full(FRAME, 7, np.uint8)
    data = to_data(frame, DataTypes.Byte, ())
    frame[:] = 9  # the camera writes the next frame into the same memory
    assert not np.shares_memory(from_data(data), frame)
    assert int(from_data(data).max()) == 7


def test_received_data_is_forwarded_without_a_copy():
    """What a service echoes or forwards (a received frame) is already read-only: the
    update it sends points into the payload it received."""
    sent = to_data(np.full(FRAME, 7, np.uint8), DataTypes.Byte, ())
    payload = codec.encode("A", "i", _update(sent))
    arr = from_data(codec.decode(payload).body.data)
    forwarded = to_data(arr, DataTypes.Byte, ())
    assert np.shares_memory(np.frombuffer(forwarded.buffer, np.uint8),
                            np.frombuffer(payload, np.uint8))
    assert codec.encode("DEV", "i", _update(forwarded), time_ns=1) == codec.encode(
        "DEV", "i", _update(sent), time_ns=1
    )


def test_a_mutable_payload_is_copied_before_views_are_taken():
    payload = bytearray(codec.encode("A", "i", _update(to_data(
        np.arange(8, dtype=np.uint8), DataTypes.Byte, ()))))
    data = codec.decode(payload).body.data
    payload[:] = bytes(len(payload))  # the caller's buffer changes afterwards
    assert from_data(data).tolist() == list(range(8))


def test_a_view_of_writeable_memory_is_read_as_read_only():
    memory = bytearray(b"\x01\x02\x03")
    arr = from_data(Data(DataTypes.Byte, (3,), memoryview(memory)))
    assert not arr.flags.writeable and arr.tolist() == [1, 2, 3]


def test_views_are_checked_like_bytes():
    check_data(Data(DataTypes.Boolean, (2,), memoryview(b"\x01\x00")), DataTypes.Boolean, (2,))
    with pytest.raises(DataError, match="other than 0 and 1"):
        check_data(Data(DataTypes.Boolean, (2,), memoryview(b"\x01\x02")),
                   DataTypes.Boolean, (2,))
    wide = memoryview(np.zeros(2, "<i4"))  # 2 items of 4 bytes: not a byte buffer
    with pytest.raises(DataError, match="must carry a byte buffer"):
        check_data(Data(DataTypes.Integer, (2,), wide), DataTypes.Integer, (2,))
    with pytest.raises(DataError, match=r"buffer of 3 bytes does not match Integer\[1\]"):
        check_data(Data(DataTypes.Integer, (1,), memoryview(b"abc")), DataTypes.Integer, (1,))


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=40), st.sampled_from([DataTypes.Byte, DataTypes.Boolean]))
def test_the_journal_text_of_a_view_is_that_of_its_bytes(buffer, data_type):
    if data_type is DataTypes.Boolean:
        buffer = bytes(b & 1 for b in buffer)
    size = (len(buffer),)
    assert summary(Data(data_type, size, memoryview(buffer))) == summary(
        Data(data_type, size, buffer))


def test_a_batch_decodes_every_frame_as_a_view():
    frames = [np.full(1000, i, np.uint8) for i in range(3)]
    batch = ProcessUpdateBatch(updates=[
        _update(to_data(f, DataTypes.Byte, ()), seq=i + 1) for i, f in enumerate(frames)])
    payload = codec.encode("DEV", "i", batch)
    for frame, update in zip(frames, process_updates(codec.decode(payload).body), strict=True):
        assert update.data.buffer.obj is payload
        np.testing.assert_array_equal(from_data(update.data), frame)


def _peak_bytes(action) -> int:
    """Most memory Python and numpy held at once during ``action`` beyond what was before."""
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        tracemalloc.reset_peak()
        action()
        return tracemalloc.get_traced_memory()[1] - before
    finally:
        tracemalloc.stop()


def test_sending_a_read_only_frame_copies_it_once_into_the_payload():
    frame = _read_only(np.full(FRAME, 7, np.uint8))
    writeable = np.full(FRAME, 7, np.uint8)

    def send(arr):
        return lambda: codec.encode("DEV", "i", _update(to_data(arr, DataTypes.Byte, ())))

    viewed, copied = _peak_bytes(send(frame)), _peak_bytes(send(writeable))
    # the payload alone (msgspec's output buffer grows by half as it writes: < 2 frames)
    assert viewed < frame.nbytes * 2
    assert copied - viewed > frame.nbytes * 0.9  # a writeable frame: its copy as well


def test_receiving_a_frame_copies_nothing():
    payload = codec.encode("DEV", "i", _update(to_data(
        np.full(FRAME, 7, np.uint8), DataTypes.Byte, ())))

    def receive():
        arr = from_data(codec.decode(payload).body.data)
        assert arr.shape == FRAME

    assert _peak_bytes(receive) < 64 * 1024


def test_the_journal_keeps_a_summary_of_a_frame_not_its_bytes(tmp_path):
    frame = to_data(_read_only(np.full(FRAME, 7, np.uint8)), DataTypes.Byte, ())
    journal = Journal(tmp_path / "DEV.sqlite", "DEV")
    try:
        def record():
            journal.record_update("A", 7, 1, "Running", "", summary(frame))
            journal.commit()

        assert _peak_bytes(record) < 64 * 1024
    finally:
        journal.close()
    db = sqlite3.connect(tmp_path / "DEV.sqlite")
    try:
        assert db.execute("SELECT data FROM updates").fetchall() == [("Byte[480, 640, 3]",)]
    finally:
        db.close()


async def _streamed_frames(tmp_path, count: int) -> list[ProcessUpdateNotification]:
    cell = unique_cell()
    publisher = bench_service("PUBLISHER", cell=cell, journal=tmp_path / "journal")
    consumer = Participant("CONSUMER", cell=cell)
    await publisher.start()
    try:
        await consumer.start()
        assert await consumer.wait_for("PUBLISHER", 10)
        call = await consumer.create_process("PUBLISHER", "Push", data=[count, *FRAME])
        frames = []
        async for update in call:
            if update.data is not None:
                frames.append(update)
                if len(frames) == count:
                    break
        await (await consumer.stop_process(call)).result()
        await call.result()
        return frames
    finally:
        await consumer.close()
        await publisher.close()


def test_streamed_frames_arrive_whole_as_views_of_their_samples(tmp_path):
    """End to end through Zenoh: each frame a requester reads is a read-only view into
    the bytes of the sample it came in, holding the values the device streamed."""
    frames = run(_streamed_frames(tmp_path, 3))
    for update in frames:
        arr = from_data(update.data)
        assert arr.shape == FRAME and not arr.flags.writeable
        assert int(arr.min()) == int(arr.max()) == 7
        payload = update.data.buffer.obj
        assert type(payload) is bytes and len(payload) > arr.nbytes
        assert np.shares_memory(arr, np.frombuffer(payload, np.uint8))
