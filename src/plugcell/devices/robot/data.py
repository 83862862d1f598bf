"""The Data field of an ACTIVATE string ↔ typed process data (thesis 5.2.1.3, 4.1.3.2).

A robot program writes its data as text — ``500`` (SnapShot's exposure time),
``550,1100`` (Drill's feed and speed), a POSITION as ``x,y,z,a,b,c`` — and gets
data back in its ``ext_cmd_*`` variables.  The partner's catalogue says what the
text must be (type and size, appendix F.5), so:

* :func:`data_from_text` reads the text as the command's declared input, or
  raises :class:`DataTextError` saying exactly why it does not fit;
* :func:`result_data` turns a command's output into the ``DATA``/``TEXT`` (or
  ``FRAME``) message for the program, or explains why it cannot go (a 480×640
  image does not fit a controller's 4096 data values — the command still
  succeeded, the data stays with the service).

Text form: values separated by ``,`` (blanks around them are ignored), matrix
rows by ``;`` (or a flat list of the right count, row-major); Boolean as
``TRUE``/``FALSE``/``1``/``0``; Integer and Byte as whole numbers (``550.000000``,
how PDL writes a REAL, counts as whole); String as the text itself for one
string, comma-separated for several.  The thesis's ``##, 500`` (5.2.3.6): a
leading comma before the first value is ignored.
"""

from __future__ import annotations

import math
import re
from typing import Any

import numpy as np

from plugcell.devices.robot.protocol import ResultData
from plugcell.framework.data import DataError, describe, from_data, to_data
from plugcell.framework.messages import Command, DataTypes

__all__ = ["DataTextError", "data_from_text", "result_data"]

_NUMBER = re.compile(r"[+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?\Z")


class DataTextError(ValueError):
    """Data text that does not fit a command's declared input."""


def _value(token: str, data_type: DataTypes, position: int) -> Any:
    t = token.strip()
    if not t:
        raise ValueError(f"value {position} is empty")
    if data_type is DataTypes.Boolean:
        upper = t.upper()
        if upper in ("TRUE", "1"):
            return True
        if upper in ("FALSE", "0"):
            return False
        raise ValueError(f"value {position} {t[:30]!r} is not a Boolean (TRUE or FALSE)")
    if not _NUMBER.match(t):
        raise ValueError(f"value {position} {t[:30]!r} is not a number")
    x = float(t)
    if not math.isfinite(x):
        raise ValueError(f"value {position} {t[:30]!r} is out of range")
    if data_type in (DataTypes.Integer, DataTypes.Byte):
        if not x.is_integer():
            raise ValueError(f"value {position} {t[:30]!r} is not a whole number "
                             f"({data_type.value})")
        return int(x)
    return x


def _shape(items: list[Any], size: tuple[int, ...]) -> Any:
    """A flat list given for a fixed n-D size is read row-major."""
    if len(size) > 1 and all(d > 0 for d in size) and len(items) == math.prod(size):
        return np.asarray(items).reshape(size)
    return items


def data_from_text(text: str, command: Command, device: str) -> Any:
    """The input of ``command`` at ``device`` read from ``text`` (None for no data)."""
    what = f"{device} {command.name}"
    declared = describe(command.input_data_type, command.input_data_size)
    body = text.strip()
    if not command.takes_input:
        if body:
            raise DataTextError(f"{what} takes no data, got {body[:60]!r}")
        return None
    data_type = command.input_data_type
    assert data_type is not None
    size = tuple(command.input_data_size)
    if not body:
        raise DataTextError(f"{what} expects {declared}, got no data")
    if data_type is DataTypes.String:
        value: Any = [body] if size == (1,) else [s.strip() for s in body.split(",")]
    else:
        if body.startswith(","):  # "ACTIVATE CAMERA #SnapShot##, 500" (5.2.3.6)
            body = body[1:].strip()
        rows: list[list[Any]] = []
        position = 0
        try:
            for row in body.split(";"):
                values = []
                for token in row.split(","):
                    position += 1
                    values.append(_value(token, data_type, position))
                rows.append(values)
        except ValueError as exc:
            raise DataTextError(f"{what}: data {body[:60]!r} does not fit {declared}: "
                                f"{exc}") from None
        if len(rows) == 1:
            value = _shape(rows[0], size)
        elif len({len(r) for r in rows}) != 1:
            raise DataTextError(f"{what}: data {body[:60]!r} does not fit {declared}: "
                                "rows of different lengths")
        else:
            value = rows
    try:
        if data_type is DataTypes.String:
            return _strings(value, size, what)
        return from_data(to_data(value, data_type, size, f"{what} input"))
    except DataError as exc:
        raise DataTextError(f"{what}: data {body[:60]!r} does not fit {declared}: "
                            f"{_why(exc)}") from None


def _strings(value: list[str], size: tuple[int, ...], what: str) -> np.ndarray:
    to_data(value, DataTypes.String, size, f"{what} input")
    arr = np.empty(len(value), dtype=object)
    arr[:] = value
    return arr


def _why(exc: DataError) -> str:
    """The reason of a DataError without its ``what:`` prefix."""
    text = str(exc)
    return text.split(": ", 1)[1] if ": " in text else text


def result_data(value: Any, capacity: int, text_capacity: int,
                frame: bool = False) -> tuple[ResultData | None, str]:
    """The message carrying ``value`` to the program, or ``(None, why not)``.

    Numbers (Boolean as 0/1) go as ``rows × cols`` (rows: the first dimension,
    cols: the product of the others), strings as text joined by ``,``.
    """
    if value is None:
        return None, ""
    arr = np.asarray(value)
    if arr.dtype.kind in "OUS":
        text = ",".join(str(s) for s in arr.reshape(-1))
        if len(text) > text_capacity:
            return None, (f"text of {len(text)} characters does not fit ext_cmd_text "
                          f"({text_capacity}): not sent to the controller")
        return ResultData(text=text, frame=frame), ""
    if arr.dtype.kind not in "biuf":
        return None, f"{arr.dtype} data cannot be sent to the controller"
    flat = arr.astype(float).reshape(-1)
    if flat.size > capacity:
        shape = "×".join(str(d) for d in arr.shape) or "1"
        return None, (f"{shape} data ({flat.size} values) does not fit ext_cmd_data "
                      f"({capacity}): not sent to the controller")
    if not np.all(np.isfinite(flat)):
        return None, "the data holds NaN or infinite values: not sent to the controller"
    rows = int(arr.shape[0]) if arr.ndim else 1
    cols = flat.size // rows if rows else 0
    return ResultData(rows, cols, tuple(float(v) for v in flat), frame=frame), ""
