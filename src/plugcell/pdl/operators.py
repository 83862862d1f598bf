"""Operator semantics, shared by the type checker, constant folding and the interpreter.

Precedence is PASCAL's (and PDL's): ``NOT``/unary minus, then ``* / DIV MOD AND``,
then ``+ - OR XOR``, then the comparisons (which do not chain).

* ``/`` always gives a REAL; ``DIV`` truncates towards zero and ``MOD`` has the
  sign of the dividend (``-7 DIV 2 = -3``, ``-7 MOD 2 = -1``), both INTEGER only.
* ``AND``, ``OR``, ``XOR``, ``NOT`` are logical on BOOLEAN and bitwise on INTEGER;
  both operands are always evaluated.
* INTEGER results must stay in 32 bits and REAL results finite, otherwise
  :class:`~.errors.OverflowProgramError`.
* ``+`` also concatenates STRINGs and adds VECTORs (``-`` subtracts them).
"""

from __future__ import annotations

import math
from typing import Any

from plugcell.pdl.errors import (
    DivisionByZeroError,
    Location,
    OverflowProgramError,
    TypeMismatchError,
)
from plugcell.pdl.types import (
    ANY_STRING,
    BOOLEAN,
    INT_MAX,
    INT_MIN,
    INTEGER,
    REAL,
    VECTOR,
    LangType,
    StringType,
    comparable,
    is_numeric,
)
from plugcell.pdl.values import Vector

__all__ = [
    "COMPARISONS",
    "apply_binary",
    "apply_unary",
    "binary_type",
    "checked_int",
    "checked_real",
    "int_div",
    "int_mod",
    "unary_type",
]

COMPARISONS = frozenset({"=", "<>", "<", "<=", ">", ">="})
_LOGICAL = frozenset({"AND", "OR", "XOR"})


# --------------------------------------------------------------------------- static types
def binary_type(op: str, left: LangType, right: LangType) -> LangType | None:
    """Result type of ``left op right``; ``None`` if the operands do not fit ``op``."""
    if op in COMPARISONS:
        ordering = op not in ("=", "<>")
        return BOOLEAN if comparable(left, right, ordering) else None
    if op in _LOGICAL:
        if left == right and left in (BOOLEAN, INTEGER):
            return left
        return None
    if op in ("DIV", "MOD"):
        return INTEGER if left == right == INTEGER else None
    if op == "/":
        return REAL if is_numeric(left) and is_numeric(right) else None
    if is_numeric(left) and is_numeric(right):
        return INTEGER if left == right == INTEGER else REAL
    if op == "+" and isinstance(left, StringType) and isinstance(right, StringType):
        return ANY_STRING
    if op in ("+", "-") and left == right == VECTOR:
        return VECTOR
    return None


def unary_type(op: str, operand: LangType) -> LangType | None:
    """Result type of a unary operator, ``None`` if it does not apply."""
    if op == "NOT":
        return operand if operand in (BOOLEAN, INTEGER) else None
    if is_numeric(operand) or operand == VECTOR:
        return operand
    return None


# --------------------------------------------------------------------------- run time
def checked_int(value: int, loc: Location | None) -> int:
    """``value`` if it fits 32 bits, else :class:`~.errors.OverflowProgramError`."""
    if not INT_MIN <= value <= INT_MAX:
        raise OverflowProgramError.at(loc, f"INTEGER overflow: {value} is outside 32 bits")
    return value


def checked_real(value: float, loc: Location | None) -> float:
    """``value`` if it is finite, else :class:`~.errors.OverflowProgramError`."""
    if not math.isfinite(value):
        raise OverflowProgramError.at(loc, f"REAL overflow ({value})")
    return value


def int_div(a: int, b: int, loc: Location | None) -> int:
    """``a DIV b``: truncation towards zero."""
    if b == 0:
        raise DivisionByZeroError.at(loc, "division by zero (DIV)")
    q = abs(a) // abs(b)
    return checked_int(q if (a >= 0) == (b >= 0) else -q, loc)


def int_mod(a: int, b: int, loc: Location | None) -> int:
    """``a MOD b``: the remainder with the sign of ``a``."""
    if b == 0:
        raise DivisionByZeroError.at(loc, "division by zero (MOD)")
    return a - b * int_div(a, b, loc)


def _number(value: Any, loc: Location | None) -> int | float:
    if isinstance(value, float):
        return checked_real(value, loc)
    return checked_int(value, loc)


def apply_binary(op: str, a: Any, b: Any, loc: Location | None = None) -> Any:
    """Evaluate ``a op b`` on run-time values (types already checked)."""
    if op in COMPARISONS:
        if op == "=":
            return a == b
        if op == "<>":
            return a != b
        if op == "<":
            return a < b
        if op == "<=":
            return a <= b
        if op == ">":
            return a > b
        return a >= b
    if op in _LOGICAL:
        if isinstance(a, bool):
            return (a and b) if op == "AND" else (a or b) if op == "OR" else (a != b)
        return (a & b) if op == "AND" else (a | b) if op == "OR" else (a ^ b)
    if op == "DIV":
        return int_div(a, b, loc)
    if op == "MOD":
        return int_mod(a, b, loc)
    if isinstance(a, str):
        return a + b
    if isinstance(a, Vector):
        sign = 1.0 if op == "+" else -1.0
        return Vector(
            checked_real(a.x + sign * b.x, loc),
            checked_real(a.y + sign * b.y, loc),
            checked_real(a.z + sign * b.z, loc),
        )
    if op == "/":
        if b == 0:
            raise DivisionByZeroError.at(loc, "division by zero")
        return checked_real(a / b, loc)
    if op == "+":
        return _number(a + b, loc)
    if op == "-":
        return _number(a - b, loc)
    if op == "*":
        return _number(a * b, loc)
    raise TypeMismatchError.at(loc, f"unknown operator {op}")  # pragma: no cover


def apply_unary(op: str, v: Any, loc: Location | None = None) -> Any:
    """Evaluate a unary operator on a run-time value."""
    if op == "NOT":
        return (not v) if isinstance(v, bool) else ~v
    if op == "+":
        return v
    if isinstance(v, Vector):
        return Vector(-v.x, -v.y, -v.z)
    return _number(-v, loc)
