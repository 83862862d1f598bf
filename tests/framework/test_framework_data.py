"""Typed data buffers checked against the command's declared type and n-D size (F.4, F.5)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from plugcell.framework.data import (
    DTYPES,
    DataError,
    check_data,
    describe,
    from_data,
    size_matches,
    summary,
    to_data,
)
from plugcell.framework.messages import Data, DataTypes

pytestmark = pytest.mark.timeout(120)

NUMERIC = [DataTypes.Boolean, DataTypes.Byte, DataTypes.Integer, DataTypes.Double]


@settings(max_examples=200, deadline=None)
@given(
    st.sampled_from(NUMERIC).flatmap(
        lambda t: st.tuples(
            st.just(t), hnp.arrays(DTYPES[t], hnp.array_shapes(min_dims=1, max_dims=4, max_side=6))
        )
    )
)
def test_arrays_round_trip_exactly(case):
    data_type, arr = case
    declared = tuple(-1 for _ in arr.shape)
    data = to_data(arr, data_type, declared)
    check_data(data, data_type, declared)
    back = from_data(data)
    assert back.dtype == DTYPES[data_type] and back.shape == arr.shape
    np.testing.assert_array_equal(back, arr)


@settings(max_examples=100, deadline=None)
@given(st.lists(st.text(max_size=10), min_size=1, max_size=6))
def test_strings_round_trip(items):
    data = to_data(items, DataTypes.String, (len(items),))
    assert from_data(data).tolist() == items


@settings(max_examples=200, deadline=None)
@given(st.lists(st.integers(0, 6), min_size=1, max_size=4), st.data())
def test_size_matching_follows_f5(shape, draw):
    declared = tuple(draw.draw(st.sampled_from([d, -1])) for d in shape)
    assert size_matches(tuple(shape), declared)
    assert size_matches(tuple(shape), ())
    assert not size_matches((*shape, 1), declared)
    bigger = tuple(d + 1 for d in shape)
    assert size_matches(bigger, declared) == all(d == -1 for d in declared)


def test_scalar_is_size_one():
    data = to_data(500, DataTypes.Integer, (1,))
    assert data.size == (1,) and from_data(data).tolist() == [500]


def test_image_declaration():
    img = np.zeros((480, 640), np.uint8)
    assert to_data(img, DataTypes.Byte, (480, 640)).size == (480, 640)
    with pytest.raises(
        DataError, match=r"size \[640, 480\] does not match the declared \[480, 640\]"
    ):
        to_data(img.T, DataTypes.Byte, (480, 640))


@pytest.mark.parametrize(
    ("value", "data_type", "size", "reason"),
    [
        (1.5, DataTypes.Integer, (1,), "Integer expected, got float64"),
        ([1, 2, 3], DataTypes.Integer, (2,), r"size \[3\] does not match the declared \[2\]"),
        (300, DataTypes.Byte, (1,), "outside the Byte range"),
        (2**40, DataTypes.Integer, (1,), "outside the Integer range"),
        (1, DataTypes.Boolean, (1,), "Boolean expected"),
        (True, DataTypes.Integer, (1,), "Integer expected, got bool"),
        ("x", DataTypes.Double, (1,), "Double expected"),
        (None, DataTypes.Integer, (1,), r"Integer\[1\] expected, got no data"),
        (5, None, (0,), "no data expected"),
        ([[1, 2], [3]], DataTypes.Integer, (2,), "cannot read"),
    ],
)
def test_conversion_refuses_with_reason(value, data_type, size, reason):
    with pytest.raises(DataError, match=reason):
        to_data(value, data_type, size, "input")


@pytest.mark.parametrize(
    ("data", "reason"),
    [
        (
            Data(DataTypes.Double, (1,), b"\0" * 8),
            "type Double does not match the declared Integer",
        ),
        (Data(DataTypes.Integer, (2,), b"\0" * 8), r"size \[2\] does not match the declared \[1\]"),
        (
            Data(DataTypes.Integer, (1,), b"\0" * 3),
            r"buffer of 3 bytes does not match Integer\[1\]",
        ),
        (Data(DataTypes.Integer, (1,), ["1"]), "must carry a byte buffer"),
        (None, r"Integer\[1\] expected, got no data"),
    ],
)
def test_received_buffers_are_checked(data, reason):
    with pytest.raises(DataError, match=reason):
        check_data(data, DataTypes.Integer, (1,))


def test_boolean_buffer_must_hold_zero_or_one():
    with pytest.raises(DataError, match="other than 0 and 1"):
        check_data(Data(DataTypes.Boolean, (2,), b"\x01\x02"), DataTypes.Boolean, (2,))


def test_strings_are_checked():
    with pytest.raises(DataError, match="2 strings for size"):
        check_data(Data(DataTypes.String, (3,), ["a", "b"]), DataTypes.String, (-1,))
    with pytest.raises(DataError, match="list of strings"):
        check_data(Data(DataTypes.String, (1,), b"a"), DataTypes.String, (1,))


def test_huge_declared_size_does_not_allocate():
    lie = Data(DataTypes.Double, (2**31 - 1, 2**31 - 1, 2**31 - 1), b"\0" * 8)
    with pytest.raises(DataError, match="does not match"):
        check_data(lie, DataTypes.Double, ())


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=24), st.sampled_from([DataTypes.Byte, DataTypes.Boolean]))
def test_summary_of_bytes_reads_like_the_values(buffer, data_type):
    """The journal's text of a small buffer lists its values (Byte without numpy, the
    same text the generic path gives); a large one only its declaration."""
    if data_type is DataTypes.Boolean:
        buffer = bytes(b & 1 for b in buffer)
    data = Data(data_type, (len(buffer),), buffer)
    text = summary(data)
    head = describe(data_type, (len(buffer),))
    if len(buffer) > 16:
        assert text == head
    else:
        assert text == f"{head} {from_data(data).tolist()}"
