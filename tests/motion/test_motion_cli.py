"""``plugcell motion plan`` and the moves file it reads (#37)."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from plugcell.apps.cli import main
from plugcell.io.moves import MovesFileError, parse_moves
from plugcell.io.robots import load_robot
from plugcell.io.units import pose_from_robot
from plugcell.motion import CIRC, LIN, PTP

MOVES = """\
# pick and place on elbow6 (mm, degrees)
PTP  10, -80, 20, 30, 60, -20
LIN  1700, 300, 1000, 90, 150, -100   blend=50
LIN  1700, 0, 1000, 90, 150, -100
CIRC 1600, -100, 1100; 1500, 0, 1200, 90, 150, -100  speed=0.5
ptp  0, -90, 0, 0, 90, 0   blend=5 acc=0.8
"""


def test_the_moves_file_in_si_with_its_lines() -> None:
    desc = load_robot("elbow6")
    moves = parse_moves(MOVES, "pick.moves", desc)
    assert [type(m) for m in moves] == [PTP, LIN, LIN, CIRC, PTP]
    assert [m.line for m in moves] == [2, 3, 4, 5, 6]
    assert np.allclose(moves[0].target, np.radians([10, -80, 20, 30, 60, -20]))
    assert moves[1].blend == pytest.approx(0.05)  # mm → m
    assert moves[4].blend == pytest.approx(np.radians(5.0)) and moves[4].acceleration == 0.8
    assert np.allclose(moves[1].target, pose_from_robot([1700, 300, 1000, 90, 150, -100]))
    assert np.allclose(moves[3].via, [1.6, -0.1, 1.1]) and moves[3].speed == 0.5


@pytest.mark.parametrize(("text", "message"), [
    ("PTP 1, 2", "pick.moves:1: PTP needs 6 joint values for elbow6 (1, 2, 3, 4, 5, 6), got 2"),
    ("\nLIN 1, 2, 3", "pick.moves:2: expected a pose of 6 numbers"),
    ("MOVE 1", "pick.moves:1: unknown move 'MOVE' (PTP, LIN, CIRC)"),
    ("PTP 1, 2, 3, 4, 5, x", "pick.moves:1: 'x' is not a number"),
    ("LIN 1, 2, 3, 4, 5, 6 blend=-1", "pick.moves:1: blend must be a radius ≥ 0, got -1"),
    ("LIN 1, 2, 3, 4, 5, 6 colour=3", "pick.moves:1: unknown option 'colour'"),
    ("CIRC 1, 2, 3, 4, 5, 6", "pick.moves:1: CIRC needs a via point and an end pose"),
    ("CIRC 1, 2; 1, 2, 3, 4, 5, 6", "pick.moves:1: the via point needs 3 numbers"),
    ("PTP 1, 2, 3, 4, 5, 6 speed=2", "pick.moves:1: speed must be a fraction in (0, 1]"),
    ("PTP speed=1 1, 2, 3, 4, 5, 6", "pick.moves:1: options (blend=…, speed=…, acc=…) come "
                                     "after the values"),
    ("PTP 1, 2, 3, 4, 5, inf", "pick.moves:1: values must be finite"),
    ("# nothing\n\n", "pick.moves: no moves"),
    ("12 3", "pick.moves:1: expected PTP, LIN or CIRC"),
])
def test_a_malformed_line_names_file_line_and_cause(text: str, message: str) -> None:
    with pytest.raises(MovesFileError) as info:
        parse_moves(text, "pick.moves", load_robot("elbow6"))
    assert str(info.value).startswith(message)


@settings(max_examples=300, deadline=None)
@given(st.text(alphabet=st.sampled_from(list("PTLINCRptlinc ,;.=-+e0123456789#\n\tabdspx")),
               max_size=80))
def test_any_text_gives_moves_or_a_moves_file_error(text: str) -> None:
    desc = load_robot("elbow6")
    try:
        moves = parse_moves(text, "f", desc)
    except MovesFileError as exc:
        assert str(exc).startswith("f:") or str(exc).startswith("f ")
    else:
        assert moves and all(isinstance(m, (PTP, LIN, CIRC)) and m.line for m in moves)


def _rows(path: Path) -> list[dict[str, str]]:
    with open(path, encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def test_plan_writes_every_cycle(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    moves, out = tmp_path / "pick.moves", tmp_path / "pick.csv"
    moves.write_text(MOVES, encoding="utf-8")
    rc = main(["motion", "plan", "--robot", "elbow6", "--moves", str(moves), "--out", str(out),
               "--cycle", "0.004"])
    assert rc == 0
    assert "5 moves" in capsys.readouterr().err
    rows = _rows(out)
    t = np.array([float(r["t_s"]) for r in rows])
    assert np.allclose(np.diff(t), 0.004)
    q = np.array([[float(r[f"j{i}"]) for i in range(1, 7)] for r in rows])
    assert np.allclose(q[0], [0, -90, 0, 0, 90, 0]) and np.allclose(q[-1], [0, -90, 0, 0, 90, 0])
    # the second LIN (file line 4) runs along y at x = 1700, z = 1000 mm (after the blend)
    lin = [r for r in rows if r["move_line"] == "4"]
    xyz = np.array([[float(r["x_mm"]), float(r["y_mm"]), float(r["z_mm"])] for r in lin])
    late = xyz[len(xyz) // 2:]
    assert np.allclose(late[:, 0], 1700.0, atol=1e-4) and np.allclose(late[:, 2], 1000, atol=1e-4)
    assert {r["move_line"] for r in rows} == {"2", "3", "4", "5", "6"}


def test_plan_errors_name_the_file_and_the_line(tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    moves = tmp_path / "far.moves"
    moves.write_text("PTP 0, -90, 0, 0, 90, 0\nLIN 4000, 0, 1000, 0, 90, 0\n", encoding="utf-8")
    assert main(["motion", "plan", "--robot", "elbow6", "--moves", str(moves)]) == 2
    err = capsys.readouterr().err
    assert f"{moves}: move 1 (LIN, line 2): target unreachable" in err
    moves.write_text("PTP 0, -90, 0, 0, 90, 0\nPTP 0, -180, 0, 0, 90, 0\n", encoding="utf-8")
    assert main(["motion", "plan", "--robot", "elbow6", "--moves", str(moves)]) == 2
    assert "move 1 (PTP, line 2): target: joint 2" in capsys.readouterr().err
    assert main(["motion", "plan", "--robot", "elbow6", "--moves", str(moves),
                 "--joint-speed", "1,2"]) == 2
    assert "--joint-speed: expected 1 or 6 values, got 2" in capsys.readouterr().err
    assert main(["motion", "plan", "--robot", "elbow6", "--moves", str(tmp_path / "none")]) == 2
    assert "cannot read" in capsys.readouterr().err
