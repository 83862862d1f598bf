"""Text → :class:`~.nodes.Module`: the lark LALR parser and the tree transformer.

:func:`parse_module` is the only entry point.  Whatever the input, it returns a
module or raises :class:`~.errors.ParseError` (or another
:class:`~.errors.ProgramError`) with the file, line and column and a message of
the form ``expected …, found …`` — never a lark exception.
"""

from __future__ import annotations

import contextlib
import functools
import math
from collections.abc import Iterator
from typing import Any

from lark import Lark, Token, Transformer, v_args
from lark.exceptions import (
    LarkError,
    UnexpectedCharacters,
    UnexpectedEOF,
    UnexpectedInput,
    UnexpectedToken,
    VisitError,
)
from lark.lexer import PatternStr

from plugcell.pdl import nodes as n
from plugcell.pdl.errors import Location, ParseError, ProgramError
from plugcell.pdl.grammar import GRAMMAR
from plugcell.pdl.types import (
    BOOLEAN,
    INT_MAX,
    INTEGER,
    JOINTPOS,
    MAX_ARRAY_ELEMENTS,
    MAX_STRING,
    POSITION,
    REAL,
    VECTOR,
    ArrayType,
    StringType,
)

__all__ = ["ContinuationLines", "parse_module"]

#: Most dimensions an ARRAY may have.
MAX_DIMS = 3


class ContinuationLines:
    """Post-lexer: a line break right after ``(``, ``[`` or ``,`` inside brackets
    continues the statement (long WRITE or POS(...) argument lists)."""

    always_accept = ("_NL",)

    def process(self, stream: Iterator[Token]) -> Iterator[Token]:
        depth = 0
        previous = ""
        for tok in stream:
            if tok.type in ("LPAR", "LSQB"):
                depth += 1
            elif tok.type in ("RPAR", "RSQB"):
                depth = max(0, depth - 1)
            elif tok.type == "_NL" and depth and previous in ("LPAR", "LSQB", "COMMA"):
                continue
            previous = tok.type
            yield tok


@functools.cache
def _lark() -> Lark:
    return Lark(
        GRAMMAR,
        parser="lalr",
        lexer="basic",
        postlex=ContinuationLines(),
        propagate_positions=True,
        maybe_placeholders=False,
    )


# --------------------------------------------------------------------------- errors
_DESCRIBE = {
    "NAME": "a name",
    "INT": "an integer",
    "REAL": "a real number",
    "STRING": "a string",
    "_NL": "end of line",
    "$END": "end of file",
}
_STATEMENT_STARTERS = {
    "IF", "FOR", "WHILE", "REPEAT", "SELECT", "WAIT", "DELAY", "MOVE", "WRITE",
    "RETURN", "DEACTIVATE",
}  # fmt: skip
_EXPRESSION_STARTERS = {"INT", "REAL", "STRING", "TRUE", "FALSE", "LPAR", "MINUS", "PLUS", "NOT"}
_COMPARISONS = {"=", "<>", "<", "<=", ">", ">="}
_OPERATORS = _COMPARISONS | {"+", "-", "*", "/", "DIV", "MOD", "AND", "OR", "XOR"}


@functools.cache
def _terminal_text() -> dict[str, str]:
    out: dict[str, str] = {}
    for term in _lark().terminals:
        pat = term.pattern
        if term.name in _DESCRIBE:
            out[term.name] = _DESCRIBE[term.name]
        elif isinstance(pat, PatternStr):
            out[term.name] = pat.value.upper() if pat.value.isalpha() else f"'{pat.value}'"
        else:
            out[term.name] = term.name
    out.update({k: v for k, v in _DESCRIBE.items() if k not in out})
    return out


def _describe_expected(expected: set[str]) -> str:
    names = set(expected)
    parts: list[str] = []
    if len(names & _STATEMENT_STARTERS) >= 4:
        names -= _STATEMENT_STARTERS | {"NAME"}
        parts.append("a statement")
    if len(names & _EXPRESSION_STARTERS) >= 4:
        names -= _EXPRESSION_STARTERS | {"NAME"}
        parts.append("an expression")
    text = _terminal_text()
    operators = {x for x in names if text.get(x, x).strip("'") in _OPERATORS}
    if len(operators) >= 4:
        names -= operators
        parts.append("an operator")
    shown = sorted({text.get(x, x) for x in names})
    if len(shown) > 8:
        shown = [*shown[:8], "…"]
    parts.extend(shown)
    if not parts:
        return "something else"
    if len(parts) == 1:
        return parts[0]
    return ", ".join(parts[:-1]) + " or " + parts[-1]


