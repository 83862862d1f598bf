"""Text → preset values of a program's variables (``VALUE`` lines of the protocol).

PDL keeps a program's taught points in its variable file; here the robot service
sends them with the RUN request, one ``VALUE <id> <name> <text>`` line each, in
the text WRITE prints (docs/robot-language.md): ``800,0,600,0,90,0`` for a
POSITION, ``TRUE``, ``42``, plain text for a STRING; an ARRAY as comma-separated
values, rows separated by ``;`` if its elements are POSITIONs, JOINTPOSs or
VECTORs.  The result is plain Python that ``Execution(values=...)`` converts
and checks against the declaration.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from plugcell.devices.robot.protocol import ProtocolError, parse_number
from plugcell.pdl.types import (
    BOOLEAN,
    INTEGER,
    JOINTPOS,
    POSITION,
    REAL,
    VECTOR,
    ArrayType,
    LangType,
    StringType,
)

__all__ = ["numbers_text", "rows_text", "value_from_text"]


def _numbers(text: str, what: str) -> list[float]:
    items = [t.strip() for t in text.split(",")] if text.strip() else []
    try:
        return [parse_number(t) for t in items]
    except ProtocolError as exc:
        raise ValueError(f"{what}: {exc}") from None


def _scalar(text: str, t: LangType) -> Any:
    token = text.strip()
    if isinstance(t, StringType):
        return text
    if t == BOOLEAN:
        upper = token.upper()
        if upper in ("TRUE", "1"):
            return True
        if upper in ("FALSE", "0"):
            return False
        raise ValueError(f"{token[:40]!r} is not a BOOLEAN (TRUE or FALSE)")
    if t == INTEGER:
        value = _numbers(token, "INTEGER")
        if len(value) != 1 or not float(value[0]).is_integer():
            raise ValueError(f"{token[:40]!r} is not an INTEGER")
        return int(value[0])
    if t == REAL:
        value = _numbers(token, "REAL")
        if len(value) != 1:
            raise ValueError(f"{token[:40]!r} is not a REAL")
        return value[0]
    if t in (POSITION, JOINTPOS, VECTOR):
        return _numbers(token, str(t))
    raise ValueError(f"a {t} cannot be given as text")


def value_from_text(text: str, t: LangType) -> Any:
    """The Python value of ``text`` for a variable of type ``t`` (ValueError if unreadable)."""
    if not isinstance(t, ArrayType):
        return _scalar(text, t)
    element = t.element
    if element in (POSITION, JOINTPOS, VECTOR):
        return [_scalar(row, element) for row in text.split(";")] if text.strip() else []
    if isinstance(element, StringType):
        return text.split(",")
    if ";" in text:
        return [[_scalar(v, element) for v in row.split(",")] for row in text.split(";")]
    items = [_scalar(v, element) for v in text.split(",")] if text.strip() else []
    dims = t.dims
    if len(dims) > 1 and all(d is not None for d in dims):
        total = 1
        for d in dims:
            total *= d or 0
        if len(items) == total:  # a flat list for a matrix: row-major
            for d in reversed(dims[1:]):
                items = [items[i : i + d] for i in range(0, len(items), d or 1)]
    return items


def numbers_text(values: Any) -> str:
    """Numbers as a value's text (``1500.000000,0.000000,…``: a POSITION, a JOINTPOS,
    or the data of an ACTIVATE string); 6 decimals, as WRITE prints a REAL."""
    return ",".join(f"{v:.6f}" for v in np.ravel(np.asarray(values, dtype=float)))


def rows_text(rows: Any) -> str:
    """Rows of numbers as the text of an ARRAY OF POSITION/JOINTPOS (rows joined by ``;``)."""
    return ";".join(numbers_text(r) for r in np.atleast_2d(np.asarray(rows, dtype=float)))
