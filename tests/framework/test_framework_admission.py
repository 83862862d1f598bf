"""The admission checks on their own (framework/admission.py): each returns the reason a
request fails, never raises, and changes nothing."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from plugcell.framework import codec
from plugcell.framework.admission import (
    check_envelope,
    check_input,
    check_process,
    decode_request,
)
from plugcell.framework.data import to_data
from plugcell.framework.messages import (
    Command,
    CommandTypes,
    DataTypes,
    Device,
    GetRequest,
    Process,
    Tag,
)


class _Payload:
    """What a Zenoh payload offers the decoder: a length and its bytes."""

    def __init__(self, data: bytes) -> None:
        self.data = data

    def __len__(self) -> int:
        return len(self.data)

    def to_bytes(self) -> bytes:
        return self.data


SET = Command(name="Set", type=CommandTypes.NoData, input_data_type=DataTypes.Integer,
              input_data_size=(2,))
DEVICE = Device(name="DEV", commands=[SET])


def _envelope(body, sender="R1", instance="i1") -> codec.Envelope:
    return codec.decode(codec.encode(sender, instance, body))


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=300))
def test_any_bytes_decode_or_say_why(raw):
    out = decode_request(_Payload(raw), 200, "DEV")
    assert isinstance(out, str) or (isinstance(out, tuple) and out[1] == raw)
    if len(raw) > 200:
        assert out == f"payload of {len(raw)} bytes exceeds the limit of 200 bytes of DEV"


def test_empty_and_missing_requests():
    assert decode_request(None, 10, "DEV") == "empty request"
    assert decode_request(_Payload(b""), 10, "DEV") == "empty request"


def test_envelope_checks():
    p = Process(command=SET, tag=Tag("R1", "DEV"), identifier=1)
    env = _envelope(p)
    assert check_envelope(env, "R1") == "" and check_envelope(env, None) == ""
    assert "differs from the sender R2 of the request key" in check_envelope(env, "R2")
    assert check_envelope(_envelope(GetRequest()), None) == "expected a Process, got GetRequest"


def test_process_checks_in_order():
    def reason(process, departed=frozenset()):
        return check_process("DEV", DEVICE, _envelope(process), process, set(departed))

    ok = Process(command=SET, tag=Tag("R1", "DEV"), identifier=1)
    assert reason(ok) == ""
    assert reason(Process(command=SET, tag=Tag("R1", "CAM"), identifier=1)) == \
        "process addressed to CAM, this is DEV"
    assert "tag sender R9 differs" in reason(Process(command=SET, tag=Tag("R9", "DEV"),
                                                     identifier=1))
    assert "is already gone" in reason(ok, {"i1"})
    assert reason(Process(command=Command(name="Nope"), tag=Tag("R1", "DEV"), identifier=1)) == \
        "unknown command 'Nope' for DEV (commands: Set)"


def test_input_check_gives_the_array_or_the_reason():
    good = Process(command=SET, tag=Tag("R1", "DEV"), identifier=1,
                   data=to_data([1, 2], DataTypes.Integer, (2,)))
    array, why = check_input(SET, good)
    assert why == "" and np.array_equal(array, [1, 2])
    bad = Process(command=SET, tag=Tag("R1", "DEV"), identifier=1,
                  data=to_data([1, 2, 3], DataTypes.Integer, (3,)))
    array, why = check_input(SET, bad)
    assert array is None and why == "Set input: size [3] does not match the declared [2]"
