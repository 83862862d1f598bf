"""``plugcell cell run R1 PROGRAM``: a relative program path is the caller's (issue 39 §6).

The robot service and its controller may run in another folder: a relative path to a
file in the caller's folder goes out absolute; a library name and anything the caller
cannot find go out unchanged (the controller's error says where it looked)."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from plugcell.apps.commands.cell import program_ref
from plugcell.devices.robot.runner import RunError, resolve_program


def test_a_relative_path_to_a_file_here_goes_out_absolute(tmp_path, monkeypatch):
    (tmp_path / "progs").mkdir()
    (tmp_path / "progs" / "mine.pdl").write_text("PROGRAM mine\nBEGIN\nEND mine\n")
    (tmp_path / "calibration").write_text("a file named like a library program")
    monkeypatch.chdir(tmp_path)
    assert program_ref("progs/mine.pdl") == str(tmp_path / "progs" / "mine.pdl")
    assert program_ref("./progs/mine.pdl") == str(tmp_path / "progs" / "mine.pdl")
    assert program_ref("calibration") == "calibration"  # a name: the library's
    assert program_ref("progs/other.pdl") == "progs/other.pdl"  # not here: the robot's
    assert program_ref("progs") == "progs"  # a folder is no program
    assert program_ref("/abs/x.pdl") == "/abs/x.pdl"


def test_the_controller_says_where_it_looked_for_a_relative_path(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(RunError) as caught:
        resolve_program("progs/mine.pdl")
    assert str(caught.value) == (
        f"no such program file: progs/mine.pdl (looked for {tmp_path}/progs/mine.pdl: a "
        f"relative path is taken from the robot controller's folder {tmp_path}, not the "
        "caller's; give an absolute path, or put the program in the program library "
        "(library=DIR) and give its name)")
    with pytest.raises(RunError, match=r"^no such program file: /nowhere/x.pdl \(no such file\)$"):
        resolve_program("/nowhere/x.pdl")
    with pytest.raises(RunError, match=r"\(not a file\)$"):
        resolve_program(str(tmp_path))


@given(st.text(max_size=40))
@settings(max_examples=200, deadline=None)
def test_any_program_argument_is_kept_or_made_an_existing_absolute_file(text):
    out = program_ref(text)
    assert out == text or (Path(out).is_absolute() and Path(out).is_file()
                           and Path(out) == Path(text).expanduser().resolve())
