"""``--sine`` of ``plugcell rsi run`` and ``plugcell egm run``: one parser for both."""

from __future__ import annotations

import contextlib
import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from plugcell.apps.cli import CommandError
from plugcell.apps.commands.streaming import sine_or_hold
from plugcell.devices.robot.stream.source import Hold, SineOffset

AXES = ("A1", "A2", "A3", "A4", "A5", "A6")


def deg(i: int) -> float:
    return math.pi / 180


def test_no_sine_holds_and_a_sine_swings_the_named_axis_in_si():
    assert isinstance(sine_or_hold(None, AXES, deg), Hold)
    assert isinstance(sine_or_hold("", AXES, deg), Hold)
    source = sine_or_hold("A6:2:4", AXES, deg)
    assert isinstance(source, SineOffset)
    assert (source.axis, source.period) == (5, 4.0)
    assert source.amplitude == pytest.approx(2 * math.pi / 180)


@pytest.mark.parametrize(("text", "message"), [
    ("A6:2", "expected AXIS:AMPLITUDE:PERIOD"),
    ("A6:two:4", "expected AXIS:AMPLITUDE:PERIOD"),
    ("Q:1:1", "axis 'Q' is not one of A1"),
    ("A1:1:0", "the period must be > 0"),
    ("A4:1:1", "no rotation here"),
])
def test_a_bad_sine_is_one_line_naming_what_is_wrong(text: str, message: str):
    with pytest.raises(CommandError, match=message):
        sine_or_hold(text, AXES, deg, lambda i: "no rotation here" if i >= 3 else "")


@given(st.text(max_size=30))
def test_any_text_is_a_source_or_a_command_error(text: str):
    with contextlib.suppress(CommandError):  # anything else escaping fails the test
        assert isinstance(sine_or_hold(text, AXES, deg), Hold | SineOffset)
