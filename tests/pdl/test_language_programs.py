"""The language's statements, routines, libraries, waits and data from services."""

from __future__ import annotations

import math
import textwrap
from pathlib import Path

import numpy as np
import pytest
from language_fakes import FakeArm, execution, run_source

from plugcell.pdl import (
    BUILTIN_LIBRARY,
    ExecutionState,
    JointPos,
    LibraryError,
    Position,
    Program,
    ValueConversionError,
    Vector,
    WaitTimeoutError,
)


def program(body: str, decls: str = "", routines: str = "") -> str:
    """A PROGRAM t with the given declarations, routines and main body."""
    return (
        "PROGRAM t\n"
        + textwrap.dedent(decls)
        + textwrap.dedent(routines)
        + "BEGIN\n"
        + textwrap.dedent(body)
        + "END t\n"
    )


def run_ok(text: str, **kw):
    result, ex, arm, channel = run_source(text, **kw)
    assert result.ok, result.error
    return ex, arm, channel


def console(body: str, decls: str = "", routines: str = "", **kw) -> list[str]:
    ex, _, _ = run_ok(program(body, decls, routines), **kw)
    return ex.console


# --------------------------------------------------------------------------- routines
def test_recursion_and_return_values():
    out = console(
        """
        WRITE LUN_CRT (FACT(10), ' ', FIB(15), ' ', HALF(7))
        """,
        routines="""
        ROUTINE FACT(n : INTEGER) : INTEGER
        BEGIN
          IF n <= 1 THEN
            RETURN 1
          ENDIF
          RETURN n * FACT(n - 1)
        END FACT
        ROUTINE FIB(n : INTEGER) : INTEGER
        BEGIN
          IF n < 2 THEN
            RETURN n
          ENDIF
          RETURN FIB(n - 1) + FIB(n - 2)
        END FIB
        ROUTINE HALF(n : INTEGER) : REAL
        BEGIN
          RETURN n / 2
        END HALF
        """,
    )
    assert out == ["3628800 610 3.500000"]


def test_parameters_are_passed_by_value_and_procedures_return_nothing():
    out = console(
        """
        a[1] := 1
        a[2] := 2
        n := 5
        BUMP(n, a)
        WRITE LUN_CRT (n, ' ', a[1], ' ', a[2])
        """,
        decls="""
        VAR n : INTEGER
            a : ARRAY[2] OF INTEGER
        """,
        routines="""
        ROUTINE BUMP(k : INTEGER; arr : ARRAY[*] OF INTEGER)
        BEGIN
          k := k + 1
          arr[1] := 100
          WRITE LUN_CRT ('inside ', k, ' ', arr[1], ' of ', ARRAY_DIM1(arr))
          RETURN
        END BUMP
        """,
    )
    assert out == ["inside 6 100 of 2", "5 1 2"]


def test_runaway_recursion_is_a_stack_overflow_error():
    text = program(
        "n := DEEP(0)\n",
        "VAR n : INTEGER\n",
        ("ROUTINE DEEP(k : INTEGER) : INTEGER\nBEGIN\n  RETURN DEEP(k + 1)\nEND DEEP\n"),
    )
    result, *_ = run_source(text)
    assert result.state is ExecutionState.FAILED
    assert "more than 64 nested routine calls" in str(result.error) and result.error.line == 5


def test_deeper_recursion_when_allowed():
    text = program(
        "n := DEPTH(250)\n",
        "VAR n : INTEGER\n",
        (
            "ROUTINE DEPTH(k : INTEGER) : INTEGER\nBEGIN\n  IF k = 0 THEN\n    RETURN 0\n  ENDIF\n"
            "  RETURN 1 + DEPTH(k - 1)\nEND DEPTH\n"
        ),
    )
    ex, _, _ = run_ok(text, max_call_depth=300)
    assert ex.get_variable("n") == 250


def test_function_without_return_fails_at_run_time():
    text = program(
        "n := F(1)\n",
        "VAR n : INTEGER\n",
        ("ROUTINE F(k : INTEGER) : INTEGER\nBEGIN\n  k := k + 1\nEND F\n"),
    )
    result, *_ = run_source(text)
    assert "F ended without RETURN" in str(result.error)


