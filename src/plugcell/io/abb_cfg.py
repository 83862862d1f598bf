"""ABB's controller configuration files (``.cfg``: MOC, SIO, SIOC, EIO …) written and read.

A configuration file is line based::

    MOC:CFG_1.0:6:0::            the domain, the format version, RobotWare major:minor
    #                            a comment line (a line starting with '#')
    EXT_MOTION_DATA:             a type, ended by ':'; its instances follow

          -name "pathCorr" -ext_motion_Kp 5\\
          -ramp_time 0.5

* an instance is a run of ``-attribute value`` pairs (a flag attribute has no value),
  indented, separated from the previous one by a blank line; a ``\\`` at a line's end
  continues the instance on the next line;
* a value is a number, a word, or a string in double quotes (no quotes inside).

:func:`cfg_text` writes one file from ``{type: [instance, …]}`` (an instance a dict of
attribute → value, ``True`` for a flag); :func:`parse_cfg` reads one back, raising
:class:`CfgError` naming the line for anything it does not understand.  The layout
follows the files RobotStudio's *Save Parameters* writes (an attribute pair per
instance line, at most :data:`WIDTH` characters a line).
"""

from __future__ import annotations

import re
from typing import Any

__all__ = ["WIDTH", "CfgError", "cfg_text", "parse_cfg"]

#: The longest line :func:`cfg_text` writes (a continued line ends in ``\``).
WIDTH = 80
_HEADER = re.compile(r"^([A-Z][A-Z0-9_]*):CFG_(\d+\.\d+):(\d+):(\d+)::$")
_TYPE = re.compile(r"^([A-Z][A-Z0-9_]*):$")
_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")
_TOKEN = re.compile(r'\s*(-[A-Za-z][A-Za-z0-9_]*|"[^"]*"|[^\s"]+)')
_WORD = re.compile(r"^[A-Za-z0-9_.+\-]+$")


class CfgError(ValueError):
    """A configuration text that is not ABB's ``.cfg`` syntax (the line and why)."""


def _value_text(attr: str, value: Any) -> str:
    if value is True:
        return f"-{attr}"
    if isinstance(value, bool) or value is None:
        raise CfgError(f"-{attr}: a flag is True, got {value!r}")
    if isinstance(value, int | float):
        if value != value or value in (float("inf"), float("-inf")):
            raise CfgError(f"-{attr}: not a finite number: {value!r}")
        return f"-{attr} {value:.9g}" if isinstance(value, float) else f"-{attr} {value}"
    text = str(value)
    if '"' in text or "\n" in text or "\\" in text:
        raise CfgError(f"-{attr}: a string cannot hold quotes, backslashes or line ends: "
                       f"{text!r}")
    return f'-{attr} "{text}"'


def cfg_text(domain: str, types: dict[str, list[dict[str, Any]]],
             version: tuple[int, int] = (6, 0)) -> str:
    """One ``.cfg`` file's text (module docstring).

    Parameters
    ----------
    domain : str
        ``MOC``, ``SIO``, ``SIOC``, ``EIO`` …
    types : dict of str to list of dict
        Each type's instances; an instance maps attribute → value (str: quoted; int,
        float: a number; ``True``: a flag).
    version : tuple of int
        The RobotWare version of the header (major, minor).

    Returns
    -------
    str
        The text, ``\\n`` line ends (:func:`~plugcell.devices.robot.stream.files.write_files`
        writes CRLF).

    Raises
    ------
    CfgError
        A name that is not a cfg name, or a value it cannot write.
    """
    for name in (domain, *types):
        if not _NAME.match(name) or name.upper() != name:
            raise CfgError(f"{name!r}: a domain or type is upper-case letters, digits, '_'")
    lines = [f"{domain}:CFG_1.0:{version[0]}:{version[1]}::", "#"]
    for type_name, instances in types.items():
        lines += [f"{type_name}:", ""]
        for instance in instances:
            pairs = []
            for attr, value in instance.items():
                if not _NAME.match(attr):
                    raise CfgError(f"attribute {attr!r}: letters, digits and '_'")
                pairs.append(_value_text(attr, value))
            lines += _wrapped(pairs)
            lines.append("")
        lines.append("#")
    return "\n".join(lines) + "\n"


