"""The ACTIVATE string of thesis 4.1.3.2: grammar, round trip, and no crash on any text."""

from __future__ import annotations

import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from plugcell.devices.robot.activate import (
    ActivateString,
    ActivateSyntaxError,
    format_activate,
    parse_activate,
)

DEVICE_CHARS = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789"
devices = st.builds(
    lambda head, tail: head + tail,
    st.sampled_from(DEVICE_CHARS),
    st.text(alphabet=DEVICE_CHARS + "_.-", max_size=63),
)
printable = st.characters(blacklist_categories=("Cc", "Cs"))


def field(allow_hash: bool, min_size: int = 0, max_size: int = 80) -> st.SearchStrategy[str]:
    chars = printable if allow_hash else st.characters(
        blacklist_categories=("Cc", "Cs"), blacklist_characters="#")
    return st.text(alphabet=chars, min_size=min_size, max_size=max_size).map(
        lambda s: s.strip(" \t")).filter(lambda s: len(s) >= min_size)


activates = st.builds(
    ActivateString,
    device=devices,
    command=field(False, 1, 64),
    option=field(False),
    data=field(True),
)


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("ACTIVATE CAMERA #SnapShot##500", ("CAMERA", "SnapShot", "", "500")),
        ("ACTIVATE TOOL #Drill#Air#550,1100", ("TOOL", "Drill", "Air", "550,1100")),
        ("ACTIVATE CAMERA #SnapShot##, 500", ("CAMERA", "SnapShot", "", ", 500")),  # 5.2.3.6
        ("  activate TRACKER#Set Base#rpy2tr# 1,2,3,4,5,6 ",
         ("TRACKER", "Set Base", "rpy2tr", "1,2,3,4,5,6")),
        ("ACTIVATE CAMERA #Connect", ("CAMERA", "Connect", "", "")),
        ("ACTIVATE MATLAB #Evaluate##f('a#b')", ("MATLAB", "Evaluate", "", "f('a#b')")),
    ],
)
def test_the_thesis_strings(text: str, expected: tuple[str, str, str, str]) -> None:
    assert parse_activate(text) == ActivateString(*expected)


@pytest.mark.parametrize(
    ("text", "reason", "column"),
    [
        ("", "empty line", 1),
        ("ACTIVATE", "missing device name after ACTIVATE", 9),
        ("ACTIVATE CAMERA SnapShot 500", "expected '#' and a command after the device name "
                                         "CAMERA, found 'S'", 17),
        ("ACTIVATE CAMERA", "expected '#' and a command after the device name CAMERA, found "
                            "the end of the line", 16),
        ("ACTIVATE CAM/ERA #x", "bad device name 'CAM/ERA'", 10),
        ("ACTIVATE _CAM #x", "bad device name '_CAM'", 10),
        ("ACTIVATE CAMERA ##500", "missing command name after 'CAMERA #'", 18),
        ("ACTIVATE#CAMERA", "expected a blank and a device name after ACTIVATE", 9),
        ("DEACTIVATE CAMERA #x", "expected ACTIVATE, found 'DEACTIVATE'", 1),
        ("ACTIVATE CAMERA #Snap\nShot", "control character U+000A", 22),
        ("ACTIVATE CAMERA #" + "x" * 65, "command name of 65 characters (at most 64)", 18),
    ],
)
def test_precise_errors(text: str, reason: str, column: int) -> None:
    with pytest.raises(ActivateSyntaxError) as info:
        parse_activate(text)
    assert info.value.reason.startswith(reason)
    assert info.value.column == column
    assert str(info.value).endswith(f"(column {column})")


@settings(max_examples=400)
@given(activates)
def test_round_trip(a: ActivateString) -> None:
    text = format_activate(a)
    assert parse_activate(text) == a
    assert str(a) == text


@settings(max_examples=1500)
@given(st.text(max_size=120))
@example("ACTIVATE \x00#x")
@example("ACTIVATE A #\ud800")
@example("ACTIVATE A#" + "#" * 200)
def test_any_text_parses_or_is_refused_precisely(text: str) -> None:
    try:
        a = parse_activate(text)
    except ActivateSyntaxError as exc:
        assert exc.reason and 1 <= exc.column <= len(text) + 1
        return
    assert parse_activate(format_activate(a)) == a  # a parsed string has a canonical form


@settings(max_examples=600)
@given(activates, st.text(alphabet=" \t", max_size=3), st.text(alphabet=" \t", max_size=3),
       st.sampled_from(["ACTIVATE", "activate", "Activate"]))
def test_blanks_and_keyword_case_do_not_matter(a: ActivateString, before: str, after: str,
                                               keyword: str) -> None:
    text = f"{before}{keyword} {a.device}{after}#{a.command}#{a.option}#{a.data}{after}"
    assert parse_activate(text) == a


@given(activates)
def test_format_refuses_what_it_cannot_write(a: ActivateString) -> None:
    for bad in (ActivateString("bad name", a.command), ActivateString(a.device, "a#b"),
                ActivateString(a.device, a.command, "o#p"), ActivateString(a.device, ""),
                ActivateString(a.device, a.command, data=" padded ")):
        with pytest.raises(ValueError):
            format_activate(bad)
