"""Typed data buffers: numpy arrays ↔ :class:`~plugcell.framework.messages.Data` (F.4, F.5).

The thesis carries process data as a generic ``Object`` that "can be converted to
the right types and sizes thanks to the descriptions given in the fields
Command.InputDataType/InputDataSize and OutputDataType/OutputDataSize" (5.2.1.3).
Here that conversion is explicit and checked:

* :func:`to_data` turns a Python/numpy value into a typed buffer of the declared
  type and size, refusing lossy conversions;
* :func:`check_data` verifies a received buffer against a declaration (type,
  rank, every dimension, byte length) — the recipient never trusts the sender;
* :func:`from_data` gives the n-D numpy array back (read-only, no copy).

Large frames travel without copies in Python (issue 20, §2): a received message's
buffers are read-only ``memoryview`` s into the payload Zenoh handed over
(:func:`plugcell.framework.codec.decode`), :func:`from_data` a read-only numpy view of
one, and :func:`to_data` of a *read-only* array (from :data:`VIEW_MIN_BYTES` up) a view
of that array — what a service forwards or streams is encoded straight from the array's
memory.  A *writeable* array is copied (``tobytes``) when it is converted: its owner may
reuse it at once.  A view keeps
what it looks at alive (a received payload, a sent array) as long as it is referenced,
and what is read-only stays so: nothing a view shows can change under it.
"""

from __future__ import annotations

import functools
import math
from typing import Any

import numpy as np

from plugcell.framework.messages import MAX_RANK, Data, DataTypes

#: Smallest read-only array :func:`to_data` takes as a view rather than copying: below
#: it a copy (``tobytes``) is cheaper than a view, whose creation and encoding cost a
#: few hundred nanoseconds more (measured: a 4 KiB frame's path 0.1 µs slower as a
#: view, a 16 KiB frame's 0.1 µs faster).
VIEW_MIN_BYTES = 8 * 1024

#: numpy dtype of each numeric DataType on the wire (little-endian, C order).
DTYPES: dict[DataTypes, np.dtype] = {
    DataTypes.Boolean: np.dtype("?"),
    DataTypes.Byte: np.dtype("u1"),
    DataTypes.Integer: np.dtype("<i4"),
    DataTypes.Double: np.dtype("<f8"),
}


class DataError(ValueError):
    """Data that does not match its declaration; the message is the precise reason."""


def size_text(size: tuple[int, ...]) -> str:
    """``(480, 640)`` → ``"[480, 640]"``, ``-1`` shown as ``*``, ``()`` as ``[any]``."""
    if not size:
        return "[any]"
    return "[" + ", ".join("*" if d < 0 else str(d) for d in size) + "]"


@functools.lru_cache(maxsize=1024)
def describe(data_type: DataTypes | None, size: tuple[int, ...]) -> str:
    """A declaration as people read it, e.g. ``Integer[1]`` or ``no data``."""
    if size == (0,):
        return "no data"
    name = data_type.value if data_type is not None else "?"
    return f"{name}{size_text(size)}"


def size_matches(actual: tuple[int, ...], declared: tuple[int, ...]) -> bool:
    """Whether an actual n-D shape satisfies a declared size (``-1`` any, ``()`` anything)."""
    if not declared:
        return True
    if len(actual) != len(declared):
        return False
    return all(d < 0 or a == d for a, d in zip(actual, declared, strict=True))


def _shape_for(value_shape: tuple[int, ...], declared: tuple[int, ...]) -> tuple[int, ...]:
    """The F.5 size of a value: a 0-d scalar is size ``(1,)``."""
    if value_shape == () and declared != ():
        return (1,)
    return value_shape


