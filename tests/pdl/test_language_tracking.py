"""``MOVE LINEAR TO p WITH TRACKING [service]`` (issue 38): parsed, checked, printed, run.

A tracked move goes to the arm's ``move_tracked(pose, tracker)``; an arm without it (a
controller that runs its moves by itself) fails the move with the reason.
"""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st
from language_fakes import FakeArm, run_source

from plugcell.pdl import MotionFailedError, Position, Program, TrackedMotion, TypeMismatchError
from plugcell.pdl import nodes as n

PROGRAM = """PROGRAM tracked
VAR p, q : POSITION
BEGIN
  p := POS(1400, -200, 1800, 0, 90, 0)
  q := POS(1400, 200, 1800, 0, 90, 0)
  MOVE TO p
  MOVE LINEAR TO q WITH TRACKING
  move linear to p with tracking tracker_b
  MOVE LINEAR TO q
END tracked
"""


class TrackedArm(FakeArm):
    """The fake arm with the tracked move of a streaming link."""

    def move_tracked(self, pose: Position, tracker: str) -> float:
        self.q = list(self.pos_to_jntp(pose).joints)
        self.log.append(("tracked", (pose, tracker)))
        return self.move_s


def _moves(program: Program) -> list[n.Move]:
    return [s for s in program.module.body if isinstance(s, n.Move)]


def test_the_clause_names_the_tracker_service_default_tracker():
    moves = _moves(Program.from_source(PROGRAM, "t.pdl"))
    assert [(m.kind, m.tracking) for m in moves] == [
        ("TO", None), ("LINEAR", "TRACKER"), ("LINEAR", "TRACKER_B"), ("LINEAR", None)]


def test_the_printer_writes_the_clause_back():
    program = Program.from_source(PROGRAM, "t.pdl")
    text = program.source()
    assert "MOVE LINEAR TO q WITH TRACKING TRACKER\n" in text
    assert "MOVE LINEAR TO p WITH TRACKING TRACKER_B\n" in text
    again = Program.from_source(text, "t2.pdl")
    assert [m.tracking for m in _moves(again)] == [m.tracking for m in _moves(program)]


@pytest.mark.parametrize("move", ["MOVE TO q WITH TRACKING", "MOVE JOINT TO q WITH TRACKING X"])
def test_only_a_linear_move_can_be_tracked(move):
    text = PROGRAM.replace("MOVE LINEAR TO q WITH TRACKING", move)
    with pytest.raises(TypeMismatchError, match="WITH TRACKING: only a MOVE LINEAR has a path "
                       "for the tracker to correct") as info:
        Program.from_source(text, "t.pdl")
    assert "t.pdl:7" in str(info.value)


def test_a_tracked_move_runs_on_an_arm_that_can_track():
    arm = TrackedArm()
    assert isinstance(arm, TrackedMotion) and not isinstance(FakeArm(), TrackedMotion)
    result, _, arm, _ = run_source(PROGRAM, arm=arm)
    assert result.ok, result.error
    assert [kind for kind, _ in arm.log] == ["to", "tracked", "tracked", "linear"]
    assert arm.log[1][1] == (Position(1400, 200, 1800, 0, 90, 0), "TRACKER")
    assert arm.log[2][1][1] == "TRACKER_B"


def test_an_arm_that_runs_its_moves_itself_refuses_the_tracked_move():
    result, _, arm, _ = run_source(PROGRAM)
    assert not result.ok
    assert isinstance(result.error, MotionFailedError)
    message = str(result.error)
    assert "test.pdl:7" in message
    assert "MOVE LINEAR TO q WITH TRACKING TRACKER: tracking needs a streaming link " \
        "(--rsi/--egm)" in message
    assert [kind for kind, _ in arm.log] == ["to"]  # nothing moved after it


@given(st.from_regex(r"[A-Za-z_][A-Za-z0-9_]{0,12}", fullmatch=True))
def test_any_service_name_parses_and_prints_back(name):
    keywords = {"TO", "END", "WITH", "TRACKING", "IF", "FOR", "DO", "OF", "OR", "AND", "NOT",
                "MOD", "DIV", "XOR", "IN", "BEGIN", "VAR", "CONST", "TRUE", "FALSE", "STEP",
                "THEN", "ELSE", "ENDIF", "ENDFOR", "WHILE", "ENDWHILE", "REPEAT", "UNTIL",
                "SELECT", "CASE", "ENDSELECT", "RETURN", "DELAY", "WAIT", "WRITE", "MOVE",
                "LINEAR", "JOINT", "RELATIVE", "ROUTINE", "PROGRAM", "IMPORT", "EXPORTED",
                "FROM", "INTEGER", "REAL", "BOOLEAN", "STRING", "POSITION", "JOINTPOS",
                "VECTOR", "ARRAY", "DOWNTO", "TIMEOUT", "DEACTIVATE"}
    if name.upper() in keywords:
        return
    text = PROGRAM.replace("WITH TRACKING\n", f"WITH TRACKING {name}\n")
    program = Program.from_source(text, "t.pdl")
    assert _moves(program)[1].tracking == name.upper()
    printed = program.source()
    assert _moves(Program.from_source(printed, "t.pdl"))[1].tracking == name.upper()