def _describe_found(tok: Token, expected: set[str]) -> str:
    if tok.type in ("_NL", "$END"):
        return _DESCRIBE[tok.type]
    value = str(tok.value)
    if tok.type != "NAME" and value.isalpha():
        note = " (a reserved word: not usable as a name)" if "NAME" in expected else ""
        return f"the keyword {value.upper()}{note}"
    if len(value) > 30:
        value = value[:27] + "..."
    return f"'{value}'"


def _syntax_error(exc: UnexpectedInput, file: str, text: str) -> ParseError:
    last_line = text.count("\n") or 1
    if isinstance(exc, UnexpectedCharacters):
        ch = exc.char
        what = "a quote (strings are written 'like this')" if ch == '"' else repr(ch)
        return ParseError(file, exc.line, f"unexpected character {what}", exc.column)
    if isinstance(exc, UnexpectedToken):
        tok = exc.token
        expected = set(exc.expected)
        if exc.interactive_parser is not None:
            # the exact set (LALR's lookahead sets are merged across contexts)
            with contextlib.suppress(LarkError):
                expected = set(exc.interactive_parser.accepts()) or expected
        line = tok.line if isinstance(tok.line, int) else last_line
        column = tok.column if isinstance(tok.column, int) else 0
        message = f"expected {_describe_expected(expected)}, found {_describe_found(tok, expected)}"
        if tok.value == "=" and any(_terminal_text().get(e) == "':='" for e in expected):
            message += " (assignment is ':=')"
        elif str(tok.value) in _COMPARISONS and tok.type not in expected:
            message += " (comparisons cannot be chained: write (a > 0) AND (b > 0))"
        elif tok.type == "$END":
            message = f"unexpected end of file: expected {_describe_expected(expected)}"
        return ParseError(file, line, message, column)
    if isinstance(exc, UnexpectedEOF):
        return ParseError(
            file,
            last_line,
            f"unexpected end of file: expected {_describe_expected(set(exc.expected))}",
        )
    return ParseError(file, getattr(exc, "line", last_line) or last_line, str(exc))


# --------------------------------------------------------------------------- transformer
def _unquote(token: str) -> str:
    return token[1:-1].replace("''", "'")


