"""The Evaluate language: what it accepts, what it refuses and why, and that it can only
ever call registered functions (no eval, no attribute access, no dunder names)."""

from __future__ import annotations

import contextlib

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from plugcell.devices.compute.expr import (
    Assign,
    Call,
    EvaluationError,
    Matrix,
    Name,
    Neg,
    Num,
    Str,
    evaluate,
    parse,
)
from plugcell.devices.compute.workspace import Workspace

calls: list[tuple] = []


def _scale(ctx, a, k=2.0):
    calls.append(("scale", ctx))
    return np.asarray(a) * k


def _nothing(ctx):
    calls.append(("nothing", ctx))


FUNCTIONS = {"scale": _scale, "nothing": _nothing}


def test_statements_calls_keywords_literals_and_matrices_are_parsed():
    (st1, st2, st3) = parse("p = scale(mJ, k=-2.5e1)\nq = [1, 2; 3, .5]; 'text'")
    assert st1 == Assign("p", Call("scale", (Name("mJ", 11),), (("k", Neg(Num(25.0, 18), 17)),),
                                   5), 1)
    assert st2.target == "q" and isinstance(st2.value, Matrix)
    assert st2.value.rows == ((Num(1.0, 30), Num(2.0, 33)), (Num(3.0, 36), Num(0.5, 39)))
    assert st3 == Assign(None, Str("text", 44), 44)  # columns count from the start of the text
    # inside brackets a statement may span lines
    assert len(parse("p = scale(\n  [1, 2],\n  k=3)")) == 1
    with pytest.raises(EvaluationError, match=r"^line 2, column 7: operator '\+'"):
        parse("p = scale(a)\nq = a + 1")


def test_evaluation_stores_results_and_ans_and_passes_the_context():
    ws = Workspace("R")
    ws.set("a", [1.0, 2.0])
    calls.clear()
    assert evaluate("b = scale(a); scale(b, k=0.5); nothing()", ws, FUNCTIONS,
                    context="CTX") == ["b", "ans"]
    np.testing.assert_allclose(ws.get("b"), [[2.0, 4.0]])
    np.testing.assert_allclose(ws.get("ans"), [[1.0, 2.0]])
    assert calls == [("scale", "CTX"), ("scale", "CTX"), ("nothing", "CTX")]
    evaluate("c = -[1, 2]; d = 3", ws, FUNCTIONS)
    np.testing.assert_allclose(ws.get("c"), [[-1.0, -2.0]])
    assert ws.get("d").shape == (1, 1)


@pytest.mark.parametrize(
    ("text", "reason"),
    [
        ("__import__('os')", "column 1: names may not begin with '_' ('__import__')"),
        ("x = __builtins__", "column 5: names may not begin with '_'"),
        ("os.system('rm -rf /')", "column 3: attribute access ('os.') is not allowed"),
        ("scale(a).__class__", "column 9: attribute access ('.') is not allowed"),
        ("a.__dict__", "attribute access ('a.')"),
        ("eval('1+1')", "column 1: unknown function 'eval' (functions: nothing, scale)"),
        ("exec('import os')", "unknown function 'exec'"),
        ("open('/etc/passwd')", "unknown function 'open'"),
        ("getattr(a, 'x')", "unknown function 'getattr'"),
        ("lambda: 1", "column 7: character ':' is not allowed"),
        ("a + 1", "column 3: operator '+' is not part of Evaluate expressions"),
        ("a * 2", "operator '*'"),
        ("a[0]", "column 2: indexing ('name[…]') is not allowed"),
        ("{1: 2}", "column 1: character '{' is not allowed"),
        ("a == a", "comparisons ('==')"),
        ("'unterminated", "column 1: unterminated string"),
        ("scale(a,)", "column 9: expected a value, found ')'"),
        ("scale(k=1, a)", "a positional argument after a keyword argument"),
        ("scale(a, k=1, k=2)", "argument 'k' given twice"),
        ("scale(a, z=1)", "column 1: scale(): got an unexpected keyword argument 'z'"),
        ("scale()", "scale(): missing a required argument: 'a'"),
        ("nothing(1)", "nothing(): too many positional arguments"),
        ("x = nothing()", "nothing() returns nothing to assign to x"),
        ("x = 'text'", "x: a string cannot be stored"),
        ("b = undefined_name", "'undefined_name' is not defined in the workspace"),
        ("a(1)", "'a' is a workspace value, not a function"),
        ("[1, 2; 3]", "matrix rows of different lengths"),
        ("['a', 1]", "matrix literals hold numbers only"),
        ("-'a'", "'-' applies to numbers and matrices only"),
        ("1abc", "unexpected 'a' after the number 1"),
        ("", "empty expression"),
        (";;", "empty expression"),
        ("x = " + "scale(" * 40 + "a" + ")" * 40, "nested deeper than 32"),
        ("x = 1" + "; x = 1" * 100, "more than 100 statements"),
        ("a" * 70, "longer than 63 characters"),
        ("x" * 10_001, "longer than 10000 characters"),
    ],
)
def test_everything_else_is_refused_with_a_precise_reason(text, reason):
    ws = Workspace("R")
    ws.set("a", [1.0])
    calls.clear()
    with pytest.raises(EvaluationError) as info:
        evaluate(text, ws, FUNCTIONS)
    assert reason in str(info.value)
    assert ws.names() == ["a"]  # nothing was stored...
    assert not calls or text.startswith("x = nothing")  # ...and nothing ran, but refused calls


@settings(max_examples=400, deadline=None)
@given(st.text(alphabet=st.sampled_from(list("abcos_.()[]=,;'\"-+*1 e\n")), max_size=40))
def test_any_text_is_either_evaluated_or_refused_and_never_reaches_python(text):
    ws = Workspace("R")
    ws.set("a", [1.0])
    called: list[str] = []

    def spy(ctx, *args, **kwargs):
        called.append("spy")
        return 1.0

    with contextlib.suppress(EvaluationError):
        evaluate(text, ws, {"c": spy})
    assert set(called) <= {"spy"}
    assert all(not n.startswith("_") for n in ws.names())
