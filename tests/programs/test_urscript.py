"""URScript: byte-exact round trip, equality with ``plugcell compensate``, bad input."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from programlib import (
    FIXTURES,
    assert_equals_plugcell_compensate,
    assert_generated_round_trip,
    assert_nominal_round_trip,
    model_for,
    poses_in,
)

from plugcell.apps.cli import main
from plugcell.io.programs import ProgramError, read_program
from plugcell.io.programs.filter import filter_targets

FIX = FIXTURES / "pick_place.script"


def test_fixture_targets():
    prog, notes = read_program(FIX)
    kinds = {t.name: (t.kind, t.base, t.tool, t.used) for t in prog.targets}
    assert kinds["Waypoint_1_p"] == ("pose", None, "set_tcp (line 4)", True)
    assert kinds["movel line 16"][1] == "Plane_1" and "Plane_1" in prog.frames
    assert kinds["movej line 18"][0] == "joints" and not kinds["Waypoint_1_q"][3]
    assert any("get_actual_tcp_pose" not in n and "left as it is" in n for n in notes)


def test_nominal_round_trip_is_byte_identical(nominal_params, tmp_path):
    assert_nominal_round_trip(nominal_params, FIX, tmp_path / "o.script")


def test_equals_plugcell_compensate(calibrated_result, params_file, tmp_path):
    prog, _ = read_program(FIX)
    fr = filter_targets(prog, model_for(calibrated_result), payload_kg=36.0,
                        joints="compensate")
    # the targets left out, named with their reasons if the count is off (once in CI,
    # 2026-11-28: 5, cause unknown)
    skipped = [(r.target.name, r.target.kind, r.reason) for r in fr.reports
               if not r.compensated]
    assert assert_equals_plugcell_compensate(prog, fr, calibrated_result) == 6, skipped
    jt = next(r for r in fr.reports if r.target.name == "movej line 18")
    assert jt.compensated and np.abs(jt.after - jt.before).max() > 1e-4  # radians moved
    out = tmp_path / "o.script"
    assert main(["compensate", "--params", str(params_file), "--program", str(FIX), "--out",
                 str(out), "--payload-kg", "36"]) == 0
    got = {t.name: t.values for t in read_program(out)[0].targets}
    for r in fr.reports:
        if r.target.kind == "pose":
            np.testing.assert_allclose(got[r.target.name], r.after, atol=5.01e-7)


def test_without_set_tcp_the_tool_is_asked_for(params_file, tmp_path, capsys):
    src = tmp_path / "t.script"
    src.write_text(FIX.read_text().replace(
        "  set_tcp(p[0.0125, -0.003, 0.215, 0.0, -0.5236, 0.0])\n", ""))
    out = tmp_path / "o.script"
    argv = ["compensate", "--params", str(params_file), "--program", str(src), "--out", str(out)]
    assert main(argv) == 2
    assert "tool 'TCP' (--tool 'TCP=…')" in capsys.readouterr().err and not out.exists()
    assert main([*argv, "--tool", "TCP=0.0125,-0.003,0.215,0,-0.5236,0"]) == 0


@pytest.mark.parametrize(("line", "message", "col"), [
    ("  movel(p[0.1, 0.2, 0.3, 0.0, 0.0], a=1.2)", "a pose has 6 numbers, this one 5", 10),
    ("  movel(p[0.1, 0.2, x, 0.0, 0.0, 0.0])", "expected a number in the pose, got 'x'", 21),
    ("  movel(pose_add(get_actual_tcp_pose(), p[0, 0, 0.01, 0, 0, 0]))",
     "a pose inside an expression", 41),
    ("  movel(pose_trans(Plane_1, Waypoint_2_p))", "is used with frame Plane_1", 29),
])
def test_unknown_syntax_is_named(tmp_path, line, message, col):
    src = tmp_path / "t.script"
    lines = FIX.read_text().splitlines(keepends=True)
    lines.insert(-1, line + "\n")
    src.write_text("".join(lines))
    with pytest.raises(ProgramError) as ei:
        read_program(src)
    assert f"t.script:{len(lines) - 1}:{col}: " in str(ei.value) and message in str(ei.value)


_fmt = st.sampled_from(["{:.6f}", "{:.5f}", "{:.7g}", "{:.6e}"])


@st.composite
def scripts(draw):
    n = draw(st.integers(1, 5))
    ks = np.array(draw(st.lists(st.integers(0, 39), min_size=n, max_size=n)))
    vals = poses_in("ur", [0, 0, 0, 0, 0, 0], [0, 0, 0.2, 0, 0, 0], ks)
    nl = draw(st.sampled_from(["\n", "\r\n"]))
    sep = draw(st.sampled_from([",", ", "]))
    body = ["def gen():", "  set_tcp(p[0,0,0.2,0,0,0])  # drill"]
    for i, v in enumerate(vals):
        fmt = draw(_fmt)
        pose = "p[" + sep.join(fmt.format(x) for x in v) + "]"
        if draw(st.booleans()):
            body.insert(1, f"  global Waypoint_{i}_p={pose}")
            body.append(f"  movel(Waypoint_{i}_p, a=1.2, v=0.25)")
        else:
            body.append(f"  {draw(st.sampled_from(['movel', 'movej', 'movep']))}({pose}, a=1.2)")
    body.append("end")
    return nl.join(body) + nl


@settings(max_examples=15, deadline=None, suppress_health_check=[
    HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(text=scripts())
def test_generated_scripts_round_trip(nominal_result, tmp_path, text):
    fr = assert_generated_round_trip(nominal_result, tmp_path, {"g.script": text})
    for r in fr.reports:
        np.testing.assert_allclose(r.after, r.before, atol=1e-9)
