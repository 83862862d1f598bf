"""Malformed programs are refused with file, line and a clear message."""

from __future__ import annotations

import textwrap

import pytest
from language_fakes import run_source

from plugcell.pdl import (
    ArgumentError,
    DeclarationError,
    DivisionByZeroError,
    ExecutionError,
    IndexOutOfBoundsError,
    LibraryError,
    MathError,
    MotionFailedError,
    OverflowProgramError,
    ParseError,
    Program,
    ProgramError,
    TypeMismatchError,
    UninitializedError,
)

HEADER = """PROGRAM bad
VAR n : INTEGER
    r : REAL
    s : STRING[10]
    a : ARRAY[3] OF INTEGER
    m : ARRAY[2, 2] OF REAL
    p : POSITION
    j : JOINTPOS
CONST limit = 10
ROUTINE F(x : INTEGER) : INTEGER
BEGIN
  RETURN x + 1
END F
ROUTINE PROC(x : INTEGER)
BEGIN
  n := x
END PROC
BEGIN
"""
FIRST = HEADER.count("\n") + 1  # the line of the first statement of the main body

# (statements of the main body, error class, line offset from FIRST, message)
BAD_BODIES = [
    ("IF n > 0 THEN\n  n := 1\n", ParseError, 2, "expected ELSE or ENDIF, found the keyword END"),
    ("n = 1\n", ParseError, 0, "found '=' (assignment is ':=')"),
    ('s := "text"\n', ParseError, 0, "unexpected character a quote"),
    ("n := (1 + 2\n", ParseError, 0, "expected ')', found end of line"),
    ("IF n > 0 AND n < 5 THEN\nENDIF\n", ParseError, 0, "comparisons cannot be chained"),
    ("FOR n := 1 TO 3 DO\n  r := 1\nENDWHILE\n", ParseError, 2, "expected ENDFOR, found"),
    ("MOVE x\n", ParseError, 0, "expected JOINT, LINEAR, RELATIVE or TO, found 'x'"),
    ("n := 1 +\n", ParseError, 0, "expected an expression, found end of line"),
    ("n := 99999999999\n", ParseError, 0, "integer 99999999999 out of range"),
    ("step := 1\n", ParseError, 0, "found the keyword STEP (a reserved word: not usable as"),
    ("y := 1\n", DeclarationError, 0, "y is not declared"),
    ("n := 'abc'\n", TypeMismatchError, 0, "cannot assign a STRING[3] to n (INTEGER)"),
    ("r := p\n", TypeMismatchError, 0, "cannot assign a POSITION to r (REAL)"),
    ("n := F(1, 2)\n", ArgumentError, 0, "F expects 1 argument, got 2"),
    ("n := F\n", ArgumentError, 0, "F expects 1 argument, got 0"),
    ("n := F('x')\n", TypeMismatchError, 0, "argument 1 of F (x) must be INTEGER, not STRING[1]"),
    ("FOO(1)\n", DeclarationError, 0, "unknown routine FOO"),
    ("n := PROC(1)\n", TypeMismatchError, 0, "PROC returns no value"),
    ("r := SIN('a')\n", TypeMismatchError, 0, "argument 1 of SIN must be INTEGER or REAL"),
    ("r := SQRT(1, 2)\n", ArgumentError, 0, "SQRT expects 1 argument(s), got 2"),
    ("IF n THEN\nENDIF\n", TypeMismatchError, 0, "the IF condition must be BOOLEAN, not INTEGER"),
    ("WAIT FOR n TIMEOUT 10\n", TypeMismatchError, 0, "WAIT FOR condition must be BOOLEAN"),
    ("RETURN 1\n", DeclarationError, 0, "RETURN outside a routine"),
    ("limit := 3\n", TypeMismatchError, 0, "cannot assign to the constant limit"),
    ("n := a[1, 2]\n", TypeMismatchError, 0, "a has 1 dimension(s), 2 index(es) given"),
    ("r := n.X\n", TypeMismatchError, 0, "INTEGER has no fields (.X)"),
    ("r := p.Q\n", TypeMismatchError, 0, "POSITION has no field Q"),
    ("MOVE LINEAR TO j\n", TypeMismatchError, 0, "MOVE LINEAR TO needs a POSITION, not JOINTPOS"),
    ("MOVE RELATIVE VEC(0, 0, 1) IN WORLD\n", DeclarationError, 0, "the frame must be BASE"),
    ("WRITE printer ('x')\n", DeclarationError, 0, "unknown logical unit printer"),
    ("n := 1 + 'a'\n", TypeMismatchError, 0, "operator + cannot combine INTEGER and STRING[1]"),
    ("n := n DIV 2.0\n", TypeMismatchError, 0, "operator DIV cannot combine INTEGER and REAL"),
    ("s := NL\n", TypeMismatchError, 0, "cannot assign a NL to s"),
    ("ext_cmd_finished := 1\n", TypeMismatchError, 0, "to ext_cmd_finished (BOOLEAN)"),
]


