"""KUKA KRL: byte-exact round trip, equality with ``plugcell compensate``, bad input."""

from __future__ import annotations

import shutil

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from programlib import FIXTURES, assert_generated_round_trip, model_for, poses_in

from plugcell.apps.cli import main
from plugcell.compensation import IdentifiedModel, filter_program
from plugcell.io.programs import ProgramError, read_program
from plugcell.io.programs.core import NumberStyle
from plugcell.io.programs.filter import MissingFramesError, filter_targets
from plugcell.io.units import pose_from_notation

BASE = "1200,-150,300,90,0,0"
TOOL = "12.5,-3,215,0,-30,0"
FRAMES = ["--base", f"BASE_DATA[1]={BASE}", "--tool", f"TOOL_DATA[1]={TOOL}"]


def _frames():
    return ({"BASE_DATA[1]": pose_from_notation(np.array([1200, -150, 300, 90, 0, 0.]), "kuka")},
            {"TOOL_DATA[1]": pose_from_notation(np.array([12.5, -3, 215, 0, -30, 0.]), "kuka")})


def _copy(tmp_path):
    for f in ("drill_plate.src", "drill_plate.dat"):
        shutil.copy(FIXTURES / f, tmp_path / f)
    return tmp_path / "drill_plate.src"


def test_fixture_targets_frames_and_notes():
    prog, notes = read_program(FIXTURES / "drill_plate.src")
    names = [t.name for t in prog.targets]
    assert names == ["LIN line 44", "PTP line 45", "PTP line 46", "XP1", "XP2", "XP3", "XP4",
                     "XP5", "XUNUSED"]
    by = {t.name: t for t in prog.targets}
    assert by["XP1"].base == "BASE_DATA[1]" and by["XP1"].tool == "TOOL_DATA[1]"
    assert by["LIN line 44"].base == "$BASE (line 42)"
    assert by["PTP line 46"].kind == "joints" and not by["XUNUSED"].used
    assert [n.text for n in by["PTP line 45"].extra] == ["'B010'", "'B000110'"]
    assert any("XHOME is not declared" in n for n in notes)
    assert prog.files[0].text.count("\r\n") == prog.files[0].text.count("\n")  # CRLF kept


@pytest.mark.parametrize("joints", ["keep", "compensate"])
def test_nominal_round_trip_is_byte_identical(nominal_params, tmp_path, capsys, joints):
    src = _copy(tmp_path)
    out = tmp_path / "out"
    assert main(["compensate", "--params", str(nominal_params), "--program", str(src),
                 "--out", str(out), "--joint-targets", joints, *FRAMES]) == 0
    for f in ("drill_plate.src", "drill_plate.dat"):
        assert (out / f).read_bytes() == (FIXTURES / f).read_bytes()
    assert "0 numbers changed" in capsys.readouterr().out


def test_nominal_model_gives_back_every_number(nominal_result):
    prog, _ = read_program(FIXTURES / "drill_plate.src")
    b, t = _frames()
    fr = filter_targets(prog, model_for(nominal_result), bases=b, tools=t, payload_kg=36.0)
    for r in fr.reports:
        np.testing.assert_allclose(r.after, r.before, atol=1e-7)
    assert not fr.edits


def test_equals_plugcell_compensate(calibrated_result, params_file, tmp_path):
    """Library level to 1e-9 mm, and the command's written numbers to their rounding."""
    prog, _ = read_program(FIXTURES / "drill_plate.src")
    b, t = _frames()
    fr = filter_targets(prog, model_for(calibrated_result), bases=b, tools=t, payload_kg=36.0)
    poses = [r for r in fr.reports if r.compensated]
    assert len(poses) == 7
    B, tool = b["BASE_DATA[1]"], t["TOOL_DATA[1]"]
    # plugcell compensate's own path: rpy angles (C, B, A), --user-frame, --tool
    vals = np.array([r.before for r in poses])
    model = IdentifiedModel(calibrated_result.model, tool)
    ref = filter_program(model, vals[:, :3] / 1e3, np.radians(vals[:, [5, 4, 3]]), "rpy",
                         user_frame=B, payload_kg=36.0)
    q = np.array([r.q for r in poses])
    fk = model.pose(q, 36.0)[:, :3, 3]
    fk_ref = model.pose(ref.q, 36.0)[:, :3, 3]
    assert np.abs(fk - fk_ref).max() * 1e3 < 1e-9
    # the model reaches the program's targets with those joints
    target = (B @ pose_from_notation(vals, "kuka"))[:, :3, 3]
    assert np.abs(fk - target).max() < 1e-6
    # the command writes the same numbers (rounded to the file's digits)
    src = _copy(tmp_path)
    out = tmp_path / "out"
    assert main(["compensate", "--params", str(params_file), "--program", str(src), "--out",
                 str(out), "--payload-kg", "36", *FRAMES]) == 0
    got, _ = read_program(out / "drill_plate.src")
    new = {tt.name: tt.values for tt in got.targets}
    for r in poses:
        np.testing.assert_allclose(new[r.target.name], r.after, atol=5.01e-4)
        assert np.abs(r.after - r.before).max() > 1e-3  # the calibration moved them


