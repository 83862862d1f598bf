"""The docs test's reading of markdown and its comparison of output (``docexamples``):
fast, no process started."""

from __future__ import annotations

from pathlib import Path

import pytest
from docexamples import (
    DocsMarkupError,
    line_matches,
    output_matches,
    parse_console,
    read_blocks,
    shows_error,
)
from hypothesis import given
from hypothesis import strategies as st

PAGE = """# A page

```sh
plugcell twin measure --poses 3 --out cal.csv
```

<!-- docs-test: skip reason="needs an OPC UA PLC" -->

```sh
plugcell serve opcua-device --endpoint opc.tcp://plc:4840 --map gripper.toml
```

```text
plugcell x [--y N]
```

<!-- docs-test: timeout=30 rel=0.1 -->
```console
$ plugcell kin fk --robot smart_h4 \\
    --joints 0,-60,-150,0,30,0
{"x": 1234.5, …}
$ plugcell services &
```
"""


def test_blocks_kinds_markers_and_commands(tmp_path: Path) -> None:
    page = tmp_path / "p.md"
    page.write_text(PAGE)
    blocks = read_blocks(page)
    assert [(b.kind, b.line) for b in blocks] == [("sh", 3), ("sh", 9), ("console", 18)]
    assert blocks[0].skip is None and blocks[1].skip == "needs an OPC UA PLC"
    console = blocks[2]
    assert console.timeout_s == 30 and console.rel == 0.1
    fk, services = console.commands
    assert fk.text.endswith("--joints 0,-60,-150,0,30,0") and fk.line == 19
    assert fk.expected == ['{"x": 1234.5, …}'] and not fk.background
    assert services.background and services.expected == []


@pytest.mark.parametrize(("text", "message"), [
    ('<!-- docs-test: skip -->\n```sh\nls\n```\n', "skip needs reason"),
    ('<!-- docs-test: sometimes -->\n```sh\nls\n```\n', "unknown option 'sometimes'"),
    ('<!-- docs-test: timeout=3 -->\n```text\nls\n```\n', "only sh and console blocks run"),
    ('```console\nls\n```\n', r"starts with a '\$ ' command"),
    ('<!-- docs-test: file=x.sh -->\n```sh\nls\n```\n', "file= is for a block that does"),
    ('<!-- docs-test: file=../x -->\n```toml\nx = 1\n```\n', "file=NAME saves"),
])
def test_bad_markup_is_refused_with_page_and_line(tmp_path: Path, text: str, message: str):
    page = tmp_path / "p.md"
    page.write_text(text)
    with pytest.raises(DocsMarkupError, match=message) as err:
        read_blocks(page)
    assert "p.md:" in str(err.value)


def test_file_blocks_are_saved_not_run(tmp_path: Path) -> None:
    page = tmp_path / "p.md"
    page.write_text('<!-- docs-test: file=laser_point.py -->\n```python\nX = 1\n```\n')
    (block,) = read_blocks(page)
    assert (block.kind, block.file, block.text) == ("file", "laser_point.py", "X = 1\n")


def test_a_marker_belongs_to_the_next_block_only(tmp_path: Path) -> None:
    page = tmp_path / "p.md"
    page.write_text('<!-- docs-test: skip reason="x" -->\nSome text.\n\n```sh\nls\n```\n')
    assert read_blocks(page)[0].skip is None


@pytest.mark.parametrize(("shown", "printed", "ok"), [
    ("κ = 351.9", "κ = 352.1", True),           # within 2 %
    ("κ = 351.9", "κ = 400.0", False),
    ("0.128 mm", "0.129 mm", True),             # one unit of the last digit
    ("0.128 mm", "0.140 mm", False),
    ("40 poses", "41 poses", False),            # integers are exact
    ("ur10 robot", "ur10 robot", True),
    ("in cell '…' as instance …", "in cell 'docs-x' as instance 3f9c12", True),
    ("wrote  a.csv", "wrote a.csv  ", True),    # white space
    ("wrote a.csv", "wrote b.csv", False),
    ("-0.5", "0.5", False),
])
def test_line_matches(shown: str, printed: str, ok: bool) -> None:
    assert line_matches(shown, printed) is ok


def test_output_matches_all_lines_in_order_with_ellipsis_lines() -> None:
    printed = ["plan: drawing", "plan: choosing", "wrote plan.csv"]
    assert output_matches(["…", "wrote plan.csv"], printed)
    assert output_matches(["plan: drawing", "…"], printed)
    assert not output_matches(["wrote plan.csv"], printed)        # lines before not shown
    assert not output_matches(["plan: choosing", "plan: drawing", "…"], printed)
    assert output_matches(["…"], [])
    assert not output_matches(["x"], [])


def test_console_continuation_and_output() -> None:
    cmds = parse_console("$ a \\\n  b\nout 1\n\n$ c\n", "p:1", 1)
    assert [c.text for c in cmds] == ["a \\\n  b", "c"]
    assert cmds[0].expected == ["out 1"] and cmds[1].expected == []


@pytest.mark.parametrize(("text", "background"), [
    ("plugcell serve camera &", True),
    ("plugcell serve camera &    # a service", True),
    ("plugcell serve camera & plugcell serve drill &", True),
    ("plugcell wire A B && plugcell wire A C", False),
    ("plugcell services    # what & who", False),
])
def test_background(text: str, background: bool) -> None:
    (cmd,) = parse_console(f"$ {text}\n", "p:1", 1)
    assert cmd.background is background


def test_shows_error() -> None:
    assert shows_error(["plugcell: error: --poses must be positive"])
    assert shows_error(['{"state": "Failed", "reason": "x"}'])
    assert shows_error(["drift of BASE: 0.189 mm at the nests …: ALARM (> 0.05 mm)"])
    assert not shows_error(["wrote cal.csv"])


_text = st.text(st.characters(blacklist_categories=("Cs", "Cc", "Zl", "Zp"),
                              blacklist_characters="…"), max_size=40)


@given(_text)
def test_every_line_matches_itself(line: str) -> None:
    assert line_matches(line, line)


@given(st.lists(_text, max_size=6))
def test_every_output_matches_itself_and_ellipsis(lines: list[str]) -> None:
    assert output_matches(lines, lines)
    assert output_matches(["…"], lines)
