"""Comau PDL2 (``.pdl``): ``POS(…)``/``JNTP(…)`` targets of MOVE statements and assignments.

What is read (everything else passes through as it is):

* **literals** ``POS(x, y, z, a, b, c[, 'cnfg'])`` (a POSITION: mm, ZYZ Euler degrees,
  notation ``comau``) and ``JNTP(q1, …, qn)`` (a JOINTPOS, degrees), with number
  arguments only;
* **assignments** ``name := POS(…)`` / ``JNTP(…)`` (``VAR name : POSITION`` /
  ``JOINTPOS`` / ``XTNDPOS`` declared), which MOVE statements then use by name (an
  ``ARRAY`` element ``name[3]`` is a name of its own);
* **motions** ``MOVE [JOINT|LINEAR|CIRCULAR] TO target [VIA target]`` and ``MOVEFLY …``
  (``ADVANCE`` and ``WITH`` clauses are left alone); ``MOVE RELATIVE`` and ``MOVE AWAY``
  are relative: left as they are, noted;
* **frames**: ``$TOOL := POS(…)`` (flange → TCP), ``$UFRAME := POS(…)`` (the user frame in
  the world) and ``$BASE := POS(…)`` (the robot base in the world): a target ``P`` is
  ``$BASE⁻¹ · $UFRAME · P`` in the robot base frame.  Not set above a motion, they are
  the controller's — give them with ``--base '$UFRAME=…' --base '$BASE=…'
  --tool '$TOOL=…'`` (X, Y, Z, A, B, C).

Comments (``--``) and strings are skipped; a statement continues on the next line after
``(``, ``[`` or ``,``.  A ``POS(…)`` with an expression among its numbers, a component
changed at run time (``p.X := …``) or a target reassigned are errors at file:line:column.
"""

from __future__ import annotations

import re
from pathlib import Path

from plugcell.io.programs.core import Program, SourceFile, Target, Token
from plugcell.io.units import pose_from_notation

__all__ = ["read_pdl2"]

_TOKEN = re.compile(r"""\s*(?:
    (?P<comment>--[^\r\n]*)
  | (?P<num>(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)
  | (?P<name>[A-Za-z_$][A-Za-z0-9_]*)
  | (?P<str>'[^'\r\n]*')
  | (?P<op>:=|<>|<=|>=|[()\[\],:=+\-*/<>.;&])
  | (?P<bad>\S)
)""", re.VERBOSE)
_BREAK = {"(", "[", ","}


def _statements(f: SourceFile) -> list[list[Token]]:
    """Statements: a line end closes one, unless after ``(``, ``[``, ``,`` or inside ()."""
    out: list[list[Token]] = []
    cur: list[Token] = []
    depth = 0
    text = f.text
    for m in _TOKEN.finditer(text):
        kind = m.lastgroup
        if kind is None or kind == "comment":
            continue
        a, b = m.span(kind)
        if cur and depth == 0 and cur[-1].text not in _BREAK and "\n" in text[cur[-1].end:a]:
            out.append(cur)
            cur = []
        if kind == "bad":
            raise f.error(a, f"unexpected character {text[a:b]!r}")
        t = Token(kind, text[a:b], a, b)
        depth += {"(": 1, "[": 1, ")": -1, "]": -1}.get(t.text, 0)
        cur.append(t)
    if cur:
        out.append(cur)
    return out


