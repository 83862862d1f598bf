"""Universal Robots URScript: ``p[…]`` poses of ``movel``, ``movej``, ``movep``, ``movec``.

What is read (everything else passes through as it is):

* **motions** ``movel``, ``movej``, ``movep`` (one pose) and ``movec`` (via and end pose)
  whose pose argument is a literal ``p[x, y, z, rx, ry, rz]``, a variable assigned one, a
  ``pose_trans(FRAME, pose)`` (the pose in the frame ``FRAME``, a variable assigned a
  ``p[…]`` — a Polyscope feature — or given on the command line), or
  ``get_inverse_kin(pose, …)``; ``movej([j1, …, j6])`` is a joint target (radians);
* **assignments** ``[global|local] NAME = p[…]`` (and ``NAME = [ … ]`` of six numbers, a
  joint position);
* **the tool** ``set_tcp(p[…])`` or ``set_tcp(NAME)``: motions after it use it; before
  any, the installation's TCP, named ``TCP`` (``--tool TCP=…``).

Poses are metres and a rotation vector in radians (notation ``ur``).  A motion argument
holding a ``p[…]`` the reader cannot place (``pose_add(…)``, arithmetic) is an error at
file:line:column; one without a pose literal (``get_actual_tcp_pose()``) is left as it is,
with a note.
"""

from __future__ import annotations

import re
from pathlib import Path

from plugcell.io.programs.core import Num, Program, ProgramError, SourceFile, Target, Token
from plugcell.io.units import pose_from_notation

__all__ = ["read_urscript"]

MOTIONS = {"movel": 1, "movej": 1, "movep": 1, "movec": 2}

_TOKEN = re.compile(r"""[ \t\f\v]*(?:
    (?P<num>(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)
  | (?P<name>[A-Za-z_][A-Za-z0-9_]*)
  | (?P<str>"[^"\r\n]*"|'[^'\r\n]*')
  | (?P<op>==|!=|<=|>=|[()\[\],=+\-*/:<>.%])
  | (?P<bad>\S)
)""", re.VERBOSE)


def _lines(f: SourceFile) -> list[list[Token]]:
    """Tokens of each line, the ``#`` comment (outside strings) cut off."""
    out = []
    pos = 0
    for line in f.text.splitlines(keepends=True):
        body = line.rstrip("\r\n")
        toks = []
        for m in _TOKEN.finditer(body):
            kind = m.lastgroup
            if kind is None:  # trailing blanks
                continue
            a, b = m.span(kind)
            if body[a] == "#":
                break
            toks.append(Token(kind, body[a:b], pos + a, pos + b))
        out.append(toks)
        pos += len(line)
    return out