# --------------------------------------------------------------------------- control flow
def test_for_to_downto_step_while_repeat_select():
    out = console(
        """
        s := ''
        FOR i := 1 TO 10 STEP 3 DO
          ENCODE (s, s, i, ' ')
        ENDFOR
        FOR i := 3 DOWNTO 1 DO
          ENCODE (s, s, i)
        ENDFOR
        i := 0
        WHILE i < 5 DO
          i := i + 2
        ENDWHILE
        k := 0
        REPEAT
          k := k + 1
        UNTIL k * k > 50
        FOR j := 1 TO 0 DO
          k := -1
        ENDFOR
        SELECT k OF
          CASE (1, 2):
            WRITE LUN_CRT ('small')
          CASE (8):
            WRITE LUN_CRT ('eight')
          ELSE:
            WRITE LUN_CRT ('other')
        ENDSELECT
        WRITE LUN_CRT (s, '|', i, '|', k)
        """,
        decls="VAR i, j, k : INTEGER\n    s : STRING[40]\n",
    )
    assert out == ["eight", "1 4 7 10 321|6|8"]


def test_if_else_and_boolean_operators():
    out = console(
        """
        b := (3 > 2) AND NOT (1 = 2) OR FALSE
        IF b XOR FALSE THEN
          WRITE LUN_CRT ('yes ', 6 AND 3, ' ', 6 OR 3, ' ', NOT 0)
        ELSE
          WRITE LUN_CRT ('no')
        ENDIF
        """,
        decls="VAR b : BOOLEAN\n",
    )
    assert out == ["yes 2 7 -1"]


# --------------------------------------------------------------------------- data
def test_arrays_one_and_two_dimensional_with_bounds_errors():
    out = console(
        """
        FOR i := 1 TO 3 DO
          v[i] := i * 1.5
          FOR j := 1 TO 4 DO
            m[i, j] := i * 10 + j
          ENDFOR
        ENDFOR
        w := v
        w[1] := 0
        WRITE LUN_CRT (ARRAY_DIM(m, 1), 'x', ARRAY_DIM2(m), ' ', m[3, 4], ' ',
                       v[1]::1::1, ' ', w[1])
        """,
        decls="VAR m : ARRAY[3, 4] OF INTEGER\n    v, w : ARRAY[3] OF REAL\n    i, j : INTEGER\n",
    )
    assert out == ["3x4 34 1.5 0.000000"]
    result, *_ = run_source(program("a[4] := 1\n", "VAR a : ARRAY[3] OF INTEGER\n"))
    assert "index [4] outside a[1..3]" in str(result.error) and result.error.line == 4


def test_strings_and_string_builtins():
    out = console(
        """
        s := 'Hello, robot'
        short := s
        WRITE LUN_CRT (short, '|', STR_LEN(s), '|', STR_LOC(s, 'robot'), '|', STR_XTRT(s, 8, 5))
        WRITE LUN_CRT (STR_EDIT('  Mixed Case ', ED_UPPER), '|', STR_EDIT('  x y ', ED_TRIM), '|')
        WRITE LUN_CRT (STR_TO_INT(' 42 ') + 1, ' ', STR_TO_REAL('2.5') * 2, ' ',
                       CHR(65), ORD('AB', 2))
        WRITE LUN_CRT ('it''s ', 'a' + 'b', ' ', 'abc' < 'abd')
        """,
        decls="VAR s : STRING[40]\n    short : STRING[5]\n",
    )
    assert out == ["Hello|12|8|robot", "  MIXED CASE |x y|", "43 5.000000 A66", "it's ab TRUE"]


def test_math_builtins_use_degrees():
    out = console(
        """
        WRITE LUN_CRT (SIN(30)::0::4, ' ', COS(60)::0::4, ' ', TAN(45)::0::4, ' ', ATAN2(1, 1))
        WRITE LUN_CRT (ASIN(1)::0::1, ' ', ACOS(0)::0::1, ' ', SQRT(2)::0::5, ' ',
                       ABS(-3), ' ', ABS(-2.5))
        WRITE LUN_CRT (ROUND(2.5), ROUND(-2.5), ' ', TRUNC(-2.7), ' ',
                       7 DIV 2, -7 DIV 2, ' ', -7 MOD 2)
        WRITE LUN_CRT (EXP(0), ' ', LN(EXP(2))::0::3, ' ', MIN(3, 2), ' ', MAX(1.5, 2))
        """
    )
    assert out == [
        "0.5000 0.5000 1.0000 45.000000",
        "90.0 90.0 1.41421 3 2.500000",
        "3-3 -2 3-3 -1",
        "1.000000 2.000 2 2.000000",
    ]