@pytest.mark.parametrize(("body", "kind", "offset", "message"), BAD_BODIES)
def test_bad_statement_is_refused_at_its_line(body, kind, offset, message):
    text = HEADER + body + "END bad\n"
    with pytest.raises(kind) as info:
        Program.from_source(text, "bad.pdl")
    err = info.value
    assert isinstance(err, ProgramError)
    assert message in err.message, str(err)
    assert err.file == "bad.pdl"
    assert err.line == FIRST + offset, str(err)
    assert str(err).startswith(f"bad.pdl:{err.line}:")


BAD_PROGRAMS = [
    ("", ParseError, 1, "unexpected end of file: expected PROGRAM"),
    ("PROGRAM x\nBEGIN\nEND y\n", ParseError, 3, "END y does not match PROGRAM x"),
    ("PROGRAM x\nBEGIN\n", ParseError, 2, "unexpected end of file"),
    ("PROGRAM x\nVAR n, n : INTEGER\nBEGIN\nEND x\n", DeclarationError, 2, "already declared"),
    ("PROGRAM x\nVAR s : STRING\nBEGIN\nEND x\n", TypeMismatchError, 2, "needs a length"),
    ("PROGRAM x\nVAR a : ARRAY[0] OF REAL\nBEGIN\nEND x\n", ParseError, 2, "at least 1, not 0"),
    ("PROGRAM x\nVAR NL : INTEGER\nBEGIN\nEND x\n", DeclarationError, 2, "NL is a predefined name"),
    (
        "PROGRAM x\nVAR ext_cmd_result : INTEGER\nBEGIN\nEND x\n",
        TypeMismatchError,
        2,
        "is the service variable ext_cmd_result : BOOLEAN",
    ),
    (
        "PROGRAM x\nROUTINE R\nBEGIN\n  r := 1\n  VAR k : INTEGER\nEND R\nBEGIN\nEND x\n",
        ParseError,
        5,
        "VAR must come before BEGIN",
    ),
    (
        "PROGRAM x\nROUTINE R : INTEGER\nBEGIN\n  RETURN 'a'\nEND R\nBEGIN\nEND x\n",
        TypeMismatchError,
        4,
        "R returns an INTEGER, not a STRING[1]",
    ),
    (
        "PROGRAM x\nROUTINE R\nBEGIN\n  RETURN 1\nEND R\nBEGIN\nEND x\n",
        TypeMismatchError,
        4,
        "routine R returns no value",
    ),
    (
        "PROGRAM x\nROUTINE R(a, a : REAL)\nBEGIN\nEND R\nBEGIN\nEND x\n",
        DeclarationError,
        2,
        "a is already declared",
    ),
    ("PROGRAM x\nCONST k = n\nVAR n : INTEGER\nBEGIN\nEND x\n", DeclarationError, 2, "constant"),
    ("PROGRAM x\nIMPORT 'no_such_lib'\nBEGIN\nEND x\n", LibraryError, 2, "cannot find library"),
    ("PROGRAM x\nBEGIN\n  WRITE LUN_CRT ('a'\n  'b')\nEND x\n", ParseError, 3, "expected ')'"),
    ("PROGRAM x\nBEGIN\n  x := 1 y := 2\nEND x\n", ParseError, 3, "expected an operator or end"),
    ("PROGRAM x\nBEGIN\n  n := 1\x00\nEND x\n", ParseError, 3, "binary file"),
]


