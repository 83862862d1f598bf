"""The path file of ``plugcell path run``: columns, units, segments, and every error named."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from plugcell.io.path_files import PathFileError, parse_path, read_path
from plugcell.io.units import robot_from_pose

LINE = """# a line, its end without the tracker
x,y,z,a,b,c,speed,tracking
1473.3,-231.7,2488.4,-60,30,-90,,
1473.3,568.3,2488.4,-60,30,-90,100,1

1473.3,768.3,2488.4,-60,30,-90,,0
"""


def test_a_path_in_si_with_its_segments_and_lines():
    p = parse_path(LINE, "line.csv")
    assert p.poses.shape == (3, 4, 4) and p.oriented
    np.testing.assert_allclose(p.poses[1, :3, 3], [1.4733, 0.5683, 2.4884])
    np.testing.assert_allclose(robot_from_pose(p.poses[0]), [1473.3, -231.7, 2488.4, -60, 30,
                                                               -90], atol=1e-9)
    np.testing.assert_allclose(p.speeds, [0.1, 0.1])  # a blank speed keeps the last one
    assert p.tracking.tolist() == [True, False]
    assert p.lines.tolist() == [3, 4, 6]
    np.testing.assert_allclose(p.lengths(), [0.8, 0.2])


def test_columns_in_any_order_without_angles_and_default_speed():
    p = parse_path("Z, X ,y\n1,2,3\n1,2,13\n", "p.csv", speed_mm_s=50)
    np.testing.assert_allclose(p.poses[:, :3, 3], [[0.002, 0.003, 0.001],
                                                   [0.002, 0.013, 0.001]])
    assert not p.oriented and p.speeds.tolist() == [0.05] and p.tracking.tolist() == [True]


@pytest.mark.parametrize(("text", "message"), [
    ("", r"^p\.csv: no header line"),
    ("x,y\n1,2\n3,4\n", r"^p\.csv: line 1: missing column\(s\) z"),
    ("x,y,z,q\n", r"^p\.csv: line 1: unknown column 'q' \(known: x, y, z, a, b, c"),
    ("x,y,z,x\n", r"^p\.csv: line 1: column 'x' given twice"),
    ("x,y,z,a,b\n", r"^p\.csv: line 1: columns a, b, c come together \(got a, b\)"),
    ("x,y,z\n1,2,3\n", r"^p\.csv: a path needs at least 2 points, the file has 1"),
    ("x,y,z\n1,2,3\n4,5\n", r"^p\.csv: line 3: 2 cells, the header has 3"),
    ("x,y,z\n1,2,3\n1,2,abc\n", r"^p\.csv: line 3, column 'z': not a number: 'abc'"),
    ("x,y,z\n1,2,nan\n1,2,4\n", r"^p\.csv: line 2, column 'z': not finite"),
    ("x,y,z,speed\n1,2,3,\n1,2,4,-5\n", r"^p\.csv: line 3, column 'speed': speed must be "
                                        r"> 0 mm/s, got -5"),
    ("x,y,z,tracking\n1,2,3,\n1,2,4,yes\n", r"^p\.csv: line 3, column 'tracking': expected "
                                            r"1 or 0, got 'yes'"),
    ("x,y,z\n1,2,3\n# c\n1,2,3.000001\n", r"^p\.csv: line 4: the same point as the row "
                                          r"before"),
    ('x,y,z\n1,2,3\n"1,2,4\n', r"^p\.csv: line 3: 1 cells, the header has 3"),
])
def test_every_malformed_file_names_its_line_and_column(text, message):
    with pytest.raises(PathFileError, match=message):
        parse_path(text, "p.csv")


def test_a_missing_file_says_so(tmp_path):
    with pytest.raises(PathFileError, match=r"^nope\.csv: cannot read"):
        read_path(tmp_path / "nope.csv")
    (tmp_path / "ok.csv").write_text("x,y,z\n0,0,0\n0,0,1\n")
    assert read_path(tmp_path / "ok.csv").n_segments == 1


_CELL = st.one_of(st.sampled_from(["", " ", "1", "0", "-5", "1e3", "nan", "inf", "x", '"',
                                   "#", "\n", ",", "100", "1.5"]),
                  st.text(max_size=5))


@settings(max_examples=300, deadline=None)
@given(st.lists(st.lists(_CELL, min_size=0, max_size=9), min_size=0, max_size=6),
       st.sampled_from(["x,y,z", "x,y,z,speed", "x,y,z,a,b,c,speed,tracking", "x,y"]))
def test_any_text_parses_or_fails_with_a_named_reason(rows, header):
    text = header + "\n" + "\n".join(",".join(r) for r in rows)
    try:
        p = parse_path(text, "fuzz.csv")
    except PathFileError as exc:
        assert str(exc).startswith("fuzz.csv: ")
        return
    # what is accepted is a well-formed path
    assert len(p.poses) >= 2 and p.speeds.shape == (len(p.poses) - 1,)
    assert np.all(np.isfinite(p.poses)) and np.all(p.speeds > 0)


@settings(max_examples=100, deadline=None)
@given(st.lists(st.tuples(*[st.floats(-3000, 3000, allow_nan=False)] * 3,
                          st.floats(1, 2000, allow_nan=False), st.booleans()),
                min_size=2, max_size=8, unique_by=lambda r: tuple(round(v, 3) for v in r[:3])))
def test_written_points_come_back_in_si(points):
    text = "x,y,z,speed,tracking\n" + "\n".join(
        f"{x!r},{y!r},{z!r},{s!r},{int(t)}" for x, y, z, s, t in points)
    try:
        p = parse_path(text, "w.csv")
    except PathFileError as exc:  # two points closer than 0.01 mm: refused, by name
        assert "the same point as the row before" in str(exc)
        return
    np.testing.assert_allclose(p.poses[:, :3, 3], np.array([r[:3] for r in points]) * 1e-3)
    np.testing.assert_allclose(p.speeds, [r[3] * 1e-3 for r in points[1:]])
    assert p.tracking.tolist() == [r[4] for r in points[1:]]