def test_positions_vectors_jointpos_and_motion_builtins():
    arm = FakeArm()
    ex, arm, _ = run_ok(
        program(
            """
            p := POS(100, 200, 300, 10, 20, 30, 'S')
            p.Z := p.Z + 1
            v := POS_GET_LOC(p) + VEC(1, 1, 1)
            MOVE TO p
            MOVE LINEAR TO POS(110, 200, 300, 10, 20, 30)
            MOVE RELATIVE VEC(0, 0, 50) IN TOOL
            j := ARM_JNTP
            j[6] := 45
            MOVE JOINT TO j
            q := POS_TO_JNTP(ARM_POS)
            r := JNTP_TO_POS(JNTP(1, 2, 3, 4, 5, 6))
            POS_XTRT(r, x, y, z, a, b, c, cnfg)
            POS_TO_JNTP(p, j2)
            WRITE LUN_CRT (p.Z, ' ', p.CNFG, ' ', v, ' ', q[6], ' ', x, ' ', c, ' ', j2[3])
            WRITE LUN_CRT (p::0::1)
            """,
            """
            VAR p, r : POSITION
                v : VECTOR
                j, j2, q : JOINTPOS
                x, y, z, a, b, c : REAL
                cnfg : STRING[10]
            """,
        ),
        arm=arm,
    )
    assert ex.console == [
        "301.000000 S 101.000000,201.000000,302.000000 45.000000 10.000000 6.000000 30.100000",
        "100.0,200.0,301.0,10.0,20.0,30.0",
    ]
    kinds = [k for k, _ in arm.log]
    assert kinds == ["to", "linear", "relative", "joints"]
    assert arm.log[2][1] == ((0.0, 0.0, 50.0), "TOOL")
    assert arm.log[3][1][5] == 45.0
    assert ex.sim_time == pytest.approx(4 * arm.move_s)


def test_motion_failure_is_an_error_at_the_move():
    text = program("MOVE TO POS(100, 0, 0, 0, 0, 0)\nMOVE TO POS(5000, 0, 0, 0, 0, 0)\n")
    result, *_ = run_source(text, arm=FakeArm(unreachable_x=1000))
    assert result.state is ExecutionState.FAILED
    assert result.error.line == 4 and "out of reach" in str(result.error)


def test_delay_and_clock_run_on_simulated_time():
    ex, _, _ = run_ok(
        program(
            "DELAY 1500\nt := CLOCK\nDELAY 250\nWRITE LUN_CRT (t, ' ', CLOCK)\n",
            "VAR t : INTEGER\n",
        ),
        speed=1000.0,
    )
    assert ex.console == ["1500 1750"]
    assert ex.sim_time == pytest.approx(1.75)


# --------------------------------------------------------------------------- waits
def test_wait_timeout_fails_the_program_with_its_line():
    text = program("ext_cmd_finished := FALSE\nWAIT FOR ext_cmd_finished TIMEOUT 2000\n")
    result, *_ = run_source(text, speed=1000.0)
    assert result.state is ExecutionState.FAILED
    assert isinstance(result.error, WaitTimeoutError)
    assert result.error.line == 4 and "timed out after 2000 ms" in str(result.error)
    assert result.sim_time == pytest.approx(2.0, abs=0.01)
    assert result.real_time < 1.0


def test_wait_timeout_can_be_trapped():
    out = console(
        """
        ERR_TRAP_ON(ERR_WAIT_TIMEOUT)
        WAIT FOR ext_cmd_finished TIMEOUT 500
        IF $ERROR = ERR_WAIT_TIMEOUT THEN
          WRITE LUN_CRT ('timed out at ', CLOCK, ' ms')
        ENDIF
        ERR_TRAP_OFF(ERR_WAIT_TIMEOUT)
        """,
        speed=1000.0,
    )
    assert out == ["timed out at 500 ms"]


def test_a_wait_without_timeout_has_a_real_time_budget():
    text = program("WAIT FOR ext_cmd_finished\n")
    result, *_ = run_source(text, speed=1000.0, wait_budget_s=0.2)
    assert isinstance(result.error, WaitTimeoutError) and "real-time budget" in str(result.error)
    assert 0.15 < result.real_time < 2.0