@v_args(meta=True)
class _ToAst(Transformer):
    """lark tree → :mod:`.nodes` (checks what the grammar cannot: END names, sizes)."""

    def __init__(self, file: str) -> None:
        super().__init__(visit_tokens=False)
        self.file = file

    # -- helpers
    def _loc(self, meta: Any) -> Location:
        if getattr(meta, "empty", True):
            return Location(self.file, 0, 0)
        return Location(self.file, meta.line, meta.column)

    def _tok(self, tok: Token) -> Location:
        return Location(self.file, tok.line or 0, tok.column or 0)

    def _error(self, where: Location, message: str) -> ParseError:
        return ParseError(where.file, where.line, message, where.column)

    def _check_end(self, kind: str, name: Token, end: Token) -> None:
        if str(end).upper() != str(name).upper():
            raise self._error(
                self._tok(end), f"END {end} does not match {kind} {name} (expected END {name})"
            )

    # -- program structure
    def start(self, meta, children):
        return children[-1]

    def module(self, meta, children):
        name, attrs, *decls, body, end = children
        self._check_end("PROGRAM", name, end)
        flat: list[n.Decl] = []
        for d in decls:
            flat.extend(d if isinstance(d, list) else [d])
        return n.Module(str(name), attrs, tuple(flat), body, self.file, self._tok(name))

    def prog_attrs(self, meta, children):
        return tuple(children)

    def prog_attr(self, meta, children):
        value = children[1] if len(children) > 1 else None
        return n.ProgAttr(str(children[0]), value, self._tok(children[0]))

    def main_body(self, meta, children):
        return children[0] if children else None

    def var_section(self, meta, children):
        return list(children)

    def var_decl(self, meta, children):
        names, type_, *attrs = children
        exported_from = None
        plain: list[str] = []
        for a in attrs:
            if isinstance(a, tuple):
                exported_from = a[1]
            else:
                plain.append(a)
        return n.VarDecl(tuple(names), type_, tuple(plain), exported_from, self._loc(meta))

    def name_list(self, meta, children):
        return [str(c) for c in children]

    def exported_from(self, meta, children):
        return ("FROM", str(children[0]))

    def exported(self, meta, children):
        return "EXPORTED"

    def attr_name(self, meta, children):
        return str(children[0]).upper()

    def const_section(self, meta, children):
        return list(children)

    def const_decl(self, meta, children):
        return n.ConstDecl(str(children[0]), children[1], self._tok(children[0]))

    def import_decl(self, meta, children):
        return n.Import(_unquote(str(children[0])), self._loc(meta))

    # -- routines
    def routine(self, meta, children):
        name, params, ret, rest = children
        loc = self._tok(name)
        if rest[0] == "extern":
            return n.Routine(str(name), params, ret, (), (), rest[1], loc)
        _, items, end = rest
        self._check_end("ROUTINE", name, end)
        local_vars: list[n.VarDecl] = []
        body: list[n.Stmt] = []
        in_var = seen_begin = False
        for item in items:
            if item == "VAR":
                if seen_begin or body:
                    raise self._error(item.loc, "VAR must come before BEGIN and the statements")
                in_var = True
            elif isinstance(item, n.VarDecl):
                if seen_begin or body:
                    raise self._error(
                        item.loc, "declarations must come before BEGIN and the statements"
                    )
                if not in_var:
                    raise self._error(item.loc, "declaration without VAR")
                local_vars.append(item)
            elif item == "BEGIN":
                if seen_begin or body:
                    raise self._error(item.loc, "BEGIN after the routine's statements started")
                seen_begin = True
            else:
                body.append(item)
        return n.Routine(str(name), params, ret, tuple(local_vars), tuple(body), None, loc)

    def params(self, meta, children):
        return tuple(p for group in children for p in group)

    def param_group(self, meta, children):
        names, type_ = children
        loc = self._loc(meta)
        return [n.Param(x, type_, loc) for x in names]

    def return_type(self, meta, children):
        return children[0] if children else None

    def routine_extern(self, meta, children):
        return ("extern", str(children[0]))

    def routine_body(self, meta, children):
        *items, end = children
        return ("body", items, end)

    def var_kw(self, meta, children):
        return _Marker("VAR", self._loc(meta))

    def begin_kw(self, meta, children):
        return _Marker("BEGIN", self._loc(meta))

    # -- types
    def t_integer(self, meta, children):
        return INTEGER

    def t_real(self, meta, children):
        return REAL

    def t_boolean(self, meta, children):
        return BOOLEAN

    def t_position(self, meta, children):
        return POSITION

    def t_jointpos(self, meta, children):
        return JOINTPOS

    def t_vector(self, meta, children):
        return VECTOR

    def t_string(self, meta, children):
        if not children:
            return StringType(None)
        size = children[0]
        if size is not None and not 1 <= size <= MAX_STRING:
            raise self._error(self._loc(meta), f"STRING length must be 1..{MAX_STRING}, not {size}")
        return StringType(size)

    def t_array(self, meta, children):
        *dims, element = children
        loc = self._loc(meta)
        if len(dims) > MAX_DIMS:
            raise self._error(loc, f"an ARRAY has at most {MAX_DIMS} dimensions")
        if isinstance(element, ArrayType):
            raise self._error(loc, "ARRAY OF ARRAY: write ARRAY[n, m] OF … instead")
        total = 1
        for d in dims:
            if d is not None:
                if d < 1:
                    raise self._error(loc, f"array dimension must be at least 1, not {d}")
                total *= d
        if total > MAX_ARRAY_ELEMENTS:
            raise self._error(loc, f"array too large ({total} elements > {MAX_ARRAY_ELEMENTS})")
        return ArrayType(element, tuple(dims))

    def dim(self, meta, children):
        tok = children[0]
        return None if tok == "*" else int(tok)

    # -- statements
    def block(self, meta, children):
        return tuple(children)

    def assign(self, meta, children):
        return n.Assign(children[0], children[1], self._loc(meta))

    def call_stmt(self, meta, children):
        name = children[0]
        args = children[1] if len(children) > 1 else ()
        return n.CallStmt(str(name), args, self._tok(name))

    def move_to(self, meta, children):
        return n.Move("TO", children[0], self._loc(meta), *children[1:])

    def move_joint(self, meta, children):
        return n.Move("JOINT", children[0], self._loc(meta), *children[1:])

    def move_linear(self, meta, children):
        return n.Move("LINEAR", children[0], self._loc(meta), *children[1:])

    def tracking(self, meta, children):
        """``WITH TRACKING [NAME]``: the tracker service's name (upper case)."""
        return str(children[0]).upper() if children else "TRACKER"

    def move_relative(self, meta, children):
        return n.MoveRelative(children[0], str(children[1]).upper(), self._loc(meta))

    def write_stmt(self, meta, children):
        lun, *items = children
        return n.Write(str(lun), tuple(items), self._loc(meta))

    def write_item(self, meta, children):
        expr, *fmt = children
        width = fmt[0] if fmt else None
        precision = fmt[1] if len(fmt) > 1 else None
        return n.WriteItem(expr, width, precision, self._loc(meta))

    def wait_stmt(self, meta, children):
        timeout = children[1] if len(children) > 1 else None
        return n.Wait(children[0], timeout, self._loc(meta))

    def delay_stmt(self, meta, children):
        return n.Delay(children[0], self._loc(meta))

    def return_stmt(self, meta, children):
        return n.Return(children[0] if children else None, self._loc(meta))

    def deactivate_stmt(self, meta, children):
        return n.Deactivate(tuple(children[0]) if children else (), self._loc(meta))

    def if_stmt(self, meta, children):
        cond, then, *rest = children
        return n.If(cond, then, rest[0] if rest else None, self._loc(meta))

    def else_part(self, meta, children):
        return children[0]

    def for_stmt(self, meta, children):
        var, start, direction, stop, step, body = children
        return n.For(str(var), start, stop, direction, step, body, self._loc(meta))

    def for_dir(self, meta, children):
        return str(children[0]).upper() == "DOWNTO"

    def for_step(self, meta, children):
        return children[0] if children else None

    def while_stmt(self, meta, children):
        return n.While(children[0], children[1], self._loc(meta))

    def repeat_stmt(self, meta, children):
        return n.Repeat(children[0], children[1], self._loc(meta))

    def select_stmt(self, meta, children):
        subject, *rest = children
        cases = tuple(c for c in rest if isinstance(c, n.Case))
        orelse = next((c for c in rest if isinstance(c, tuple)), None)
        return n.Select(subject, cases, orelse, self._loc(meta))

    def case_clause(self, meta, children):
        *values, body = children
        return n.Case(tuple(values), body, self._loc(meta))

    def select_else(self, meta, children):
        return children[0]

    # -- expressions
    def binary(self, meta, children):
        left, (op, loc), right = children
        return n.Binary(op, left, right, loc)

    def unary(self, meta, children):
        (op, loc), operand = children
        return n.Unary(op, operand, loc)

    def _op(self, children):
        tok = children[0]
        return (str(tok).upper(), self._tok(tok))

    def comp_op(self, meta, children):
        return self._op(children)

    def add_op(self, meta, children):
        return self._op(children)

    def mul_op(self, meta, children):
        return self._op(children)

    def unary_op(self, meta, children):
        return self._op(children)

    def int_lit(self, meta, children):
        tok = children[0]
        value = int(tok)
        if value > INT_MAX:
            raise self._error(self._tok(tok), f"integer {tok} out of range (max {INT_MAX})")
        return n.IntLit(value, self._tok(tok))

    def real_lit(self, meta, children):
        tok = children[0]
        value = float(tok)
        if not math.isfinite(value):
            raise self._error(self._tok(tok), f"real number {tok} out of range")
        return n.RealLit(value, self._tok(tok))

    def str_lit(self, meta, children):
        tok = children[0]
        value = _unquote(str(tok))
        if len(value) > MAX_STRING:
            raise self._error(self._tok(tok), f"string literal longer than {MAX_STRING}")
        return n.StrLit(value, self._tok(tok))

    def true_lit(self, meta, children):
        return n.BoolLit(True, self._loc(meta))

    def false_lit(self, meta, children):
        return n.BoolLit(False, self._loc(meta))

    def call(self, meta, children):
        name = children[0]
        args = children[1] if len(children) > 1 else ()
        return n.Call(str(name), args, self._tok(name))

    def name(self, meta, children):
        return n.Name(str(children[0]), self._tok(children[0]))

    def index(self, meta, children):
        base, *indices = children
        return n.Index(base, tuple(indices), self._loc(meta))

    def field(self, meta, children):
        base, name = children
        return n.Field(base, str(name).upper(), self._tok(name))

    def args(self, meta, children):
        return tuple(children)


