"""``plugcell export --out``: a file named for another format is refused before anything
is read (issue 39 §8: ``--out x.yaml --format urdf`` wrote a URDF into a .yaml)."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from plugcell.apps.cli import CommandError, main
from plugcell.apps.commands.export import EXTENSIONS, _check_extension


@pytest.mark.parametrize(("out", "fmt", "message"), [
    ("x.yaml", "urdf", "x.yaml: a .yaml file is --format ur-kinematics, not urdf: name it "
                       "x.urdf or give --format ur-kinematics"),
    ("x.toml", "ur-kinematics", "a .toml file is --format toml, not ur-kinematics: name it "
                                "x.yaml"),
    ("x.URDF", "toml", "a .urdf file is --format urdf, not toml: name it x.toml"),
])
def test_an_out_file_of_another_format_is_refused_up_front(tmp_path, capsys, out, fmt, message):
    path = tmp_path / out
    assert main(["export", "--params", str(tmp_path / "missing.json"), "--format", fmt,
                 "--out", str(path)]) == 2
    err = capsys.readouterr().err
    assert message in err and "missing.json" not in err, err
    assert not path.exists()


def test_the_formats_own_and_unknown_endings(tmp_path, capsys):
    for fmt, ends in EXTENSIONS.items():
        for end in ends:
            _check_extension(tmp_path / f"robot{end}", fmt)
    assert capsys.readouterr().err == ""
    _check_extension(tmp_path / "robot.txt", "urdf")
    err = capsys.readouterr().err
    assert "warning: --out" in err and "usually ends in .urdf" in err


@given(st.text(max_size=12), st.sampled_from(sorted(EXTENSIONS)))
@settings(max_examples=200, deadline=None)
def test_any_name_is_accepted_warned_or_refused_naming_the_format(name, fmt):
    try:
        path = Path("out") / f"x{name}"
    except ValueError:
        return
    try:
        _check_extension(path, fmt)
    except CommandError as exc:
        other = next(f for f, ends in EXTENSIONS.items() if path.suffix.lower() in ends)
        assert other != fmt and f"--format {other}, not {fmt}" in str(exc)
