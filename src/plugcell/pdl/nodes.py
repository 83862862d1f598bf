"""The abstract syntax tree: immutable dataclasses, each with its source location.

Locations are excluded from equality, so two parses of equivalent text compare
equal (the parse → print → parse property).  Identifiers keep their spelling;
the language is case-insensitive, so lookups use :func:`key`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from plugcell.pdl.errors import Location
from plugcell.pdl.types import LangType

__all__ = [
    "Assign",
    "Binary",
    "BoolLit",
    "Call",
    "CallStmt",
    "Case",
    "ConstDecl",
    "Deactivate",
    "Delay",
    "Expr",
    "Field",
    "For",
    "If",
    "Import",
    "Index",
    "IntLit",
    "Module",
    "Move",
    "MoveRelative",
    "Name",
    "Param",
    "ProgAttr",
    "RealLit",
    "Repeat",
    "Return",
    "Routine",
    "Select",
    "Stmt",
    "StrLit",
    "Unary",
    "VarDecl",
    "Wait",
    "While",
    "Write",
    "WriteItem",
    "key",
]

_NOWHERE = Location("<ast>", 0, 0)


def key(name: str) -> str:
    """Lookup key of an identifier (the language is case-insensitive)."""
    return name.upper()


# --------------------------------------------------------------------------- expressions
@dataclass(frozen=True, slots=True)
class IntLit:
    value: int
    loc: Location = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(frozen=True, slots=True)
class RealLit:
    value: float
    loc: Location = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(frozen=True, slots=True)
class StrLit:
    value: str
    loc: Location = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(frozen=True, slots=True)
class BoolLit:
    value: bool
    loc: Location = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(frozen=True, slots=True)
class Name:
    """A variable, constant, or a routine called without parentheses."""

    name: str
    loc: Location = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(frozen=True, slots=True)
class Index:
    """``base[i]`` or ``base[i, j]`` (1-based)."""

    base: Expr
    indices: tuple[Expr, ...]
    loc: Location = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(frozen=True, slots=True)
class Field:
    """``base.X`` — a POSITION or VECTOR component."""

    base: Expr
    name: str
    loc: Location = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(frozen=True, slots=True)
class Call:
    """``NAME(args)`` — a routine or built-in function."""

    name: str
    args: tuple[Expr, ...]
    loc: Location = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(frozen=True, slots=True)
class Unary:
    """``-x``, ``+x``, ``NOT x``."""

    op: str
    operand: Expr
    loc: Location = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(frozen=True, slots=True)
class Binary:
    """``left op right``; ``op`` is upper case (``+``, ``DIV``, ``<=``, ``AND`` …)."""

    op: str
    left: Expr
    right: Expr
    loc: Location = field(default=_NOWHERE, compare=False, repr=False)


Expr = IntLit | RealLit | StrLit | BoolLit | Name | Index | Field | Call | Unary | Binary


# --------------------------------------------------------------------------- statements
@dataclass(frozen=True, slots=True)
class Assign:
    target: Expr
    value: Expr
    loc: Location = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(frozen=True, slots=True)
class CallStmt:
    name: str
    args: tuple[Expr, ...]
    loc: Location = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(frozen=True, slots=True)
class If:
    cond: Expr
    then: tuple[Stmt, ...]
    orelse: tuple[Stmt, ...] | None
    loc: Location = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(frozen=True, slots=True)
class For:
    var: str
    start: Expr
    stop: Expr
    downto: bool
    step: Expr | None
    body: tuple[Stmt, ...]
    loc: Location = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(frozen=True, slots=True)
class While:
    cond: Expr
    body: tuple[Stmt, ...]
    loc: Location = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(frozen=True, slots=True)
class Repeat:
    body: tuple[Stmt, ...]
    cond: Expr
    loc: Location = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(frozen=True, slots=True)
class Case:
    values: tuple[Expr, ...]
    body: tuple[Stmt, ...]
    loc: Location = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(frozen=True, slots=True)
class Select:
    subject: Expr
    cases: tuple[Case, ...]
    orelse: tuple[Stmt, ...] | None
    loc: Location = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(frozen=True, slots=True)
class Wait:
    """``WAIT FOR cond [TIMEOUT ms]``."""

    cond: Expr
    timeout: Expr | None
    loc: Location = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(frozen=True, slots=True)
class Delay:
    """``DELAY ms``."""

    duration: Expr
    loc: Location = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(frozen=True, slots=True)
class Move:
    """``MOVE TO x`` (kind ``TO``), ``MOVE JOINT TO x``, ``MOVE LINEAR TO x``; with
    ``WITH TRACKING [service]`` ``tracking`` is the tracker service's name (default
    ``TRACKER``): the laser tracker corrects the move while it runs (issue 38)."""

    kind: str
    target: Expr
    loc: Location = field(default=_NOWHERE, compare=False, repr=False)
    tracking: str | None = None


@dataclass(frozen=True, slots=True)
class MoveRelative:
    """``MOVE RELATIVE vec IN frame`` (frame ``BASE`` or ``TOOL``)."""

    vector: Expr
    frame: str
    loc: Location = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(frozen=True, slots=True)
class WriteItem:
    """One WRITE argument with its optional ``::width::precision``."""

    expr: Expr
    width: Expr | None = None
    precision: Expr | None = None
    loc: Location = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(frozen=True, slots=True)
class Write:
    """``WRITE lun (items)``."""

    lun: str
    items: tuple[WriteItem, ...]
    loc: Location = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(frozen=True, slots=True)
class Return:
    value: Expr | None
    loc: Location = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(frozen=True, slots=True)
class Deactivate:
    names: tuple[str, ...]
    loc: Location = field(default=_NOWHERE, compare=False, repr=False)


Stmt = (
    Assign
    | CallStmt
    | If
    | For
    | While
    | Repeat
    | Select
    | Wait
    | Delay
    | Move
    | MoveRelative
    | Write
    | Return
    | Deactivate
)


# --------------------------------------------------------------------------- declarations
@dataclass(frozen=True, slots=True)
class VarDecl:
    """``a, b : type [EXPORTED FROM prog] [NOSAVE …]``."""

    names: tuple[str, ...]
    type: LangType
    attrs: tuple[str, ...] = ()
    exported_from: str | None = None
    loc: Location = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(frozen=True, slots=True)
class ConstDecl:
    """``name = constant-expression`` in a CONST section."""

    name: str
    value: Expr
    loc: Location = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(frozen=True, slots=True)
class Param:
    name: str
    type: LangType
    loc: Location = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(frozen=True, slots=True)
class Routine:
    """A ROUTINE with a body, or a declaration ``… EXPORTED FROM lib`` (no body)."""

    name: str
    params: tuple[Param, ...]
    return_type: LangType | None
    locals: tuple[VarDecl, ...]
    body: tuple[Stmt, ...]
    exported_from: str | None = None
    loc: Location = field(default=_NOWHERE, compare=False, repr=False)

    @property
    def is_declaration(self) -> bool:
        """True for ``ROUTINE … EXPORTED FROM lib`` (body lives in ``lib``)."""
        return self.exported_from is not None


@dataclass(frozen=True, slots=True)
class Import:
    """``IMPORT 'file'``."""

    path: str
    loc: Location = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(frozen=True, slots=True)
class ProgAttr:
    """A program attribute after the name: ``NOHOLD``, ``PROG_ARM = 1``."""

    name: str
    value: Expr | None = None
    loc: Location = field(default=_NOWHERE, compare=False, repr=False)


Decl = VarDecl | ConstDecl | Routine | Import


@dataclass(frozen=True, slots=True)
class Module:
    """One source file: ``PROGRAM name … [BEGIN …] END name``."""

    name: str
    attrs: tuple[ProgAttr, ...]
    decls: tuple[Decl, ...]
    body: tuple[Stmt, ...] | None
    file: str = field(default="<string>", compare=False)
    loc: Location = field(default=_NOWHERE, compare=False, repr=False)

    @property
    def imports(self) -> tuple[Import, ...]:
        return tuple(d for d in self.decls if isinstance(d, Import))

    @property
    def consts(self) -> tuple[ConstDecl, ...]:
        return tuple(d for d in self.decls if isinstance(d, ConstDecl))

    @property
    def variables(self) -> tuple[VarDecl, ...]:
        return tuple(d for d in self.decls if isinstance(d, VarDecl))

    @property
    def routines(self) -> tuple[Routine, ...]:
        return tuple(d for d in self.decls if isinstance(d, Routine))