def to_data(
    value: Any, data_type: DataTypes | None, size: tuple[int, ...], what: str = "data"
) -> Data | None:
    """Convert ``value`` to a typed buffer declared as ``data_type``/``size``.

    ``None`` is the only valid value when the declaration is *no data* (``(0,)``).
    Integers are accepted for Double; values must fit Integer (int32) and Byte
    (0…255); floats are never silently truncated; Boolean accepts only booleans.
    Raises :class:`DataError` with the precise reason.
    """
    if size == (0,):
        if value is None:
            return None
        raise DataError(f"{what}: no data expected, got {type(value).__name__}")
    if value is None:
        raise DataError(f"{what}: {describe(data_type, size)} expected, got no data")
    if data_type is None:
        raise DataError(f"{what}: the declaration has a size but no data type")
    if isinstance(value, Data):
        check_data(value, data_type, size, what)
        return value
    if (  # fast path: an array of exactly the declared type and size
        type(value) is np.ndarray
        and value.dtype == DTYPES.get(data_type)
        and value.flags.c_contiguous
        and value.ndim
        and size_matches(value.shape, size)
    ):
        if value.flags.writeable or value.nbytes < VIEW_MIN_BYTES:  # inline: small frames
            return Data(data_type, value.shape, value.tobytes())
        return Data(data_type, value.shape, _buffer_of(value))
    if data_type is DataTypes.String:
        return _strings_to_data(value, size, what)
    target = DTYPES[data_type]
    try:
        arr = np.asarray(value)
    except (ValueError, TypeError, OverflowError) as exc:
        raise DataError(f"{what}: cannot read {type(value).__name__} as an array: {exc}") from exc
    arr = _cast(arr, data_type, target, what)
    shape = _shape_for(arr.shape, size)
    if len(shape) > MAX_RANK:
        raise DataError(f"{what}: rank {len(shape)} exceeds the maximum of {MAX_RANK}")
    if not size_matches(shape, size):
        raise DataError(
            f"{what}: size {size_text(shape)} does not match the declared {size_text(size)}"
        )
    return Data(data_type, shape, np.ascontiguousarray(arr).tobytes())


def _buffer_of(arr: np.ndarray) -> bytes | memoryview:
    """The bytes of a C-contiguous array: a read-only view of a read-only array of at
    least :data:`VIEW_MIN_BYTES` (no copy — nobody can change it through this array, and
    its owner promised not to through another), else a copy (a writeable array's owner
    may reuse it as soon as it is posted)."""
    if arr.flags.writeable or arr.nbytes < VIEW_MIN_BYTES:
        return arr.tobytes()
    return memoryview(arr).cast("B")


def _cast(arr: np.ndarray, data_type: DataTypes, target: np.dtype, what: str) -> np.ndarray:
    kind = arr.dtype.kind
    if arr.dtype == target:
        return arr
    if data_type is DataTypes.Boolean:
        if kind != "b":
            raise DataError(f"{what}: Boolean expected, got {arr.dtype} values")
        return arr.astype(target)
    if kind not in "iuf":
        raise DataError(f"{what}: {data_type.value} expected, got {arr.dtype} values")
    if data_type is DataTypes.Double:
        return arr.astype(target)
    if kind == "f":
        raise DataError(f"{what}: {data_type.value} expected, got {arr.dtype} values")
    info = np.iinfo(target)
    if arr.size and (int(arr.min()) < info.min or int(arr.max()) > info.max):
        raise DataError(f"{what}: values outside the {data_type.value} range {info.min}…{info.max}")
    return arr.astype(target)


def _strings_to_data(value: Any, size: tuple[int, ...], what: str) -> Data:
    if isinstance(value, str):
        items, shape = [value], (1,)
    else:
        arr = value if isinstance(value, np.ndarray) else _object_array(value, what)
        if arr.dtype.kind not in "UO" or not all(isinstance(s, str) for s in arr.reshape(-1)):
            raise DataError(f"{what}: String expected, got {arr.dtype} values")
        shape = _shape_for(arr.shape, size)
        items = [str(s) for s in arr.reshape(-1)]
    if not size_matches(shape, size):
        raise DataError(
            f"{what}: size {size_text(shape)} does not match the declared {size_text(size)}"
        )
    return Data(DataTypes.String, shape, items)


def _object_array(value: Any, what: str) -> np.ndarray:
    """Nested lists of str as an object array (numpy's ``<U`` would drop trailing NULs)."""
    try:
        probe = np.asarray(value, dtype=object)
    except ValueError as exc:
        raise DataError(f"{what}: cannot read {type(value).__name__} as an array: {exc}") from exc
    return probe


