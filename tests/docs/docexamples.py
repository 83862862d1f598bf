"""The shell examples of the docs, read from the markdown, and the comparison of what a
command printed with what a page shows (issue 39: the docs are tests).

Which blocks are examples
    A fenced block whose info string is ``sh`` (the block is a script: pasted as a whole)
    or ``console`` (``$ `` lines are commands, the lines after one are what it prints).
    Blocks fenced otherwise (``text``, none, ``toml``…) are not run: synopses of a
    command's options (``plugcell x [--y N]``) are ``text``.

Markers
    An HTML comment in the lines just before a block (blank lines allowed) says more::

        <!-- docs-test: skip reason="needs an OPC UA PLC" -->
        <!-- docs-test: timeout=300 rel=0.1 -->

    ``skip`` with its ``reason`` (listed by the test), ``timeout`` (s, the block; default
    :data:`DEFAULT_TIMEOUT_S`) and ``rel`` (relative tolerance of the decimal numbers a
    page shows; default :data:`DEFAULT_REL`).  Before a block of any other kind (a
    ``python`` module, a ``toml`` map), ``file=NAME`` makes the block the file ``NAME`` of
    the page's folder, as the page asks the reader to save it::

        <!-- docs-test: file=laser_point.py -->

What a ``console`` page shows, and how it is compared
    Each line a page shows must match the line the command printed (stdout and stderr
    as a terminal interleaves them), in order, all of them:

    * runs of white space are one space; leading and trailing space is ignored;
    * ``…`` inside a line stands for any text; a line that is only ``…`` for any number
      of lines (also none);
    * a number with decimals matches within ``rel`` of it or one unit of its last shown
      digit, whichever is larger; an integer matches exactly.

    Each ``$`` command runs in a fresh ``bash`` in the page's folder: shell variables,
    functions and ``cd`` do not carry over to the next one (an example that needs them is
    an ``sh`` block, run as one script with ``set -e``).

    A command may end with a non-zero exit status only if what the page shows of it
    names an error or an alarm (``error``, ``Failed``, ``ALARM``); its status is
    otherwise 0.
"""

from __future__ import annotations

import re
import shlex
from dataclasses import dataclass, field
from pathlib import Path

DEFAULT_TIMEOUT_S = 180.0
DEFAULT_REL = 0.02
ELLIPSIS = "…"

_FENCE = re.compile(r"^(\s*)```\s*([\w+-]*)\s*(.*)$")
_MARKER = re.compile(r"<!--\s*docs-test:(.*?)-->", re.S)
_NUMBER = r"[-+]?(?:\d+\.\d*|\.\d+|\d+)(?:[eE][-+]?\d+)?"
_NUM_RE = re.compile(_NUMBER)


class DocsMarkupError(ValueError):
    """A docs-test marker or a console block that cannot be read (names page and line)."""


@dataclass
class Command:
    """One ``$`` command of a console block and the lines the page shows after it."""

    text: str
    expected: list[str]
    line: int

    @property
    def background(self) -> bool:
        """Whether the command line ends in ``&`` before any comment (it starts something in
        the background)."""
        try:
            words = shlex.split(self.text.replace("\\\n", " "), comments=True)
        except ValueError:
            return self.text.rstrip().endswith("&")
        return bool(words) and words[-1].endswith("&") and not words[-1].endswith("&&")


@dataclass
class Block:
    """One runnable example: its page, first line, kind (``sh``/``console``) and text."""

    page: str
    line: int
    kind: str
    text: str
    skip: str | None = None
    timeout_s: float = DEFAULT_TIMEOUT_S
    rel: float = DEFAULT_REL
    commands: list[Command] = field(default_factory=list)
    file: str | None = None

    @property
    def where(self) -> str:
        return f"{self.page}:{self.line}"


def _options(text: str, where: str) -> dict[str, str]:
    try:
        words = shlex.split(text)
    except ValueError as exc:
        raise DocsMarkupError(f"{where}: docs-test marker: {exc}") from None
    out: dict[str, str] = {}
    for word in words:
        key, eq, value = word.partition("=")
        if key not in ("skip", "reason", "timeout", "rel", "file"):
            raise DocsMarkupError(f"{where}: docs-test marker: unknown option {key!r} "
                                  "(skip, reason=, timeout=, rel=, file=)")
        out[key] = value if eq else ""
    if "skip" in out and not out.get("reason"):
        raise DocsMarkupError(f"{where}: docs-test marker: skip needs reason=\"…\"")
    return out


def parse_console(text: str, where: str, first_line: int) -> list[Command]:
    """The commands of a console block: ``$ `` lines (a trailing ``\\`` continues one on the
    next line) and, after each, the lines it prints."""
    commands: list[Command] = []
    lines = text.split("\n")
    i = 0
    while i < len(lines):
        line = lines[i]
        if line.startswith("$ "):
            start = i
            cmd = [line[2:]]
            while cmd[-1].rstrip().endswith("\\") and i + 1 < len(lines):
                i += 1
                cmd.append(lines[i])
            commands.append(Command("\n".join(cmd), [], first_line + start))
        elif not commands:
            if line.strip():
                raise DocsMarkupError(f"{where}: a console block starts with a '$ ' command, "
                                      f"not {line!r}")
        else:
            commands[-1].expected.append(line)
        i += 1
    for c in commands:
        while c.expected and not c.expected[-1].strip():
            c.expected.pop()
    return commands


