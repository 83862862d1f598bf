"""docs/robot-language.md names every built-in, predefined name and keyword."""

from __future__ import annotations

import re
from pathlib import Path

from lark.lexer import PatternStr

from plugcell.pdl import predefined
from plugcell.pdl.parser import _lark

DOC = (Path(__file__).resolve().parents[2] / "docs" / "robot-language.md").read_text()


def test_every_builtin_and_predefined_name_is_documented():
    names = [
        *predefined.FUNCTIONS,
        *predefined.PROCEDURES,
        *predefined.CONSTANTS,
        *(k.lower() for k in predefined.EXTERNALS),
        *predefined.SYSTEM_VARIABLES,
    ]
    missing = [name for name in names if name not in DOC]
    assert not missing, f"undocumented: {missing}"


def test_every_keyword_is_listed_as_reserved():
    keywords = {
        t.pattern.value.upper()
        for t in _lark().terminals
        if isinstance(t.pattern, PatternStr) and t.pattern.value.isalpha()
    }
    section = DOC[DOC.index("Keywords are reserved") : DOC.index("One statement per line")]
    listed = set(re.findall(r"[A-Z]+", section))
    missing = sorted(keywords - listed)
    assert not missing, f"keywords missing from the reserved list: {missing}"