def check_data(
    data: Data | None, data_type: DataTypes | None, size: tuple[int, ...], what: str = "data"
) -> None:
    """Verify a received buffer against a declaration; raise :class:`DataError` if it lies."""
    if size == (0,):
        if data is not None:
            raise DataError(f"{what}: no data expected, got {describe(data.type, data.size)}")
        return
    if data is None:
        raise DataError(f"{what}: {describe(data_type, size)} expected, got no data")
    if data.type is not data_type:
        raise DataError(
            f"{what}: type {data.type.value} does not match the declared "
            f"{data_type.value if data_type else None}"
        )
    if not size_matches(data.size, size):
        raise DataError(
            f"{what}: size {size_text(data.size)} does not match the declared {size_text(size)}"
        )
    count = math.prod(data.size)
    if data.type is DataTypes.String:
        if not isinstance(data.buffer, list):
            raise DataError(f"{what}: String data must carry a list of strings")
        if len(data.buffer) != count:
            raise DataError(
                f"{what}: {len(data.buffer)} strings for size {size_text(data.size)} ({count})"
            )
        return
    buffer = data.buffer
    if isinstance(buffer, memoryview):
        if buffer.format != "B" or not buffer.c_contiguous:
            raise DataError(f"{what}: {data.type.value} data must carry a byte buffer")
    elif not isinstance(buffer, bytes):
        raise DataError(f"{what}: {data.type.value} data must carry a byte buffer")
    expected = count * DTYPES[data.type].itemsize
    if len(buffer) != expected:
        raise DataError(
            f"{what}: buffer of {len(buffer)} bytes does not match "
            f"{describe(data.type, data.size)} ({expected} bytes)"
        )
    if data.type is DataTypes.Boolean and _not_boolean(buffer):
        raise DataError(f"{what}: Boolean buffer holds bytes other than 0 and 1")


def _not_boolean(buffer: bytes | memoryview) -> bool:
    """Whether a Boolean buffer holds a byte other than 0 and 1 (without copying it)."""
    if isinstance(buffer, bytes):
        return bool(buffer.translate(None, b"\x00\x01"))
    return bool(buffer) and int(np.frombuffer(buffer, np.uint8).max()) > 1


def from_data(data: Data | None) -> np.ndarray | None:
    """The n-D array carried by a checked buffer: for numbers a read-only view of the
    buffer (no copy — of a received message, a view into the payload it came in)."""
    if data is None:
        return None
    buffer = data.buffer
    if data.type is DataTypes.String:
        arr = np.empty(len(buffer), dtype=object)
        arr[:] = buffer
        return arr.reshape(data.size)
    if isinstance(buffer, memoryview) and not buffer.readonly:
        buffer = buffer.toreadonly()  # a view of someone's writeable memory: read it only
    return np.frombuffer(buffer, dtype=DTYPES[data.type]).reshape(data.size)


_described = functools.lru_cache(maxsize=1024)(describe)
""":func:`describe` of a buffer's type and size (a tuple), remembered: streams repeat one."""


def summary(data: Data | None, limit: int = 16) -> str:
    """A short text for journals and logs: the declaration and, if small, the values."""
    if data is None:
        return ""
    head = _described(data.type, data.size)
    if len(data.buffer) > limit * 8 or math.prod(data.size) > limit:
        return head
    if data.type is DataTypes.Byte and isinstance(data.buffer, (bytes, memoryview)):
        return f"{head} {list(data.buffer)}"  # the same text, without numpy (streams)
    try:
        arr = from_data(data)
    except (ValueError, TypeError):
        return head
    assert arr is not None
    return f"{head} {arr.reshape(-1).tolist()}"


def to_json_value(data: Data | None, max_items: int = 1000) -> Any:
    """A JSON-friendly view: the values as nested lists, or a summary if large."""
    if data is None:
        return None
    count = math.prod(data.size)
    arr = from_data(data)
    assert arr is not None
    out: dict[str, Any] = {"type": data.type.value, "size": list(data.size)}
    if count <= max_items:
        out["value"] = arr.tolist()
    elif data.type is not DataTypes.String:
        out.update(min=arr.min().item(), max=arr.max().item(), mean=float(arr.mean()))
    return out