def _wrapped(pairs: list[str]) -> list[str]:
    """``-attr value`` pairs as indented lines of at most :data:`WIDTH` characters, each
    but the last ending in ``\\``."""
    out, line = [], "      "
    for pair in pairs:
        if line.strip() and len(line) + 1 + len(pair) + 1 > WIDTH:
            out.append(line + "\\")
            line = "      "
        line += (" " if line.strip() else "") + pair
    out.append(line)
    return out


def _parse_value(token: str) -> Any:
    if token.startswith('"'):
        return token[1:-1]
    try:
        return int(token)
    except ValueError:
        pass
    try:
        return float(token)
    except ValueError:
        return token


def _pairs(text: str, line: int) -> dict[str, Any]:
    """The ``-attr value`` pairs of one instance's joined text."""
    tokens, pos = [], 0
    while pos < len(text):
        if not text[pos:].strip():
            break
        m = _TOKEN.match(text, pos)
        if m is None:
            raise CfgError(f"line {line}: cannot read {text[pos:].strip()[:30]!r} (an "
                           "unclosed quote?)")
        tokens.append(m.group(1))
        pos = m.end()
    out: dict[str, Any] = {}
    i = 0
    while i < len(tokens):
        attr = tokens[i]
        if not attr.startswith("-"):
            raise CfgError(f"line {line}: expected -attribute, got {attr!r}")
        name = attr[1:]
        if name in out:
            raise CfgError(f"line {line}: -{name} given twice")
        nxt = tokens[i + 1] if i + 1 < len(tokens) else None
        if nxt is None or (nxt.startswith("-") and not _is_number(nxt)):
            out[name] = True
            i += 1
            continue
        if not nxt.startswith('"') and not _WORD.match(nxt):
            raise CfgError(f"line {line}: -{name}: cannot read the value {nxt!r}")
        out[name] = _parse_value(nxt)
        i += 2
    return out


def _is_number(token: str) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return True


def parse_cfg(text: str) -> tuple[str, tuple[int, int], dict[str, list[dict[str, Any]]]]:
    """Read a ``.cfg`` text (module docstring).

    Parameters
    ----------
    text : str
        The file's text (``\\n`` or ``\\r\\n`` line ends).

    Returns
    -------
    domain : str
    version : tuple of int
        RobotWare (major, minor) of the header.
    types : dict of str to list of dict
        Each type's instances (attribute → str, int, float, or ``True`` for a flag).

    Raises
    ------
    CfgError
        No header, an instance outside a type, a line continued at the end of the file, or
        an instance that does not read — with the line number.
    """
    lines = text.replace("\r\n", "\n").split("\n")
    m = _HEADER.match(lines[0].strip()) if lines else None
    if m is None:
        raise CfgError(f"line 1: expected a header DOMAIN:CFG_1.0:MAJOR:MINOR::, got "
                       f"{(lines[0] if lines else '')[:40]!r}")
    domain, version = m.group(1), (int(m.group(3)), int(m.group(4)))
    types: dict[str, list[dict[str, Any]]] = {}
    current: list[dict[str, Any]] | None = None
    pending, start = "", 0
    for number, raw in enumerate(lines[1:], start=2):
        line = raw.rstrip()
        if pending:
            pending += " " + line.strip().removesuffix("\\")
            if not line.endswith("\\"):
                current.append(_pairs(pending, start))  # type: ignore[union-attr]
                pending = ""
            continue
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        if (t := _TYPE.match(stripped)) is not None and not raw[:1].isspace():
            current = types.setdefault(t.group(1), [])
            continue
        if not stripped.startswith("-"):
            raise CfgError(f"line {number}: expected a type 'NAME:' or an instance "
                           f"'-attribute value …', got {stripped[:40]!r}")
        if current is None:
            raise CfgError(f"line {number}: an instance before any type")
        if line.endswith("\\"):
            pending, start = stripped.removesuffix("\\"), number
            continue
        current.append(_pairs(stripped, number))
    if pending:
        raise CfgError(f"line {start}: the instance is continued ('\\') past the end")
    return domain, version, types
