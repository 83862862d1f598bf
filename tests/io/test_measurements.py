"""The measurement file format: round trips and precise errors."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from plugcell.io.measurements import (
    MeasurementFileError,
    MeasurementSet,
    format_measurements,
    parse_measurements,
    read_measurements,
    write_measurements,
)

GOOD = """# a comment
j1,j2,j3,x,y,z,rx,ry,rz,payload_kg
10,20,30,1000,2000,3000,1,2,3,18
-10,-20,-30,-1000,0.5,7,4,5,6,36
"""


def test_parse_converts_to_si():
    m = parse_measurements(GOOD, rotation="zyz")
    assert len(m) == 2 and m.n_joints == 3 and m.rotation == "zyz"
    np.testing.assert_allclose(m.joints[0], np.deg2rad([10, 20, 30]))
    np.testing.assert_allclose(m.positions[1], [-1.0, 0.0005, 0.007])
    np.testing.assert_allclose(m.angles[0], np.deg2rad([1, 2, 3]))
    np.testing.assert_allclose(m.payload_kg, [18, 36])


def test_round_trip_through_a_file(tmp_path):
    rng = np.random.default_rng(3)
    m = MeasurementSet(
        joints=rng.uniform(-3, 3, (50, 6)),
        positions=rng.uniform(-3, 3, (50, 3)),
        angles=rng.uniform(-3, 3, (50, 3)),
        payload_kg=rng.uniform(0, 40, 50),
    )
    path = tmp_path / "cal.csv"
    write_measurements(path, m, comments=["made by a test"])
    back = read_measurements(path, n_joints=6)
    np.testing.assert_allclose(back.joints, m.joints, atol=1e-8)
    np.testing.assert_allclose(back.positions, m.positions, atol=1e-8)
    np.testing.assert_allclose(back.angles, m.angles, atol=1e-8)
    np.testing.assert_allclose(back.payload_kg, m.payload_kg, atol=1e-6)


def test_position_only_file():
    m = parse_measurements("j1,j2,x,y,z\n1,2,3,4,5\n")
    assert m.angles is None and m.payload_kg is None and not m.has_orientation


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("", "no header"),
        ("# only a comment\n", "no header"),
        ("j1,x,y,z\n", "no data rows"),
        ("j1,j3,x,y,z\n1,2,3,4,5\n", "without gaps"),
        ("x,y,z\n1,2,3\n", "no joint columns"),
        ("j1,x,y\n1,2,3\n", "lacks the column 'z'"),
        ("j1,x,y,z,rx\n1,2,3,4,5\n", "needs all of rx, ry, rz"),
        ("j1,x,y,z,foo\n1,2,3,4,5\n", "unknown columns ['foo']"),
        ("j1,x,y,z\n1,2,3\n", "line 2: expected 4 values, got 3"),
        ("j1,x,y,z\n1,2,abc,4\n", "line 2, column 'y': not a number: 'abc'"),
        ("j1,x,y,z\n# c\n1,2,3,nan\n", "line 3, column 'z': not finite"),
        ("j1,x,y,z,payload_kg\n1,2,3,4,-1\n", "negative mass"),
        ("j1,x,x,y,z\n1,2,3,4,5\n", "column 'x' twice"),
    ],
)
def test_bad_files_get_precise_errors(text, message):
    with pytest.raises(MeasurementFileError, match=message.replace("(", r"\(").replace("[", r"\[")):
        parse_measurements(text, name="cal.csv")


def test_joint_count_checked_against_robot():
    with pytest.raises(MeasurementFileError, match="the file has 2 joint columns, the robot has 6"):
        parse_measurements("j1,j2,x,y,z\n1,2,3,4,5\n", n_joints=6)


def test_missing_file_is_named(tmp_path):
    with pytest.raises(MeasurementFileError, match="no such file"):
        read_measurements(tmp_path / "nope.csv")


def test_unknown_rotation_convention():
    with pytest.raises(MeasurementFileError, match="rotation convention 'abc' unknown"):
        parse_measurements(GOOD, rotation="abc")


@settings(max_examples=300, deadline=None)
@given(st.text(alphabet=st.sampled_from(list("j123xyzr,.-e#\n abn_kgpload0")), max_size=120))
def test_arbitrary_text_never_crashes(text):
    """Whatever the bytes, the reader either parses or raises MeasurementFileError."""
    try:
        m = parse_measurements(text)
    except MeasurementFileError:
        return
    assert np.all(np.isfinite(m.joints)) and np.all(np.isfinite(m.positions))


@settings(max_examples=100, deadline=None)
@given(
    st.integers(1, 8),
    st.integers(1, 20),
    st.booleans(),
    st.integers(0, 2**31 - 1),
)
def test_format_then_parse_is_identity(nj, n, with_angles, seed):
    rng = np.random.default_rng(seed)
    m = MeasurementSet(
        joints=rng.uniform(-6, 6, (n, nj)),
        positions=rng.uniform(-5, 5, (n, 3)),
        angles=rng.uniform(-3, 3, (n, 3)) if with_angles else None,
    )
    back = parse_measurements(format_measurements(m))
    np.testing.assert_allclose(back.joints, m.joints, atol=1e-7)
    np.testing.assert_allclose(back.positions, m.positions, atol=1e-8)


def test_bare_carriage_returns_end_lines_like_a_file():
    """Found by the parser fuzzer: '\\r' alone must not crash the text parser."""
    m = parse_measurements("j1,x,y,z\r1,2,3,4\r\n5,6,7,8\n")
    assert len(m) == 2
    with pytest.raises(MeasurementFileError):
        parse_measurements('j1,x,y,z\n"1,2,3,4\n')


def test_a_0d_or_1d_joints_array_is_a_value_error():
    for joints in (np.array(1.0), np.zeros(3)):
        with pytest.raises(ValueError, match=r"joints must be \(N, n\)"):
            MeasurementSet(joints, np.zeros((1, 3)))


@pytest.mark.parametrize(("text", "line"), [
    ("j1,x,y\n1,2,3\n", 1),
    ("# c\n\n# c\nj1,x,y\n1,2,3\n", 4),
    ("# c\nj1,j3,x,y,z\n1,2,3,4,5\n", 2),
    ("j1,x,y,z,rx\n1,2,3,4,5\n", 1),
    ("\nj1,x,y,z,foo\n1,2,3,4,5\n", 2),
    ("j1,x,x,y,z\n1,2,3,4,5\n", 1),
    ("j1,,x,y,z\n1,2,3,4,5\n", 1),
    ("x,y,z\n1,2,3\n", 1),
])
def test_header_errors_name_the_header_line(text, line):
    with pytest.raises(MeasurementFileError, match=rf"^cal\.csv: line {line}: "):
        parse_measurements(text, name="cal.csv")


def test_the_documented_error_messages_are_the_printed_ones():
    """docs/measurement-files.md shows these messages: they are what the reader says."""
    from pathlib import Path

    doc = (Path(__file__).parents[2] / "docs" / "measurement-files.md").read_text()
    block = doc.split("Errors name the file, the line and the column, for example")[1]
    shown = block.split("```")[1].strip().splitlines()
    rows = "".join(f"{k},0,0,{k},0,{k},1,2,3\n" for k in range(2, 17))
    files = [
        "j1,j2,j3,j4,j5,j6,x,y,z\n" + rows + '1,2,3,4,5,6,7,"12,5",9\n',
        "j1,j2,j3,j4,j5,x,y,z\n1,2,3,4,5,6,7,8\n",
        "j1,j2,j3,j4,j5,j6,x,y,z,rx,ry\n1,2,3,4,5,6,7,8,9,10,11\n",
    ]
    printed = []
    for text in files:
        with pytest.raises(MeasurementFileError) as exc:
            parse_measurements(text, name="cal.csv", n_joints=6)
        printed.append(str(exc.value))
    assert shown == printed
