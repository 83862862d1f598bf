"""Property tests: the parser is the printer's inverse, expressions evaluate as
Python does, and no input crashes the parser with anything but a ProgramError."""

from __future__ import annotations

import math
import string

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from plugcell.pdl import (
    BUILTIN_LIBRARY,
    DivisionByZeroError,
    Execution,
    OverflowProgramError,
    Program,
    ProgramError,
    SimClock,
    format_expr,
    format_module,
    parse_module,
)
from plugcell.pdl import nodes as n
from plugcell.pdl.types import (
    BOOLEAN,
    INTEGER,
    POSITION,
    REAL,
    ArrayType,
    StringType,
)

SETTINGS = settings(
    max_examples=150,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow],
)
INT32 = (-(2**31), 2**31 - 1)

# --------------------------------------------------------------------------- reference semantics


def py_div(a: int, b: int) -> int:
    q = abs(a) // abs(b)
    return q if (a >= 0) == (b >= 0) else -q


def py_eval(e: n.Expr):
    """Python reference evaluator (raises ZeroDivisionError / OverflowError)."""
    if isinstance(e, n.IntLit | n.RealLit | n.BoolLit):
        return e.value
    if isinstance(e, n.Unary):
        v = py_eval(e.operand)
        if e.op == "NOT":
            return (not v) if isinstance(v, bool) else ~v
        return check(-v) if e.op == "-" else v
    assert isinstance(e, n.Binary)
    a, b = py_eval(e.left), py_eval(e.right)
    op = e.op
    if op in ("AND", "OR", "XOR"):
        if isinstance(a, bool):
            return {"AND": a and b, "OR": a or b, "XOR": a != b}[op]
        return {"AND": a & b, "OR": a | b, "XOR": a ^ b}[op]
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
    if op == ">=":
        return a >= b
    if op == "DIV":
        if b == 0:
            raise ZeroDivisionError
        return check(py_div(a, b))
    if op == "MOD":
        if b == 0:
            raise ZeroDivisionError
        return check(a - b * py_div(a, b))
    if op == "/":
        if b == 0:
            raise ZeroDivisionError
        return check(a / b)
    return check({"+": a + b, "-": a - b, "*": a * b}[op])


def check(v):
    if isinstance(v, float):
        if not math.isfinite(v):
            raise OverflowError
    elif not INT32[0] <= v <= INT32[1]:
        raise OverflowError
    return v


# --------------------------------------------------------------------------- generators
small_ints = st.integers(min_value=0, max_value=40).map(n.IntLit)
big_ints = st.integers(min_value=0, max_value=2**31 - 1).map(n.IntLit)
int_leaf = st.one_of(small_ints, big_ints)
reals = st.floats(min_value=0, max_value=1e6, allow_nan=False).map(n.RealLit)


def int_exprs() -> st.SearchStrategy[n.Expr]:
    return st.recursive(
        int_leaf,
        lambda sub: st.one_of(
            st.builds(n.Unary, st.just("-"), sub),
            st.builds(
                n.Binary, st.sampled_from(["+", "-", "*", "DIV", "MOD", "AND", "OR"]), sub, sub
            ),
        ),
        max_leaves=12,
    )


def num_exprs() -> st.SearchStrategy[n.Expr]:
    return st.recursive(
        st.one_of(small_ints, reals),
        lambda sub: st.one_of(
            st.builds(n.Unary, st.just("-"), sub),
            st.builds(n.Binary, st.sampled_from(["+", "-", "*", "/"]), sub, sub),
        ),
        max_leaves=10,
    )


def bool_exprs() -> st.SearchStrategy[n.Expr]:
    comparison = st.builds(
        n.Binary, st.sampled_from(["=", "<>", "<", "<=", ">", ">="]), int_exprs(), int_exprs()
    )
    return st.recursive(
        st.one_of(st.booleans().map(n.BoolLit), comparison),
        lambda sub: st.one_of(
            st.builds(n.Unary, st.just("NOT"), sub),
            st.builds(n.Binary, st.sampled_from(["AND", "OR", "XOR"]), sub, sub),
        ),
        max_leaves=8,
    )


def run_expr(expr: n.Expr, type_name: str):
    text = f"PROGRAM e\nVAR r : {type_name}\nBEGIN\n  r := {format_expr(expr)}\nEND e\n"
    ex = Execution(Program.from_source(text, "e.pdl"), clock=SimClock(math.inf))
    result = ex.run()
    return result.error, (ex.get_variable("r") if result.error is None else None)


