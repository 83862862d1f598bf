"""G-code: byte-exact round trip, modal words, arcs, equality with ``plugcell compensate``."""

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
    model_for,
    poses_in,
)

from plugcell.apps.cli import main
from plugcell.io.programs import read_program
from plugcell.io.programs.filter import filter_targets
from plugcell.io.units import pose_from_notation

FIX = FIXTURES / "pocket.nc"
FRAMES = ["--base", "G54=1200,-150,300,90,0,0", "--tool", "T1=0,0,215,0,0,0"]


def _frames():
    return ({"G54": pose_from_notation(np.array([1200, -150, 300, 90, 0, 0.]), "kuka")},
            {"T1": pose_from_notation(np.array([0, 0, 215, 0, 0, 0.]), "kuka")})


def _modal(prog):
    """Every motion line's full pose as the controller holds it (modal values)."""
    return {t.name: t.values for t in prog.targets}


def test_fixture_lines_are_modal_targets():
    prog, notes = read_program(FIX)
    t = {x.name: x for x in prog.targets}
    assert list(t) == ["line 6", "line 7", "line 8", "line 9", "line 10", "line 11"]
    np.testing.assert_allclose(t["line 7"].values, [35.55, -311.089, 863.594, -122.453,
                                                    72.112, -29.938])
    assert [n.virtual for n in t["line 8"].nums] == [False, True, True, True, True, True]
    assert (t["line 8"].base, t["line 8"].tool) == ("G54", "T1")
    assert any("X, Y not known yet" in n for n in notes)


def test_nominal_round_trip_is_byte_identical(nominal_params, tmp_path):
    out = tmp_path / "o.nc"
    assert main(["compensate", "--params", str(nominal_params), "--program", str(FIX),
                 "--out", str(out), *FRAMES]) == 0
    assert out.read_bytes() == FIX.read_bytes()


def test_equals_plugcell_compensate_and_the_written_modal_poses(calibrated_result,
                                                                  params_file, tmp_path):
    prog, _ = read_program(FIX)
    b, t = _frames()
    fr = filter_targets(prog, model_for(calibrated_result), bases=b, tools=t, payload_kg=36.0)
    assert assert_equals_plugcell_compensate(prog, fr, calibrated_result, b, t) == 6
    out = tmp_path / "o.nc"
    assert main(["compensate", "--params", str(params_file), "--program", str(FIX), "--out",
                 str(out), "--payload-kg", "36", *FRAMES]) == 0
    got = _modal(read_program(out)[0])     # what the controller will hold on each line
    for r in fr.reports:
        np.testing.assert_allclose(got[r.target.name], r.after, atol=5.01e-4)
    # every other byte: the comments, N words, feeds, M codes
    text = out.read_text()
    for keep in ("(POCKET - written by hand", "; along Y", "N100 M30", "F500", "%\n"):
        assert keep in text


def test_arc_centre_follows_the_corrections_on_one_circle(calibrated_result):
    prog, _ = read_program(FIX)
    b, t = _frames()
    fr = filter_targets(prog, model_for(calibrated_result), bases=b, tools=t, payload_kg=36.0)
    rep = {r.target.name: r for r in fr.reports}
    start, end = rep["line 9"], rep["line 10"]
    nums = {n.text: n for n in end.target.extra}
    ijk = np.array([float(fr.edits.get((0, nums[x].start), x)) for x in ("-50.0", "0.0")])
    centre = start.after[:2] + ijk
    r0 = np.linalg.norm(start.after[:2] - centre)
    r1 = np.linalg.norm(end.after[:2] - centre)
    assert abs(r0 - r1) < 2e-3          # both ends on one circle (IJK rounded to 0.001)
    mean = ((start.after - start.before) + (end.after - end.before))[:2] / 2
    nominal_centre = start.before[:2] + np.array([-50.0, 0.0])
    assert np.linalg.norm(centre - nominal_centre - mean) < 0.2  # near the mean correction
    assert abs(r0 - 50.0) < 0.5


@pytest.mark.parametrize(("old", "new", "message"), [
    ("N10 G21 G90", "N10 G20 G90", "G20: inches are not supported"),
    ("N10 G21 G90", "N10 G21 G91", "G91: incremental coordinates"),
    ("I-50.0 J0.0", "R50.0", "an arc by radius (R) is not supported"),
    ("N60 X85.550", "N60 G81 X85.550 Z800 R900", "canned cycles are not supported"),
    ("N70 Y-261.089", "N70 Y-261.089 X=3", "expected a word"),
])
def test_refused_constructs_are_named(tmp_path, old, new, message):
    assert_edit_refused(FIX, tmp_path / "p.nc", old, new, message)


def test_work_offset_and_tool_are_asked_for(params_file, tmp_path, capsys):
    assert main(["compensate", "--params", str(params_file), "--program", str(FIX),
                 "--out", str(tmp_path / "o.nc")]) == 2
    err = capsys.readouterr().err
    assert "base 'G54' (--base 'G54=…')" in err and "tool 'T1' (--tool 'T1=…')" in err


@st.composite
def gcode_programs(draw):
    n = draw(st.integers(2, 6))
    ks = np.array(draw(st.lists(st.integers(0, 39), min_size=n, max_size=n)))
    vals = poses_in("kuka", [0, 0, 0, 0, 0, 0], [0, 0, 200, 0, 0, 0], ks)
    nl = draw(st.sampled_from(["\n", "\r\n"]))
    lines = ["%", "(generated)", "G21 G90 G54", "T2 M6"]
    for i, v in enumerate(vals):
        d = draw(st.sampled_from([3, 4]))
        words = [f"{k}{x:.{d}f}" for k, x in zip("XYZABC", v, strict=True)]
        lines.append(f"N{10 * (i + 1)} G{draw(st.sampled_from([0, 1]))} " + " ".join(words)
                     + draw(st.sampled_from(["", " F1000", " ; cut"])))
    lines += ["M30", "%"]
    return nl.join(lines) + nl


@settings(max_examples=15, deadline=None, suppress_health_check=[
    HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(text=gcode_programs())
def test_generated_programs_round_trip(nominal_result, tmp_path, text):
    tools = {"T2": pose_from_notation(np.array([0, 0, 200, 0, 0, 0.]), "kuka")}
    assert_generated_round_trip(nominal_result, tmp_path, {"g.nc": text},
                                bases={"G54": np.eye(4)}, tools=tools)
