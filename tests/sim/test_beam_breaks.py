"""Beam breaks from text (``plugcell path run --beam-break``, ``plugcell serve tracker
--param beam_breaks=…``): what parses, what is refused and why, and the ``blocked(t)``."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from plugcell.sim.beam_breaks import blocked, parse_beam_breaks
from plugcell.sim.drivers.tracker import SimulatedTrackerDriver

finite = st.floats(0, 1e6, allow_nan=False, allow_infinity=False)


@given(st.lists(st.tuples(finite, finite.filter(lambda d: d > 0)), max_size=5))
@settings(max_examples=80, deadline=None)
def test_what_is_written_is_read(pairs):
    texts = [f"{a!r}:{d!r}" for a, d in pairs]
    assert parse_beam_breaks(texts) == tuple(pairs)


@given(st.text(max_size=20))
@settings(max_examples=200, deadline=None)
def test_any_text_parses_or_is_refused_naming_it(text):
    try:
        ((a, d),) = parse_beam_breaks([text])
    except ValueError as exc:
        assert str(exc).startswith(f"{text!r}: expected START:DURATION in seconds")
    else:
        assert math.isfinite(a) and math.isfinite(d) and a >= 0 and d > 0


@pytest.mark.parametrize("text", ["1", "1:", ":1", "-1:1", "1:0", "1:-2", "nan:1", "1:inf",
                                  "a:b", "1:2:3"])
def test_bad_breaks_are_refused(text):
    with pytest.raises(ValueError, match="expected START:DURATION in seconds"):
        parse_beam_breaks([text])


def test_blocked_is_the_half_open_windows():
    b = blocked(parse_beam_breaks(["1:0.5", "3:1"]))
    assert [b(t) for t in (0.99, 1.0, 1.49, 1.5, 3.0, 3.99, 4.0)] == \
        [False, True, True, False, True, True, False]


def test_the_simulated_tracker_takes_them_as_a_parameter():
    driver = SimulatedTrackerDriver(beam_breaks="1.0:0.5,2:0.1")
    assert driver.blocked is not None and driver.blocked(1.2) and not driver.blocked(1.6)
    assert SimulatedTrackerDriver().blocked is None
    with pytest.raises(ValueError, match=r"beam_breaks '2': expected START:DURATION"):
        SimulatedTrackerDriver(beam_breaks="1:1,2")