class _Reader:
    def __init__(self, f: SourceFile) -> None:
        self.f = f
        self.program = Program("pdl2", [f], resolution=(1e-3, 1e-3, 1e-6))
        self.vars: dict[str, Target] = {}
        self.notes: list[str] = []
        self.frame = {"$BASE": None, "$UFRAME": None, "$TOOL": None}

    def literal(self, st: list[Token], i: int, name: str) -> tuple[Target, int]:
        """``POS(…)`` or ``JNTP(…)`` at ``st[i]`` → its target and the index after it."""
        f = self.f
        head = st[i].text.upper()
        if i + 1 >= len(st) or st[i + 1].text != "(":
            raise f.error(st[i].start, f"{head}: expected '('")
        j = i + 2
        nums = []
        while True:
            if j >= len(st):
                raise f.error(st[i].start, f"{head}( not closed")
            t = st[j]
            start = t.start
            if t.text == "-" and j + 1 < len(st) and st[j + 1].kind == "num":
                if st[j + 1].start != t.end:
                    raise f.error(t.start, "a space between the sign and the number")
                j += 1
                t = st[j]
            if t.kind == "num":
                nums.append(f.number(start, t.end))
                j += 1
            elif t.kind == "str" and head == "POS":
                if len(nums) != 6:
                    raise f.error(t.start, "POS needs x, y, z, a, b, c before its "
                                  f"configuration string, got {len(nums)} numbers")
                j += 1  # the configuration string: kept as written
            else:
                raise f.error(t.start, f"{head}: a number expected, got {t.text!r} (a position "
                              "computed at run time cannot be compensated)")
            if j < len(st) and st[j].text == ",":
                j += 1
                continue
            if j < len(st) and st[j].text == ")":
                j += 1
                break
            raise f.error(st[j].start if j < len(st) else st[-1].end,
                          f"{head}: expected ',' or ')'")
        if head == "POS":
            if len(nums) != 6:
                raise f.error(st[i].start, f"POS needs x, y, z, a, b, c, got {len(nums)} "
                              "numbers")
            return Target(name, 0, st[i].start, "pose", nums, "comau"), j
        if not 1 <= len(nums) <= 10:
            raise f.error(st[i].start, f"JNTP takes 1 to 10 joints, got {len(nums)}")
        return Target(name, 0, st[i].start, "joints", nums), j

    def is_literal(self, st: list[Token], i: int) -> bool:
        return i < len(st) and st[i].kind == "name" and st[i].text.upper() in ("POS", "JNTP") \
            and i + 1 < len(st) and st[i + 1].text == "("

    def statement(self, st: list[Token]) -> None:
        f = self.f
        head = st[0].text.upper()
        # name[idx] := … / name := … / $SYS := …
        k = 1
        if len(st) > 1 and st[1].text == "[":
            while k < len(st) and st[k].text != "]":
                k += 1
            k += 1
        if k < len(st) and st[k].text == ":=" and st[0].kind == "name":
            name = "".join(t.text for t in st[:k]).upper()
            if self.is_literal(st, k + 1):
                if head in self.frame:
                    tg, j = self.literal(st, k + 1, head)
                    if tg.kind != "pose":
                        raise f.error(st[k + 1].start, f"{head} must be a POS(…)")
                    m = pose_from_notation(tg.values, "comau")
                    line = f.position(st[0].start)[0]
                    key = f"{head} (line {line})"
                    (self.program.tools if head == "$TOOL" else self.program.frames)[key] = m
                    self.frame[head] = key
                else:
                    if name in self.vars:
                        raise f.error(st[0].start, f"{name} is assigned a position twice: "
                                      "the reader cannot tell which one each MOVE uses")
                    tg, j = self.literal(st, k + 1, "".join(t.text for t in st[:k]))
                    tg.used = False
                    self.vars[name] = tg
                    self.program.targets.append(tg)
                if j != len(st):
                    raise f.error(st[j].start, "unexpected text after the position")
            return
        if len(st) > 3 and st[1].text == "." and st[3].text == ":=" and head in self.vars:
            raise f.error(st[0].start, f"{st[0].text}.{st[2].text} := …: a component of a "
                          "target changed at run time cannot be compensated")
        if head in ("MOVE", "MOVEFLY"):
            self.motion(st)

    def motion(self, st: list[Token]) -> None:
        f = self.f
        i = 1
        if i < len(st) and st[i].text.upper() in ("RELATIVE", "AWAY", "NEAR"):
            self.notes.append(f"{self.program.where(0, st[0].start)}: MOVE "
                              f"{st[i].text.upper()} is relative: left as it is")
            return
        if i < len(st) and st[i].text.upper() in ("JOINT", "LINEAR", "CIRCULAR"):
            i += 1
        if i < len(st) and st[i].text.upper() == "ARM":  # MOVE ARM[1] TO
            while i < len(st) and st[i].text.upper() != "TO":
                i += 1
        if i >= len(st) or st[i].text.upper() != "TO":
            raise f.error(st[min(i, len(st) - 1)].start, "MOVE: expected TO")
        i = self.target(st, i + 1)
        if i < len(st) and st[i].text.upper() == "VIA":
            i = self.target(st, i + 1)

    def target(self, st: list[Token], i: int) -> int:
        f = self.f
        if i >= len(st):
            raise f.error(st[-1].end, "MOVE: expected a target")
        t = st[i]
        line = f.position(t.start)[0]
        if self.is_literal(st, i):
            tg, j = self.literal(st, i, f"MOVE line {line}")
            self.program.targets.append(tg)
            self.use(tg, t)
            return j
        if t.kind == "name":
            j = i + 1
            name = t.text
            if j < len(st) and st[j].text == "[":
                while j < len(st) and st[j].text != "]":
                    name += st[j].text
                    j += 1
                name += "]"
                j += 1
            if j < len(st) and st[j].text not in (",",) and st[j].text.upper() not in (
                    "VIA", "ADVANCE", "WITH", "NODE"):
                if any(self.is_literal(st, k) for k in range(i, len(st))):
                    raise f.error(st[j].start, "MOVE: a position inside an expression the "
                                  "reader does not know")
                self.notes.append(f"{self.program.where(0, t.start)}: MOVE to an expression: "
                                  "left as it is")
                return len(st)
            tg = self.vars.get(name.upper())
            if tg is None:
                self.notes.append(f"{self.program.where(0, t.start)}: {name} is not assigned a "
                                  "POS/JNTP in the program (.var?): left as it is")
                return j
            self.use(tg, t)
            return j
        raise f.error(t.start, f"MOVE: unexpected {t.text!r}")

    def use(self, tg: Target, tok: Token) -> None:
        base = None
        if tg.kind == "pose":
            b, u = self.frame["$BASE"] or "$BASE", self.frame["$UFRAME"] or "$UFRAME"
            base = f"{b}⁻¹ · {u}"
            self.program.composites[base] = [(b, True), (u, False)]
        tool = self.frame["$TOOL"] or "$TOOL"
        tg.use(base, tool, self.f, 0, tok.start, lambda b, t: f"{b} and {t}")


def read_pdl2(path: str | Path) -> tuple[Program, list[str]]:
    """Read a PDL2 program (module docstring).

    Parameters
    ----------
    path : str or Path
        The ``.pdl`` file.

    Returns
    -------
    program : Program
        Its targets; a pose's frame is the composite ``"$BASE⁻¹ · $UFRAME"`` of the
        frames set above its MOVE (``Program.composites``).
    notes : list of str
        MOVEs left as they are.

    Raises
    ------
    ProgramError
        Unreadable file or unknown syntax in a position or a MOVE (file:line:column).
    """
    r = _Reader(SourceFile.read(Path(path)))
    for st in _statements(r.f):
        if st[0].kind == "name":
            r.statement(st)
    r.program.targets.sort(key=lambda t: t.offset)
    return r.program, r.notes