class _Reader:
    def __init__(self, f: SourceFile) -> None:
        self.f = f
        self.program = Program("urscript", [f], resolution=(1e-6, 1e-6, 1e-6))
        self.vars: dict[str, Target] = {}
        self.notes: list[str] = []
        self.tool = "TCP"
        self.listed: set[int] = set()

    def literal(self, toks: list[Token], i: int, joints: bool = False) -> tuple[list[Num], int]:
        """``p[…]`` (or ``[…]``) at ``toks[i]`` → its six numbers and the index after it."""
        if not joints:
            i += 1  # the p
        if i >= len(toks) or toks[i].text != "[":
            raise self.f.error(toks[min(i, len(toks) - 1)].start, "expected '['")
        open_tok = toks[i]
        i += 1
        nums: list[Num] = []
        while True:
            if i >= len(toks):
                raise self.f.error(open_tok.start, "a pose literal not closed on its line")
            t = toks[i]
            sign = None
            if t.text == "-" and i + 1 < len(toks) and toks[i + 1].kind == "num":
                sign, t = t, toks[i + 1]
                i += 1
            if t.kind != "num":
                raise self.f.error(t.start, f"expected a number in the pose, got {t.text!r}")
            start = sign.start if sign is not None else t.start
            if sign is not None and sign.end != t.start:
                raise self.f.error(sign.start, "a space between the sign and the number")
            nums.append(self.f.number(start, t.end))
            i += 1
            if i < len(toks) and toks[i].text == ",":
                i += 1
                continue
            if i < len(toks) and toks[i].text == "]":
                i += 1
                break
            raise self.f.error(toks[i].start if i < len(toks) else t.end,
                               "expected ',' or ']' in the pose")
        if len(nums) != 6:
            raise self.f.error(open_tok.start, f"a pose has 6 numbers, this one {len(nums)}")
        return nums, i

    def is_pose(self, toks: list[Token], i: int) -> bool:
        return (i + 1 < len(toks) and toks[i].text == "p" and toks[i + 1].text == "["
                and toks[i + 1].start == toks[i].end)

    def run(self) -> None:
        lines = _lines(self.f)
        for toks in lines:  # pass 1: assignments
            self.assignment(toks)
        for toks in lines:  # pass 2: tool and motions in order
            self.statement(toks)

    def assignment(self, toks: list[Token]) -> None:
        i = 1 if toks and toks[0].text in ("global", "local") else 0
        if len(toks) < i + 3 or toks[i].kind != "name" or toks[i + 1].text != "=":
            return
        name = toks[i].text
        j = i + 2
        if self.is_pose(toks, j):
            nums, k = self.literal(toks, j)
            kind = "pose"
        elif toks[j].text == "[" and len(toks) > j + 1 and toks[j + 1].kind in ("num", "op"):
            try:
                nums, k = self.literal(toks, j, joints=True)
            except ProgramError:
                return  # a list that is no joint position
            kind = "joints"
        else:
            return
        if k != len(toks):
            raise self.f.error(toks[k].start, f"{name}: unexpected text after the pose")
        tg = Target(name, 0, toks[j].start, kind, nums, "ur" if kind == "pose" else "",
                    used=False, unit=1.0 if kind == "joints" else None)
        if name in self.vars:  # assigned twice: which one a motion uses depends on the run
            raise self.f.error(toks[i].start, f"{name} is assigned a position twice: the "
                               "reader cannot tell which one each motion uses")
        self.vars[name] = tg
        self.listed.add(id(tg))
        self.program.targets.append(tg)

    def statement(self, toks: list[Token]) -> None:
        for k, t in enumerate(toks):
            if t.kind != "name" or k + 1 >= len(toks) or toks[k + 1].text != "(":
                continue
            if t.text == "set_tcp":
                self.set_tcp(toks, k + 2)
            elif t.text in MOTIONS:
                self.motion(toks, k, MOTIONS[t.text])

    def set_tcp(self, toks: list[Token], i: int) -> None:
        if self.is_pose(toks, i):
            nums, _ = self.literal(toks, i)
            line = self.f.position(toks[i].start)[0]
            name = f"set_tcp (line {line})"
            self.program.tools[name] = pose_from_notation([n.value for n in nums], "ur")
        elif i < len(toks) and toks[i].text in self.vars:
            tg = self.vars[toks[i].text]
            name = toks[i].text
            self.program.tools[name] = pose_from_notation(tg.values, "ur")
            self.program.targets.remove(tg)
            del self.vars[name]
        else:
            raise self.f.error(toks[min(i, len(toks) - 1)].start,
                               "set_tcp: expected p[…] or a pose variable")
        self.tool = name

    def motion(self, toks: list[Token], k: int, count: int) -> None:
        i = k + 2
        for n in range(count):
            i = self.argument(toks, i, toks[k].text)
            if n + 1 < count:
                if i >= len(toks) or toks[i].text != ",":
                    raise self.f.error(toks[min(i, len(toks) - 1)].start,
                                       f"{toks[k].text}: expected a second pose")
                i += 1

    def argument(self, toks: list[Token], i: int, move: str, base: str | None = None) -> int:
        if i >= len(toks):
            raise self.f.error(toks[-1].end, f"{move}: expected a target")
        t = toks[i]
        line = self.f.position(t.start)[0]
        if self.is_pose(toks, i):
            nums, j = self.literal(toks, i)
            self.use(Target(f"{move} line {line}", 0, t.start, "pose", nums, "ur"), base, t)
            return j
        if t.text == "[" and move == "movej" and base is None:
            nums, j = self.literal(toks, i, joints=True)
            self.use(Target(f"{move} line {line}", 0, t.start, "joints", nums, unit=1.0),
                     None, t)
            return j
        if t.text == "pose_trans" and toks[i + 1].text == "(" and base is None:
            frame = toks[i + 2]
            if frame.kind != "name" or toks[i + 3].text != ",":
                raise self.f.error(frame.start, "pose_trans: expected a frame name first")
            fr = frame.text
            if fr in self.vars:
                tg = self.vars.pop(fr)
                self.program.targets.remove(tg)
                self.program.frames[fr] = pose_from_notation(tg.values, "ur")
            j = self.argument(toks, i + 4, move, fr)
            if j >= len(toks) or toks[j].text != ")":
                raise self.f.error(toks[min(j, len(toks) - 1)].start, "pose_trans: expected ')'")
            return j + 1
        if t.text == "get_inverse_kin" and toks[i + 1].text == "(" and base is None:
            j = self.argument(toks, i + 2, move)
            depth = 1
            while j < len(toks) and depth:
                depth += {"(": 1, ")": -1}.get(toks[j].text, 0)
                j += 1
            return j
        if t.kind == "name" and t.text in self.vars and (
                i + 1 >= len(toks) or toks[i + 1].text in (",", ")")):
            self.use(self.vars[t.text], base, t)
            return i + 1
        # an expression: a pose literal inside it cannot be placed
        depth, j = 0, i
        while j < len(toks) and not (depth == 0 and toks[j].text in (",", ")")):
            depth += {"(": 1, "[": 1, ")": -1, "]": -1}.get(toks[j].text, 0)
            if self.is_pose(toks, j) or (toks[j].kind == "name" and toks[j].text in self.vars
                                         and self.vars[toks[j].text].kind == "pose"):
                raise self.f.error(toks[j].start, f"{move}: a pose inside an expression the "
                                   "reader does not know (only p[…], a variable, pose_trans("
                                   "FRAME, …) and get_inverse_kin(…))")
            j += 1
        self.notes.append(f"{self.f.path}:{line}:{self.f.position(t.start)[1]}: {move} to an "
                          "expression without a pose literal: left as it is")
        return j

    def use(self, tg: Target, base: str | None, tok: Token) -> None:
        if id(tg) not in self.listed:
            self.listed.add(id(tg))
            self.program.targets.append(tg)
        tg.use(base, self.tool, self.f, 0, tok.start, lambda b, t: f"frame {b} and tool {t}")


def read_urscript(path: str | Path) -> tuple[Program, list[str]]:
    """Read a URScript program (module docstring).

    Parameters
    ----------
    path : str or Path
        The ``.script`` file.

    Returns
    -------
    program : Program
        Its targets, frames (``pose_trans`` features) and tools (``set_tcp``).
    notes : list of str
        Motions left as they are.

    Raises
    ------
    ProgramError
        Unreadable file, or a pose the reader cannot place (file:line:column).
    """
    r = _Reader(SourceFile.read(Path(path)))
    r.run()
    r.program.targets.sort(key=lambda t: t.offset)
    return r.program, r.notes
