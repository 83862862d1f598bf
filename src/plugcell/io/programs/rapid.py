"""ABB RAPID: robtarget, jointtarget, tooldata, wobjdata and the Move instructions.

What is read (everything else passes through as it is, comments included):

* **declarations** ``[LOCAL|TASK] CONST|PERS|VAR robtarget|jointtarget|tooldata|wobjdata
  NAME[{n}] := value;`` (a statement may span lines);
* **motions** ``MoveL``, ``MoveJ``, ``MoveC`` (circle and end point), ``MoveAbsJ``
  (a joint target), ``MoveLDO``, ``MoveJDO``, ``MoveLSync``… (any ``Move*``) with a named
  target, ``NAME{i}``, or an inline ``[[x,y,z],[q1..q4],[cf1,cf4,cf6,cfx],[eax]]``;
  the tool is the instruction's tool argument, the frame its ``\\WObj:=`` (default
  ``wobj0``, the robot base frame).  ``Offs(…)``/``RelTool(…)`` targets are relative:
  left as they are (noted).

Poses are mm and a unit quaternion ``q1..q4 = w, x, y, z`` (notation ``abb``).  A
tool's ``tframe`` and a work object's ``uframe · oframe`` compose the target;
``tool0`` and ``wobj0`` are the flange and the base.  A stationary tool (``robhold``
FALSE) or a moving user frame (``ufprog`` FALSE) is refused where a motion uses it.
confdata is kept consistent: ``cf1``, ``cf4``, ``cf6`` (the quarter revolution of axes
1, 4, 6) change by as many quarters as the compensated joints moved across a quarter
boundary from the nominal ones; ``cfx`` is kept.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from plugcell.io.programs.core import Num, Program, SourceFile, Target, Token
from plugcell.io.units import pose_from_notation

__all__ = ["read_rapid"]

TYPES = {"robtarget", "jointtarget", "tooldata", "wobjdata"}

_NUM = r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?"
_NUM_RE = re.compile(_NUM)
_TOKEN = re.compile(r"""\s*(?:
    (?P<nums>\[[ \t]*""" + _NUM + r"""(?:[ \t]*,[ \t]*""" + _NUM + r""")*[ \t]*\])
  | (?P<comment>![^\r\n]*|%%%[\s\S]*?%%%)
  | (?P<num>(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)
  | (?P<name>[A-Za-z_][A-Za-z0-9_]*)
  | (?P<str>"(?:[^"\r\n]|"")*")
  | (?P<op>:=|<>|<=|>=|[\[\](){},;:=+\-*/<>\\.%])
  | (?P<bad>\S)
)""", re.VERBOSE)
_BLOCK = {"MODULE", "PROC", "ENDPROC", "ENDMODULE", "FUNC", "ENDFUNC", "TRAP", "ENDTRAP", "IF",
          "ELSE", "ENDIF", "WHILE", "ENDWHILE", "FOR", "ENDFOR"}


def _statements(f: SourceFile) -> list[list[Token]]:
    """The file's statements (``;`` ends one; ``PROC …``/``ENDPROC`` lines end one too)."""
    out: list[list[Token]] = []
    cur: list[Token] = []
    block = False  # the statement opens with a keyword a line end closes
    text = f.text
    for m in _TOKEN.finditer(text):
        kind = m.lastgroup
        if kind is None:  # trailing white space
            continue
        if kind == "comment":
            continue
        a, b = m.span(kind)
        if kind == "bad":
            raise f.error(a, f"unexpected character {text[a:b]!r}")
        if block and "\n" in text[cur[-1].end:a]:
            out.append(cur)
            cur, block = [], False
        t = Token(kind, text[a:b], a, b)
        if t.text == ";":
            out.append(cur)
            cur, block = [], False
        else:
            if not cur:
                block = t.text.upper() in _BLOCK
            cur.append(t)
    if cur:
        out.append(cur)
    return out