def expect_same(expr: n.Expr, type_name: str) -> None:
    error, value = run_expr(expr, type_name)
    try:
        want = py_eval(expr)
    except ZeroDivisionError:
        assert isinstance(error, DivisionByZeroError), (format_expr(expr), error)
        return
    except OverflowError:
        assert isinstance(error, OverflowProgramError), (format_expr(expr), error)
        return
    assert error is None, (format_expr(expr), error)
    if type_name == "REAL":
        assert value == pytest.approx(want, rel=1e-12, abs=1e-9), format_expr(expr)
    else:
        assert value == want, format_expr(expr)


@SETTINGS
@given(int_exprs())
def test_integer_expressions_evaluate_like_python(expr):
    expect_same(expr, "INTEGER")


@SETTINGS
@given(num_exprs())
def test_real_expressions_evaluate_like_python(expr):
    expect_same(expr, "REAL")


@SETTINGS
@given(bool_exprs())
def test_boolean_expressions_evaluate_like_python(expr):
    expect_same(expr, "BOOLEAN")


# --------------------------------------------------------------------------- parse ∘ print
KEYWORDS = {
    "AND", "ARRAY", "BEGIN", "BOOLEAN", "CASE", "CONST", "DEACTIVATE", "DELAY", "DIV", "DO",
    "DOWNTO", "ELSE", "END", "ENDFOR", "ENDIF", "ENDSELECT", "ENDWHILE", "EXPORTED", "FALSE",
    "FOR", "FROM", "IF", "IMPORT", "IN", "INTEGER", "JOINT", "JOINTPOS", "LINEAR", "MOD",
    "MOVE", "NOT", "OF", "OR", "POSITION", "PROGRAM", "REAL", "RELATIVE", "REPEAT", "RETURN",
    "ROUTINE", "SELECT", "STEP", "STRING", "THEN", "TIMEOUT", "TO", "TRUE", "UNTIL", "VAR",
    "VECTOR", "WAIT", "WHILE", "WRITE", "XOR",
}  # fmt: skip

names = (
    st.text(string.ascii_letters + "_", min_size=1, max_size=1)
    .flatmap(
        lambda c: st.text(string.ascii_letters + string.digits + "_", max_size=7).map(
            lambda rest: c + rest
        )
    )
    .filter(lambda s: s.upper() not in KEYWORDS)
)
literals = st.one_of(
    st.integers(0, 2**31 - 1).map(n.IntLit),
    st.floats(0, 1e300, allow_nan=False).map(n.RealLit),
    st.text(
        st.characters(blacklist_characters="\n\x00", blacklist_categories=["Cs"]), max_size=8
    ).map(n.StrLit),
    st.booleans().map(n.BoolLit),
)
ops = st.sampled_from(
    ["+", "-", "*", "/", "DIV", "MOD", "AND", "OR", "XOR", "=", "<>", "<", "<=", ">", ">="]
)


def any_exprs() -> st.SearchStrategy[n.Expr]:
    leaf = st.one_of(literals, names.map(n.Name))
    return st.recursive(
        leaf,
        lambda sub: st.one_of(
            st.builds(n.Unary, st.sampled_from(["-", "+", "NOT"]), sub),
            st.builds(n.Binary, ops, sub, sub),
            st.builds(n.Call, names, st.lists(sub, max_size=3).map(tuple)),
            st.builds(n.Index, names.map(n.Name), st.lists(sub, min_size=1, max_size=2).map(tuple)),
            st.builds(n.Field, names.map(n.Name), st.sampled_from(["X", "Y", "CNFG"])),
        ),
        max_leaves=10,
    )


def stmts(depth: int = 2) -> st.SearchStrategy[n.Stmt]:
    e = any_exprs()
    block = st.lists(st.deferred(lambda: stmts(depth - 1)), max_size=3).map(tuple)
    simple = [
        st.builds(n.Assign, names.map(n.Name), e),
        st.builds(n.CallStmt, names, st.lists(e, max_size=3).map(tuple)),
        st.builds(n.Wait, e, st.one_of(st.none(), e)),
        st.builds(n.Delay, e),
        st.builds(n.Move, st.sampled_from(["TO", "JOINT", "LINEAR"]), e),
        st.builds(n.MoveRelative, e, st.sampled_from(["BASE", "TOOL"])),
        st.builds(
            n.Write,
            names,
            st.lists(
                st.one_of(
                    st.builds(n.WriteItem, e),
                    st.builds(n.WriteItem, e, e),
                    st.builds(n.WriteItem, e, e, e),
                ),
                max_size=3,
            ).map(tuple),
        ),
        st.builds(n.Return, st.one_of(st.none(), e)),
        st.builds(n.Deactivate, st.lists(names, max_size=2).map(tuple)),
    ]
    if depth <= 0:
        return st.one_of(simple)
    compound = [
        st.builds(n.If, e, block, st.one_of(st.none(), block)),
        st.builds(n.For, names, e, e, st.booleans(), st.one_of(st.none(), e), block),
        st.builds(n.While, e, block),
        st.builds(n.Repeat, block, e),
        st.builds(
            n.Select,
            e,
            st.lists(
                st.builds(n.Case, st.lists(e, min_size=1, max_size=2).map(tuple), block),
                min_size=1,
                max_size=2,
            ).map(tuple),
            st.one_of(st.none(), block),
        ),
    ]
    return st.one_of(*simple, *compound)


