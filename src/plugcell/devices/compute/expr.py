"""The expression language of the compute service's Evaluate (thesis Table 7-2).

In the thesis the robot sends Matlab an *expression* — "a Matlab internal command or
a user-defined function" — and Matlab runs whatever it is.  Here Evaluate accepts a
deliberately tiny language that can only call **registered** functions on workspace
names and literals; it is parsed by hand (no ``eval``, no Python ``ast``), so there
is nothing to escape from::

    program    = statement *( (";" | newline) statement )
    statement  = [ NAME "=" ] expr                 ; a bare expression is stored as ans
    expr       = NUMBER | STRING | "-" expr | NAME | call | matrix
    call       = NAME "(" [ arg *( "," arg ) ] ")"
    arg        = [ NAME "=" ] expr                 ; keyword arguments after positional
    matrix     = "[" [ row *( ";" row ) ] "]"      ; row = expr *( "," expr )
    NAME       = letter *( letter | digit | "_" )  ; at most 63 characters
    STRING     = "'" … "'" | '"' … '"'             ; no escapes

e.g. ``params = calibrate(mJ, mT, model=5); save_params(params, 'h4_36kg')``.

There is no attribute access, no indexing, no operators, no names beginning with
``_``: each is refused by the parser with a precise reason and its column.
Evaluation (:func:`evaluate`) looks names up in the requester's workspace and
calls only functions from the registry it is given.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

MAX_LENGTH = 10_000
MAX_DEPTH = 32
MAX_STATEMENTS = 100
MAX_NAME = 63

__all__ = [
    "Assign",
    "Call",
    "EvaluationError",
    "Matrix",
    "Name",
    "Neg",
    "Num",
    "Str",
    "evaluate",
    "parse",
]


class EvaluationError(ValueError):
    """An expression refused or failed; the message is the precise reason."""


# -- the syntax tree ---------------------------------------------------------------------


@dataclass(frozen=True)
class Num:
    value: float
    col: int


@dataclass(frozen=True)
class Str:
    value: str
    col: int


@dataclass(frozen=True)
class Name:
    id: str
    col: int


@dataclass(frozen=True)
class Neg:
    operand: Node
    col: int


@dataclass(frozen=True)
class Matrix:
    rows: tuple[tuple[Node, ...], ...]
    col: int


@dataclass(frozen=True)
class Call:
    func: str
    args: tuple[Node, ...]
    kwargs: tuple[tuple[str, Node], ...]
    col: int


@dataclass(frozen=True)
class Assign:
    target: str | None  # None: store as ans
    value: Node
    col: int


Node = Num | Str | Name | Neg | Matrix | Call


# -- tokens ------------------------------------------------------------------------------

_PUNCT = "()[],;=-"


@dataclass(frozen=True)
class _Token:
    kind: str  # NAME NUMBER STRING NEWLINE END or the punctuation character
    text: str
    col: int


class _RefusalError(EvaluationError):
    """A refusal at a character offset (1-based) of the text; made readable by :func:`_at`."""

    def __init__(self, col: int, reason: str) -> None:
        super().__init__(reason)
        self.col = col
        self.reason = reason


def _refuse(col: int, reason: str) -> _RefusalError:
    return _RefusalError(col, reason)


def _at(text: str, exc: _RefusalError) -> EvaluationError:
    """``column C: reason``, or ``line L, column C: reason`` in a text of several lines."""
    before = text[: max(exc.col - 1, 0)]
    line = before.count("\n") + 1
    col = exc.col - (before.rfind("\n") + 1)
    where = f"line {line}, column {col}" if "\n" in text else f"column {col}"
    return EvaluationError(f"{where}: {exc.reason}")


def _tokens(text: str) -> list[_Token]:
    out: list[_Token] = []
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        col = i + 1
        if c in " \t\r":
            i += 1
        elif c == "\n":
            out.append(_Token("NEWLINE", c, col))
            i += 1
        elif c.isascii() and c.isalpha():
            j = i + 1
            while j < n and text[j].isascii() and (text[j].isalnum() or text[j] == "_"):
                j += 1
            word = text[i:j]
            if len(word) > MAX_NAME:
                raise _refuse(col, f"name {word[:20]}… longer than {MAX_NAME} characters")
            if j < n and text[j] == ".":
                raise _refuse(j + 1, f"attribute access ('{word}.') is not allowed")
            out.append(_Token("NAME", word, col))
            i = j
        elif c == "_":
            j = i
            while j < n and (text[j].isalnum() or text[j] == "_"):
                j += 1
            raise _refuse(col, f"names may not begin with '_' ({text[i:j]!r})")
        elif c.isdigit() or (c == "." and i + 1 < n and text[i + 1].isdigit()):
            j = i
            while j < n and (text[j].isdigit() or text[j] == "."):
                j += 1
            if j < n and text[j] in "eE":
                k = j + 1
                if k < n and text[k] in "+-":
                    k += 1
                if k < n and text[k].isdigit():
                    j = k
                    while j < n and text[j].isdigit():
                        j += 1
            word = text[i:j]
            try:
                float(word)
            except ValueError:
                raise _refuse(col, f"not a number: {word!r}") from None
            if j < n and (text[j].isalpha() or text[j] == "_"):
                raise _refuse(j + 1, f"unexpected {text[j]!r} after the number {word}")
            out.append(_Token("NUMBER", word, col))
            i = j
        elif c in "'\"":
            j = text.find(c, i + 1)
            if j < 0 or "\n" in text[i:j]:
                raise _refuse(col, "unterminated string")
            out.append(_Token("STRING", text[i + 1 : j], col))
            i = j + 1
        elif c in _PUNCT:
            if c == "=" and i + 1 < n and text[i + 1] == "=":
                raise _refuse(col, "comparisons ('==') are not part of Evaluate expressions")
            out.append(_Token(c, c, col))
            i += 1
        elif c == ".":
            raise _refuse(col, "attribute access ('.') is not allowed")
        elif c in "+*/\\^%@&|<>!~`":
            raise _refuse(
                col, f"operator {c!r} is not part of Evaluate expressions (call a function)"
            )
        else:
            raise _refuse(
                col,
                f"character {c!r} is not allowed (names, numbers, 'strings', ( ) [ ] , ; = -)",
            )
    out.append(_Token("END", "", n + 1))
    return out


# -- the parser --------------------------------------------------------------------------


class _Parser:
    def __init__(self, text: str) -> None:
        self.tokens = _tokens(text)
        self.pos = 0
        self.nesting = 0  # inside ( ) or [ ]: newlines are blanks

    def peek(self, ahead: int = 0) -> _Token:
        k = self.pos
        seen = -1
        while True:
            t = self.tokens[k]
            if t.kind == "NEWLINE" and self.nesting:
                k += 1
                continue
            seen += 1
            if seen == ahead:
                return t
            k += 1

    def next(self) -> _Token:
        while self.tokens[self.pos].kind == "NEWLINE" and self.nesting:
            self.pos += 1
        t = self.tokens[self.pos]
        self.pos += 1
        return t

    def expect(self, kind: str, what: str) -> _Token:
        t = self.next()
        if t.kind != kind:
            raise _refuse(t.col, f"expected {what}, found {_show(t)}")
        return t

    def program(self) -> list[Assign]:
        statements: list[Assign] = []
        while True:
            while self.peek().kind in (";", "NEWLINE"):
                self.next()
            if self.peek().kind == "END":
                break
            statements.append(self.statement())
            if len(statements) > MAX_STATEMENTS:
                raise EvaluationError(f"more than {MAX_STATEMENTS} statements")
            t = self.peek()
            if t.kind not in (";", "NEWLINE", "END"):
                raise _refuse(t.col, f"expected ';' or the end, found {_show(t)}")
        if not statements:
            raise EvaluationError("empty expression")
        return statements

    def statement(self) -> Assign:
        t = self.peek()
        if t.kind == "NAME" and self.peek(1).kind == "=":
            self.next()
            self.next()
            return Assign(t.text, self.expr(0), t.col)
        return Assign(None, self.expr(0), t.col)

    def expr(self, depth: int) -> Node:
        if depth > MAX_DEPTH:
            raise _refuse(self.peek().col, f"expression nested deeper than {MAX_DEPTH}")
        t = self.next()
        if t.kind == "NUMBER":
            return Num(float(t.text), t.col)
        if t.kind == "STRING":
            return Str(t.text, t.col)
        if t.kind == "-":
            return Neg(self.expr(depth + 1), t.col)
        if t.kind == "[":
            return self.matrix(t, depth)
        if t.kind == "NAME":
            if self.peek().kind == "(":
                return self.call(t, depth)
            if self.peek().kind == "[":
                raise _refuse(self.peek().col, "indexing ('name[…]') is not allowed; use row()")
            return Name(t.text, t.col)
        raise _refuse(t.col, f"expected a value, found {_show(t)}")

    def call(self, name: _Token, depth: int) -> Call:
        self.next()  # (
        self.nesting += 1
        args: list[Node] = []
        kwargs: list[tuple[str, Node]] = []
        if self.peek().kind != ")":
            while True:
                t = self.peek()
                if t.kind == "NAME" and self.peek(1).kind == "=":
                    self.next()
                    self.next()
                    if any(k == t.text for k, _ in kwargs):
                        raise _refuse(t.col, f"argument {t.text!r} given twice")
                    kwargs.append((t.text, self.expr(depth + 1)))
                elif kwargs:
                    raise _refuse(t.col, "a positional argument after a keyword argument")
                else:
                    args.append(self.expr(depth + 1))
                if self.peek().kind == ",":
                    self.next()
                    continue
                break
        self.nesting -= 1
        self.expect(")", f"',' or ')' closing {name.text}(")
        return Call(name.text, tuple(args), tuple(kwargs), name.col)

    def matrix(self, bracket: _Token, depth: int) -> Matrix:
        self.nesting += 1
        rows: list[tuple[Node, ...]] = []
        row: list[Node] = []
        if self.peek().kind != "]":
            while True:
                row.append(self.expr(depth + 1))
                t = self.peek()
                if t.kind == ",":
                    self.next()
                elif t.kind == ";":
                    self.next()
                    rows.append(tuple(row))
                    row = []
                else:
                    break
            rows.append(tuple(row))
        self.nesting -= 1
        self.expect("]", "',', ';' or ']' in the matrix")
        return Matrix(tuple(rows), bracket.col)


def _show(t: _Token) -> str:
    return {"END": "the end", "NEWLINE": "a new line"}.get(t.kind, repr(t.text))


def parse(text: str) -> list[Assign]:
    """Parse an Evaluate expression into statements (EvaluationError if refused)."""
    if len(text) > MAX_LENGTH:
        raise EvaluationError(f"expression longer than {MAX_LENGTH} characters")
    try:
        return _Parser(text).program()
    except _RefusalError as exc:
        raise _at(text, exc) from None


# -- evaluation --------------------------------------------------------------------------


class Scope:
    """What evaluation needs from a workspace: read a name, store a result."""

    def get(self, name: str) -> Any:  # pragma: no cover - protocol
        raise NotImplementedError

    def set(self, name: str, value: Any) -> None:  # pragma: no cover - protocol
        raise NotImplementedError

    def __contains__(self, name: str) -> bool:  # pragma: no cover - protocol
        raise NotImplementedError


def evaluate(
    text: str,
    scope: Scope,
    functions: Mapping[str, Callable[..., Any]],
    *,
    context: Any = None,
) -> list[str]:
    """Run an Evaluate expression; returns the names assigned, in order.

    Every function is called as ``function(context, *args, **kwargs)``; the arguments
    are bound against its signature first, so a wrong call is refused with Python's
    precise reason but never reaches the function.
    """
    statements = parse(text)
    assigned: list[str] = []
    try:
        for st in statements:
            _run(st, scope, functions, context, assigned)
    except _RefusalError as exc:
        raise _at(text, exc) from None
    return assigned


def _run(st: Assign, scope: Scope, functions: Mapping[str, Callable[..., Any]], context: Any,
         assigned: list[str]) -> None:
    """One statement: evaluate, then store under its target (or ``ans``)."""
    value = _value(st.value, scope, functions, context)
    if value is None:
        if st.target is not None:
            raise _refuse(st.col, f"{_what(st.value)} returns nothing to assign to {st.target}")
        return
    target = st.target or "ans"
    try:
        scope.set(target, value)
    except ValueError as exc:
        raise _refuse(st.col, str(exc)) from None
    assigned.append(target)


def _what(node: Node) -> str:
    return f"{node.func}()" if isinstance(node, Call) else "the expression"


def _value(node: Node, scope: Scope, functions: Mapping[str, Callable[..., Any]],
           context: Any) -> Any:
    if isinstance(node, Num):
        return node.value
    if isinstance(node, Str):
        return node.value
    if isinstance(node, Neg):
        v = _value(node.operand, scope, functions, context)
        if isinstance(v, float):
            return -v
        if isinstance(v, np.ndarray) and v.dtype.kind == "f":
            return -v
        raise _refuse(node.col, "'-' applies to numbers and matrices only")
    if isinstance(node, Name):
        if node.id not in scope:
            raise _refuse(node.col, f"{node.id!r} is not defined in the workspace")
        return scope.get(node.id)
    if isinstance(node, Matrix):
        return _matrix(node, scope, functions, context)
    return _call(node, scope, functions, context)


def _matrix(node: Matrix, scope: Scope, functions: Mapping[str, Callable[..., Any]],
            context: Any) -> np.ndarray:
    rows = []
    for row in node.rows:
        values = []
        for item in row:
            v = _value(item, scope, functions, context)
            if not isinstance(v, float):
                raise _refuse(getattr(item, "col", node.col),
                              "matrix literals hold numbers only")
            values.append(v)
        rows.append(values)
    if len({len(r) for r in rows}) > 1:
        raise _refuse(node.col, "matrix rows of different lengths")
    return np.array(rows, dtype=float).reshape(len(rows), len(rows[0]) if rows else 0)


def _call(node: Call, scope: Scope, functions: Mapping[str, Callable[..., Any]],
          context: Any) -> Any:
    function = functions.get(node.func)
    if function is None:
        if node.func in scope:
            raise _refuse(node.col, f"{node.func!r} is a workspace value, not a function")
        known = ", ".join(sorted(functions))
        raise _refuse(node.col, f"unknown function {node.func!r} (functions: {known})")
    args = [_value(a, scope, functions, context) for a in node.args]
    kwargs = {k: _value(v, scope, functions, context) for k, v in node.kwargs}
    try:
        inspect.signature(function).bind(context, *args, **kwargs)
    except TypeError as exc:
        raise _refuse(node.col, f"{node.func}(): {exc}") from None
    try:
        return function(context, *args, **kwargs)
    except _RefusalError:
        raise
    except EvaluationError as exc:
        raise _refuse(node.col, f"{node.func}(): {exc}") from None