def test_other_runtime_errors_can_be_trapped_with_err_any():
    out = console(
        """
        ERR_TRAP_ON(ERR_ANY)
        n := 1 DIV 0
        WRITE LUN_CRT ($ERROR = ERR_DIVISION_BY_ZERO, ' ', STR_LOC($ERROR_MSG, 'division'))
        """,
        decls="VAR n : INTEGER\n",
    )
    assert out[0].startswith("TRUE ") and out[0] != "TRUE 0"


# --------------------------------------------------------------------------- service data
def test_service_data_reaches_the_program_as_language_values():
    answers = {
        "Snap": (True, np.array([[1, 2, 3], [4, 5, 6]], dtype=np.int32), ""),
        "Pose": (True, np.eye(4), ""),
        "Name": (True, "camera-7", ""),
        "Fail": (False, None, "no such command"),
    }

    def respond(line: str):
        return answers[line.split("#")[1]]

    ex, _, channel = run_ok(
        """PROGRAM t
IMPORT 'services'
VAR p : POSITION
BEGIN
  IF EXT_CMD('CAMERA', 'Snap', '', '', 1000) THEN
    WRITE LUN_CRT (ext_cmd_count, ' ', ext_cmd_rows, 'x', ext_cmd_cols, ' ', ext_cmd_data[6])
  ENDIF
  IF EXT_CMD('TRACKER', 'Pose', '', '', 1000) THEN
    p := POS_FROM_MATRIX(ext_cmd_data, 1)
    WRITE LUN_CRT (p::0::1)
  ENDIF
  IF EXT_CMD('CAMERA', 'Name', '', '', 1000) THEN
    WRITE LUN_CRT (ext_cmd_text, ' ', ext_cmd_count)
  ENDIF
  IF NOT EXT_CMD('CAMERA', 'Fail', 'opt', '1,2', 1000) THEN
    WRITE LUN_CRT ('failed: ', ext_cmd_message)
  ENDIF
END t
""",
        responder=respond,
    )
    assert channel.lines[0] == "ACTIVATE CAMERA #Snap##"
    assert channel.lines[-1] == "ACTIVATE CAMERA #Fail#opt#1,2"
    assert ex.console == [
        "6 2x3 6.000000",
        "0.0,0.0,0.0,0.0,0.0,0.0",
        "camera-7 0",
        "failed: no such command",
    ]


def test_posting_typed_variables_converts_numpy_and_poses():
    prog = Program.from_source(
        program(
            "WRITE LUN_CRT (n, ' ', r, ' ', flag, ' ', s, ' ', m[2, 3], ' ', p::0::1, ' ', j[2])\n",
            """
            VAR n : INTEGER
                r : REAL
                flag : BOOLEAN
                s : STRING[8]
                m : ARRAY[2, 3] OF REAL
                p : POSITION
                j : JOINTPOS
            """,
        )
    )
    ex, *_ = execution(prog)
    T = np.eye(4)
    T[:3, 3] = [0.1, 0.2, 0.3]  # metres
    T[:3, :3] = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]  # 90 deg about z
    ex.post(
        {
            "n": np.int32(7),
            "r": 2,
            "flag": np.bool_(True),
            "s": "abc",
            "m": np.arange(6.0).reshape(2, 3),
            "p": T,
            "j": [10, 20, 30],
        }
    )
    result = ex.run()
    assert result.ok, result.error
    assert ex.console == ["7 2.000000 TRUE abc 5.000000 100.0,200.0,300.0,90.0,0.0,0.0 20.000000"]
    assert ex.get_variable("m") == [[0.0, 1.0, 2.0], [3.0, 4.0, 5.0]]
    assert ex.get_variable("p") == Position(100.0, 200.0, 300.0, 90.0, 0.0, 0.0)
    assert ex.get_variable("j") == JointPos((10.0, 20.0, 30.0))


