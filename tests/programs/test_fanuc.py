"""Fanuc TP .ls: byte-exact round trip, equality with ``plugcell compensate``, bad input."""

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
from plugcell.io.programs.core import Num, Program, SourceFile, Target
from plugcell.io.programs.fanuc import FanucConfig
from plugcell.io.programs.filter import filter_targets
from plugcell.io.units import pose_from_notation

FIX = FIXTURES / "deburr.ls"
UF = [1200, -150, 300, 0, 0, 90]
UT = [12.5, -3, 215, 0, -30, 0]
FRAMES = ["--base", "UFRAME[1]=" + ",".join(map(str, UF)),
          "--tool", "UTOOL[1]=" + ",".join(map(str, UT))]


def _frames():
    return ({"UFRAME[1]": pose_from_notation(np.array(UF, float), "fanuc")},
            {"UTOOL[1]": pose_from_notation(np.array(UT, float), "fanuc")})


def test_fixture_points_and_notes():
    prog, notes = read_program(FIX)
    t = {x.name: x for x in prog.targets}
    assert list(t) == ["P[1]", "P[2]", "P[3]", "P[4]", "P[5]", "P[6]"]
    assert (t["P[2]"].base, t["P[2]"].tool) == ("UFRAME[1]", "UTOOL[1]")
    assert t["P[6]"].kind == "joints" and all(x.used for x in t.values())
    assert [n.text for n in t["P[1]"].extra] == ["0", "0", "0"]
    assert any("PR[2]" in n for n in notes) and any("with an offset" in n for n in notes)


def test_nominal_round_trip_is_byte_identical(nominal_params, tmp_path):
    assert_nominal_round_trip(nominal_params, FIX, tmp_path / "o.ls", *FRAMES)


def test_equals_plugcell_compensate_and_keeps_columns(calibrated_result, params_file, tmp_path):
    prog, _ = read_program(FIX)
    b, t = _frames()
    fr = filter_targets(prog, model_for(calibrated_result), bases=b, tools=t, payload_kg=36.0)
    assert assert_equals_plugcell_compensate(prog, fr, calibrated_result, b, t) == 5
    out = tmp_path / "o.ls"
    assert main(["compensate", "--params", str(params_file), "--program", str(FIX), "--out",
                 str(out), "--payload-kg", "36", *FRAMES]) == 0
    got = {x.name: x.values for x in read_program(out)[0].targets}
    for r in fr.reports:
        if r.compensated:
            np.testing.assert_allclose(got[r.target.name], r.after, atol=5.01e-4)
    old, new = FIX.read_bytes().splitlines(), out.read_bytes().splitlines()
    assert len(old) == len(new)
    for a, c in zip(old, new, strict=True):  # every field stays in its column
        assert [m for m in range(len(a)) if a[m:m + 1] in (b"=", b"\t")] == \
            [m for m in range(len(c)) if c[m:m + 1] in (b"=", b"\t")]


def test_missing_frames_listed(params_file, tmp_path, capsys):
    out = tmp_path / "o.ls"
    assert main(["compensate", "--params", str(params_file), "--program", str(FIX),
                 "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "base 'UFRAME[1]'" in err and "tool 'UTOOL[1]'" in err and not out.exists()


@pytest.mark.parametrize(("old", "new", "message"), [
    ("W =    -2.102 deg", "W =    -2.102 mm", "W in mm, expected deg"),
    ("Z =  1174.804  mm,", "", "a partial position (no Z)"),
    ("UF : 1, UT : 1,\t\tCONFIG : 'N U T, 0, 0, 0',\r\n\tX =   875",
     "UF : F, UT : 1,\t\tCONFIG : 'N U T, 0, 0, 0',\r\n\tX =   875", "only a frame number"),
    ("CONFIG : 'N U T, 0, 0, 0',\r\n\tX =   875", "CONFIG : 'N U T, 0, x, 0',\r\n\tX =   875",
     "CONFIG turn must be an integer"),
    ("Y =  -603.699  mm,", "Y =  -603.699  mm, Q = 1,", "unknown text in the point"),
    ("   4:J P[1] 100%", "   4:J P[9] 100%", "P[9] is not in /POS"),
])
def test_unknown_syntax_is_named(tmp_path, old, new, message):
    assert_edit_refused(FIX, tmp_path / "d.ls", old, new, message)


def test_turns_follow_the_joints():
    turns = [Num(0, 1, "0", 0.0), Num(3, 4, "0", 0.0), Num(6, 8, "-1", -1.0)]
    c = FanucConfig(0, turns)
    q0 = np.radians([179.99, -40, -120, -180.01, 50, -180.02])
    q1 = np.radians([180.01, -40, -120, -179.99, 50, -180.03])
    assert c.edits(q0, q1) == {(0, 0): "1", (0, 3): "1"}


def test_a_longer_number_takes_the_padding():
    f = SourceFile(FIX, "\tX = 875.120  mm,")
    n = f.number(5, 12, pad=1)
    prog = Program("fanuc", [f], targets=[Target("P", 0, 0, "pose", [n], "fanuc")])
    assert prog.render({(0, 5): "-1875.120"}) == ["\tX = -1875.120  mm,"]
    n.pad = 3
    f2 = SourceFile(FIX, "\tX =   875.120  mm,")
    n2 = f2.number(7, 14, pad=3)
    prog2 = Program("fanuc", [f2], targets=[Target("P", 0, 0, "pose", [n2], "fanuc")])
    assert prog2.render({(0, 7): "-875.121"}) == ["\tX =  -875.121  mm,"]


@st.composite
def tp_programs(draw):
    n = draw(st.integers(1, 5))
    ks = np.array(draw(st.lists(st.integers(0, 39), min_size=n, max_size=n)))
    vals = poses_in("fanuc", [0, 0, 0, 0, 0, 0], [0, 0, 200, 0, 0, 0], ks)
    nl = draw(st.sampled_from(["\n", "\r\n"]))
    mn = ["/PROG  GEN", "/ATTR", "/MN"]
    pos = ["/POS"]
    for i, v in enumerate(vals, 1):
        mn.append(f"{i:4d}:{draw(st.sampled_from(['J', 'L']))} P[{i}] 100% FINE    ;")
        w = draw(st.sampled_from([9, 10, 12]))
        pos += [f"P[{i}]{{", "   GP1:", "\tUF : 0, UT : 2,\t\tCONFIG : 'N U T, 0, 0, 0',",
                "\t" + ",\t".join(f"{k} = {x:{w}.3f}  mm" for k, x in zip("XYZ", v[:3],
                                                                       strict=True)) + ",",
                "\t" + ",\t".join(f"{k} = {x:{w}.3f} deg" for k, x in zip("WPR", v[3:],
                                                                       strict=True)),
                "};"]
    return nl.join([*mn, *pos, "/END"]) + nl


@settings(max_examples=15, deadline=None, suppress_health_check=[
    HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(text=tp_programs())
def test_generated_programs_round_trip(nominal_result, tmp_path, text):
    tool = {"UTOOL[2]": pose_from_notation(np.array([0, 0, 200, 0, 0, 0.]), "fanuc")}
    assert_generated_round_trip(nominal_result, tmp_path, {"g.ls": text}, tools=tool)