class _Marker(str):
    """``VAR`` / ``BEGIN`` inside a routine body, with its location."""

    loc: Location

    def __new__(cls, text: str, loc: Location) -> _Marker:
        obj = super().__new__(cls, text)
        obj.loc = loc
        return obj


# --------------------------------------------------------------------------- entry point
def parse_module(text: str, file: str = "<string>") -> n.Module:
    """Parse one source file into a :class:`~.nodes.Module`.

    Raises :class:`~.errors.ParseError` (any :class:`~.errors.ProgramError`)
    carrying ``file``, line and column; nothing else escapes.
    """
    if text.startswith("\ufeff"):
        text = text[1:]
    if "\x00" in text:
        line = text[: text.index("\x00")].count("\n") + 1
        raise ParseError(file, line, "unexpected character '\\x00' (binary file?)")
    if not text.endswith("\n"):
        text += "\n"
    try:
        tree = _lark().parse(text)
    except UnexpectedInput as exc:
        raise _syntax_error(exc, file, text) from None
    except LarkError as exc:  # pragma: no cover - defensive
        raise ParseError(file, 1, f"cannot parse: {exc}") from None
    except RecursionError:
        raise ParseError(file, 1, "program nested too deeply") from None
    try:
        return _ToAst(file).transform(tree)
    except VisitError as exc:
        if isinstance(exc.orig_exc, ProgramError):
            raise exc.orig_exc from None
        if isinstance(exc.orig_exc, RecursionError):
            raise ParseError(file, 1, "program nested too deeply") from None
        raise
    except RecursionError:
        raise ParseError(file, 1, "program nested too deeply") from None
