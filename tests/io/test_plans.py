"""The plan file: round trips, measurement files accepted, precise errors, any text."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from plugcell.io.plans import (
    MeasurementPlan,
    PlanFileError,
    format_plan,
    parse_plan,
    read_plan,
    write_plan,
)


def test_round_trip(tmp_path):
    rng = np.random.default_rng(1)
    plan = MeasurementPlan(rng.uniform(-3, 3, (25, 6)), np.repeat([0.0, 18.0, 36.0], [5, 10, 10]))
    write_plan(tmp_path / "p.csv", plan, comments=["two\nlines"])
    back = read_plan(tmp_path / "p.csv", n_joints=6)
    np.testing.assert_allclose(back.joints, plan.joints, rtol=1e-9, atol=1e-12)
    np.testing.assert_array_equal(back.payload_kg, plan.payload_kg)
    assert (tmp_path / "p.csv").read_text().startswith("# two\n# lines\nj1,")


def test_a_measurement_file_is_a_plan():
    text = "# c\nj1,j2,x,y,z,rx,ry,rz,payload_kg\n10,20,1,2,3,4,5,6,18\n-10,5,0,0,0,0,0,0,0\n"
    p = parse_plan(text)
    np.testing.assert_allclose(p.joints, np.radians([[10, 20], [-10, 5]]))
    np.testing.assert_array_equal(p.payload_kg, [18, 0])
    assert parse_plan("j2,j1\n1,2\n").joints.tolist() == np.radians([[2, 1]]).tolist()
    assert parse_plan("j1\n1\n").payload_kg is None


@pytest.mark.parametrize("text, message", [
    ("", "no header line"),
    ("# only a comment\n", "no header line"),
    ("x,y\n1,2\n", "no joint columns"),
    ("j1,j3\n1,2\n", "without gaps"),
    ("j1,foo\n1,2\n", "unknown columns ['foo']"),
    ("j1,j1\n1,2\n", "names column 'j1' twice"),
    ("j1,\n1,2\n", "header column 2 is empty"),
    ("j1,j2\n", "no rows"),
    ("j1,j2\n1\n", "line 2: expected 2 values, got 1"),
    ("j1,j2\n1,abc\n", "line 2, column 'j2': not a number: 'abc'"),
    ("j1,j2\n1,nan\n", "line 2, column 'j2': not finite"),
    ("j1,payload_kg\n1,-2\n", "line 2, column 'payload_kg': negative mass -2"),
])
def test_errors_name_the_line_and_column(text, message):
    with pytest.raises(PlanFileError, match=r"^plan\.csv: ") as exc:
        parse_plan(text, name="plan.csv")
    assert message in str(exc.value)


def test_joint_count_checked(tmp_path):
    (tmp_path / "p.csv").write_text("j1,j2\n1,2\n")
    with pytest.raises(PlanFileError, match="2 joint columns, the robot has 6"):
        read_plan(tmp_path / "p.csv", n_joints=6)
    with pytest.raises(PlanFileError, match="no such file"):
        read_plan(tmp_path / "missing.csv")
    (tmp_path / "b.csv").write_bytes(b"\xff\xfe j1")
    with pytest.raises(PlanFileError, match="not a UTF-8"):
        read_plan(tmp_path / "b.csv")


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 8), st.lists(st.floats(-720, 720, allow_nan=False), min_size=1,
                                   max_size=40), st.booleans())
def test_round_trip_property(n, values, with_payload):
    rows = max(1, len(values) // n)
    q = np.radians(np.resize(np.asarray(values), (rows, n)))
    m = np.abs(np.resize(np.asarray(values), rows)) if with_payload else None
    back = parse_plan(format_plan(MeasurementPlan(q, m)))
    np.testing.assert_allclose(back.joints, q, rtol=1e-9, atol=1e-12)
    if with_payload:
        np.testing.assert_allclose(back.payload_kg, m, rtol=1e-9)


@settings(max_examples=200, deadline=None)
@given(st.text(alphabet=st.sampled_from(list("j1234567890,.-e\n\r# xyzpayload_kgnaif\"")),
               max_size=80))
def test_any_text_is_a_plan_or_a_clear_error(text):
    try:
        p = parse_plan(text, name="t.csv")
    except PlanFileError as exc:
        assert str(exc).startswith("t.csv")
    else:
        assert p.joints.ndim == 2 and np.all(np.isfinite(p.joints))


def test_every_measurement_column_is_accepted_and_passed_over():
    """A measurement file with any of its optional columns is a plan (#1 of the io review)."""
    from plugcell.io.measurements import MeasurementSet, format_measurements

    rng = np.random.default_rng(4)
    m = MeasurementSet(rng.uniform(-3, 3, (5, 6)), rng.uniform(-2, 2, (5, 3)),
                       angles=rng.uniform(-3, 3, (5, 3)), payload_kg=np.full(5, 18.0),
                       temperature_c=np.full(5, 21.5))
    p = parse_plan(format_measurements(m), n_joints=6)
    np.testing.assert_allclose(p.joints, m.joints, rtol=1e-8, atol=1e-9)
    np.testing.assert_array_equal(p.payload_kg, m.payload_kg)
    p = parse_plan("j1,x,y,z,temperature_c\n10,1,2,3,20\n")
    np.testing.assert_allclose(p.joints, np.radians([[10]]))
    with pytest.raises(PlanFileError, match=r"unknown columns \['speed'\]; expected j1\.\.jn"):
        parse_plan("j1,speed\n1,2\n")


def test_a_prismatic_joint_is_read_and_written_in_mm():
    """``joint_scale`` as for measurement files: a track's 1500 mm is 1.5 m, not 1500°."""
    scale = np.array([1e-3, np.pi / 180])  # a linear track, then a revolute joint
    p = parse_plan("j1,j2\n1500,90\n", joint_scale=scale)
    np.testing.assert_allclose(p.joints, [[1.5, np.pi / 2]])
    text = format_plan(p, joint_scale=scale)
    assert text.splitlines()[1] == "1500,90"
    with pytest.raises(PlanFileError, match=r"^p\.csv: line 1: joint_scale has 3 entries"):
        parse_plan("j1,j2\n1,2\n", name="p.csv", joint_scale=[1, 1, 1])


def test_a_prismatic_plan_file_round_trips(tmp_path):
    scale = np.array([1e-3, np.pi / 180, np.pi / 180])
    plan = MeasurementPlan(np.array([[2.25, 0.5, -1.0], [0.0, 1.0, 2.0]]), np.array([0.0, 5.0]))
    write_plan(tmp_path / "p.csv", plan, joint_scale=scale)
    assert (tmp_path / "p.csv").read_text().splitlines()[1].startswith("2250,")
    back = read_plan(tmp_path / "p.csv", n_joints=3, joint_scale=scale)
    np.testing.assert_allclose(back.joints, plan.joints, rtol=1e-9, atol=1e-12)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.booleans(), min_size=1, max_size=7),
       st.lists(st.floats(-3000, 3000, allow_nan=False), min_size=1, max_size=40))
def test_round_trip_with_prismatic_joints_property(prismatic, values):
    n = len(prismatic)
    scale = np.where(prismatic, 1e-3, np.pi / 180)
    q = np.resize(np.asarray(values), (max(1, len(values) // n), n)) * scale
    back = parse_plan(format_plan(MeasurementPlan(q), joint_scale=scale), joint_scale=scale)
    np.testing.assert_allclose(back.joints, q, rtol=1e-9, atol=1e-12)
