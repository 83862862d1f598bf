"""The thesis's EXAMPLE program (4.1.3.2) runs against a fake robot service."""

from __future__ import annotations

import threading
import time

import pytest
from language_fakes import FakeArm, FakeChannel, execution

from plugcell.pdl import (
    BUILTIN_LIBRARY,
    Execution,
    ExecutionState,
    Position,
    Program,
    SimClock,
)

EXAMPLE = BUILTIN_LIBRARY / "example.pdl"
LINES = EXAMPLE.read_text().splitlines()


def line_of(text: str, nth: int = 1) -> int:
    """1-based line of the ``nth`` line of example.pdl that starts with ``text``."""
    hits = [i for i, line in enumerate(LINES, start=1) if line.strip().startswith(text)]
    return hits[nth - 1]


TAUGHT = {"pnt0001": Position(800, 0, 600, 0, 90, 0), "pnt0002": [900, 100, 550, 0, 90, 0]}


@pytest.fixture(scope="module")
def program() -> Program:
    return Program.load(EXAMPLE)


def test_example_writes_the_thesis_activate_strings(program):
    ex, arm, channel = execution(program, values=TAUGHT)
    result = ex.run()
    assert result.state is ExecutionState.FINISHED and result.error is None
    assert not result.deactivated
    assert channel.lines == [
        "ACTIVATE CAMERA #SnapShot##500",
        "ACTIVATE TOOL #Drill#Air#550,1100",
    ]
    assert [kind for kind, _ in arm.log] == ["to", "to"]
    assert arm.log[0][1] == TAUGHT["pnt0001"]
    assert arm.log[1][1] == Position(900, 100, 550, 0, 90, 0)
    assert result.sim_time == pytest.approx(2 * arm.move_s)  # two moves, answers at once


def test_example_deactivates_when_the_camera_fails(program):
    ex, arm, channel = execution(program, lambda line: (False, None, "no camera"), values=TAUGHT)
    result = ex.run()
    assert result.ok and result.deactivated
    assert channel.lines == ["ACTIVATE CAMERA #SnapShot##500"]
    assert len(arm.log) == 1  # never went to pnt0002
    assert result.location is not None and result.location.line == line_of("DEACTIVATE")


def test_example_waits_for_a_service_answering_from_another_thread(program):
    ex, _, channel = execution(program, speed=1000.0, delay_s=0.05, values=TAUGHT)
    result = ex.run()
    assert result.ok, result.error
    assert channel.lines[-1] == "ACTIVATE TOOL #Drill#Air#550,1100"
    # 2 moves of 2 s, plus the simulated time that passed while the services worked
    assert result.sim_time >= 4.0 + 2 * 0.05 * 1000 * 0.5
    assert result.real_time < 2.0


def test_example_is_not_changed_by_running_it(program):
    before = program.source()
    for _ in range(2):
        ex, _, _ = execution(program, values=TAUGHT)
        assert ex.run().ok
    assert program.source() == before


def test_uninitialized_taught_point_is_a_line_numbered_error(program):
    ex, _, _ = execution(program)
    result = ex.run()
    assert result.state is ExecutionState.FAILED
    assert result.error is not None
    line = line_of("MOVE TO pnt0001")
    assert result.error.line == line and "pnt0001 is uninitialized" in str(result.error)
    assert str(result.error).startswith(f"{EXAMPLE}:{line}:")


def test_stop_ends_a_program_waiting_for_a_service(program):
    channel = FakeChannel(lambda line: None)  # the service never answers
    ex = Execution(
        program,
        motion=FakeArm(),
        channel=channel,
        clock=SimClock(speed=100.0),
        values=TAUGHT,
    )
    thread = ex.start()
    wait_line = line_of("WAIT FOR ext_cmd_finished")
    deadline = time.monotonic() + 5
    while time.monotonic() < deadline and (ex.location is None or ex.location.line != wait_line):
        time.sleep(0.005)
    assert channel.lines == ["ACTIVATE CAMERA #SnapShot##500"]
    assert ex.location is not None and ex.location.line == wait_line
    assert [name for name, _ in ex.call_stack] == ["EXAMPLE", "SNAPSHOT"]
    ex.stop("connection dropped")
    result = ex.join(timeout=5)
    thread.join(timeout=5)
    assert result is not None and result.state is ExecutionState.STOPPED
    assert ex.state is ExecutionState.STOPPED


def test_stop_interrupts_a_long_move(program):
    ex = Execution(
        program,
        motion=FakeArm(move_s=3600.0),
        channel=FakeChannel(),
        clock=SimClock(speed=1.0),
        values=TAUGHT,
    )
    ex.start()
    time.sleep(0.05)
    t0 = time.monotonic()
    ex.stop()
    result = ex.join(timeout=5)
    assert result is not None and result.state is ExecutionState.STOPPED
    assert time.monotonic() - t0 < 1.0
    assert 0 < result.sim_time < 10


def test_an_execution_runs_once(program):
    ex, _, _ = execution(program, values=TAUGHT)
    ex.run()
    with pytest.raises(RuntimeError, match="runs once"):
        ex.run()


def test_posted_batches_are_applied_atomically_between_statements():
    """Threads posting {a: k, b: k} while the program compares a and b: never torn."""
    src = """PROGRAM atomic
VAR a, b, torn, loops : INTEGER
BEGIN
  a := 0
  b := 0
  torn := 0
  loops := 0
  WHILE NOT ext_cmd_finished DO
    IF a <> b THEN
      torn := torn + 1
    ENDIF
    loops := loops + 1
  ENDWHILE
END atomic
"""
    prog = Program.from_source(src)
    ex = Execution(prog, clock=SimClock(speed=1e6), statement_budget=5_000_000)
    ex.start()

    def poster(offset: int) -> None:
        for k in range(300):
            ex.post({"a": offset + k, "b": offset + k})

    posters = [threading.Thread(target=poster, args=(1000 * i,)) for i in range(4)]
    for p in posters:
        p.start()
    for p in posters:
        p.join(timeout=10)
    ex.post({"ext_cmd_finished": True})
    result = ex.join(timeout=10)
    assert result is not None and result.ok, result and result.error
    assert ex.get_variable("torn") == 0
    assert ex.get_variable("loops") > 0
    assert ex.get_variable("a") == ex.get_variable("b")