@pytest.mark.parametrize(
    ("name", "value", "message"),
    [
        ("n", 2.5, "2.5 is not an INTEGER"),
        ("n", 2**40, "does not fit a 32-bit INTEGER"),
        ("n", True, "is a BOOLEAN, not an INTEGER"),
        ("r", "fast", "is not a REAL"),
        ("r", float("nan"), "not a finite REAL"),
        ("s", "x" * 9, "a string of 9 characters does not fit STRING[8]"),
        ("m", np.zeros((3, 2)), "data of shape (3, 2) does not fit ARRAY[2, 3] OF REAL"),
        ("m", [[1, 2, 3], [4, "five", 6]], "element [2, 2]"),
        ("p", np.ones((4, 4)), "last row of a pose matrix"),
        ("p", [1, 2, 3], "is not a POSITION"),
        ("v", [1, 2], "a VECTOR has 3 values, not 2"),
        ("nothing", 1, "has no variable nothing"),
    ],
)
def test_data_that_does_not_fit_is_refused_with_the_reason(name, value, message):
    prog = Program.from_source(
        program(
            "",
            """
            VAR n : INTEGER
                r : REAL
                s : STRING[8]
                m : ARRAY[2, 3] OF REAL
                p : POSITION
                v : VECTOR
            """,
        ),
        "conv.pdl",
    )
    ex, *_ = execution(prog)
    with pytest.raises(ValueConversionError) as info:
        ex.set_variable(name, value)
    assert message in str(info.value)
    assert info.value.file == "conv.pdl"


def test_post_result_refuses_oversized_data_and_sets_nothing():
    prog = Program.from_source(program(""))
    ex, *_ = execution(prog)
    with pytest.raises(ValueConversionError, match="do not fit ext_cmd_data"):
        ex.post_result(True, np.zeros(5000))
    ex.run()
    assert ex.get_variable("ext_cmd_finished") is False


def test_values_preset_globals_like_a_variable_file():
    prog = Program.from_source(program("WRITE LUN_CRT (k)\n", "VAR k : INTEGER\n"))
    ex, *_ = execution(prog, values={"K": 3})
    assert ex.run().ok and ex.console == ["3"]


# --------------------------------------------------------------------------- libraries
def test_imported_library_routines_relative_and_on_the_search_path(tmp_path: Path):
    libdir = tmp_path / "libs"
    libdir.mkdir()
    (libdir / "geometry.pdl").write_text(
        textwrap.dedent(
            """\
            PROGRAM geometry NOHOLD
            CONST scale = 2
            VAR calls : INTEGER
            ROUTINE DOUBLE(x : REAL) : REAL
            BEGIN
              RETURN x * scale
            END DOUBLE
            ROUTINE NORM(v : VECTOR) : REAL
            BEGIN
              RETURN SQRT(v.X * v.X + v.Y * v.Y + v.Z * v.Z)
            END NORM
            BEGIN
            END geometry
            """
        )
    )
    (tmp_path / "local.pdl").write_text(
        "PROGRAM local\nROUTINE TRIPLE(x : INTEGER) : INTEGER\nBEGIN\n  RETURN 3 * x\nEND TRIPLE\n"
        "END local\n"
    )
    main = tmp_path / "main.pdl"
    main.write_text(
        textwrap.dedent(
            """\
            PROGRAM main
            IMPORT 'local'
            IMPORT 'geometry.pdl'
            ROUTINE NORM(v : VECTOR) : REAL EXPORTED FROM geometry
            BEGIN
              WRITE LUN_CRT (TRIPLE(2), ' ', DOUBLE(1.25), ' ', NORM(VEC(3, 4, 0)))
            END main
            """
        )
    )
    with pytest.raises(LibraryError, match=r"cannot find library 'geometry\.pdl'") as info:
        Program.load(main)
    assert info.value.line == 3
    prog = Program.load(main, library_path=[libdir])
    assert len(prog.libraries) == 2
    ex, *_ = execution(prog)
    assert ex.run().ok
    assert ex.console == ["6 2.500000 5.000000"]


def test_exported_from_must_match_the_library(tmp_path: Path):
    (tmp_path / "lib.pdl").write_text(
        "PROGRAM lib\nROUTINE F(x : INTEGER) : INTEGER\nBEGIN\n  RETURN x\nEND F\nEND lib\n"
    )
    bad = "PROGRAM m\nROUTINE F(x : REAL) : INTEGER EXPORTED FROM lib\nBEGIN\nEND m\n"
    with pytest.raises(LibraryError, match=r"does not match its definition at .*lib.pdl:2"):
        Program.from_source(bad, "m.pdl", base_dir=tmp_path)
    missing = "PROGRAM m\nROUTINE G EXPORTED FROM lib\nBEGIN\nEND m\n"
    with pytest.raises(LibraryError, match="has no routine G"):
        Program.from_source(missing, "m.pdl", base_dir=tmp_path)