def test_a_joint_target_is_compensated_in_its_own_configuration(calibrated_result):
    prog, _ = read_program(FIXTURES / "drill_plate.src")
    b, t = _frames()
    fr = filter_targets(prog, model_for(calibrated_result), bases=b, tools=t, payload_kg=36.0,
                        joints="compensate")
    r = next(r for r in fr.reports if r.target.name == "PTP line 46")
    assert r.compensated and r.ok and r.seed is not None
    d = np.abs(r.after - r.before)
    assert 1e-3 < d.max() < 0.5   # a correction, not another configuration
    # the identified model at the new joints is where the nominal one was at the old ones
    from plugcell.compensation import NominalModel

    tool = t["TOOL_DATA[1]"]
    want = NominalModel(IdentifiedModel(calibrated_result.model).description, tool).pose(
        np.radians(r.before))
    got = IdentifiedModel(calibrated_result.model, tool).pose(np.radians(r.after)[None], 36.0)
    assert np.abs(got[0, :3, 3] - want[0, :3, 3]).max() < 3e-5  # (joints printed to 0.001°)


def test_missing_frames_are_listed_and_nothing_written(params_file, tmp_path, capsys):
    src = _copy(tmp_path)
    out = tmp_path / "out"
    assert main(["compensate", "--params", str(params_file), "--program", str(src),
                 "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "base 'BASE_DATA[1]'" in err and "tool 'TOOL_DATA[1]'" in err
    assert not out.exists()
    prog, _ = read_program(src)
    with pytest.raises(MissingFramesError) as ei:
        filter_targets(prog, lambda tool: None, bases={}, tools={})  # type: ignore[arg-type]
    assert ei.value.bases == ["BASE_DATA[1]"] and ei.value.tools == ["TOOL_DATA[1]"]


@pytest.mark.parametrize(("line", "message", "col"), [
    ("LIN {X 1.0,Y 2.0,Z 3.0,A 0.0,B 0.0} C_DIS", "a partial position (no C)", 5),
    ("LIN {X 1.0,Y 2.0 Z 3.0,A 0.0,B 0.0,C 0.0}", "expected '}'", 18),
    ("$BASE = EK(MACHINE_DEF[2].ROOT, MACHINE_DEF[2].MECH_TYPE, BASE_DATA[1])",
     "not a frame the reader knows", 9),
    ("XP1.X = 100.0", "a component of a target changed at run time", 1),
    ("MYPOS = {X 1.0,Y 2.0,Z 3.0,A 0.0,B 0.0,C 0.0} + OFFSET",
     "unexpected text after the aggregate", 47),
])
def test_unknown_syntax_is_named_and_nothing_written(params_file, tmp_path, capsys, line,
                                                      message, col):
    src = _copy(tmp_path)
    text = src.read_bytes().replace(b"\r\nEND\r\n", f"\r\n{line}\r\nEND\r\n".encode())
    src.write_bytes(text)
    n_line = text.split(b"\r\n").index(line.encode()) + 1
    out = tmp_path / "out"
    assert main(["compensate", "--params", str(params_file), "--program", str(src),
                 "--out", str(out), *FRAMES]) == 2
    err = capsys.readouterr().err
    assert f"drill_plate.src:{n_line}:{col}: " in err and message in err, err
    assert "nothing written" in err and not out.exists()


def test_a_frame_variable_as_base(tmp_path):
    """``$BASE=MYBASE`` with ``DECL FRAME MYBASE={…}`` in the .dat: a frame, not a target."""
    src = _copy(tmp_path)
    dat = tmp_path / "drill_plate.dat"
    dat.write_bytes(dat.read_bytes().replace(
        b"ENDDAT", b"DECL FRAME MYBASE={X 1200.0,Y -150.0,Z 300.0,A 90.0,B 0.0,C 0.0}\r\nENDDAT"))
    src.write_bytes(src.read_bytes().replace(
        b"$BASE = {FRAME: X 1200.0, Y -150.0, Z 300.0, A 90.0, B 0.0, C 0.0}",
        b"$BASE=MYBASE"))
    prog, _ = read_program(src)
    assert "MYBASE" in prog.frames and "MYBASE" not in [t.name for t in prog.targets]
    lin = next(t for t in prog.targets if t.name == "LIN line 44")
    assert lin.base == "MYBASE"
    np.testing.assert_allclose(prog.frames["MYBASE"][:3, 3], [1.2, -0.15, 0.3])


def test_a_point_used_with_two_frames_is_refused(tmp_path):
    src = _copy(tmp_path)
    src.write_bytes(src.read_bytes().replace(b"\r\nEND\r\n", b"\r\nPTP XP1\r\nEND\r\n"))
    with pytest.raises(ProgramError, match="XP1 is used with base"):
        read_program(src)


def test_unreachable_target_fails_with_its_line_unless_partial(params_file, tmp_path, capsys):
    src = _copy(tmp_path)
    dat = tmp_path / "drill_plate.dat"
    dat.write_bytes(dat.read_bytes().replace(b"X 1002.938", b"X 9002.938"))
    out = tmp_path / "out"
    argv = ["compensate", "--params", str(params_file), "--program", str(src), "--out",
            str(out), *FRAMES]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "drill_plate.dat:9:16 (XP1): no nominal joint solution" in err
    assert not out.exists()
    assert main([*argv, "--partial"]) == 0
    assert b"X 9002.938" in (out / "drill_plate.dat").read_bytes()
    assert b"X 1136.966" not in (out / "drill_plate.dat").read_bytes()


def test_status_and_turn_follow_a_joint_crossing_zero():
    from plugcell.io.programs.core import Num
    from plugcell.io.programs.krl import KrlConfig

    s = Num(0, 5, "'B010'", 2.0)
    t = Num(10, 19, "'B100011'", 35.0)
    cfg = KrlConfig(0, s, t)
    q0 = np.radians([1e-4, -80, -150, 5, -1e-4, 10])
    q1 = q0.copy()
    q1[0], q1[4] = -1e-4, 1e-4   # A1 and A5 change side: T bits 0 and 4, S bit 2
    ed = cfg.edits(q0, q1)
    assert ed[(0, 10)] == "'B110010'" and ed[(0, 0)] == "'B110'"
    assert cfg.edits(q0, q0) == {}


@pytest.mark.parametrize(("text", "value", "out"), [
    ("1200", 1200.25, "1200.250"), ("+792.278", 792.5, "+792.500"),
    ("7.92278E+02", 792.8721, "7.92872E+02"), (".5", 0.25, ".250"),
    ("-0.000", 0.0004, "0.000"), ("-12.5", -12.7, "-12.700"), ("007.5", 7.25, "007.250"),
])
def test_number_style(text, value, out):
    assert NumberStyle.of(text).format(value, 3) == out


# ---------------------------------------------------------------- property: generated programs
_num = st.sampled_from(["{:.3f}", "{:.4f}", "{:+.3f}", "{:.5E}", "{:.6f}"])


@st.composite
def krl_programs(draw):
    n = draw(st.integers(1, 5))
    ks = np.array(draw(st.lists(st.integers(0, 39), min_size=n, max_size=n)))
    vals = poses_in("kuka", [1200, -150, 300, 90, 0, 0], [12.5, -3, 215, 0, -30, 0], ks)
    nl = draw(st.sampled_from(["\n", "\r\n"]))
    sp = draw(st.sampled_from(["", " ", "  "]))
    src = ["DEF gen( )", ";FOLD INI;%{PE}", ";ENDFOLD (INI)",
           "$BASE = {FRAME: X 1200.0, Y -150.0, Z 300.0, A 90.0, B 0.0, C 0.0}",
           "$TOOL={X 12.5,Y -3.0,Z 215.0,A 0.0,B -30.0,C 0.0}   ; drill"]
    dat = ["DEFDAT gen PUBLIC"]
    for i, v in enumerate(vals):
        fmt = draw(_num)
        agg = ("{" + ("E6POS: " if draw(st.booleans()) else "") + f",{sp}".join(
            f"{k} {fmt.format(x)}" for k, x in zip("XYZABC", v, strict=True))
            + f",{sp}S 2,{sp}T 35" + "}")
        move = draw(st.sampled_from(["PTP", "LIN", "SLIN"]))
        if draw(st.booleans()):
            dat.append(f"DECL E6POS XP{i}={agg}")
            src.append(f"{draw(st.sampled_from(['', '  ', chr(9)]))}{move} XP{i} C_DIS ; p{i}")
        else:
            src.append(f"{move} {agg} C_DIS")
    src.append("END")
    dat.append("ENDDAT")
    return nl.join(src) + nl, nl.join(dat) + nl


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                 HealthCheck.function_scoped_fixture])
@given(prog=krl_programs())
def test_generated_programs_round_trip(nominal_result, tmp_path, prog):
    src, dat = prog
    fr = assert_generated_round_trip(nominal_result, tmp_path, {"gen.src": src, "gen.dat": dat})
    for r in fr.reports:
        np.testing.assert_allclose(r.after, r.before, atol=1e-7)
