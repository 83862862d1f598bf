"""A PDL2-flavoured robot language: parser (lark, LALR) and interpreter.

The robot is not a dumb slave of a PC program (thesis 4.1.3.2): it runs its own
program, written by a technician in the robot's language, and drives the
peripherals by writing ``ACTIVATE DEVICE #Command#Option#Data`` lines to the
robot service and waiting for the service to set ``ext_cmd_finished``.

>>> prog = Program.load("example.pdl")                      # parse + check, immutable
>>> run = Execution(prog, motion=arm, channel=link, clock=SimClock(speed=100))
>>> run.start()                                               # background thread
>>> run.post({"ext_cmd_result": True, "ext_cmd_finished": True})   # service answers
>>> run.join().state

Errors are :class:`ProgramError` ``(file, line, message)`` at load time (syntax,
declarations, types, calls, libraries) and at run time (timeouts, bounds, …).
See docs/robot-language.md.
"""

from plugcell.pdl.conversion import (
    ConversionError,
    position_from_matrix,
    to_language,
    to_python,
)
from plugcell.pdl.errors import (
    ArgumentError,
    ChannelError,
    DeclarationError,
    DivisionByZeroError,
    ExecutionError,
    IndexOutOfBoundsError,
    LibraryError,
    Location,
    MathError,
    MotionFailedError,
    OverflowProgramError,
    ParseError,
    ProgramError,
    StackOverflowError,
    TypeMismatchError,
    UninitializedError,
    ValueConversionError,
    WaitTimeoutError,
)
from plugcell.pdl.formatting import format_value
from plugcell.pdl.interfaces import Channel, Clock, Motion, MotionError, SimClock, TrackedMotion
from plugcell.pdl.interpreter import Execution, ExecutionResult, ExecutionState
from plugcell.pdl.library import BUILTIN_LIBRARY
from plugcell.pdl.parser import parse_module
from plugcell.pdl.printer import format_expr, format_module
from plugcell.pdl.program import Program
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
from plugcell.pdl.values import UNINIT, ArrayValue, JointPos, Position, Vector

__all__ = [
    "BOOLEAN",
    "BUILTIN_LIBRARY",
    "INTEGER",
    "JOINTPOS",
    "POSITION",
    "REAL",
    "UNINIT",
    "VECTOR",
    "ArgumentError",
    "ArrayType",
    "ArrayValue",
    "Channel",
    "ChannelError",
    "Clock",
    "ConversionError",
    "DeclarationError",
    "DivisionByZeroError",
    "Execution",
    "ExecutionError",
    "ExecutionResult",
    "ExecutionState",
    "IndexOutOfBoundsError",
    "JointPos",
    "LangType",
    "LibraryError",
    "Location",
    "MathError",
    "Motion",
    "MotionError",
    "MotionFailedError",
    "OverflowProgramError",
    "ParseError",
    "Position",
    "Program",
    "ProgramError",
    "SimClock",
    "StackOverflowError",
    "StringType",
    "TrackedMotion",
    "TypeMismatchError",
    "UninitializedError",
    "ValueConversionError",
    "Vector",
    "WaitTimeoutError",
    "format_expr",
    "format_module",
    "format_value",
    "parse_module",
    "position_from_matrix",
    "to_language",
    "to_python",
]