types_ = st.one_of(
    st.sampled_from([INTEGER, REAL, BOOLEAN, POSITION]),
    st.integers(1, 300).map(StringType),
    st.builds(
        ArrayType,
        st.sampled_from([INTEGER, REAL, POSITION]),
        st.lists(st.integers(1, 50), min_size=1, max_size=2).map(tuple),
    ),
)


def modules() -> st.SearchStrategy[n.Module]:
    var = st.builds(
        n.VarDecl,
        st.lists(names, min_size=1, max_size=3).map(tuple),
        types_,
        st.sampled_from([(), ("NOSAVE",)]),
        st.one_of(st.none(), names),
    )
    const = st.builds(n.ConstDecl, names, any_exprs())
    param = st.builds(n.Param, names, types_)
    routine = st.builds(
        n.Routine,
        names,
        st.lists(param, max_size=3).map(tuple),
        st.one_of(st.none(), types_),
        st.lists(var.map(lambda v: n.VarDecl(v.names, v.type)), max_size=2).map(tuple),
        st.lists(stmts(1), max_size=3).map(tuple),
    )
    extern = st.builds(
        n.Routine,
        names,
        st.lists(param, max_size=2).map(tuple),
        st.one_of(st.none(), types_),
        st.just(()),
        st.just(()),
        names,
    )
    decls = st.lists(
        st.one_of(var, const, routine, extern, st.builds(n.Import, st.text("ab/'._", max_size=6))),
        max_size=4,
    )
    attrs = st.lists(st.builds(n.ProgAttr, names, st.one_of(st.none(), small_ints)), max_size=2)
    return st.builds(
        n.Module,
        names,
        attrs.map(tuple),
        decls.map(tuple),
        st.one_of(st.none(), st.lists(stmts(), max_size=4).map(tuple)),
    )


@settings(
    max_examples=200,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow],
)
@given(modules())
def test_parse_is_the_inverse_of_print(module):
    text = format_module(module)
    again = parse_module(text, "gen.pdl")
    assert again == module, text
    assert format_module(again) == text


@SETTINGS
@given(any_exprs())
def test_expressions_print_and_parse_back(expr):
    text = f"PROGRAM p\nBEGIN\n  x := {format_expr(expr)}\nEND p\n"
    body = parse_module(text).body
    assert body is not None and body[0] == n.Assign(n.Name("x"), expr), text


# --------------------------------------------------------------------------- robustness
def only_program_errors(text: str) -> None:
    try:
        Program.from_source(text, "fuzz.pdl", base_dir=BUILTIN_LIBRARY)
    except ProgramError as exc:
        assert exc.file and exc.line >= 0
        assert str(exc).startswith(exc.file)


@settings(max_examples=300, deadline=None, derandomize=True)
@given(st.binary(max_size=200))
def test_random_bytes_never_crash_the_parser(data):
    only_program_errors(data.decode("latin-1"))


@settings(max_examples=200, deadline=None, derandomize=True)
@given(st.text(max_size=200))
def test_random_text_never_crashes_the_parser(text):
    only_program_errors(text)


EXAMPLE_TEXT = (BUILTIN_LIBRARY / "example.pdl").read_text()
TOKENS = ["(", ")", "[", "]", ",", ":", ":=", "::", "'", "--", "\n", " END ", " IF ", "=", "0"]


@settings(max_examples=300, deadline=None, derandomize=True)
@given(st.data())
def test_mutated_programs_fail_only_with_program_errors(data):
    text = EXAMPLE_TEXT
    for _ in range(data.draw(st.integers(1, 4))):
        i = data.draw(st.integers(0, len(text)))
        j = data.draw(st.integers(i, min(len(text), i + 12)))
        insert = data.draw(st.one_of(st.sampled_from(TOKENS), st.text(max_size=3)))
        text = text[:i] + insert + text[j:]
    only_program_errors(text)


def test_deep_nesting_is_a_program_error_not_a_crash():
    only_program_errors("PROGRAM p\nBEGIN\n  x := " + "(" * 5000 + "1" + ")" * 5000 + "\nEND p\n")
    only_program_errors("PROGRAM p\nBEGIN\n" + "IF TRUE THEN\n" * 800 + "ENDIF\n" * 800 + "END p\n")
