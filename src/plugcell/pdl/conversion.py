"""Values from outside (services' data: numbers, lists, numpy arrays, 4×4 poses) →
language values of a declared type, and back.

This is how data returned by services reaches a program (thesis 5.2.1.3, 4.1.3.2):
the robot service posts Python/numpy values, and :func:`to_language` converts them
to the type the program declared, refusing anything lossy with a precise reason.

* INTEGER: integers (numpy too) or integral floats, within 32 bits; never booleans.
* REAL: any finite integer or float.
* BOOLEAN: booleans, 0/1, ``'TRUE'``/``'FALSE'``.
* STRING[n]: ``str`` (or UTF-8 ``bytes``) of at most n characters.
* POSITION: a :class:`~.values.Position`; 6 or 7 values ``x, y, z, a, b, c[, cnfg]``
  (mm, deg); or a 4×4 homogeneous transform in **metres** (plugcell's SI
  convention), converted to mm and Comau ZYZ degrees.
* JOINTPOS: a :class:`~.values.JointPos` or 1–10 joint angles (deg).
* VECTOR: a :class:`~.values.Vector` or 3 values (mm).
* ARRAY[d1(, d2 …)] OF t: nested sequences / a numpy array whose leading shape is
  exactly the declared dimensions, each element converted as ``t`` (so an
  ``ARRAY[5] OF POSITION`` takes a ``(5, 4, 4)`` array of poses).
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Sequence
from typing import Any

import numpy as np

from plugcell.pdl.errors import ValueConversionError
from plugcell.pdl.types import (
    BOOLEAN,
    INT_MAX,
    INT_MIN,
    INTEGER,
    JOINTPOS,
    POSITION,
    REAL,
    VECTOR,
    ArrayType,
    LangType,
    StringType,
)
from plugcell.pdl.values import (
    UNINIT,
    ArrayValue,
    JointPos,
    Position,
    Vector,
)

__all__ = ["ConversionError", "position_from_matrix", "to_language", "to_python"]

#: Most joints a JOINTPOS may have.
MAX_JOINTS = 10
#: Capacity of EXT_CMD_DATA (REAL values a service's answer may carry).
EXT_DATA_MAX = 4096
#: Millimetres per unit of the translation of a 4×4 matrix (metres → mm).
MATRIX_UNIT_MM = 1000.0


class ConversionError(ValueError):
    """A value that does not fit the declared type; the message says why."""


def _describe(value: Any) -> str:
    if isinstance(value, np.ndarray):
        return f"a {value.dtype} array of shape {value.shape}"
    text = repr(value)
    if len(text) > 40:
        text = text[:37] + "..."
    return f"{type(value).__name__} {text}"


def _is_bool(value: Any) -> bool:
    return isinstance(value, bool | np.bool_)


def _int(value: Any) -> int:
    if _is_bool(value):
        raise ConversionError(f"{_describe(value)} is a BOOLEAN, not an INTEGER")
    if isinstance(value, numbers.Integral) or (
        isinstance(value, numbers.Real) and float(value).is_integer()
    ):
        out = int(value)
    else:
        raise ConversionError(f"{_describe(value)} is not an INTEGER")
    if not INT_MIN <= out <= INT_MAX:
        raise ConversionError(f"{out} does not fit a 32-bit INTEGER")
    return out


def _real(value: Any) -> float:
    if _is_bool(value) or not isinstance(value, numbers.Real):
        raise ConversionError(f"{_describe(value)} is not a REAL")
    out = float(value)
    if not math.isfinite(out):
        raise ConversionError(f"{out} is not a finite REAL")
    return out


def _bool(value: Any) -> bool:
    if _is_bool(value):
        return bool(value)
    if isinstance(value, numbers.Integral) and int(value) in (0, 1):
        return bool(value)
    if isinstance(value, str) and value.strip().upper() in ("TRUE", "FALSE"):
        return value.strip().upper() == "TRUE"
    raise ConversionError(f"{_describe(value)} is not a BOOLEAN")


def _string(value: Any, t: StringType) -> str:
    if isinstance(value, bytes):
        try:
            value = value.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise ConversionError(f"bytes are not UTF-8 text ({exc.reason})") from None
    if not isinstance(value, str):
        raise ConversionError(f"{_describe(value)} is not a STRING")
    if t.length is not None and len(value) > t.length:
        raise ConversionError(f"a string of {len(value)} characters does not fit {t}")
    return value


def _sequence(value: Any, what: str) -> Sequence[Any]:
    if isinstance(value, str | bytes) or not hasattr(value, "__len__"):
        raise ConversionError(f"{_describe(value)} is not a {what}")
    return value


def position_from_matrix(T: Any, unit_mm: float = MATRIX_UNIT_MM) -> Position:
    """A 4×4 homogeneous transform (translation in units of ``unit_mm`` mm) → POSITION
    (the conversion: :func:`plugcell.io.units.robot_from_pose`, Z-Y-Z)."""
    from plugcell.io.units import MM_PER_M, robot_from_pose

    M = np.asarray(T, dtype=float)
    if M.shape != (4, 4) or not np.all(np.isfinite(M)):
        raise ConversionError(f"{_describe(T)} is not a finite 4×4 matrix")
    if not np.allclose(M[3], [0.0, 0.0, 0.0, 1.0], atol=1e-9):
        raise ConversionError("the last row of a pose matrix must be 0 0 0 1")
    R = M[:3, :3]
    if not np.allclose(R.T @ R, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
        raise ConversionError("the rotation part of the pose matrix is not a rotation")
    x, y, z, a, b, c = robot_from_pose(M, "zyz")
    scale = unit_mm / MM_PER_M  # robot_from_pose reads the translation as metres
    return Position(float(x * scale), float(y * scale), float(z * scale),
                    float(a), float(b), float(c))


def _position(value: Any) -> Position:
    if isinstance(value, Position):
        return value
    arr = np.asarray(value, dtype=object) if not isinstance(value, np.ndarray) else value
    if arr.shape == (4, 4):
        return position_from_matrix(np.asarray(value, dtype=float))
    seq = _sequence(value, "POSITION (6 or 7 values, or a 4×4 matrix)")
    if len(seq) not in (6, 7):
        raise ConversionError(
            f"{_describe(value)} is not a POSITION (6 or 7 values, or a 4×4 matrix)"
        )
    nums = [_real(v) for v in list(seq)[:6]]
    cnfg = _string(seq[6], StringType(None)) if len(seq) == 7 else ""
    return Position(*nums, cnfg=cnfg)


def _jointpos(value: Any) -> JointPos:
    if isinstance(value, JointPos):
        return value
    seq = _sequence(value, "JOINTPOS (a list of joint angles)")
    if not 1 <= len(seq) <= MAX_JOINTS:
        raise ConversionError(f"a JOINTPOS has 1..{MAX_JOINTS} joints, not {len(seq)}")
    return JointPos(tuple(_real(v) for v in seq))


def _vector(value: Any) -> Vector:
    if isinstance(value, Vector):
        return value
    seq = _sequence(value, "VECTOR (3 values)")
    if len(seq) != 3:
        raise ConversionError(f"a VECTOR has 3 values, not {len(seq)}")
    return Vector(*(_real(v) for v in seq))


def _array(value: Any, t: ArrayType) -> ArrayValue:
    dims = t.dims
    if isinstance(value, ArrayValue):
        same_shape = all(d is None or d == v for d, v in zip(dims, value.dims, strict=False))
        if value.type.element == t.element and len(value.dims) == len(dims) and same_shape:
            return value.copy()
        value = value.to_nested()

    def walk(v: Any, path: tuple[int, ...]) -> list[Any]:
        if len(path) == len(dims):
            try:
                return [to_language(v, t.element)]
            except ConversionError as exc:
                where = ", ".join(str(i) for i in path)
                raise ConversionError(f"element [{where}]: {exc}") from None
        seq = _sequence(v, f"{t} ({_shape_text(value)})")
        want = dims[len(path)]
        if want is not None and len(seq) != want:
            raise ConversionError(f"{_shape_text(value)} does not fit {t}")
        out: list[Any] = []
        for i, item in enumerate(seq, start=1):
            out.extend(walk(item, (*path, i)))
        return out

    data = walk(value, ())
    if any(d is None for d in dims):  # a `*` parameter: take the actual shape
        shape = _leading_shape(value, len(dims))
        t = ArrayType(t.element, shape)
    return ArrayValue(t, data)


def _leading_shape(value: Any, n: int) -> tuple[int, ...]:
    shape: list[int] = []
    v = value
    for _ in range(n):
        shape.append(len(v))
        v = v[0] if len(v) else []
    return tuple(shape)


def _shape_text(value: Any) -> str:
    if isinstance(value, np.ndarray):
        return f"data of shape {value.shape}"
    try:
        return f"data of shape {np.asarray(value, dtype=object).shape}"
    except ValueError:  # pragma: no cover - ragged
        return "ragged data"


def to_language(value: Any, t: LangType) -> Any:
    """Convert ``value`` to a language value of type ``t`` or raise
    :class:`ConversionError` with the reason."""
    if t == INTEGER:
        return _int(value)
    if t == REAL:
        return _real(value)
    if t == BOOLEAN:
        return _bool(value)
    if isinstance(t, StringType):
        return _string(value, t)
    if t == POSITION:
        return _position(value)
    if t == JOINTPOS:
        return _jointpos(value)
    if t == VECTOR:
        return _vector(value)
    if isinstance(t, ArrayType):
        return _array(value, t)
    raise ConversionError(f"no conversion to {t}")  # pragma: no cover


def to_python(value: Any) -> Any:
    """A language value as plain Python: arrays → nested lists, UNINIT → ``None``;
    INTEGER/REAL/BOOLEAN/STRING and :class:`Position`/:class:`JointPos`/:class:`Vector`
    as they are."""
    if value is UNINIT:
        return None
    if isinstance(value, ArrayValue):
        return to_python(value.to_nested())
    if isinstance(value, list):
        return [to_python(v) for v in value]
    return value


def data_updates(data: Any, file: str = "<program>") -> list[tuple[str, Any]]:
    """The ``ext_cmd_*`` data variables for a service's answer ``data``
    (see :meth:`Execution.post_result
    <plugcell.pdl.interpreter.Execution.post_result>`)."""
    if data is None:
        return [("ext_cmd_count", 0), ("ext_cmd_rows", 0), ("ext_cmd_cols", 0)]
    if isinstance(data, str | bytes):
        text = _string(data, StringType(None)) if isinstance(data, bytes) else data
        if len(text) > 255:
            raise ValueConversionError(file, 0, f"text data of {len(text)} characters > 255")
        return [("ext_cmd_text", text), ("ext_cmd_count", 0)]
    try:
        arr = np.asarray(data)
    except ValueError:
        raise ValueConversionError(file, 0, "ragged data cannot be returned") from None
    if arr.dtype == object or arr.dtype.kind not in "biuf":
        raise ValueConversionError(file, 0, f"{_describe(data)} is not numeric data")
    flat = arr.astype(float).ravel()
    if flat.size > EXT_DATA_MAX:
        raise ValueConversionError(
            file, 0, f"{flat.size} values do not fit ext_cmd_data ({EXT_DATA_MAX})"
        )
    if not np.all(np.isfinite(flat)):
        raise ValueConversionError(file, 0, "data contains NaN or infinite values")
    rows = int(arr.shape[0]) if arr.ndim else 1
    cols = int(flat.size // rows) if rows else 0
    buffer = ArrayValue(ArrayType(REAL, (EXT_DATA_MAX,)), [UNINIT] * EXT_DATA_MAX)
    buffer.data[: flat.size] = [float(x) for x in flat]
    return [
        ("ext_cmd_data", buffer),
        ("ext_cmd_count", int(flat.size)),
        ("ext_cmd_rows", rows),
        ("ext_cmd_cols", cols),
    ]
