"""The ACTIVATE string of thesis 4.1.3.2: ``ACTIVATE DEVICE #Command#Option#Data``.

A robot program drives a peripheral by writing one such string to the robot
service (``WRITE pc_client ('ACTIVATE CAMERA #SnapShot##', exposure_time)``); the
service turns it into a CreateProcess of ``Command`` at the partner ``DEVICE``
(5.2.3.6).  This module is the string's grammar and nothing else:

* :func:`parse_activate` — text → :class:`ActivateString`, or
  :class:`ActivateSyntaxError` with the reason and the column; it never raises
  anything else, whatever the text;
* :func:`format_activate` — :class:`ActivateString` → the canonical text, so that
  ``parse_activate(format_activate(a)) == a``.

Grammar (docs/controller-protocol.md §4)::

    activate := ws* ACTIVATE ws+ device ws* '#' command ['#' option ['#' data]] ws*

* ``ACTIVATE`` in any letter case; ``ws`` is space or tab;
* ``device`` a service name: a letter or digit, then letters, digits, ``_ . -``,
  at most 64 characters (docs/protocol.md §2);
* ``command`` 1–64 characters, no ``#`` (spaces inside are allowed: the thesis's
  Matlab service has ``Set Matrix``);
* ``option`` no ``#``; ``data`` the rest of the line (it may hold ``#``);
* fields are trimmed of surrounding blanks; control characters are refused;
* the thesis's examples: ``ACTIVATE CAMERA #SnapShot##500`` and ``ACTIVATE TOOL
  #Drill#Air#550,1100`` (4.1.3.2); ``ACTIVATE CAMERA #SnapShot##, 500`` (5.2.3.6).
  A missing option and data (``ACTIVATE CAMERA #Connect``) mean empty ones.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

__all__ = [
    "KEYWORD",
    "MAX_NAME",
    "ActivateString",
    "ActivateSyntaxError",
    "format_activate",
    "parse_activate",
]

KEYWORD = "ACTIVATE"
#: Longest device or command name (the framework's limit, docs/protocol.md §4).
MAX_NAME = 64
_DEVICE = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.\-]{0,63}\Z")
_BLANK = " \t"


class ActivateSyntaxError(ValueError):
    """An ACTIVATE string that cannot be read: ``reason`` at ``column`` (1-based)."""

    def __init__(self, reason: str, text: str, column: int) -> None:
        self.reason = reason
        self.text = text
        self.column = column
        super().__init__(f"{reason} (column {column})")


@dataclass(frozen=True, slots=True)
class ActivateString:
    """One request of a robot program: run ``command`` at ``device`` (4.1.3.2)."""

    device: str
    command: str
    option: str = ""
    data: str = ""

    def __str__(self) -> str:
        return format_activate(self)


def _control(text: str) -> int:
    """Index of the first control character (not tab), or -1."""
    for i, ch in enumerate(text):
        if (ord(ch) < 0x20 and ch != "\t") or ord(ch) == 0x7F:
            return i
    return -1


def _skip_blanks(text: str, i: int) -> int:
    while i < len(text) and text[i] in _BLANK:
        i += 1
    return i


def parse_activate(text: str) -> ActivateString:
    """Read one ACTIVATE string (see the module docstring for the grammar)."""
    if not isinstance(text, str):
        raise ActivateSyntaxError(f"expected text, got {type(text).__name__}", "", 1)
    bad = _control(text)
    if bad >= 0:
        raise ActivateSyntaxError(
            f"control character U+{ord(text[bad]):04X} in an ACTIVATE string", text, bad + 1
        )
    i = _skip_blanks(text, 0)
    if i == len(text):
        raise ActivateSyntaxError("empty line: expected ACTIVATE DEVICE #Command#Option#Data",
                                  text, i + 1)
    word_end = i
    while word_end < len(text) and text[word_end] not in _BLANK + "#":
        word_end += 1
    word = text[i:word_end]
    if word.upper() != KEYWORD:
        raise ActivateSyntaxError(f"expected ACTIVATE, found {word[:40]!r}", text, i + 1)
    i = _skip_blanks(text, word_end)
    if i == word_end and i < len(text):  # "ACTIVATE#..."
        raise ActivateSyntaxError("expected a blank and a device name after ACTIVATE",
                                  text, i + 1)
    start = i
    while i < len(text) and text[i] not in _BLANK + "#":
        i += 1
    device = text[start:i]
    if not device:
        raise ActivateSyntaxError("missing device name after ACTIVATE", text, start + 1)
    if not _DEVICE.match(device):
        raise ActivateSyntaxError(
            f"bad device name {device[:70]!r}: a letter or digit, then letters, digits, "
            f"'_', '.', '-' (at most {MAX_NAME} characters)",
            text,
            start + 1,
        )
    i = _skip_blanks(text, i)
    if i == len(text) or text[i] != "#":
        found = "the end of the line" if i == len(text) else repr(text[i])
        raise ActivateSyntaxError(
            f"expected '#' and a command after the device name {device}, found {found}",
            text,
            i + 1,
        )
    rest = text[i + 1 :]
    command, sep, rest = rest.partition("#")
    option, sep2, data = rest.partition("#") if sep else ("", "", "")
    command_col = i + 2
    if not command.strip(_BLANK):
        raise ActivateSyntaxError(f"missing command name after '{device} #'", text, command_col)
    command = command.strip(_BLANK)
    if len(command) > MAX_NAME:
        raise ActivateSyntaxError(
            f"command name of {len(command)} characters (at most {MAX_NAME})", text, command_col
        )
    del sep2
    return ActivateString(device, command, option.strip(_BLANK), data.strip(_BLANK))


def format_activate(activate: ActivateString) -> str:
    """The canonical text of ``activate``; ValueError if a field cannot be written."""
    if not _DEVICE.match(activate.device):
        raise ValueError(f"bad device name {activate.device!r}")
    for field, value in (
        ("command", activate.command),
        ("option", activate.option),
        ("data", activate.data),
    ):
        if _control(value) >= 0:
            raise ValueError(f"{field} {value!r} holds a control character")
        if value != value.strip(_BLANK):
            raise ValueError(f"{field} {value!r} has surrounding blanks")
        if field != "data" and "#" in value:
            raise ValueError(f"{field} {value!r} holds '#'")
    if not activate.command or len(activate.command) > MAX_NAME:
        raise ValueError(f"command name must have 1…{MAX_NAME} characters")
    a = activate
    return f"{KEYWORD} {a.device} #{a.command}#{a.option}#{a.data}"