class _Value:
    """A parsed aggregate ``[…]``: nested lists of tokens (numbers keep their sign)."""

    def __init__(self, f: SourceFile, toks: list[Token], i: int) -> None:
        self.f, self.toks = f, toks
        self.value, self.end = self.parse(i)

    def parse(self, i: int) -> tuple[object, int]:
        toks = self.toks
        if i >= len(toks):
            raise self.f.error(toks[-1].end, "expected a value")
        t = toks[i]
        if t.kind == "nums":  # a flat list of numbers, one token: its numbers' spans
            a = t.start
            return (t, [Token("num", m.group(), a + m.start(), a + m.end())
                        for m in _NUM_RE.finditer(t.text)]), i + 1
        if t.text == "[":
            items = []
            i += 1
            while True:
                v, i = self.parse(i)
                items.append(v)
                if i < len(toks) and toks[i].text == ",":
                    i += 1
                    continue
                if i < len(toks) and toks[i].text == "]":
                    return (t, items), i + 1
                raise self.f.error(toks[i].start if i < len(toks) else toks[-1].end,
                                   "expected ',' or ']'")
        if t.text in "+-" and i + 1 < len(toks) and toks[i + 1].kind == "num":
            if toks[i + 1].start != t.end:
                raise self.f.error(t.start, "a space between the sign and the number")
            return Token("num", "", t.start, toks[i + 1].end), i + 2
        if t.kind == "num":
            return t, i + 1
        if t.kind in ("name", "str"):
            return t, i + 1
        raise self.f.error(t.start, f"unexpected {t.text!r} in a value")


def _list(f: SourceFile, v: object, n: int | None, what: str, at: int) -> list[object]:
    if not (isinstance(v, tuple) and isinstance(v[1], list)):
        raise f.error(at, f"{what}: expected [ … ]")
    items = v[1]
    if n is not None and len(items) != n:
        raise f.error(v[0].start, f"{what}: expected {n} items, got {len(items)}")
    return items


def _nums(f: SourceFile, v: object, n: int, what: str, at: int) -> list[Num]:
    items = _list(f, v, n, what, at)
    out = []
    for it in items:
        if not (isinstance(it, Token) and it.kind == "num"):
            raise f.error(it[0].start if isinstance(it, tuple) else it.start,  # type: ignore[union-attr]
                          f"{what}: expected a number")
        v = float(it.text) if it.text else math.inf
        out.append(Num(it.start, it.end, it.text, v) if math.isfinite(v)
                   else f.number(it.start, it.end))  # (f.number says what is wrong)
    return out


def _bool(f: SourceFile, v: object, what: str, at: int) -> bool:
    if isinstance(v, Token) and v.text.upper() in ("TRUE", "FALSE"):
        return v.text.upper() == "TRUE"
    raise f.error(at, f"{what}: expected TRUE or FALSE")


def _pose(f: SourceFile, v: object, what: str, at: int) -> np.ndarray:
    """``[[x,y,z],[q1..q4]]`` → 4×4 (m)."""
    tr, rot = _list(f, v, 2, what, at)
    p = _nums(f, tr, 3, what, at)
    q = _nums(f, rot, 4, what, at)
    return pose_from_notation(np.array([n.value for n in (*p, *q)]), "abb")


@dataclass
class RapidConfig:
    """confdata of a robtarget and how it follows the joints (module docstring)."""

    file: int
    cf: list[Num]

    def mismatch(self, q: np.ndarray) -> str:
        """Where cf1, cf4, cf6 name other quarters than the joints ``q`` (``""``: none)."""
        bad = [f"cf{j + 1} = {num.text} (axis {j + 1} in quarter "
               f"{math.floor(q[j] / (math.pi / 2))})"
               for num, j in zip(self.cf[:3], (0, 3, 5), strict=True)
               if j < q.size and int(num.value) != math.floor(q[j] / (math.pi / 2))]
        return "; ".join(bad)

    def agrees(self, Q: np.ndarray) -> np.ndarray:
        """``(K,)``: which joint vectors ``Q (K, n)`` cf1, cf4, cf6 describe."""
        ok = np.ones(len(Q), dtype=bool)
        for num, j in zip(self.cf[:3], (0, 3, 5), strict=True):
            if j < Q.shape[1]:
                ok &= np.floor(Q[:, j] / (np.pi / 2)) == int(num.value)
        return ok

    def edits(self, q_nominal: np.ndarray, q: np.ndarray) -> dict[tuple[int, int], str]:
        """cf1, cf4, cf6 moved by the quarters the compensated joints crossed."""
        out: dict[tuple[int, int], str] = {}
        for num, j in zip(self.cf[:3], (0, 3, 5), strict=True):
            if j >= q.size:
                continue
            d = math.floor(q[j] / (math.pi / 2)) - math.floor(q_nominal[j] / (math.pi / 2))
            if d:
                out[(self.file, num.start)] = str(int(num.value) + d)
        return out


