"""The raw floor's requester process (apps/bench/peer.py, ``raw-requester``): every line
it reads gets one answer line, a result or the reason it could not be one, and the
process keeps measuring after bad input."""

from __future__ import annotations

import json
import os
import uuid
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from plugcell.apps.bench.peer import REQUESTER_OPERATIONS, requester_answer
from plugcell.apps.bench.transport import Child, RawRequester


class _Floor:
    """Stands in for RawFloor: records each measurement asked of it."""

    def __init__(self) -> None:
        self.calls: list[tuple[str, tuple[int, ...]]] = []

    def latency(self, nbytes: int, cycles: int, warmup: int) -> dict[str, float]:
        self.calls.append(("latency", (nbytes, cycles, warmup)))
        return {"avg": 0.1}

    def latency_in_callback(self, nbytes: int, cycles: int, warmup: int) -> dict[str, float]:
        self.calls.append(("latency_in_callback", (nbytes, cycles, warmup)))
        raise RuntimeError("in-callback ping-pong: 3/10 echoes arrived")

    def latency_in_loop(self, nbytes: int, cycles: int, warmup: int) -> dict[str, float]:
        self.calls.append(("latency_in_loop", (nbytes, cycles, warmup)))
        return {"avg": 0.2}

    def throughput(self, nbytes: int, messages: int) -> float:
        self.calls.append(("throughput", (nbytes, messages)))
        return 1000.0


def _answer(line: str, floor: Any = None) -> dict[str, Any]:
    out = requester_answer(floor if floor is not None else _Floor(), line)
    assert "\n" not in out
    answer = json.loads(out)
    assert isinstance(answer, dict) and len(answer) == 1 and set(answer) <= {"result", "error"}
    return answer


@pytest.mark.parametrize(("line", "reason"), [
    ("not json", "JSONDecodeError"),
    ('{"op": "latency"}', "a command is [operation, *counts]"),
    ("[]", "a command is [operation, *counts]"),
    ('[4, 1, 1]', "a command is [operation, *counts]"),
    ('["latnecy", 4, 10, 1]', "unknown operation 'latnecy' (known: latency,"),
    ('["latency", -4, 10, 1]', "arguments must be counts, got [-4, 10, 1]"),
    ('["latency", true, 10, 1]', "arguments must be counts"),
    ('["latency", 4.0, 10, 1]', "arguments must be counts"),
    ('["latency", 4]', "TypeError"),
])
def test_a_bad_command_gets_the_reason_and_measures_nothing(line: str, reason: str) -> None:
    floor = _Floor()
    answer = _answer(line, floor)
    assert reason in answer["error"]
    assert floor.calls == []


def test_a_failed_measurement_gets_its_reason() -> None:
    floor = _Floor()
    answer = _answer('["latency_in_callback", 4, 10, 1]', floor)
    assert answer["error"] == "RuntimeError: in-callback ping-pong: 3/10 echoes arrived"
    assert floor.calls == [("latency_in_callback", (4, 10, 1))]


def test_a_command_gets_the_measurement() -> None:
    floor = _Floor()
    assert _answer('["latency", 4, 10, 2]\n', floor) == {"result": {"avg": 0.1}}
    assert _answer('["throughput", 4, 500]', floor) == {"result": 1000.0}
    assert floor.calls == [("latency", (4, 10, 2)), ("throughput", (4, 500))]


@settings(max_examples=300, deadline=None)
@given(st.one_of(
    st.text(max_size=60),
    st.lists(st.one_of(st.sampled_from(REQUESTER_OPERATIONS), st.integers(-3, 10**6),
                       st.booleans(), st.none(), st.floats(allow_nan=False), st.text(max_size=5)),
             max_size=5).map(json.dumps),
))
def test_any_line_gets_one_answer_line(line: str) -> None:
    floor = _Floor()
    answer = _answer(line, floor)
    assert len(floor.calls) <= 1  # a line measures at most once
    if "result" in answer:
        assert len(floor.calls) == 1


@pytest.mark.slow
def test_the_requester_process_keeps_measuring_after_bad_input(tmp_path: Path) -> None:
    cell = f"rawreq{uuid.uuid4().hex[:8]}"
    env = {**os.environ, "PLUGCELL_HOME": str(tmp_path), "PYTHONUNBUFFERED": "1"}
    peer = Child("raw", cell, env, False, [])
    requester = None
    try:
        requester = RawRequester(cell, env, [])
        assert requester.popen.stdin is not None and requester.popen.stdout is not None
        requester.popen.stdin.write("latency 4 10 1\n")
        requester.popen.stdin.flush()
        assert "JSONDecodeError" in json.loads(requester.popen.stdout.readline())["error"]
        requester.popen.stdin.write('["echo", 4]\n')
        requester.popen.stdin.flush()
        assert "unknown operation 'echo'" in json.loads(requester.popen.stdout.readline())["error"]
        with pytest.raises(RuntimeError, match=r"failed in latency: ValueError: arguments must"):
            requester.latency(-4, 20, 2)
        measured = requester.latency(4, 20, 2)  # still serving
        assert measured["min"] > 0 and measured["avg"] >= measured["min"]
    finally:
        if requester is not None:
            requester.close()
            assert requester.popen.returncode == 0  # ended when its input did
        peer.stop()