def test_library_global_variables_are_shared_with_exported_from(tmp_path: Path):
    (tmp_path / "state.pdl").write_text(
        "PROGRAM state\nVAR counter : INTEGER\nROUTINE TICK\nBEGIN\n  counter := counter + 1\n"
        "END TICK\nEND state\n"
    )
    text = (
        "PROGRAM m\nIMPORT 'state'\nVAR counter : INTEGER EXPORTED FROM state\nBEGIN\n"
        "  counter := 40\n  TICK\n  TICK\n  WRITE LUN_CRT (counter)\nEND m\n"
    )
    prog = Program.from_source(text, "m.pdl", base_dir=tmp_path)
    ex, *_ = execution(prog)
    assert ex.run().ok and ex.console == ["42"]


# --------------------------------------------------------------------------- shipped programs
def _split(line: str) -> tuple[str, str, str, str]:
    """``ACTIVATE DEVICE #Command#Option#Data`` → its four parts."""
    head, command, option, data = line.split("#", 3)
    return head.split()[1], command, option, data


@pytest.mark.parametrize("route", [True, False])
def test_shipped_calibration_program_runs_fifteen_simulated_minutes_in_seconds(route):
    """Fig. 8-4: 100 poses, a 1 s measurement at each; measurements routed straight to
    COMPUTE (9.3) or, as in the thesis, through the program."""
    rng = np.random.default_rng(0)
    configs = rng.uniform(-60, 60, size=(100, 6))
    arm = FakeArm(move_s=8.0)

    def respond(line: str):
        _, command, _, data = _split(line)
        if command == "Single Measurement":
            ex.clock.advance(float(data) / 1000.0)  # the tracker integrates that long
            return True, np.array(arm.arm_pos().as_tuple()), ""
        return True, None, ""

    prog = Program.load(BUILTIN_LIBRARY / "calibration.pdl")
    identify = "params = calibrate(mJ, mT, model=5, payload=36); save_params(params, 'h4')"
    ex, arm, channel = execution(  # 100 of the 200 rows given: the rest stay uninitialised
        prog, respond, arm=arm, speed=float("inf"),
        values={"configs": configs.tolist(), "n_configs": 100, "route": route,
                "base_est": [4000.0, 100.0, -300.0, 10.0, 2.0, -20.0],
                "probe_est": [45.0, -30.0, 140.0, 30.0, 2.0, 1.5],
                "duration_ms": 1000, "identify": identify})
    result = ex.run()
    assert result.ok, result.error
    assert result.sim_time == pytest.approx(101 * 8.0 + 100 * 1.0)  # 15 simulated minutes
    assert result.real_time < 5.0
    parts = [_split(line) for line in channel.lines]
    measured = [p for p in parts if p[1] == "Single Measurement"]
    assert len(measured) == 100 and {p[0] for p in measured} == {"TRACKER"}
    mT = [p for p in parts if p[1:3] == ("Set Matrix", "mT:append")]
    if route:
        assert {p[2] for p in measured} == {"tr2euler; to=COMPUTE:Set Matrix:mT:append"}
        assert mT == []
    else:
        assert {p[2] for p in measured} == {"tr2euler"} and len(mT) == 100
    mJ = [p for p in parts if p[1:3] == ("Set Matrix", "mJ:append")]
    assert len(mJ) == 100
    np.testing.assert_allclose([float(x) for x in mJ[0][3].split(",")], configs[0], atol=1e-6)
    # the beam is caught with the estimates, then measurements are raw
    assert parts[1][1:] == ("Set Base", "euler2tr", "4000.000000,100.000000,-300.000000,"
                                                    "10.000000,2.000000,-20.000000")
    assert parts[4][1:] == ("Set Base", "euler2tr", "0,0,0,0,0,0")
    assert parts[-1] == ("COMPUTE", "Evaluate", "", identify)
    assert ex.console[-1] == "calibration: identified after 908 s"


def test_calibration_program_values_that_do_not_fit_are_refused_with_the_line():
    prog = Program.load(BUILTIN_LIBRARY / "calibration.pdl")
    with pytest.raises(ValueConversionError, match=r"calibration.pdl:\d+:\d+: cannot set configs"):
        execution(prog, lambda line: (True, None, ""),
                  values={"configs": np.zeros((201, 6)).tolist()})


