"""Wire codec and data model: round trips, strict decoding, property tests, decoder fuzz."""

from __future__ import annotations

import msgspec
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from plugcell.apps.bench.fuzz import fuzz_decoder
from plugcell.framework import codec
from plugcell.framework.data import DTYPES, to_data
from plugcell.framework.messages import (
    Acknowledgement,
    Command,
    CommandTypes,
    ConnectionStates,
    ConnectionUpdateNotification,
    Data,
    DataTypes,
    Device,
    DeviceStates,
    GenericDeviceState,
    GetRequest,
    Process,
    ProcessStates,
    ProcessUpdateNotification,
    ShutdownNotification,
    StateUpdateNotification,
    SubscribeRequest,
    SubscribeResponse,
    Tag,
    UnsubscribeRequest,
)

pytestmark = pytest.mark.timeout(120)

names = st.from_regex(r"\A[A-Za-z0-9][A-Za-z0-9_.\-]{0,20}\Z")
texts = st.text(max_size=30)
sizes = st.lists(st.integers(-1, 50), max_size=4).map(tuple)
data_types = st.sampled_from(list(DataTypes))


@st.composite
def datas(draw: st.DrawFn) -> Data:
    dtype = draw(data_types)
    shape = tuple(draw(st.lists(st.integers(0, 5), min_size=1, max_size=3)))
    count = int(np.prod(shape))
    if dtype is DataTypes.String:
        return Data(dtype, shape, draw(st.lists(texts, min_size=count, max_size=count)))
    raw = draw(
        st.binary(min_size=count * DTYPES[dtype].itemsize, max_size=count * DTYPES[dtype].itemsize)
    )
    if dtype is DataTypes.Boolean:
        raw = bytes(b & 1 for b in raw)
    return Data(dtype, shape, raw)


commands = st.builds(
    Command,
    name=st.text(min_size=1, max_size=20),
    option=texts,
    success_code=texts,
    type=st.sampled_from(list(CommandTypes)),
    input_data_type=st.none() | data_types,
    input_data_size=sizes,
    output_data_type=st.none() | data_types,
    output_data_size=sizes,
    timeout=st.floats(0.001, 1e6),
    info=texts,
)
tags = st.builds(Tag, names, names)
identifiers = st.integers(1, 2**63 - 1)
devices = st.builds(
    Device,
    name=names,
    vendor=texts,
    info=texts,
    connection=st.sampled_from(list(ConnectionStates)),
    state=st.sampled_from(list(DeviceStates)),
    commands=st.lists(commands, max_size=3).map(tuple),
    kind=texts,
)
messages = st.one_of(
    st.builds(
        Process,
        command=commands,
        tag=tags,
        identifier=identifiers,
        state=st.sampled_from(list(ProcessStates)),
        data=st.none() | datas(),
    ),
    st.builds(
        Acknowledgement,
        identifier=st.integers(0, 2**63),
        state=st.sampled_from(list(ProcessStates)),
        reason=texts,
        instance=texts,
    ),
    st.builds(
        ProcessUpdateNotification,
        tag=tags,
        identifier=st.integers(0, 2**63),
        state=st.sampled_from(list(ProcessStates)),
        data=st.none() | datas(),
        reason=texts,
        seq=st.integers(0, 10**9),
    ),
    st.builds(StateUpdateNotification, name=names, state=st.sampled_from(list(DeviceStates))),
    st.builds(
        ConnectionUpdateNotification, name=names, connection=st.sampled_from(list(ConnectionStates))
    ),
    st.builds(ShutdownNotification, name=names, reason=texts),
    st.just(GetRequest()),
    st.builds(GenericDeviceState, device_info=devices, partners=st.lists(devices, max_size=2)),
    st.builds(SubscribeRequest, partner=names),
    st.builds(UnsubscribeRequest, partner=names),
    st.builds(SubscribeResponse, ok=st.booleans(), reason=texts, partner=st.none() | devices),
)


@settings(max_examples=300, deadline=None)
@given(messages, names, st.text(max_size=32))
def test_every_message_round_trips(body, sender, instance):
    envelope = codec.decode(codec.encode(sender, instance, body))
    assert envelope.v == codec.VERSION
    assert envelope.sender == sender and envelope.instance == instance
    assert envelope.body == body


def test_wire_names_are_the_thesis_names():
    """Table F-5/F-9 member names appear verbatim on the wire."""
    process = Process(
        command=Command(name="SnapShot", type=CommandTypes.SingleData),
        tag=Tag("ROBOT", "CAMERA"),
        identifier=7,
    )
    raw = msgspec.msgpack.decode(codec.encode("ROBOT", "z1", process))
    assert set(raw) == {"V", "Sender", "Instance", "TimeNs", "Body"}
    body = raw["Body"]
    assert body["Kind"] == "Process"
    assert set(body["Command"]) >= {
        "Name",
        "Option",
        "SuccessCode",
        "Type",
        "InputDataType",
        "InputDataSize",
        "OutputDataType",
        "OutputDataSize",
    }
    assert body["Tag"] == {"Sender": "ROBOT", "Recipient": "CAMERA"}
    assert body["Identifier"] == 7 and body["State"] == "Queued"


def _valid() -> bytes:
    data = to_data(np.arange(12, dtype=np.int32).reshape(3, 4), DataTypes.Integer, (3, 4))
    return codec.encode(
        "ROBOT",
        "abc",
        Process(command=Command(name="Set"), tag=Tag("ROBOT", "DEV"), identifier=99, data=data),
    )


@pytest.mark.parametrize(
    ("payload", "reason"),
    [
        (b"", "empty payload"),
        (b"\xc1", "malformed message"),
        (b"\x93\x01\x02", "invalid message"),
        (
            msgspec.msgpack.encode(
                {"V": 2, "Sender": "A", "Instance": "", "TimeNs": 0, "Body": {}}
            ),
            "unsupported protocol version 2",
        ),
        (
            msgspec.msgpack.encode(
                {"V": 1, "Sender": "A", "Instance": "", "TimeNs": 0, "Body": {"Kind": "Nope"}}
            ),
            "invalid message",
        ),
        (
            msgspec.msgpack.encode(
                {
                    "V": 1,
                    "Sender": "bad name!",
                    "Instance": "",
                    "TimeNs": 0,
                    "Body": {"Kind": "GetRequest"},
                }
            ),
            "Sender",
        ),
    ],
)
def test_decoder_gives_precise_reasons(payload, reason):
    with pytest.raises(codec.WireError, match=reason):
        codec.decode(payload)


def test_every_truncation_is_rejected():
    payload = _valid()
    for cut in range(len(payload)):
        with pytest.raises(codec.WireError):
            codec.decode(payload[:cut])


def test_oversized_payload_is_rejected_before_decoding():
    with pytest.raises(codec.WireError, match="exceeds the limit of 100 bytes"):
        codec.decode(_valid() + b"\0" * 200, max_size=100)


def test_identifier_out_of_range_is_invalid():
    raw = msgspec.msgpack.decode(_valid())
    raw["Body"]["Identifier"] = 2**63
    with pytest.raises(codec.WireError, match="Identifier"):
        codec.decode(msgspec.msgpack.encode(raw))


def test_decoder_fuzz_only_raises_wire_error():
    counts = fuzz_decoder(4000)  # benchmarks/fuzz_wire.py runs >= 100 000
    assert counts["decoded"] + counts["rejected"] == 4000
    assert counts["rejected"] > 0 and counts["decoded"] > 0
