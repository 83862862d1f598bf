"""ABB RAPID: byte-exact round trip, equality with ``plugcell compensate``, bad input."""

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
from plugcell.io.programs.core import Num
from plugcell.io.programs.filter import filter_targets
from plugcell.io.programs.rapid import RapidConfig

FIX = FIXTURES / "Module1.mod"


def test_fixture_targets():
    prog, notes = read_program(FIX)
    t = {x.name: x for x in prog.targets}
    assert list(t) == ["Target_10", "Target_20", "Path{1}", "Path{2}", "jHome", "Unused",
                       "MoveL line 26", "MoveL line 28"]
    assert (t["Path{2}"].base, t["Path{2}"].tool) == ("wFixture", "tSpindle")
    assert t["MoveL line 28"].base == "wobj0" and not t["Unused"].used
    assert t["jHome"].kind == "joints" and t["jHome"].base is None
    assert "tSpindle" in prog.tools and "wFixture" in prog.frames
    assert any("Offs" in n for n in notes)


def test_nominal_round_trip_is_byte_identical(nominal_params, tmp_path):
    assert_nominal_round_trip(nominal_params, FIX, tmp_path / "o.mod")


def test_equals_plugcell_compensate(calibrated_result, params_file, tmp_path):
    prog, _ = read_program(FIX)
    fr = filter_targets(prog, model_for(calibrated_result), payload_kg=36.0)
    assert assert_equals_plugcell_compensate(prog, fr, calibrated_result) == 6
    out = tmp_path / "o.mod"
    assert main(["compensate", "--params", str(params_file), "--program", str(FIX), "--out",
                 str(out), "--payload-kg", "36"]) == 0
    got = {t.name: t.values for t in read_program(out)[0].targets}
    for r in fr.reports:
        if r.compensated:
            np.testing.assert_allclose(got[r.target.name][:3], r.after[:3], atol=5.01e-4)
            np.testing.assert_allclose(got[r.target.name][3:], r.after[3:], atol=5.01e-7)


def test_missing_tool_and_wobj_are_listed(params_file, tmp_path, capsys):
    src = tmp_path / "m.mod"
    text = FIX.read_text().replace("wFixture:=", "wOther:=").replace("tSpindle:=", "tX:=")
    src.write_text(text)
    argv = ["compensate", "--params", str(params_file), "--program", str(src), "--out",
            str(tmp_path / "o.mod")]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "base 'wFixture' (--base 'wFixture=…')" in err
    assert "tool 'tSpindle' (--tool 'tSpindle=…')" in err
    assert main([*argv, "--base", "wFixture=1200,-150,300,0.707107,0,0,0.707107",
                 "--tool", "tSpindle=12.5,-3,215,0.965926,0,-0.258819,0"]) == 0


@pytest.mark.parametrize(("old", "new", "message"), [
    ("[0,0,1,0],[9E+09", "[0,0,1],[9E+09", "robconf: expected 4 items, got 3"),
    ("[[-268.33,-281.12,1247.74]", "[[-268.33,-281.12,abc]", "trans: expected a number"),
    ("tSpindle:=[TRUE", "tSpindle:=[FALSE", "a stationary tool"),
    ("MoveJ Target_10, v1000, z50, tSpindle\\WObj:=wFixture;",
     "MoveJ Target_10, v1000, z50, tSpindle\\WObj:=wFixture;\n MoveL Target_10, v9, z1, "
     "tool0;", "Target_10 is used with tool tool0"),
])
def test_unknown_syntax_is_named(tmp_path, old, new, message):
    assert_edit_refused(FIX, tmp_path / "m.mod", old, new, message)


def test_the_programs_arm_configuration_is_the_one_compensated(calibrated_result):
    """MoveL line 28 names the flipped wrist (cf4 = -2, cf6 = -1): the nominal inverse
    kinematics from home finds the other one, so it is solved again from the flipped seed
    and compensated there; the others keep home's solution (seed None)."""
    prog, _ = read_program(FIX)
    fr = filter_targets(prog, model_for(calibrated_result), payload_kg=36.0)
    by = {r.target.name: r for r in fr.reports}
    r28 = by["MoveL line 28"]
    assert r28.seed is not None and r28.q[4] < 0 and not r28.reason
    assert r28.target.config.mismatch(r28.q) == ""
    assert all(r.seed is None for n, r in by.items() if n != "MoveL line 28")
    assert not any(r.reason.startswith("configuration") for r in fr.reports)


def test_optional_arguments_anywhere(tmp_path):
    """``\\Conc`` before the target, ``\\T:=`` in the speed, ``\\WObj`` after the tool."""
    src = tmp_path / "m.mod"
    text = FIX.read_text().replace("MoveJ Target_10, v1000, z50, tSpindle\\WObj:=wFixture;",
                                   "MoveJ \\Conc, Target_10, v1000\\T:=5, z50 \\Inpos:=inpos50, "
                                   "tSpindle \\WObj:=wFixture;")
    assert "\\Conc" in text
    src.write_text(text)
    prog, _ = read_program(src)
    t = next(x for x in prog.targets if x.name == "Target_10")
    assert t.used and (t.base, t.tool) == ("wFixture", "tSpindle")


def test_confdata_follows_quarters():
    cf = [Num(0, 1, "0", 0.0), Num(2, 3, "-1", -1.0), Num(4, 5, "2", 2.0), Num(6, 7, "0", 0.0)]
    c = RapidConfig(0, cf)
    q0 = np.radians([89.99, -40, -120, -0.001, 50, 180.01])
    q1 = np.radians([90.01, -40, -120, 0.001, 50, 179.99])
    assert c.edits(q0, q1) == {(0, 0): "1", (0, 2): "0", (0, 4): "1"}
    assert c.edits(q0, q0) == {}


_fmt = st.sampled_from(["{:.6f}", "{:.3f}", "{:.9f}", "{:.4f}"])


@st.composite
def modules(draw):
    n = draw(st.integers(1, 5))
    ks = np.array(draw(st.lists(st.integers(0, 39), min_size=n, max_size=n)))
    vals = poses_in("abb", [0, 0, 0, 1, 0, 0, 0], [0, 0, 200, 1, 0, 0, 0], ks)
    nl = draw(st.sampled_from(["\n", "\r\n"]))
    decl, body = [], []
    for i, v in enumerate(vals):
        f = draw(_fmt)
        rt = ("[[" + ",".join(f.format(x) for x in v[:3]) + "],[" +
              ",".join(f"{x:.6f}" for x in v[3:]) + "],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]]")
        if draw(st.booleans()):
            decl.append(f"    CONST robtarget p{i}:={rt};  ! p{i}")
            body.append(f"        MoveL p{i}, v100, z10, tDrill;")
        else:
            body.append(f"        MoveJ {rt}, v100, fine, tDrill\\WObj:=wobj0;")
    lines = ["MODULE Gen", "    PERS tooldata tDrill:=[TRUE,[[0,0,200],[1,0,0,0]],"
             "[1,[0,0,1],[1,0,0,0],0,0,0]];", *decl, "    PROC main()", *body,
             "    ENDPROC", "ENDMODULE"]
    return nl.join(lines) + nl


@settings(max_examples=15, deadline=None, suppress_health_check=[
    HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(text=modules())
def test_generated_modules_round_trip(nominal_result, tmp_path, text):
    assert_generated_round_trip(nominal_result, tmp_path, {"g.mod": text})