@pytest.mark.parametrize(("text", "kind", "line", "message"), BAD_PROGRAMS)
def test_bad_program_is_refused_at_its_line(text, kind, line, message):
    with pytest.raises(kind) as info:
        Program.from_source(text, "bad.pdl")
    assert message in info.value.message, str(info.value)
    assert info.value.line == line, str(info.value)


def test_parse_errors_are_not_lark_tracebacks():
    with pytest.raises(ParseError) as info:
        Program.from_source("PROGRAM x\nBEGIN\n  IF THEN\nEND x\n", "t.pdl")
    text = str(info.value)
    assert text.startswith("t.pdl:3:6: expected an expression, found the keyword THEN")
    assert info.value.__cause__ is None and info.value.__suppress_context__


def test_errors_in_a_library_name_the_library_file(tmp_path):
    (tmp_path / "lib.pdl").write_text(
        "PROGRAM lib\nROUTINE R : INTEGER\nBEGIN\n  RETURN undeclared\nEND R\nEND lib\n"
    )
    with pytest.raises(DeclarationError) as info:
        Program.from_source("PROGRAM m\nIMPORT 'lib'\nBEGIN\nEND m\n", "m.pdl", base_dir=tmp_path)
    assert info.value.file == str(tmp_path / "lib.pdl") and info.value.line == 4


# (statements, variables, error class, line offset, message) — errors only found at run time
RUNTIME = [
    ("n := 0\nn := 10 DIV n\n", DivisionByZeroError, 1, "division by zero (DIV)"),
    ("n := 0\nr := 1 / n\n", DivisionByZeroError, 1, "division by zero"),
    ("n := 4\na[n] := 1\n", IndexOutOfBoundsError, 1, "index [4] outside a[1..3]"),
    ("n := a[2]\n", UninitializedError, 0, "a[2] is uninitialized"),
    ("r := r + 1\n", UninitializedError, 0, "r is uninitialized"),
    ("n := 2147483647\nn := n + 1\n", OverflowProgramError, 1, "INTEGER overflow"),
    ("r := SQRT(-1)\n", MathError, 0, "SQRT of a negative number"),
    ("r := ACOS(2)\n", MathError, 0, "ACOS(2) is undefined"),
    ("FOR n := 1 TO 3 STEP 0 DO\nENDFOR\n", ExecutionError, 0, "FOR STEP must be positive"),
    ("DELAY -5\n", ExecutionError, 0, "DELAY of a negative time"),
    ("s := STR_XTRT('abc', 5, 1)\n", IndexOutOfBoundsError, 0, "STR_XTRT start 5"),
    ("j := JNTP(1, 2)\nr := j[3]\n", IndexOutOfBoundsError, 1, "axis 3 outside j[1..2]"),
    ("n := STR_TO_INT('12a')\n", ExecutionError, 0, "'12a' is not an INTEGER"),
]


@pytest.mark.parametrize(("body", "kind", "offset", "message"), RUNTIME)
def test_runtime_errors_carry_the_line(body, kind, offset, message):
    result, *_ = run_source(HEADER + body + "END bad\n")
    err = result.error
    assert isinstance(err, kind), err
    assert message in err.message, str(err)
    assert err.line == FIRST + offset, str(err)


def test_a_dropped_connection_fails_the_write():
    from language_fakes import FakeChannel, execution

    prog = Program.from_source(
        textwrap.dedent(
            """\
            PROGRAM x
            BEGIN
              WRITE pc_client ('one')
              WRITE pc_client ('two')
            END x
            """
        ),
        "x.pdl",
    )
    ex, _, channel = execution(prog)
    assert isinstance(channel, FakeChannel)
    channel.fail_after = 1
    result = ex.run()
    assert result.error is not None and result.error.line == 4
    assert "connection to the robot service dropped" in str(result.error)


def test_no_arm_attached_is_a_motion_error():
    from plugcell.pdl import Execution

    prog = Program.from_source("PROGRAM x\nBEGIN\n  MOVE TO ARM_POS\nEND x\n")
    result = Execution(prog).run()
    assert isinstance(result.error, MotionFailedError) and result.error.line == 3
