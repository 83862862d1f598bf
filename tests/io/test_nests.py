"""Nest files: the writer writes only what the reader reads back unchanged."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from plugcell.io.nests import NestFileError, format_nests, parse_nests

TRIANGLE = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])


def test_a_name_with_a_comma_or_a_quote_round_trips():
    names = ["N1, left", 'say "hi"', "N3"]
    back_names, back = parse_nests(format_nests(names, TRIANGLE))
    assert back_names == names
    np.testing.assert_allclose(back, TRIANGLE)


@pytest.mark.parametrize(("names", "positions", "message"), [
    (["A", "B", "A"], TRIANGLE, "nest 'A' named twice"),
    (["A", "B"], TRIANGLE[:2], "2 nest(s); the drift watch needs at least 3"),
    (["A", "", "C"], TRIANGLE, "nest 2: empty name"),
    (["A", " B", "C"], TRIANGLE, "nest 2: name ' B' has blanks around it"),
    (["A", "#B", "C"], TRIANGLE, "nest 2: name '#B' starts with '#'"),
    (["A", "B\nC", "D"], TRIANGLE, "nest 2: name 'B\\nC' has a line break"),
    (["A", "B", "C"], np.zeros((3, 2)), "positions must be (3, 3)"),
    (["A", "B", "C"], [[0, 0, 0], [1, 1, 1], [np.nan, 0, 0]], "nest 3: position not finite"),
])
def test_the_writer_refuses_what_the_reader_would_refuse(names, positions, message):
    with pytest.raises(ValueError) as exc:
        format_nests(names, np.asarray(positions, float))
    assert message in str(exc.value)


def test_too_few_nests_message_claims_nothing_unchecked():
    with pytest.raises(NestFileError) as exc:
        parse_nests("name,x,y,z\nA,1,2,3\nB,4,5,6\n", "n.csv")
    assert str(exc.value) == "n.csv: 2 nest(s); the drift watch needs at least 3"


_name = st.text(st.characters(blacklist_categories=("Cs",), blacklist_characters="\r\n\x00"),
                min_size=1, max_size=8).filter(
    lambda s: s == s.strip() and s and not s.startswith("#"))


@settings(max_examples=150, deadline=None)
@given(st.lists(_name, min_size=3, max_size=8, unique=True), st.integers(0, 2**31 - 1))
def test_format_then_parse_is_identity(names, seed):
    pos = np.random.default_rng(seed).uniform(-5, 5, (len(names), 3))
    back_names, back = parse_nests(format_nests(names, pos, ("made, by a test",)))
    assert back_names == names
    np.testing.assert_allclose(back, pos, atol=1e-9)
