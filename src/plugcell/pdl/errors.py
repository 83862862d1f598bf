"""One error hierarchy for everything that can go wrong with a robot program.

Every error carries the file and line (and column where known) of the offending
source, so that a technician reading ``example.pdl:12:5: ...`` can go straight to
the line.  Compile-time errors (syntax, declarations, types, calls, imports) are
raised while a program is loaded; run-time errors (:class:`ExecutionError` and its
subclasses) while it runs.  Run-time errors have an integer ``code`` that a program
can trap with ``ERR_TRAP_ON(code)`` (see docs/robot-language.md).
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = [
    "ArgumentError",
    "ChannelError",
    "DeclarationError",
    "DivisionByZeroError",
    "ExecutionError",
    "IndexOutOfBoundsError",
    "LibraryError",
    "Location",
    "MathError",
    "MotionFailedError",
    "OverflowProgramError",
    "ParseError",
    "ProgramError",
    "StackOverflowError",
    "TypeMismatchError",
    "UninitializedError",
    "ValueConversionError",
    "WaitTimeoutError",
]


@dataclass(frozen=True, slots=True)
class Location:
    """A place in a source file: 1-based ``line`` and ``column`` (0 = unknown)."""

    file: str
    line: int
    column: int = 0

    def __str__(self) -> str:
        if self.column:
            return f"{self.file}:{self.line}:{self.column}"
        return f"{self.file}:{self.line}"


class ProgramError(Exception):
    """Base of all robot-program errors: ``file:line[:column]: message``."""

    #: Trap code for run-time errors (0: not trappable).
    code: int = 0

    def __init__(self, file: str, line: int, message: str, column: int = 0) -> None:
        self.file = file
        self.line = line
        self.column = column
        self.message = message
        super().__init__(str(self))

    @classmethod
    def at(cls, loc: Location | None, message: str) -> ProgramError:
        """Build the error at ``loc`` (``<unknown>:0`` when there is none)."""
        if loc is None:
            return cls("<unknown>", 0, message)
        return cls(loc.file, loc.line, message, loc.column)

    @property
    def location(self) -> Location:
        """Where the error happened."""
        return Location(self.file, self.line, self.column)

    def __str__(self) -> str:
        return f"{self.location}: {self.message}"

    def __reduce__(self):  # picklable across processes
        return (type(self), (self.file, self.line, self.message, self.column))


# --------------------------------------------------------------------------- compile time
class ParseError(ProgramError):
    """The text is not a program: ``expected …, found …``."""


class DeclarationError(ProgramError):
    """Undeclared or duplicate names, unknown routines, misplaced declarations."""


class TypeMismatchError(ProgramError):
    """An expression or value of the wrong type for where it is used."""


class ArgumentError(ProgramError):
    """A routine called with the wrong number of arguments."""


class LibraryError(ProgramError):
    """An IMPORT or ``EXPORTED FROM`` that cannot be resolved."""


# --------------------------------------------------------------------------- run time
class ExecutionError(ProgramError):
    """An error while the program runs (trappable by ``ERR_TRAP_ON(code)``)."""

    code = 100


class WaitTimeoutError(ExecutionError):
    """A ``WAIT FOR … TIMEOUT`` expired, or a wait exceeded the real-time budget."""

    code = 101


class DivisionByZeroError(ExecutionError):
    """Division (``/``, ``DIV``, ``MOD``) by zero."""

    code = 102


class IndexOutOfBoundsError(ExecutionError):
    """An array, joint or string index outside its bounds."""

    code = 103


class UninitializedError(ExecutionError):
    """A variable (or array element) read before anything was assigned to it."""

    code = 104


class OverflowProgramError(ExecutionError):
    """An INTEGER result outside the 32-bit range, or a REAL that is not finite."""

    code = 105


class MathError(ExecutionError):
    """A math built-in outside its domain (``SQRT(-1)``, ``ACOS(2)``)."""

    code = 106


class MotionFailedError(ExecutionError):
    """The motion interface refused or failed a move (unreachable, limits…)."""

    code = 107


class ChannelError(ExecutionError):
    """``WRITE pc_client`` failed (e.g. the connection dropped)."""

    code = 108


class ValueConversionError(ExecutionError):
    """A value from outside (a service's data) does not fit the variable's type."""

    code = 109


class StackOverflowError(ExecutionError):
    """Routine calls nested deeper than the configured limit (runaway recursion)."""

    code = 110
