"""How WRITE (and ENCODE) turn values into text.

Defaults follow PDL: an INTEGER in its minimal width (``500``), a REAL in fixed
point with 6 decimals (``2.500000``), a BOOLEAN as ``TRUE``/``FALSE``, a STRING as
it is.  ``expr::w`` right-justifies in ``w`` columns and ``expr::w::p`` gives a
REAL ``p`` decimals.  POSITION, JOINTPOS, VECTOR and ARRAY values are written as
comma-separated numbers (the data field of an ``ACTIVATE`` string,
``#550,1100``), a POSITION as ``x,y,z,a,b,c`` (its configuration string is not
written).
"""

from __future__ import annotations

from typing import Any

from plugcell.pdl.values import ArrayValue, JointPos, Position, Vector

__all__ = ["DEFAULT_REAL_DECIMALS", "format_value"]

DEFAULT_REAL_DECIMALS = 6


def _real(x: float, decimals: int) -> str:
    text = f"{x:.{decimals}f}"
    if text.startswith("-") and float(text) == 0.0:
        text = text[1:]  # no "-0.000000"
    return text


def format_value(value: Any, width: int | None = None, precision: int | None = None) -> str:
    """One WRITE item as text."""
    decimals = DEFAULT_REAL_DECIMALS if precision is None else max(0, precision)
    if isinstance(value, bool):
        text = "TRUE" if value else "FALSE"
    elif isinstance(value, int):
        text = str(value)
    elif isinstance(value, float):
        text = _real(value, decimals)
    elif isinstance(value, str):
        text = value
    elif isinstance(value, Position):
        text = ",".join(_real(v, decimals) for v in value.as_tuple())
    elif isinstance(value, Vector):
        text = ",".join(_real(v, decimals) for v in (value.x, value.y, value.z))
    elif isinstance(value, JointPos):
        text = ",".join(_real(v, decimals) for v in value.joints)
    elif isinstance(value, ArrayValue):
        text = ",".join(format_value(v, None, precision) for v in value.data)
    else:  # pragma: no cover - the checker rejects anything else
        text = str(value)
    if width is not None and len(text) < width:
        text = text.rjust(width)
    return text