def test_shipped_compensation_library_converges_with_a_fake_tracker(tmp_path: Path):
    """SENSOR_COM: measure, CALC (robot service), move, until 0.08 mm / 0.05 deg."""
    arm = FakeArm(move_s=1.0)
    bias = np.array([0.8, -0.5, 0.3])  # mm, shrinking by half per correction
    state = {"corrections": 0}

    def respond(line: str):
        device, command, option, data = _split(line)
        if (device, command) == ("COMPUTE", "Evaluate"):
            return True, None, ""
        if (device, command, option) == ("COMPUTE", "Get Matrix", "q"):
            return True, np.full(6, 0.01), ""  # the compensated joints
        if device == "COMPUTE" and command == "Get Matrix":  # the identified base
            return True, np.zeros((1, 6)), ""
        if device == "TRACKER" and command in ("Set Base", "Set Probe", "Move"):
            return True, None, ""
        if command == "Single Measurement":  # the true pose: the target plus an error
            xyz = np.array([800.0, 0.0, 600.0]) + bias / 2 ** state["corrections"]
            return True, np.r_[xyz, 0.0, 90.0, 0.0], ""
        if command == "JointIncrement":
            values = [float(v) for v in data.split(",")]
            err = float(np.linalg.norm(np.subtract(values[:3], values[6:9])))
            state["corrections"] += 1
            return True, np.r_[err, 0.0, np.zeros(6)], ""
        return False, None, f"unknown {command}"

    text = """PROGRAM holes
IMPORT 'services'
IMPORT 'compensation'
VAR target : POSITION
    iterations : INTEGER
BEGIN
  IF NOT INITIALIZE('h4') THEN
    DEACTIVATE
  ENDIF
  target := POS(800, 0, 600, 0, 90, 0)
  MOVE TO target
  IF MODEL_COM(target, 36) THEN
    iterations := SENSOR_COM(target)
  ENDIF
END holes
"""
    prog = Program.from_source(text, "holes.pdl")
    ex, arm, channel = execution(prog, respond, arm=arm)
    result = ex.run()
    assert result.ok, result.error
    # 0.99 mm → 0.49 → 0.25 → 0.12 → 0.06 < 0.08: four corrections (five CALCs)
    assert ex.get_variable("iterations") == 4
    assert state["corrections"] == 5
    assert channel.lines[0] == ("ACTIVATE COMPUTE #Evaluate##params = load_params(\"h4\"); "
                                "base = frame(params, \"base\")")
    assert channel.lines[1] == "ACTIVATE COMPUTE #Get Matrix#base#"
    assert channel.lines[2].startswith("ACTIVATE TRACKER #Set Base#euler2tr#0.000000,")
    assert "payload=36.000000)" in channel.lines[4]
    assert arm.q[5] == pytest.approx(0.01)  # the compensated joints were used


def test_shipped_programs_all_load():
    for path in sorted(BUILTIN_LIBRARY.glob("*.pdl")):
        prog = Program.load(path)
        assert prog.name and math.isfinite(len(prog.source()))


def test_vectors_add():
    out = console(
        "v := VEC(1, 2, 3) + VEC(1, 1, 1) - VEC(0, 0, 1)\nWRITE LUN_CRT (v::0::0)\n",
        "VAR v : VECTOR\n",
    )
    assert out == ["2,3,3"]
    assert Vector(1, 2, 3).get("Y") == 2


def test_value_texts_read_back_as_what_they_were():
    """numbers_text / rows_text write what value_from_text reads (program values)."""
    from plugcell.devices.robot.value_text import numbers_text, rows_text, value_from_text
    from plugcell.pdl.types import JOINTPOS, POSITION, ArrayType

    pos = [1500.0, -0.25, 1200.125, 10.0, 90.0, -179.5]
    assert value_from_text(numbers_text(pos), POSITION) == pos
    rows = np.array([[1.0, -2.0, 3.0, 4.0, 5.0, 6.0], [0.5, 0.0, -0.5, 1e-6, 2.0, 3.0]])
    back = value_from_text(rows_text(rows), ArrayType(JOINTPOS, (200,)))
    np.testing.assert_allclose(back, rows, atol=1e-6)
    assert numbers_text(np.float64(2.5)) == "2.500000"
