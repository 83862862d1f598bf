"""The examples of docs/motion.md run and print what the page says (#37)."""

from __future__ import annotations

import contextlib
import io
import re
from pathlib import Path

import pytest

from plugcell.apps.cli import main

DOC = Path(__file__).resolve().parents[2] / "docs" / "motion.md"


def _blocks(kind: str) -> list[str]:
    """The bodies of the page's fenced blocks of language ``kind`` ("" for none)."""
    out, lang, body = [], None, []
    for line in DOC.read_text(encoding="utf-8").splitlines():
        if line.startswith("```"):
            if lang is None:
                lang, body = line[3:].strip(), []
            else:
                if lang == kind:
                    out.append("\n".join(body) + "\n")
                lang = None
        elif lang is not None:
            body.append(line)
    return out


@pytest.mark.slow
def test_the_python_examples_run_in_order() -> None:
    ns: dict[str, object] = {}
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        for code in _blocks("python"):
            exec(compile(code, str(DOC), "exec"), ns)
    text = out.getvalue()
    assert "s stopping" in text and "s flying by" in text
    assert "FAILED line 7:" in text and "LIN: target unreachable" in text  # the PDL example
    # the printed errors match the page's "prints" block (… stands for any text)
    printed = next(b for b in _blocks("") if b.startswith("UnreachablePoseError"))
    for expected in printed.strip().splitlines():
        pattern = ".*".join(re.escape(p) for p in expected.split("…"))
        assert re.search(pattern, text), (expected, text)


def test_the_moves_file_example_plans(tmp_path: Path) -> None:
    moves = next(b for b in _blocks("") if b.startswith("# pick and place"))
    (tmp_path / "pick.moves").write_text(moves, encoding="utf-8")
    out = tmp_path / "pick.csv"
    assert main(["motion", "plan", "--robot", "elbow6", "--moves",
                 str(tmp_path / "pick.moves"), "--out", str(out)]) == 0
    assert out.read_text().splitlines()[0].startswith("t_s,j1,")
