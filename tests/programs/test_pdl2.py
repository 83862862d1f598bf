"""Comau PDL2: byte-exact round trip, equality with ``plugcell compensate``, bad input."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from programlib import (
    FIXTURES,
    assert_edit_refused,
    assert_equals_plugcell_compensate,
    assert_generated_round_trip,
    assert_nominal_round_trip,
    model_for,
    poses_in,
)

from plugcell.apps.cli import main
from plugcell.io.programs import read_program
from plugcell.io.programs.filter import filter_targets

FIX = FIXTURES / "glue.pdl"


def test_fixture_targets():
    prog, notes = read_program(FIX)
    t = {x.name: x for x in prog.targets}
    assert list(t) == ["pnt0001P", "pnt0002P", "path[1]", "path[2]", "jnt0001J", "MOVE line 20"]
    assert t["pnt0002P"].base == "$BASE (line 9)⁻¹ · $UFRAME (line 8)"
    assert t["pnt0002P"].tool == "$TOOL (line 7)" and t["jnt0001J"].kind == "joints"
    assert any("MOVE RELATIVE" in n for n in notes)


def test_nominal_round_trip_is_byte_identical(nominal_params, tmp_path):
    assert_nominal_round_trip(nominal_params, FIX, tmp_path / "o.pdl")


def test_equals_plugcell_compensate(calibrated_result, params_file, tmp_path):
    prog, _ = read_program(FIX)
    fr = filter_targets(prog, model_for(calibrated_result), payload_kg=36.0)
    b = {n: np.linalg.inv(prog.frames["$BASE (line 9)"]) @ prog.frames["$UFRAME (line 8)"]
         for n in prog.composites}
    assert assert_equals_plugcell_compensate(prog, fr, calibrated_result, b) == 5
    out = tmp_path / "o.pdl"
    assert main(["compensate", "--params", str(params_file), "--program", str(FIX), "--out",
                 str(out), "--payload-kg", "36"]) == 0
    got = {x.name: x.values for x in read_program(out)[0].targets}
    for r in fr.reports:
        if r.compensated:
            np.testing.assert_allclose(got[r.target.name], r.after, atol=5.01e-4)


def test_frames_not_set_are_asked_for(params_file, tmp_path, capsys):
    src = tmp_path / "g.pdl"
    text = FIX.read_text()
    for line in ("  $UFRAME := POS(1200, -150, 300, 90, 0, 0, '')\n",
                 "  $BASE := POS(0, 0, 0, 0, 0, 0, '')\n"):
        text = text.replace(line, "")
    src.write_text(text)
    argv = ["compensate", "--params", str(params_file), "--program", str(src), "--out",
            str(tmp_path / "o.pdl")]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "base '$BASE' (--base '$BASE=…')" in err and "base '$UFRAME'" in err
    assert main([*argv, "--base", "$BASE=0,0,0,0,0,0",
                 "--base", "$UFRAME=1200,-150,300,90,0,0"]) == 0


@pytest.mark.parametrize(("old", "new", "message"), [
    ("POS(875.120, -603.699, 1174.804,", "POS(875.120 + 1, -603.699, 1174.804,",
     "expected ',' or ')'"),
    ("-107.321, 59.663, -1.231, '')", "-107.321, 59.663, '')", "POS needs x, y, z, a, b, c"),
    ("  MOVE TO pnt0001P\n", "  pnt0001P.X := 3\n", "a component of a target changed"),
    ("  MOVE TO pnt0001P\n", "  MOVE TO pnt0001P\n  pnt0001P := POS(1,2,3,4,5,6,'')\n",
     "assigned a position twice"),
    ("MOVE LINEAR TO POS(30.531", "MOVE LINEAR TO POS(x0", "a number expected, got 'x0'"),
    ("  MOVE LINEAR TO pnt0002P ADVANCE\n", "  MOVE LINEAR TO pnt0002P ADVANCE\n"
     "  $TOOL := POS(0, 0, 100, 0, 0, 0, '')\n  MOVE TO pnt0001P\n",
     "pnt0001P is used with $BASE (line 9)⁻¹ · $UFRAME (line 8) and $TOOL (line 19) here, "
     "with $BASE (line 9)⁻¹ · $UFRAME (line 8) and $TOOL (line 7) before: one set of numbers "
     "cannot be compensated for both"),
])
def test_unknown_syntax_is_named(tmp_path, old, new, message):
    assert_edit_refused(FIX, tmp_path / "g.pdl", old, new, message)


@st.composite
def pdl_programs(draw):
    n = draw(st.integers(1, 5))
    ks = np.array(draw(st.lists(st.integers(0, 39), min_size=n, max_size=n)))
    vals = poses_in("comau", [0, 0, 0, 0, 0, 0], [0, 0, 200, 0, 0, 0], ks)
    nl = draw(st.sampled_from(["\n", "\r\n"]))
    body = ["PROGRAM gen", "VAR p1, p2, p3, p4, p5 : POSITION", "BEGIN",
            "  $TOOL := POS(0, 0, 200, 0, 0, 0, '')  -- tool", "  $UFRAME := POS(0,0,0,0,0,0,'')",
            "  $BASE := POS(0, 0, 0, 0, 0, 0, '')"]
    for i, v in enumerate(vals, 1):
        d = draw(st.sampled_from([3, 4, 6]))
        lit = "POS(" + ", ".join(f"{x:.{d}f}" for x in v) + ", '')"
        if draw(st.booleans()):
            body.insert(6, f"  p{i} := {lit}")
            body.append(f"  MOVE {draw(st.sampled_from(['', 'LINEAR ', 'JOINT ']))}TO p{i}")
        else:
            body.append(f"  MOVE LINEAR TO {lit}")
    body.append("END gen")
    return nl.join(body) + nl


@settings(max_examples=15, deadline=None, suppress_health_check=[
    HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(text=pdl_programs())
def test_generated_programs_round_trip(nominal_result, tmp_path, text):
    assert_generated_round_trip(nominal_result, tmp_path, {"g.pdl": text})