def read_blocks(path: Path, page: str | None = None) -> list[Block]:
    """The ``sh`` and ``console`` blocks of a markdown file, in order, with their markers,
    and the blocks marked ``file=`` (kind ``file``)."""
    page = page or path.name
    lines = path.read_text(encoding="utf-8").split("\n")
    blocks: list[Block] = []
    pending = ""  # marker text seen since the last non-blank, non-marker line
    i = 0
    while i < len(lines):
        m = _FENCE.match(lines[i])
        if not m:
            stripped = lines[i].strip()
            if stripped.startswith("<!--"):
                comment = [lines[i]]
                while "-->" not in comment[-1] and i + 1 < len(lines):
                    i += 1
                    comment.append(lines[i])
                pending += " ".join(comment)
            elif stripped:
                pending = ""
            i += 1
            continue
        indent, lang = m.group(1), m.group(2)
        start = i
        body: list[str] = []
        i += 1
        while i < len(lines) and not re.match(r"^\s*```\s*$", lines[i]):
            body.append(lines[i][len(indent):] if lines[i].startswith(indent) else lines[i])
            i += 1
        i += 1
        where = f"{page}:{start + 1}"
        opts: dict[str, str] = {}
        for marker in _MARKER.findall(pending):
            opts.update(_options(marker, where))
        pending = ""
        text = "\n".join(body)
        if lang not in ("sh", "console"):
            if set(opts) == {"file"} and re.fullmatch(r"[\w.-]+", opts["file"]):
                blocks.append(Block(page, start + 1, "file", text + "\n", file=opts["file"]))
            elif opts:
                raise DocsMarkupError(f"{where}: a docs-test marker before a {lang or 'plain'} "
                                      "block (only sh and console blocks run; file=NAME "
                                      "saves another block)")
            continue
        if "file" in opts:
            raise DocsMarkupError(f"{where}: file= is for a block that does not run")
        block = Block(page, start + 1, lang, text, skip=opts.get("reason") if "skip" in opts
                      else None)
        if "timeout" in opts:
            block.timeout_s = float(opts["timeout"])
        if "rel" in opts:
            block.rel = float(opts["rel"])
        if lang == "console":
            block.commands = parse_console(text, where, start + 2)
            if not block.commands:
                raise DocsMarkupError(f"{where}: a console block without a '$ ' command")
        blocks.append(block)
    return blocks


def _line_pattern(expected: str) -> tuple[re.Pattern[str], list[str]]:
    """A regex for one shown line (numbers captured) and the numbers' text."""
    parts: list[str] = []
    numbers: list[str] = []
    pos = 0
    text = " ".join(expected.split())
    token = re.compile(rf"(?P<ell>{ELLIPSIS})|(?P<ws> )|(?P<num>(?<![\w.]){_NUMBER})")
    for m in token.finditer(text):
        parts.append(re.escape(text[pos:m.start()]))
        if m.group("ell"):
            parts.append(".*?")
        elif m.group("ws"):
            parts.append(r"\s+")
        else:
            parts.append(f"({_NUMBER})")
            numbers.append(m.group("num"))
        pos = m.end()
    parts.append(re.escape(text[pos:]))
    return re.compile("".join(parts) + r"\Z"), numbers


def _close(shown: str, got: str, rel: float) -> bool:
    if "." not in shown and "e" not in shown.lower():
        return got.lstrip("+") == shown.lstrip("+")
    decimals = len(shown.split(".")[1].split("e")[0].split("E")[0]) if "." in shown else 0
    e, a = float(shown), float(got)
    return abs(a - e) <= max(rel * abs(e), 10.0 ** -decimals) + 1e-12


def line_matches(expected: str, actual: str, rel: float = DEFAULT_REL) -> bool:
    """Whether one printed line matches one shown line (module docstring)."""
    pattern, numbers = _line_pattern(expected)
    m = pattern.match(" ".join(actual.split()))
    if m is None:
        return False
    return all(_close(s, g, rel) for s, g in zip(numbers, m.groups(), strict=True))


def output_matches(expected: list[str], actual: list[str], rel: float = DEFAULT_REL) -> bool:
    """Whether the printed lines match the shown lines, all of them, in order; a shown line
    ``…`` matches any number of printed lines."""
    exp = [e for e in expected if e.strip()]
    act = [a for a in actual if a.strip()]
    # ok[i][j]: exp[i:] matches act[j:]
    ok = [[False] * (len(act) + 1) for _ in range(len(exp) + 1)]
    ok[len(exp)][len(act)] = True
    for i in range(len(exp) - 1, -1, -1):
        wild = exp[i].strip() == ELLIPSIS
        for j in range(len(act), -1, -1):
            if wild:
                ok[i][j] = ok[i + 1][j] or (j < len(act) and ok[i][j + 1])
            else:
                ok[i][j] = (j < len(act) and ok[i + 1][j + 1]
                            and line_matches(exp[i], act[j], rel))
    return ok[0][0]


def shows_error(expected: list[str]) -> bool:
    """Whether what a page shows of a command names an error or an alarm (then it may exit
    non-zero)."""
    return any(re.search(r"\berror\b|\bFailed\b|\bALARM\b", e, re.I) for e in expected)


#: What the page tests did, for the summary: (page:line, passed|failed|skipped, reason, s).
RESULTS: list[tuple[str, str, str, float]] = []
