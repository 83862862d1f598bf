"""The language's data types, as immutable descriptors.

``INTEGER`` (32-bit), ``REAL`` (Python float), ``BOOLEAN``, ``STRING[n]``,
``POSITION`` (x, y, z mm; Comau ZYZ a, b, c deg; configuration string),
``JOINTPOS`` (n joint angles, deg), ``VECTOR`` (x, y, z mm) and
``ARRAY[n(, m)] OF type``.  A dimension or string length of ``None`` is the ``*`` of
a routine parameter (any size).
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = [
    "ANY_STRING",
    "BOOLEAN",
    "INTEGER",
    "JOINTPOS",
    "POSITION",
    "REAL",
    "ArrayType",
    "LangType",
    "ScalarType",
    "StringType",
    "assignable",
    "comparable",
    "is_numeric",
]

INT_MIN = -(2**31)
INT_MAX = 2**31 - 1
#: Longest STRING a program may declare.
MAX_STRING = 1024
#: Most elements an ARRAY may hold (keeps runaway declarations out).
MAX_ARRAY_ELEMENTS = 1_000_000


@dataclass(frozen=True, slots=True)
class ScalarType:
    """A type without parameters: INTEGER, REAL, BOOLEAN, POSITION, JOINTPOS, VECTOR."""

    name: str

    def __str__(self) -> str:
        return self.name


@dataclass(frozen=True, slots=True)
class StringType:
    """``STRING[length]``; ``length=None`` is an unsized routine parameter."""

    length: int | None

    @property
    def name(self) -> str:
        return "STRING"

    def __str__(self) -> str:
        return "STRING" if self.length is None else f"STRING[{self.length}]"


@dataclass(frozen=True, slots=True)
class ArrayType:
    """``ARRAY[d1(, d2)] OF element``; a ``None`` dimension is ``*`` (parameters)."""

    element: LangType
    dims: tuple[int | None, ...]

    @property
    def name(self) -> str:
        return "ARRAY"

    @property
    def size(self) -> int:
        """Number of elements (only for fully sized arrays)."""
        n = 1
        for d in self.dims:
            n *= d or 0
        return n

    def __str__(self) -> str:
        dims = ", ".join("*" if d is None else str(d) for d in self.dims)
        return f"ARRAY[{dims}] OF {self.element}"


LangType = ScalarType | StringType | ArrayType

INTEGER = ScalarType("INTEGER")
REAL = ScalarType("REAL")
BOOLEAN = ScalarType("BOOLEAN")
POSITION = ScalarType("POSITION")
JOINTPOS = ScalarType("JOINTPOS")
VECTOR = ScalarType("VECTOR")
ANY_STRING = StringType(None)
#: Marker type of the ``NL`` constant (only meaningful inside WRITE / ENCODE).
NEWLINE = ScalarType("NL")
#: Type of a procedure call used where a value is needed (always an error).
NOTHING = ScalarType("no value")

SCALARS = {t.name: t for t in (INTEGER, REAL, BOOLEAN, POSITION, JOINTPOS, VECTOR)}


def is_numeric(t: LangType) -> bool:
    """INTEGER or REAL."""
    return t in (INTEGER, REAL)


def assignable(target: LangType, source: LangType) -> bool:
    """Whether a value of type ``source`` may be stored where ``target`` is declared.

    INTEGER widens to REAL; any STRING goes into any STRING (truncated to the
    target's length); arrays need the same element type and matching dimensions
    (a ``*`` dimension of a parameter matches any size).
    """
    if target == source:
        return True
    if target == REAL and source == INTEGER:
        return True
    if isinstance(target, StringType) and isinstance(source, StringType):
        return True
    if isinstance(target, ArrayType) and isinstance(source, ArrayType):
        if len(target.dims) != len(source.dims):
            return False
        if not all(t is None or t == s for t, s in zip(target.dims, source.dims, strict=True)):
            return False
        te, se = target.element, source.element
        if isinstance(te, StringType) and isinstance(se, StringType):
            return True
        return te == se
    return False


def comparable(a: LangType, b: LangType, ordering: bool) -> bool:
    """Whether ``a`` and ``b`` can be compared (``=``/``<>``; ``<`` etc. if ``ordering``)."""
    if is_numeric(a) and is_numeric(b):
        return True
    if isinstance(a, StringType) and isinstance(b, StringType):
        return True
    return not ordering and a == b and a == BOOLEAN
