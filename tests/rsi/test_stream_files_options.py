"""``plugcell rsi files`` and ``plugcell egm files`` refuse a bad option naming it as the
user typed it: the option (not the configuration's field), the value in the option's own
unit (degrees or mm, not the SI value it becomes), and nothing is written."""

from __future__ import annotations

import math

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from plugcell.apps.cli import main

LIMITS = ("--max-step", "--max-offset", "--max-speed")
#: numbers a limit cannot be, as a user may type them
bad_number = st.one_of(
    st.floats(max_value=0.0, allow_nan=False).map(repr),
    st.integers(max_value=0).map(str),
    st.sampled_from(["nan", "inf", "-inf", "-0", "0.0", "-1e-9", "NaN"]),
)
good_number = st.floats(min_value=1e-3, max_value=1e3).map(lambda v: f"{v:g}")


def _refused(tmp_path, capsys, command: str, *argv: str) -> str:
    out = tmp_path / "out"
    assert main([command, "files", "--out", str(out), "--ip", "10.0.0.1", *argv]) == 2
    assert not out.exists()  # nothing written
    return capsys.readouterr().err


@given(command=st.sampled_from(["rsi", "egm"]), option=st.sampled_from(LIMITS),
       bad=bad_number)
@settings(max_examples=60, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
def test_a_bad_limit_is_named_as_typed_in_degrees(tmp_path, capsys, command, option, bad):
    err = _refused(tmp_path, capsys, command, f"{option}={bad}")  # "-inf": not an option
    assert f"{option} {bad!r}: {bad} deg is not a finite number > 0" in err, err


@given(command=st.sampled_from(["rsi", "egm"]), option=st.sampled_from(LIMITS),
       axis=st.integers(0, 5), bad=bad_number, good=good_number)
@settings(max_examples=60, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
def test_a_bad_cartesian_limit_names_its_axis_and_unit(tmp_path, capsys, command, option,
                                                       axis, bad, good):
    values = [good] * 6
    values[axis] = bad
    text = ",".join(values)
    kind = ["--correction", "cartesian"] if command == "rsi" else ["--mode", "pose"]
    err = _refused(tmp_path, capsys, command, *kind, f"{option}={text}")
    unit = "mm" if axis < 3 else "deg"
    assert f"{option} {text!r}: {bad} {unit} (axis {axis + 1}) is not a finite number > 0" \
        in err, err


@given(bad=st.one_of(st.integers(max_value=0), st.integers(min_value=10001)))
@settings(max_examples=30, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
def test_rsi_timeout_is_named_as_the_option(tmp_path, capsys, bad):
    err = _refused(tmp_path, capsys, "rsi", f"--timeout={bad}")
    assert f"--timeout {bad}: expected an integer 1..10000" in err, err


@given(bad=st.one_of(st.floats(max_value=0.0199, allow_nan=False), st.floats(min_value=60.01),
                     st.just(math.nan)))
@settings(max_examples=30, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
def test_egm_timeout_is_named_as_the_option_in_seconds(tmp_path, capsys, bad):
    err = _refused(tmp_path, capsys, "egm", f"--timeout={bad!r}")
    assert f"--timeout {bad:g}: expected 20 ms .. 60 s" in err, err


@given(bad=st.integers(max_value=100).filter(lambda v: v < 4 or v % 4))
@settings(max_examples=30, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
def test_egm_sample_rate_is_named_as_the_option(tmp_path, capsys, bad):
    err = _refused(tmp_path, capsys, "egm", f"--sample-ms={bad}")
    assert f"--sample-ms {bad}: expected a multiple of 4 ms" in err, err


@given(command=st.sampled_from(["rsi", "egm"]),
       bad=st.one_of(st.integers(max_value=-1), st.integers(min_value=65536)))
@settings(max_examples=30, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
def test_the_port_is_named_as_the_option(tmp_path, capsys, command, bad):
    err = _refused(tmp_path, capsys, command, f"--port={bad}")
    assert f"--port {bad}: expected a UDP port 1..65535" in err, err


@given(bad=st.one_of(st.floats(max_value=-1e-9, allow_nan=False), st.floats(min_value=60.01),
                     st.just(math.nan)))
@settings(max_examples=30, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
def test_rsi_settle_is_named_as_the_option(tmp_path, capsys, bad):
    err = _refused(tmp_path, capsys, "rsi", "--drives", "robot", f"--settle={bad!r}")
    assert f"--settle {bad:g}: expected 0..60 seconds" in err, err


def test_rsi_sentype_is_named_as_the_option(tmp_path, capsys):
    err = _refused(tmp_path, capsys, "rsi", "--sentype", "1x")
    assert "--sentype '1x': expected an XML name" in err, err


@pytest.mark.parametrize("option", ["--dio", "--dil"])
@pytest.mark.parametrize("bad", ["0", "-3", "x", "1.5"])
def test_an_io_word_needs_an_index_from_1(tmp_path, capsys, option, bad):
    """Before, ``--dio 0`` dropped the output word without a word and ``--dio -3`` wrote
    ``$OUT[-3]`` into the signal flow."""
    out = tmp_path / "out"
    with pytest.raises(SystemExit) as exit_:
        main(["rsi", "files", "--out", str(out), "--ip", "10.0.0.1", f"{option}={bad}"])
    assert exit_.value.code == 2 and not out.exists()
    signals = "$OUT" if option == "--dio" else "$IN"
    assert f"argument {option}: {bad!r}: expected the first {signals} index of the word, " \
        "an integer >= 1" in capsys.readouterr().err
