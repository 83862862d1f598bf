"""The measuring device of ``durability_floor.py --native`` speaks plugcell's protocol.

``benchmarks/native_probe`` does the per-message work of a 4-byte ``Echo`` in Rust; its
rows in docs/results/framework-performance.md ("In one picture") claim the same bytes on the
wire and the same checks as plugcell's.  These tests hold it to that: its request and answer decode
through plugcell's own decoder to the messages plugcell's functions make, byte for byte
apart from the timestamp; its journal record reads back through the journal's log
reader; what plugcell refuses it refuses with the same reason; no input makes it do anything
but answer or refuse, and it admits exactly what plugcell's admission admits.  Skipped
where there is no cargo.
"""

from __future__ import annotations

import asyncio
import shutil
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

import msgspec
import pytest
import zenoh
from hypothesis import given, settings
from hypothesis import strategies as st

from plugcell.framework import admission, codec
from plugcell.framework.journal_log import PROCESS, UPDATE, read_log
from plugcell.framework.messages import Acknowledgement, ProcessStates, ProcessUpdateBatch

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(shutil.which("cargo") is None, reason="needs cargo (a Rust toolchain)"),
]


@pytest.fixture(scope="module")
def floor() -> Any:
    sys.path.insert(0, str(BENCHMARKS))
    try:
        import durability_floor
    finally:
        sys.path.remove(str(BENCHMARKS))
    return durability_floor


@pytest.fixture(scope="module")
def probe(floor: Any) -> ModuleType:
    return floor._load_probe(floor._build_probe())


def _without_time(payload: bytes) -> tuple[codec.Envelope, bytes]:
    """The decoded message with its timestamp zeroed, and its bytes without the stamp."""
    envelope = codec.decode(payload)
    stamp = msgspec.msgpack.encode(envelope.time_ns)
    return msgspec.structs.replace(envelope, time_ns=0), payload.replace(stamp, b"", 1)


def test_request_and_answer_are_plugcells_bytes(floor: Any, probe: ModuleType,
                                                tmp_path: Path) -> None:
    lean_requester = floor._LeanRequester()
    ours, our_attachment = lean_requester.request()
    requester = probe.Requester(floor.REQUESTER, "requester-instance", floor.SERVICE)
    theirs, their_attachment = requester.request(bytes(lean_requester.value))
    assert _without_time(theirs) == _without_time(ours)
    assert their_attachment == our_attachment == codec.attach_identifier(1)

    service = probe.Service(floor.SERVICE, "service-instance", str(tmp_path / "j.log"))
    answer = service.answer(theirs, floor.REQUESTER)
    assert _without_time(answer) == _without_time(
        floor._LeanService(None).answer(zenoh.ZBytes(theirs)))
    assert requester.is_final(answer) and lean_requester.final(answer)

    contents = read_log(tmp_path / "j.log")
    assert contents is not None
    kinds = [kind for kind, _ in contents.rows]
    assert kinds == [PROCESS, UPDATE, UPDATE]
    process, running, completed = (row for _, row in contents.rows)
    assert process[:9] == [floor.SERVICE, floor.REQUESTER, 1, "service-instance",
                           "requester-instance", "Echo", "", "SingleData", "Byte[4] [0, 1, 2, 3]"]
    assert process[11:] == ["Queued", ""]
    assert running[3] == 1 and running[5:] == ["Running", "", ""]
    assert completed[3] == 2 and completed[5:] == ["Completed", "", "Byte[4] [0, 1, 2, 3]"]


def test_the_native_core_runs_the_python_a_product_keeps(floor: Any, probe: ModuleType,
                                                        tmp_path: Path) -> None:
    """``native core``: admit, the device's handler in Python, complete — the answer
    carries the handler's output, journaled; the requester's Python hands the caller the
    final update and its data, and a refusal as an error."""
    requester = probe.Requester(floor.REQUESTER, "requester-instance", floor.SERVICE)
    request, attachment = requester.request(b"\x05\x06\x07")
    service = probe.Service(floor.SERVICE, "service-instance", str(tmp_path / "j.log"))
    admitted = service.admit(request, floor.REQUESTER)
    assert (admitted.identifier, admitted.input) == (1, b"\x05\x06\x07")
    device = floor._EchoDevice()
    output = device.run(admitted.input)
    assert output == b"\x05\x06\x07" and device.fed == []
    assert device.run(admitted.input, typed=False) == output and device.fed == []
    answer = service.complete(admitted, b"\x09" * 5)  # any output: the answer carries it
    update = codec.decode(answer).body.updates[0]
    assert (update.identifier, update.state.value, update.seq) == (1, "Completed", 2)
    assert bytes(update.data.buffer) == b"\x09" * 5 and update.data.size == (5,)
    contents = read_log(tmp_path / "j.log")
    assert contents is not None
    assert [row[-1] for _, row in contents.rows] == ["", "", "Byte[5] [9, 9, 9, 9, 9]"]
    assert contents.rows[0][1][8] == "Byte[3] [5, 6, 7]"  # the process row: its input

    calls = floor._Calls()

    async def route() -> Any:
        waiting = asyncio.get_running_loop().create_future()
        calls.expect(floor.SERVICE, int.from_bytes(attachment, "little"), waiting)
        # the input's first byte made 4 (the input ends the request; an earlier 5 in the
        # envelope, e.g. in its time stamp, stays as it is)
        at = request.rindex(b"\x05\x06\x07")
        changed = request[:at] + b"\x04" + request[at + 1:]
        calls.arrived(service.answer(changed, floor.REQUESTER))
        return await waiting

    final = asyncio.run(route())
    assert list(calls.read(final)) == [4, 6, 7] and calls.waiting == {}

    async def refused() -> None:
        waiting = asyncio.get_running_loop().create_future()
        calls.expect(floor.SERVICE, 7, waiting)
        batch = ProcessUpdateBatch(acks=[Acknowledgement(
            identifier=7, state=ProcessStates.Failed, reason="no such thing")])
        calls.arrived(codec.encode(floor.SERVICE, "service-instance", batch))
        await waiting

    with pytest.raises(RuntimeError, match="request refused: no such thing"):
        asyncio.run(refused())


