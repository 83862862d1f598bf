"""The controller line protocol v1 (docs/controller-protocol.md): messages, text, framing."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from plugcell.devices.robot.activate import ActivateString
from plugcell.devices.robot.framing import FramingError, LineBuffer, frame_line
from plugcell.devices.robot.protocol import (
    PROGRAM_STATES,
    ActivateLine,
    ArmJntp,
    ArmPos,
    Console,
    Hello,
    JntpToPos,
    Move,
    Ping,
    PosToJntp,
    ProgramEnded,
    ProgramStarted,
    ProtocolError,
    Reply,
    Result,
    ResultData,
    Run,
    Status,
    Stop,
    StreamEnd,
    Value,
    decode,
    encode,
    escape,
    unescape,
)

ids = st.integers(1, 2**31 - 1)
runs = st.integers(0, 10**6)
free = st.text(st.characters(blacklist_categories=("Cs",)), max_size=60)
finite = st.floats(allow_nan=False, allow_infinity=False)
words = st.text(st.sampled_from("abcXYZ019_."), min_size=1, max_size=12)
names = st.from_regex(r"[A-Za-z_][A-Za-z0-9_]{0,20}", fullmatch=True)

from_controller = st.one_of(
    st.builds(Hello, st.integers(0, 9999), st.dictionaries(words, words | st.just(""))),
    st.builds(ActivateLine, st.builds(ActivateString, st.just("CAMERA"), st.just("SnapShot"),
                                      st.just(""), st.sampled_from(["", "500", "1,2"]))),
    st.builds(ProgramStarted, runs, names),
    st.builds(ProgramEnded, runs, names, st.sampled_from(PROGRAM_STATES), finite, finite, free),
    st.builds(Console, runs, free),
    st.builds(Reply, ids, st.just(True), free),
    st.builds(Reply, ids, st.just(False), free.filter(bool)),
)
from_service = st.one_of(
    st.builds(Result, st.booleans(), free),
    st.builds(StreamEnd, st.booleans(), free),
    st.builds(ResultData, text=free, frame=st.booleans()),
    st.integers(0, 4).flatmap(lambda r: st.integers(0, 4).flatmap(
        lambda c: st.builds(ResultData, st.just(r), st.just(c),
                            st.lists(finite, min_size=r * c, max_size=r * c).map(tuple),
                            frame=st.booleans()))),
    st.builds(Ping, ids), st.builds(Status, ids), st.builds(ArmPos, ids), st.builds(ArmJntp, ids),
    st.builds(Value, ids, names, free),
    st.builds(Run, ids, free.filter(bool)),
    st.builds(Stop, ids, free),
    st.builds(PosToJntp, ids, st.lists(finite, min_size=6, max_size=6).map(tuple)),
    st.builds(JntpToPos, ids, st.lists(finite, min_size=1, max_size=10).map(tuple)),
    st.builds(Move, ids, st.just("TO"), st.lists(finite, min_size=6, max_size=6).map(tuple)),
    st.builds(Move, ids, st.just("JOINT"), st.lists(finite, min_size=1, max_size=10).map(tuple)),
)


@settings(max_examples=800)
@given(from_controller)
def test_controller_messages_round_trip(message) -> None:
    line = encode(message)
    assert "\n" not in line and "\r" not in line
    assert decode(line, "controller") == message


@settings(max_examples=800)
@given(from_service)
def test_service_messages_round_trip(message) -> None:
    line = encode(message)
    assert "\n" not in line and "\r" not in line
    back = decode(line, "service")
    assert back == message
    for a, b in zip(getattr(back, "values", ()), getattr(message, "values", ()), strict=True):
        assert math.copysign(1, a) == math.copysign(1, b)  # -0.0 survives too


@settings(max_examples=2000)
@given(st.text(max_size=100), st.sampled_from(["controller", "service"]))
def test_any_line_decodes_or_is_refused_precisely(line: str, sender: str) -> None:
    try:
        decode(line, sender)  # type: ignore[arg-type]
    except ProtocolError as exc:
        assert str(exc)


@settings(max_examples=600)
@given(st.sampled_from(["RESULT", "DATA", "FRAME", "TEXT", "RUN", "VALUE", "STOP", "MOVE",
                        "POS_TO_JNTP", "JNTP_TO_POS", "ARM_POS", "OK", "ERR", "EVENT", "HELLO"]),
       st.text(st.sampled_from(" 0123456789.,-eE+TRUEFALSJOINTOSDEND\\xn"), max_size=40))
def test_near_miss_lines_never_crash(verb: str, rest: str) -> None:
    for sender in ("controller", "service"):
        try:
            decode(f"{verb} {rest}", sender)  # type: ignore[arg-type]
        except ProtocolError as exc:
            assert str(exc)


@given(free)
def test_escape_round_trip(text: str) -> None:
    escaped = escape(text)
    assert all(ord(c) >= 0x20 and ord(c) != 0x7F for c in escaped)
    assert unescape(escaped) == text


@pytest.mark.parametrize(
    ("line", "sender", "reason"),
    [
        ("RESULT MAYBE", "service", "expected TRUE or FALSE, found 'MAYBE'"),
        ("DATA 1 2 1", "service", "DATA 1 2: expected 2 numbers, got 1"),
        ("DATA 1 1 nan", "service", "'nan' is not a number"),
        ("DATA 1 1 1_000", "service", "'1_000' is not a number"),
        ("RUN 0 example", "service", "bad request id '0'"),
        ("RUN 7", "service", "RUN needs a program name or path"),
        ("ARM_POS 3 now", "service", "ARM_POS takes no arguments, found 'now'"),
        ("MOVE 4 SIDEWAYS 1", "service", "expected MOVE <id> JOINT|TO <values>, found 'SIDEWAYS'"),
        ("POS_TO_JNTP 5 1,2,3", "service", "POS_TO_JNTP: expected 6 numbers, got 3"),
        ("VALUE 6 9lives 1", "service", "bad variable name '9lives'"),
        ("TEXT a\\qb", "service", "bad escape '\\\\q' at column 2"),
        ("HELLO", "service", "HELLO is not a message the service sends"),
        ("EVENT STARTED 1 EXAMPLE", "service", "EVENT is not a message the service sends"),
        ("FOO 1", "service", "unknown message 'FOO'"),
        ("", "service", "empty line"),
        ("ERR 3", "controller", "ERR 3 without a reason"),
        ("OK x", "controller", "bad request id 'x'"),
        ("HELLO other 1", "controller", "expected HELLO plugcell-controller <version>"),
        ("HELLO plugcell-controller 1 robot", "controller", "expected key=value, found 'robot'"),
        ("EVENT ENDED 1 EXAMPLE LOST 1 2", "controller", "bad program state 'LOST'"),
        ("EVENT BEGAN 1 X", "controller", "unknown event 'BEGAN'"),
        ("ACTIVATE CAMERA SnapShot", "controller", "bad ACTIVATE string: expected '#'"),
        ("RESULT TRUE", "controller", "RESULT is not a message the controller sends"),
    ],
)
def test_precise_protocol_errors(line: str, sender: str, reason: str) -> None:
    with pytest.raises(ProtocolError) as info:
        decode(line, sender)  # type: ignore[arg-type]
    assert str(info.value).startswith(reason)


def test_the_example_exchange_as_documented() -> None:
    """The sequence of docs/controller-protocol.md §6, line by line."""
    assert decode("HELLO plugcell-controller 1 robot=smart_h4 axes=6 data=4096 text=255",
                  "controller") == Hello(1, {"robot": "smart_h4", "axes": "6", "data": "4096",
                                             "text": "255"})
    assert encode(Value(7, "pnt0001", "1500,0,1300,0,90,0")) == "VALUE 7 pnt0001 1500,0,1300,0,90,0"
    assert encode(Run(7, "example")) == "RUN 7 example"
    assert decode("ACTIVATE CAMERA #SnapShot##500", "controller") == ActivateLine(
        ActivateString("CAMERA", "SnapShot", "", "500"))
    assert encode(ResultData(1, 3, (1.5, -2.0, 10.0))) == "DATA 1 3 1.5,-2.0,10.0"
    assert encode(Result(True)) == "RESULT TRUE"
    assert encode(Result(False, "TOOL Drill: feed 5 mm/min outside 10…2000")) == \
        "RESULT FALSE TOOL Drill: feed 5 mm/min outside 10…2000"
    assert decode("EVENT ENDED 7 EXAMPLE FINISHED 7.914 0.05", "controller") == ProgramEnded(
        7, "EXAMPLE", "FINISHED", 7.914, 0.05, "")
    assert encode(Console(3, "two\nlines")) == "EVENT CONSOLE 3 two\\nlines"


# ----------------------------------------------------------------------------- framing
def test_lines_are_cut_from_any_chunks() -> None:
    buffer = LineBuffer()
    stream = "RESULT TRUE\r\nTEXT é\n\nDATA 1 1 2\n".encode()
    out = [item for b in stream for item in buffer.feed(bytes([b]))]
    assert out == ["RESULT TRUE", "TEXT é", "DATA 1 1 2"]
    assert buffer.pending == 0


def test_a_line_too_long_is_reported_once_and_skipped() -> None:
    buffer = LineBuffer(max_bytes=16)
    out = buffer.feed(b"x" * 40) + buffer.feed(b"y" * 40 + b"\nRESULT TRUE\n")
    assert out == [FramingError("line longer than 16 bytes"), "RESULT TRUE"]
    assert buffer.feed(b"z" * 17 + b"\n") == [FramingError("line longer than 16 bytes")]


def test_bad_utf8_is_reported_and_the_stream_goes_on() -> None:
    out = LineBuffer().feed(b"TEXT \xff\xfe\nRESULT FALSE\n")
    assert out == [FramingError("line is not valid UTF-8 (byte 6)"), "RESULT FALSE"]


def test_frame_line_refuses_line_breaks() -> None:
    assert frame_line("RESULT TRUE") == b"RESULT TRUE\n"
    with pytest.raises(ValueError, match="line break"):
        frame_line("RESULT TRUE\nRESULT FALSE")
