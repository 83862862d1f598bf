"""plugcell.io.json_fields: a key's value of the type asked for, or an error naming the
dotted key and what was there; strict JSON values."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from plugcell.io.json_fields import (
    DocumentError,
    at,
    finite,
    flag,
    integer,
    number,
    numbers,
    strict,
    string,
    typename,
)
from plugcell.io.params import ParamsError

JSON = st.recursive(st.none() | st.booleans() | st.integers() | st.floats() | st.text(),
                    lambda c: st.lists(c, max_size=3)
                    | st.dictionaries(st.text(max_size=3), c, max_size=3), max_leaves=8)


def test_params_error_is_the_readers_error():
    assert ParamsError is DocumentError and issubclass(DocumentError, ValueError)


@given(JSON)
def test_number_takes_finite_numbers_only_and_names_the_key(x):
    doc = {"a": {"b": x}}
    try:
        value = float(x) if isinstance(x, int | float) and not isinstance(x, bool) else math.nan
    except OverflowError:  # an integer beyond float
        value = math.inf
    if math.isfinite(value):
        assert number(doc, "a", "b") == float(x)
    else:
        with pytest.raises(DocumentError) as err:
            number(doc, "a", "b")
        assert str(err.value) == f"a.b: expected a finite number, got {typename(x)}"


@given(JSON)
def test_integer_flag_string_take_their_type_only(x):
    doc = {"k": x}
    is_int = isinstance(x, int) and not isinstance(x, bool)
    for read, fits, what in ((integer, is_int, "an integer"),
                             (flag, isinstance(x, bool), "true or false"),
                             (string, isinstance(x, str), "a string")):
        if fits:
            assert read(doc, "k") is x
        else:
            with pytest.raises(DocumentError, match=f"^k: expected {what}, got "):
                read(doc, "k")


def test_at_names_the_missing_key_or_the_container_that_is_not_an_object():
    doc = {"a": {"b": [1, 2]}}
    assert at(doc, "a", "b") == [1, 2]
    assert at(doc, "a", "c", default=None) is None
    with pytest.raises(DocumentError, match=r"^missing key 'a\.c'$"):
        at(doc, "a", "c")
    with pytest.raises(DocumentError, match=r"^a\.b: expected an object, got a list$"):
        at(doc, "a", "b", "c")


def test_numbers_names_the_entry():
    assert numbers({"v": [1, 2.5]}, "v") == (1.0, 2.5)
    with pytest.raises(DocumentError, match=r"^v\[1\]: expected a finite number, got "
                                            r"the string 'x'$"):
        numbers({"v": [1, "x"]}, "v")
    with pytest.raises(DocumentError, match=r"^v: expected a list of numbers, got null$"):
        numbers({"v": None}, "v")
    with pytest.raises(DocumentError, match=r"^w: expected a finite number, got the number "
                                            r"inf$"):
        finite(float("inf"), "w")


def test_strict_makes_strict_json():
    x = {"a": (1.0, float("nan"), np.float64(-np.inf)), "b": [np.int64(3), "s", None]}
    assert strict(x) == {"a": [1.0, None, None], "b": [3, "s", None]}
    json.dumps(strict(x), allow_nan=False)