def test_it_refuses_what_plugcell_refuses_with_the_same_reason(floor: Any,
                                                               probe: ModuleType) -> None:
    requester = probe.Requester(floor.REQUESTER, "requester-instance", floor.SERVICE)
    request, _ = requester.request(b"\x01\x02")
    envelope = codec.decode(request)
    service = probe.Service(floor.SERVICE, "service-instance")
    with pytest.raises(ValueError) as refused:
        service.answer(request, "SOMEONE")
    assert str(refused.value) == admission.check_envelope(envelope, "SOMEONE")

    elsewhere = probe.Service("ELSEWHERE", "service-instance")
    with pytest.raises(ValueError) as refused:
        elsewhere.answer(request, floor.REQUESTER)
    assert str(refused.value) == f"process addressed to {floor.SERVICE}, this is ELSEWHERE"

    other = probe.Requester(floor.REQUESTER, "requester-instance", floor.SERVICE)
    unknown = other.request(b"\x01")[0].replace(b"\xa4Echo", b"\xa4Ecco", 1)
    with pytest.raises(ValueError) as refused:
        service.answer(unknown, floor.REQUESTER)
    strange = codec.decode(unknown)
    assert str(refused.value) == admission.check_process(
        floor.SERVICE, floor._LeanService(None).device, strange, strange.body, set())
    with pytest.raises(ValueError, match="malformed message"):
        service.answer(b"", floor.REQUESTER)


def _plugcell_admits(floor: Any, payload: bytes) -> bool:
    """Whether plugcell's admission (decode, envelope, process and input checks) takes a
    request published by the benchmark's requester to its service."""
    decoded = admission.decode_request(zenoh.ZBytes(payload), codec.DEFAULT_MAX_PAYLOAD,
                                       floor.SERVICE)
    if isinstance(decoded, str):
        return False
    envelope, _ = decoded
    if admission.check_envelope(envelope, floor.REQUESTER) or envelope.auth is not None:
        return False
    service = floor._LeanService(None)
    if admission.check_process(floor.SERVICE, service.device, envelope, envelope.body, set()):
        return False
    return not admission.check_input(service.command, envelope.body)[1]


@settings(max_examples=400, deadline=None)
@given(st.data())
def test_it_admits_what_plugcell_admits(floor: Any, probe: ModuleType,
                                        data: st.DataObject) -> None:
    """Random bytes, and a valid request with bytes changed, cut or appended: the probe
    answers or refuses with a ValueError, never anything else; it answers exactly what
    plugcell's admission admits, with the same message (it skips no check plugcell
    makes, and adds none)."""
    request, _ = probe.Requester(floor.REQUESTER, "r", floor.SERVICE).request(b"\x07" * 4)
    payload = data.draw(st.one_of(
        st.binary(max_size=600),
        st.builds(lambda at, new: request[:at] + new + request[at + len(new):],
                  st.integers(0, len(request) - 1), st.binary(min_size=1, max_size=4)),
        st.builds(lambda at: request[:at], st.integers(0, len(request))),
        st.builds(lambda tail: request + tail, st.binary(min_size=1, max_size=8)),
    ))
    service = probe.Service(floor.SERVICE, "service-instance")
    try:
        answer = service.answer(payload, floor.REQUESTER)
    except ValueError:
        assert not _plugcell_admits(floor, payload), payload
        return
    assert _plugcell_admits(floor, payload), payload
    assert _without_time(answer) == _without_time(
        floor._LeanService(None).answer(zenoh.ZBytes(payload)))
