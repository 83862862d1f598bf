"""Built-in functions, procedures, constants and predefined variables.

Each built-in declares its parameters (what types it accepts) so that the checker
can reject wrong calls before the program runs; the implementation gets the
already-evaluated arguments.  Angles are in degrees, lengths in millimetres, as
in PDL.  See docs/robot-language.md for the list with examples.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

from plugcell.pdl import errors
from plugcell.pdl.conversion import (
    EXT_DATA_MAX,
    ConversionError,
    position_from_matrix,
    to_language,
)
from plugcell.pdl.errors import Location
from plugcell.pdl.formatting import format_value
from plugcell.pdl.interfaces import Motion
from plugcell.pdl.operators import checked_int, checked_real
from plugcell.pdl.types import (
    ANY_STRING,
    BOOLEAN,
    INTEGER,
    JOINTPOS,
    NEWLINE,
    POSITION,
    REAL,
    VECTOR,
    ArrayType,
    LangType,
    StringType,
    assignable,
    is_numeric,
)
from plugcell.pdl.values import UNINIT, ArrayValue, JointPos, Position, Vector

__all__ = [
    "CONSTANTS",
    "EXTERNALS",
    "FUNCTIONS",
    "NEWLINE_VALUE",
    "PROCEDURES",
    "SYSTEM_VARIABLES",
    "Arg",
    "Builtin",
    "BuiltinContext",
]


class BuiltinContext(Protocol):
    """What built-ins may use of the running execution."""

    motion: Motion

    @property
    def sim_time(self) -> float:
        """Simulated seconds since the program started."""
        ...

    def trap(self, code: int, on: bool) -> None:
        """Turn trapping of run-time error ``code`` on or off."""
        ...


class _Newline:
    def __repr__(self) -> str:
        return "NL"


#: Value of the predefined ``NL`` (line break in WRITE / ENCODE).
NEWLINE_VALUE: Any = _Newline()


@dataclass(frozen=True, slots=True)
class Arg:
    """One parameter: a type test, its description, and whether it is an output
    (a variable the built-in assigns, e.g. POS_XTRT's x)."""

    accepts: Callable[[LangType], bool]
    describe: str
    output: bool = False


@dataclass(frozen=True, slots=True)
class Builtin:
    """A built-in function (``result`` set) or procedure (``result`` None).

    ``optional`` trailing parameters may be omitted; ``variadic`` may repeat up to
    ``max_variadic`` times.  A procedure's ``impl`` returns the tuple of values for
    its output parameters, in order.
    """

    name: str
    params: tuple[Arg, ...]
    result: LangType | Callable[[Sequence[LangType]], LangType] | None
    impl: Callable[[BuiltinContext, list[Any], Location], Any]
    optional: int = 0
    variadic: Arg | None = None
    max_variadic: int = 0

    @property
    def min_args(self) -> int:
        return len(self.params) - self.optional

    @property
    def max_args(self) -> int:
        return len(self.params) + self.max_variadic

    def arg_spec(self, i: int) -> Arg:
        """Spec of argument ``i`` (0-based)."""
        if i < len(self.params):
            return self.params[i]
        assert self.variadic is not None
        return self.variadic

    def result_type(self, args: Sequence[LangType]) -> LangType | None:
        if callable(self.result):
            return self.result(args)
        return self.result

    def arity_text(self) -> str:
        lo, hi = self.min_args, self.max_args
        return str(lo) if lo == hi else f"{lo} to {hi}"


# --------------------------------------------------------------------------- arg kinds
NUM = Arg(is_numeric, "INTEGER or REAL")
INT_ = Arg(lambda t: t == INTEGER, "INTEGER")
STR = Arg(lambda t: isinstance(t, StringType), "STRING")
POS_ = Arg(lambda t: t == POSITION, "POSITION")
JNT_ = Arg(lambda t: t == JOINTPOS, "JOINTPOS")
ARR = Arg(lambda t: isinstance(t, ArrayType), "ARRAY")
REAL_ARR = Arg(
    lambda t: isinstance(t, ArrayType) and t.element == REAL and len(t.dims) == 1,
    "ARRAY[n] OF REAL",
)
WRITABLE = Arg(lambda t: True, "a value")


def _out(t: LangType) -> Arg:
    return Arg(lambda target: assignable(target, t), f"a variable that can hold a {t}", True)


OUT_STR = Arg(lambda t: isinstance(t, StringType), "a STRING variable", True)


def _numeric(value: int | float, args: Sequence[Any]) -> int | float:
    """REAL if any argument is REAL (the static type), else INTEGER."""
    return float(value) if any(isinstance(a, float) for a in args) else value


def _numeric_result(args: Sequence[LangType]) -> LangType:
    return INTEGER if all(a == INTEGER for a in args) else REAL


# --------------------------------------------------------------------------- math
def _deg_fn(fn: Callable[[float], float]) -> Callable[[BuiltinContext, list[Any], Location], Any]:
    def impl(ctx: BuiltinContext, args: list[Any], loc: Location) -> float:
        return checked_real(fn(math.radians(args[0])), loc)

    return impl


def _inverse_trig(fn: Callable[[float], float], name: str):
    def impl(ctx: BuiltinContext, args: list[Any], loc: Location) -> float:
        x = float(args[0])
        if not -1.0 <= x <= 1.0:
            raise errors.MathError.at(loc, f"{name}({x:g}) is undefined (argument outside -1..1)")
        return math.degrees(fn(x))

    return impl


def _sqrt(ctx: BuiltinContext, args: list[Any], loc: Location) -> float:
    if args[0] < 0:
        raise errors.MathError.at(loc, f"SQRT of a negative number ({args[0]:g})")
    return math.sqrt(args[0])


def _ln(ctx: BuiltinContext, args: list[Any], loc: Location) -> float:
    if args[0] <= 0:
        raise errors.MathError.at(loc, f"LN of a number that is not positive ({args[0]:g})")
    return math.log(args[0])


def _exp(ctx: BuiltinContext, args: list[Any], loc: Location) -> float:
    try:
        return checked_real(math.exp(args[0]), loc)
    except OverflowError:
        raise errors.OverflowProgramError.at(loc, f"EXP({args[0]:g}) overflows") from None


def _abs(ctx: BuiltinContext, args: list[Any], loc: Location) -> int | float:
    x = args[0]
    return checked_int(abs(x), loc) if isinstance(x, int) else abs(x)


def _round(ctx: BuiltinContext, args: list[Any], loc: Location) -> int:
    x = float(args[0])
    return checked_int(int(math.copysign(math.floor(abs(x) + 0.5), x)), loc)


def _trunc(ctx: BuiltinContext, args: list[Any], loc: Location) -> int:
    return checked_int(int(float(args[0])), loc)


# --------------------------------------------------------------------------- strings
def _str_xtrt(ctx: BuiltinContext, args: list[Any], loc: Location) -> str:
    s, start, length = args
    if not 1 <= start <= len(s) + 1 or length < 0:
        raise errors.IndexOutOfBoundsError.at(
            loc, f"STR_XTRT start {start} / length {length} outside a string of {len(s)}"
        )
    return s[start - 1 : start - 1 + length]


ED_UPPER, ED_LOWER, ED_TRIM, ED_STRIP = 1, 2, 3, 4


def _str_edit(ctx: BuiltinContext, args: list[Any], loc: Location) -> str:
    s, mode = args
    if mode == ED_UPPER:
        return s.upper()
    if mode == ED_LOWER:
        return s.lower()
    if mode == ED_TRIM:
        return s.strip()
    if mode == ED_STRIP:
        return "".join(s.split())
    raise errors.ExecutionError.at(
        loc, f"unknown STR_EDIT mode {mode} (ED_UPPER, ED_LOWER, ED_TRIM…)"
    )


def _str_to_int(ctx: BuiltinContext, args: list[Any], loc: Location) -> int:
    try:
        return checked_int(int(args[0].strip()), loc)
    except ValueError:
        raise errors.ValueConversionError.at(loc, f"'{args[0]}' is not an INTEGER") from None


def _str_to_real(ctx: BuiltinContext, args: list[Any], loc: Location) -> float:
    try:
        return checked_real(float(args[0].strip()), loc)
    except ValueError:
        raise errors.ValueConversionError.at(loc, f"'{args[0]}' is not a REAL") from None


def _ord(ctx: BuiltinContext, args: list[Any], loc: Location) -> int:
    s, i = args
    if not 1 <= i <= len(s):
        raise errors.IndexOutOfBoundsError.at(loc, f"ORD index {i} outside a string of {len(s)}")
    return ord(s[i - 1])


def _chr(ctx: BuiltinContext, args: list[Any], loc: Location) -> str:
    code = args[0]
    if not 0 <= code <= 0x10FFFF:
        raise errors.IndexOutOfBoundsError.at(loc, f"CHR({code}) is not a character code")
    return chr(code)


def _encode(ctx: BuiltinContext, args: list[Any], loc: Location) -> tuple[str]:
    text = "".join("\n" if a is NEWLINE_VALUE else format_value(a) for a in args[1:])
    return (text,)


# --------------------------------------------------------------------------- arrays
def _array_dim(ctx: BuiltinContext, args: list[Any], loc: Location) -> int:
    arr: ArrayValue = args[0]
    k = args[1] if len(args) > 1 else 1
    if not 1 <= k <= len(arr.dims):
        raise errors.IndexOutOfBoundsError.at(
            loc, f"ARRAY_DIM: dimension {k} of an array with {len(arr.dims)}"
        )
    return arr.dims[k - 1]


def _array_dim_n(k: int):
    def impl(ctx: BuiltinContext, args: list[Any], loc: Location) -> int:
        return _array_dim(ctx, [args[0], k], loc)

    return impl


# --------------------------------------------------------------------------- positions
def _pos(ctx: BuiltinContext, args: list[Any], loc: Location) -> Position:
    nums = [checked_real(float(v), loc) for v in args[:6]]
    cnfg = args[6] if len(args) > 6 else ""
    return Position(*nums, cnfg=cnfg)


def _vec(ctx: BuiltinContext, args: list[Any], loc: Location) -> Vector:
    return Vector(*(float(v) for v in args))


def _jnt(ctx: BuiltinContext, args: list[Any], loc: Location) -> JointPos:
    return JointPos(tuple(float(v) for v in args))


def _pos_get_loc(ctx: BuiltinContext, args: list[Any], loc: Location) -> Vector:
    p: Position = args[0]
    return Vector(p.x, p.y, p.z)


def _pos_xtrt(ctx: BuiltinContext, args: list[Any], loc: Location) -> tuple[Any, ...]:
    p: Position = args[0]
    return (*p.as_tuple(), p.cnfg)


def _motion_call(name: str, thunk: Callable[[], Any], loc: Location) -> Any:
    try:
        return thunk()
    except errors.ProgramError:
        raise
    except Exception as exc:  # any failure of the arm is the program's error
        raise errors.MotionFailedError.at(loc, f"{name} failed: {exc}") from exc


def _arm_pos(ctx: BuiltinContext, args: list[Any], loc: Location) -> Position:
    return _motion_call("ARM_POS", lambda: _as_position(ctx.motion.arm_pos()), loc)


def _arm_jntp(ctx: BuiltinContext, args: list[Any], loc: Location) -> JointPos:
    return _motion_call("ARM_JNTP", lambda: _as_jointpos(ctx.motion.arm_jntp()), loc)


def _pos_to_jntp(ctx: BuiltinContext, args: list[Any], loc: Location) -> JointPos:
    return _motion_call("POS_TO_JNTP", lambda: _as_jointpos(ctx.motion.pos_to_jntp(args[0])), loc)


def _jntp_to_pos(ctx: BuiltinContext, args: list[Any], loc: Location) -> Position:
    return _motion_call("JNTP_TO_POS", lambda: _as_position(ctx.motion.jntp_to_pos(args[0])), loc)


def _as_position(value: Any) -> Position:
    return value if isinstance(value, Position) else to_language(value, POSITION)


def _as_jointpos(value: Any) -> JointPos:
    return value if isinstance(value, JointPos) else to_language(value, JOINTPOS)


def _pos_from_matrix(ctx: BuiltinContext, args: list[Any], loc: Location) -> Position:
    arr: ArrayValue = args[0]
    start = args[1]
    if len(arr.dims) != 1 or not 1 <= start <= len(arr.data) - 15:
        raise errors.IndexOutOfBoundsError.at(
            loc, f"POS_FROM_MATRIX needs 16 values from index {start} of a 1-D array"
        )
    values = arr.data[start - 1 : start + 15]
    if any(v is UNINIT for v in values):
        raise errors.UninitializedError.at(loc, "POS_FROM_MATRIX: uninitialized values")
    try:
        return position_from_matrix([values[i : i + 4] for i in range(0, 16, 4)])
    except ConversionError as exc:
        raise errors.ValueConversionError.at(loc, f"POS_FROM_MATRIX: {exc}") from None


def _clock(ctx: BuiltinContext, args: list[Any], loc: Location) -> int:
    return checked_int(round(ctx.sim_time * 1000.0), loc)


def _trap(on: bool):
    def impl(ctx: BuiltinContext, args: list[Any], loc: Location) -> tuple[()]:
        ctx.trap(args[0], on)
        return ()

    return impl


def _fn(name, params, result, impl, **kw) -> Builtin:
    return Builtin(name, tuple(params), result, impl, **kw)


_REAL_FNS = {
    "SIN": _deg_fn(math.sin),
    "COS": _deg_fn(math.cos),
    "TAN": _deg_fn(math.tan),
    "ASIN": _inverse_trig(math.asin, "ASIN"),
    "ACOS": _inverse_trig(math.acos, "ACOS"),
    "SQRT": _sqrt,
    "LN": _ln,
    "EXP": _exp,
}

FUNCTIONS: dict[str, Builtin] = {
    **{name: _fn(name, [NUM], REAL, impl) for name, impl in _REAL_FNS.items()},
    "ATAN2": _fn("ATAN2", [NUM, NUM], REAL, lambda c, a, loc: math.degrees(math.atan2(a[0], a[1]))),
    "ABS": _fn("ABS", [NUM], _numeric_result, _abs),
    "ROUND": _fn("ROUND", [NUM], INTEGER, _round),
    "TRUNC": _fn("TRUNC", [NUM], INTEGER, _trunc),
    "MIN": _fn("MIN", [NUM, NUM], _numeric_result, lambda c, a, loc: _numeric(min(a), a)),
    "MAX": _fn("MAX", [NUM, NUM], _numeric_result, lambda c, a, loc: _numeric(max(a), a)),
    "STR_LEN": _fn("STR_LEN", [STR], INTEGER, lambda c, a, loc: len(a[0])),
    "STR_LOC": _fn("STR_LOC", [STR, STR], INTEGER, lambda c, a, loc: a[0].find(a[1]) + 1),
    "STR_XTRT": _fn("STR_XTRT", [STR, INT_, INT_], ANY_STRING, _str_xtrt),
    "STR_EDIT": _fn("STR_EDIT", [STR, INT_], ANY_STRING, _str_edit),
    "STR_TO_INT": _fn("STR_TO_INT", [STR], INTEGER, _str_to_int),
    "STR_TO_REAL": _fn("STR_TO_REAL", [STR], REAL, _str_to_real),
    "ORD": _fn("ORD", [STR, INT_], INTEGER, _ord),
    "CHR": _fn("CHR", [INT_], ANY_STRING, _chr),
    "ARRAY_DIM": _fn("ARRAY_DIM", [ARR, INT_], INTEGER, _array_dim),
    "ARRAY_DIM1": _fn("ARRAY_DIM1", [ARR], INTEGER, _array_dim_n(1)),
    "ARRAY_DIM2": _fn("ARRAY_DIM2", [ARR], INTEGER, _array_dim_n(2)),
    "POS": _fn("POS", [NUM] * 6 + [STR], POSITION, _pos, optional=1),
    "VEC": _fn("VEC", [NUM] * 3, VECTOR, _vec),
    "JNTP": _fn("JNTP", [NUM], JOINTPOS, _jnt, variadic=NUM, max_variadic=9),
    "POS_GET_LOC": _fn("POS_GET_LOC", [POS_], VECTOR, _pos_get_loc),
    "ARM_POS": _fn("ARM_POS", [], POSITION, _arm_pos),
    "ARM_JNTP": _fn("ARM_JNTP", [], JOINTPOS, _arm_jntp),
    "POS_TO_JNTP": _fn("POS_TO_JNTP", [POS_], JOINTPOS, _pos_to_jntp),
    "JNTP_TO_POS": _fn("JNTP_TO_POS", [JNT_], POSITION, _jntp_to_pos),
    "CLOCK": _fn("CLOCK", [], INTEGER, _clock),
    "POS_FROM_MATRIX": _fn("POS_FROM_MATRIX", [REAL_ARR, INT_], POSITION, _pos_from_matrix),
}

PROCEDURES: dict[str, Builtin] = {
    "POS_XTRT": _fn("POS_XTRT", [POS_, *([_out(REAL)] * 6), OUT_STR], None, _pos_xtrt),
    "POS_TO_JNTP": _fn(
        "POS_TO_JNTP", [POS_, _out(JOINTPOS)], None, lambda c, a, loc: (_pos_to_jntp(c, a, loc),)
    ),
    "JNTP_TO_POS": _fn(
        "JNTP_TO_POS", [JNT_, _out(POSITION)], None, lambda c, a, loc: (_jntp_to_pos(c, a, loc),)
    ),
    "ENCODE": _fn("ENCODE", [OUT_STR], None, _encode, variadic=WRITABLE, max_variadic=64),
    "ERR_TRAP_ON": _fn("ERR_TRAP_ON", [INT_], None, _trap(True)),
    "ERR_TRAP_OFF": _fn("ERR_TRAP_OFF", [INT_], None, _trap(False)),
}


#: Trap code that matches every run-time error.
ERR_ANY = 1

#: Predefined constants: name → (type, value).
CONSTANTS: dict[str, tuple[LangType, Any]] = {
    "NL": (NEWLINE, NEWLINE_VALUE),
    "ED_UPPER": (INTEGER, ED_UPPER),
    "ED_LOWER": (INTEGER, ED_LOWER),
    "ED_TRIM": (INTEGER, ED_TRIM),
    "ED_STRIP": (INTEGER, ED_STRIP),
    "ERR_ANY": (INTEGER, ERR_ANY),
    "ERR_RUNTIME": (INTEGER, errors.ExecutionError.code),
    "ERR_WAIT_TIMEOUT": (INTEGER, errors.WaitTimeoutError.code),
    "ERR_DIVISION_BY_ZERO": (INTEGER, errors.DivisionByZeroError.code),
    "ERR_INDEX": (INTEGER, errors.IndexOutOfBoundsError.code),
    "ERR_UNINITIALIZED": (INTEGER, errors.UninitializedError.code),
    "ERR_OVERFLOW": (INTEGER, errors.OverflowProgramError.code),
    "ERR_MATH": (INTEGER, errors.MathError.code),
    "ERR_MOTION": (INTEGER, errors.MotionFailedError.code),
    "ERR_CHANNEL": (INTEGER, errors.ChannelError.code),
    "ERR_CONVERSION": (INTEGER, errors.ValueConversionError.code),
    "ERR_STACK": (INTEGER, errors.StackOverflowError.code),
}

#: Variables the robot service sets (thesis 4.1.3.2): name → (type, initial value).
#: A program may also declare them (with these types); it is the same variable.
#: ``None`` initial value: uninitialized.
EXTERNALS: dict[str, tuple[LangType, Any]] = {
    "EXT_CMD_FINISHED": (BOOLEAN, False),
    "EXT_CMD_RESULT": (BOOLEAN, False),
    "EXT_CMD_MESSAGE": (StringType(255), ""),
    "EXT_CMD_DATA": (ArrayType(REAL, (EXT_DATA_MAX,)), None),
    "EXT_CMD_COUNT": (INTEGER, 0),
    "EXT_CMD_ROWS": (INTEGER, 0),
    "EXT_CMD_COLS": (INTEGER, 0),
    "EXT_CMD_TEXT": (StringType(255), ""),
}

#: Controller variables only the program and the runtime write.
SYSTEM_VARIABLES: dict[str, tuple[LangType, Any]] = {
    "$ERROR": (INTEGER, 0),
    "$ERROR_MSG": (StringType(255), ""),
}
