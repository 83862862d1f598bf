"""Run-time values of the language.

========== =========================================================
INTEGER    Python ``int`` in the 32-bit range
REAL       Python ``float``
BOOLEAN    Python ``bool``
STRING     Python ``str``
POSITION   :class:`Position` (x, y, z mm; a, b, c deg, Comau ZYZ; cnfg)
JOINTPOS   :class:`JointPos` (joint angles, deg)
VECTOR     :class:`Vector` (x, y, z mm)
ARRAY      :class:`ArrayValue` (mutable, copied on assignment)
========== =========================================================

A variable nothing was assigned to holds :data:`UNINIT`; reading it is an error.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

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

__all__ = [
    "UNINIT",
    "ArrayValue",
    "JointPos",
    "Position",
    "Vector",
    "copy_value",
    "type_of_value",
]


class _Uninit:
    """The value of a variable nothing was assigned to."""

    _instance: _Uninit | None = None

    def __new__(cls) -> _Uninit:
        if cls._instance is None:
            cls._instance = super().__new__(cls)
        return cls._instance

    def __repr__(self) -> str:
        return "UNINIT"

    def __reduce__(self):
        return (_Uninit, ())


UNINIT: Any = _Uninit()

POSITION_FIELDS = ("X", "Y", "Z", "A", "B", "C", "CNFG")
VECTOR_FIELDS = ("X", "Y", "Z")


@dataclass(frozen=True, slots=True)
class Position:
    """A Cartesian pose: x, y, z in mm, Comau ZYZ Euler angles a, b, c in degrees.

    ``cnfg`` is the controller's configuration string (arm posture flags); the
    runtime passes it through untouched.
    """

    x: float
    y: float
    z: float
    a: float
    b: float
    c: float
    cnfg: str = ""

    def get(self, name: str) -> float | str:
        """Component by PDL field name (``X`` … ``C``, ``CNFG``)."""
        return getattr(self, name.lower())

    def with_field(self, name: str, value: float | str) -> Position:
        """A copy with one component replaced."""
        return replace(self, **{name.lower(): value})

    def as_tuple(self) -> tuple[float, float, float, float, float, float]:
        """``(x, y, z, a, b, c)``."""
        return (self.x, self.y, self.z, self.a, self.b, self.c)


@dataclass(frozen=True, slots=True)
class JointPos:
    """Joint angles in degrees (one per axis of the arm)."""

    joints: tuple[float, ...]

    def __post_init__(self) -> None:
        object.__setattr__(self, "joints", tuple(float(q) for q in self.joints))

    def __len__(self) -> int:
        return len(self.joints)


@dataclass(frozen=True, slots=True)
class Vector:
    """A Cartesian vector in mm (``VEC(x, y, z)``, ``MOVE RELATIVE``)."""

    x: float
    y: float
    z: float

    def get(self, name: str) -> float:
        """Component by field name ``X``, ``Y``, ``Z``."""
        return getattr(self, name.lower())

    def with_field(self, name: str, value: float) -> Vector:
        """A copy with one component replaced."""
        return replace(self, **{name.lower(): value})


@dataclass(slots=True, eq=False)
class ArrayValue:
    """An n-D array (row-major ``data``), 1-based indices as in PDL."""

    type: ArrayType
    data: list[Any] = field(default_factory=list)

    @classmethod
    def empty(cls, type_: ArrayType) -> ArrayValue:
        """All elements uninitialized."""
        return cls(type_, [UNINIT] * type_.size)

    @classmethod
    def from_nested(cls, type_: ArrayType, rows: Sequence[Any]) -> ArrayValue:
        """From nested lists of already-converted element values."""
        flat: list[Any] = list(rows)
        for _ in range(len(type_.dims) - 1):
            flat = [x for row in flat for x in row]
        return cls(type_, flat)

    @property
    def dims(self) -> tuple[int, ...]:
        return tuple(int(d or 0) for d in self.type.dims)

    def offset(self, indices: Sequence[int]) -> int | None:
        """Flat offset of 1-based ``indices``; ``None`` when out of bounds."""
        off = 0
        for i, d in zip(indices, self.dims, strict=True):
            if not 1 <= i <= d:
                return None
            off = off * d + (i - 1)
        return off

    def copy(self) -> ArrayValue:
        """A deep-enough copy (elements are immutable)."""
        return ArrayValue(self.type, list(self.data))

    def to_nested(self) -> list[Any]:
        """Nested Python lists (row-major)."""
        out: list[Any] = list(self.data)
        for d in reversed(self.dims[1:]):
            out = [out[i : i + d] for i in range(0, len(out), d)]
        return out

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, ArrayValue):
            return NotImplemented
        return self.dims == other.dims and self.data == other.data

    def __iter__(self):
        return iter(self.data)


def copy_value(value: Any) -> Any:
    """Value semantics: arrays are copied on assignment and argument passing."""
    return value.copy() if isinstance(value, ArrayValue) else value


def type_of_value(value: Any) -> LangType | None:
    """The language type of a run-time value (``None`` for UNINIT)."""
    if isinstance(value, bool):
        return BOOLEAN
    if isinstance(value, int):
        return INTEGER
    if isinstance(value, float):
        return REAL
    if isinstance(value, str):
        return StringType(len(value))
    if isinstance(value, Position):
        return POSITION
    if isinstance(value, JointPos):
        return JOINTPOS
    if isinstance(value, Vector):
        return VECTOR
    if isinstance(value, ArrayValue):
        return value.type
    return None