class _Reader:
    def __init__(self, f: SourceFile) -> None:
        self.f = f
        self.program = Program("rapid", [f], resolution=(1e-3, 1e-3, 1e-6))
        self.program.tools["tool0"] = np.eye(4)
        self.program.frames["wobj0"] = np.eye(4)
        self.vars: dict[str, Target] = {}
        self.arrays: dict[str, list[str]] = {}
        self.bad_tools: dict[str, str] = {}
        self.notes: list[str] = []

    def target(self, v: object, name: str, typ: str, at: int) -> Target:
        f = self.f
        if typ == "robtarget":
            items = _list(f, v, 4, name, at)
            p = _nums(f, items[0], 3, f"{name} trans", at)
            q = _nums(f, items[1], 4, f"{name} rot", at)
            cf = _nums(f, items[2], 4, f"{name} robconf", at)
            _list(f, items[3], 6, f"{name} extax", at)
            return Target(name, 0, at, "pose", [*p, *q], "abb", config=RapidConfig(0, cf),
                          extra=cf)
        items = _list(f, v, 2, name, at)
        j = _nums(f, items[0], 6, f"{name} robax", at)
        _list(f, items[1], 6, f"{name} extax", at)
        return Target(name, 0, at, "joints", j)

    def declaration(self, st: list[Token]) -> bool:
        i = 0
        while i < len(st) and st[i].text.upper() in ("LOCAL", "TASK"):
            i += 1
        if i + 2 >= len(st) or st[i].text.upper() not in ("CONST", "PERS", "VAR"):
            return False
        typ = st[i + 1].text.lower()
        if typ not in TYPES:
            return False
        name_tok = st[i + 2]
        j = i + 3
        dims = None
        if j < len(st) and st[j].text == "{":
            if j + 2 >= len(st) or st[j + 1].kind != "num" or st[j + 2].text != "}":
                raise self.f.error(st[j].start, "only one-dimensional arrays of positions")
            dims = int(st[j + 1].text)
            j += 3
        if j >= len(st):
            return True  # declared without a value
        if st[j].text != ":=":
            raise self.f.error(st[j].start, f"expected ':=' after {name_tok.text}")
        val = _Value(self.f, st, j + 1)
        if val.end != len(st):
            raise self.f.error(st[val.end].start, "unexpected text after the value")
        name = name_tok.text
        at = st[j + 1].start
        if dims is not None:
            elems = _list(self.f, val.value, dims, name, at)
            names = []
            for k, e in enumerate(elems, 1):
                el = f"{name}{{{k}}}"
                self.define(typ, el, e, e[0].start if isinstance(e, tuple) else at)
                names.append(el)
            self.arrays[name.lower()] = names
        else:
            self.define(typ, name, val.value, at)
        return True

    def define(self, typ: str, name: str, value: object, at: int) -> None:
        f = self.f
        if typ in ("robtarget", "jointtarget"):
            tg = self.target(value, name, typ, at)
            tg.used = False
            self.vars[name.lower()] = tg
            self.program.targets.append(tg)
        elif typ == "tooldata":
            items = _list(f, value, 3, name, at)
            if not _bool(f, items[0], f"{name} robhold", at):
                self.bad_tools[name] = "a stationary tool (robhold FALSE) is not supported"
            self.program.tools[name] = _pose(f, items[1], f"{name} tframe", at)
        else:
            items = _list(f, value, 5, name, at)
            if _bool(f, items[0], f"{name} robhold", at):
                self.bad_tools[name] = "a work object held by the robot is not supported"
            if not _bool(f, items[1], f"{name} ufprog", at):
                self.bad_tools[name] = "a moving user frame (ufprog FALSE) is not supported"
            self.program.frames[name] = (_pose(f, items[3], f"{name} uframe", at)
                                         @ _pose(f, items[4], f"{name} oframe", at))

    def motion(self, st: list[Token]) -> None:
        head = st[0].text
        n_pts = 2 if head.lower().startswith("movec") else 1
        # split the arguments at top-level commas; optional \Name[:=value] args apart
        args: list[list[Token]] = [[]]
        opts: dict[str, list[Token]] = {}
        depth = 0
        i = 1
        after_opt = False  # "MoveL \Conc, p10, …": a switch before the first argument
        while i < len(st):
            t = st[i]
            if t.text in "[(":
                depth += 1
            elif t.text in "])":
                depth -= 1
            if depth == 0 and t.text == ",":
                if not (after_opt and not args[-1]):
                    args.append([])
                after_opt = False
            elif depth == 0 and t.text == "\\" and i + 1 < len(st):
                key = st[i + 1].text.lower()
                i += 2
                val: list[Token] = []
                if i < len(st) and st[i].text == ":=":
                    i += 1
                    d = 0
                    while i < len(st) and not (d == 0 and st[i].text in (",", "\\")):
                        d += {"[": 1, "(": 1, "]": -1, ")": -1}.get(st[i].text, 0)
                        val.append(st[i])
                        i += 1
                opts[key] = val
                after_opt = True
                continue
            else:
                args[-1].append(t)
                after_opt = False
            i += 1
        absj = head.lower().startswith("moveabsj")
        tool_pos = n_pts + 2
        if len(args) <= tool_pos or not args[tool_pos]:
            raise self.f.error(st[0].start, f"{head}: expected {tool_pos + 1} arguments "
                               "(point(s), speed, zone, tool)")
        tool_toks = args[tool_pos]
        if len(tool_toks) != 1 or tool_toks[0].kind != "name":
            raise self.f.error(tool_toks[0].start, f"{head}: the tool must be a tooldata name")
        tool = tool_toks[0].text
        wobj = "wobj0"
        if "wobj" in opts:
            w = opts["wobj"]
            if len(w) != 1 or w[0].kind != "name":
                raise self.f.error(st[0].start, f"{head}: \\WObj must name a wobjdata")
            wobj = w[0].text
        for name in (tool, wobj):
            if name in self.bad_tools:
                raise self.f.error(st[0].start, f"{head}: {name}: {self.bad_tools[name]}")
        for a in args[:n_pts]:
            self.point(head, a, tool, None if absj else wobj, absj)

    def point(self, head: str, a: list[Token], tool: str, wobj: str | None, absj: bool) -> None:
        f = self.f
        if not a:
            raise f.error(0, f"{head}: an empty target")
        line = f.position(a[0].start)[0]
        if a[0].text == "[":
            val = _Value(f, a, 0)
            if val.end != len(a):
                raise f.error(a[val.end].start, f"{head}: unexpected text after the target")
            tg = self.target(val.value, f"{head} line {line}",
                             "jointtarget" if absj else "robtarget", a[0].start)
            self.program.targets.append(tg)
            self.use(tg, tool, wobj, a[0])
            return
        if a[0].kind == "name" and (len(a) == 1 or a[1].text == "{"):
            key = a[0].text.lower()
            if len(a) > 1:
                idx = "".join(t.text for t in a[2:-1])
                names = self.arrays.get(key)
                if names is None:
                    raise f.error(a[0].start, f"{a[0].text} is not an array of the module")
                sel = [n for n in names if idx.isdigit() and n.endswith(f"{{{idx}}}")] or names
                for n in sel:
                    self.use(self.vars[n.lower()], tool, wobj, a[0])
                return
            tg = self.vars.get(key)
            if tg is None:
                self.notes.append(f"{self.program.where(0, a[0].start)}: {a[0].text} is not "
                                  "declared in this module: left as it is")
                return
            self.use(tg, tool, wobj, a[0])
            return
        self.notes.append(f"{self.program.where(0, a[0].start)}: {head} to an expression "
                          f"({a[0].text}…): left as it is")

    def use(self, tg: Target, tool: str, wobj: str | None, tok: Token) -> None:
        tg.use(wobj, tool, self.f, 0, tok.start, lambda b, t: f"tool {t} and work object {b}")


def read_rapid(path: str | Path) -> tuple[Program, list[str]]:
    """Read a RAPID module (module docstring).

    Parameters
    ----------
    path : str or Path
        The ``.mod``/``.prg``/``.modx`` file.

    Returns
    -------
    program : Program
        Its targets, work objects (frames) and tools.
    notes : list of str
        Motions left as they are.

    Raises
    ------
    ProgramError
        Unreadable file, or unknown syntax in a declaration or a motion
        (file:line:column).
    """
    r = _Reader(SourceFile.read(Path(path)))
    sts = [s for s in _statements(r.f) if s]
    decl = [r.declaration(st) for st in sts]
    for st, is_decl in zip(sts, decl, strict=True):
        if is_decl:
            continue
        for k, t in enumerate(st):  # a Move* at the start of a line (after IF …, CASE 1:)
            if t.kind == "name" and t.text.lower().startswith("move") and (
                    k == 0 or "\n" in r.f.text[st[k - 1].end:t.start]) and (
                    k + 1 >= len(st) or st[k + 1].text != "("):
                r.motion(st[k:])
                break
    r.program.targets.sort(key=lambda t: t.offset)
    return r.program, r.notes
