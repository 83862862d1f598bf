"""KUKA KRL: a ``.src`` and its ``.dat`` — positions, frames and tools.

What is read (everything else passes through as it is, comments and folds included):

* **declarations and assignments** of positions, ``DECL [GLOBAL] E6POS|POS|FRAME|E6AXIS|AXIS
  NAME={…}`` and ``NAME={…}`` / ``NAME[i]={…}`` in either file;
* **motions** ``PTP``, ``LIN``, ``CIRC`` (auxiliary and end point), ``SPTP``, ``SLIN``,
  ``SCIRC``, ``SPL`` with a named position or an inline aggregate ``{X …}`` /
  ``{A1 …}`` (``_REL`` motions are relative: left as they are, noted);
* **frames**: ``$BASE=`` and ``$TOOL=`` an aggregate, ``BASE_DATA[n]``/``TOOL_DATA[n]``,
  ``$NULLFRAME`` or a FRAME variable; ``BASE_DATA[n]={…}``/``TOOL_DATA[n]={…}``; the
  inline forms' ``FDAT_ACT=FPn`` (its ``BASE_NO``, ``TOOL_NO``) and ``BAS(#BASE, n)``,
  ``BAS(#TOOL, n)``.  A motion's target takes the ``$BASE``/``$TOOL`` last set above it.

Poses are ``X, Y, Z`` mm and ``A, B, C`` degrees, ``R = Rz(A)·Ry(B)·Rx(C)`` (notation
``kuka``).  Status ``S`` and turn ``T`` are kept consistent: a bit of T (joint *i* < 0)
or of S (bit 2: A5 ≤ 0) flips only where the compensated joints fall on the other side of
zero than the nominal ones — written back in the number's own form (``35`` or
``'B100011'``).  Unknown syntax inside what is read (a bad aggregate, a partial pose, an
external TCP, an ``$BASE`` expression not listed) is an error at file:line:column.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from plugcell.io.programs.core import Num, Program, ProgramError, SourceFile, Target, Token
from plugcell.io.units import pose_from_notation

__all__ = ["read_krl"]

POSE_KEYS = ("X", "Y", "Z", "A", "B", "C")
AXIS_KEYS = ("A1", "A2", "A3", "A4", "A5", "A6")
POSITION_TYPES = {"E6POS", "POS", "FRAME", "E6AXIS", "AXIS"}
MOTIONS = {"PTP", "LIN", "CIRC", "SPTP", "SLIN", "SCIRC", "SPL"}
RELATIVE = {"PTP_REL", "LIN_REL", "CIRC_REL", "SPTP_REL", "SLIN_REL", "SCIRC_REL"}

_TOKEN = re.compile(r"""[ \t\f\v]*(?:
    (?P<num>[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)
  | (?P<name>[A-Za-z_$][A-Za-z0-9_$]*)
  | (?P<str>"[^"\r\n]*"|'[^'\r\n]*')
  | (?P<op>[{}\[\]():,#=.+\-*/<>])
  | (?P<bad>\S)
)""", re.VERBOSE)


def _code_lines(f: SourceFile) -> list[tuple[int, str]]:
    """``(offset, code)`` of each line, the comment (``;`` outside a string) cut off."""
    out = []
    pos = 0
    text = f.text
    for line in text.splitlines(keepends=True):
        body = line.rstrip("\r\n")
        cut = body.find(";")
        if cut < 0:
            cut = len(body)
        elif '"' in body[:cut]:  # a ';' inside a string does not start the comment
            in_str = False
            for k, ch in enumerate(body):
                if ch == '"':
                    in_str = not in_str
                elif ch == ";" and not in_str:
                    cut = k
                    break
            else:
                cut = len(body)
        out.append((pos, body[:cut]))
        pos += len(line)
    return out


def _tokens(f: SourceFile, offset: int, code: str) -> list[Token]:
    toks = []
    for m in _TOKEN.finditer(code):
        kind = m.lastgroup
        if kind is None:  # trailing blanks
            continue
        a, b = m.span(kind)
        toks.append(Token(kind, code[a:b], offset + a, offset + b))
    return toks


@dataclass
class _Agg:
    """A parsed aggregate: type name (or ``""``), items key → token or sub-aggregate."""

    type: str
    items: dict[str, object]
    start: int
    end: int


class _Parser:
    """Recursive descent over one line's tokens (KRL aggregates and references)."""

    def __init__(self, f: SourceFile, toks: list[Token]) -> None:
        self.f, self.toks, self.i = f, toks, 0

    def peek(self, k: int = 0) -> Token | None:
        j = self.i + k
        return self.toks[j] if j < len(self.toks) else None

    def error(self, message: str, tok: Token | None = None) -> ProgramError:
        tok = tok or self.peek()
        off = tok.start if tok else (self.toks[-1].end if self.toks else 0)
        return self.f.error(off, message)

    def expect(self, text: str) -> Token:
        t = self.peek()
        if t is None or t.text != text:
            raise self.error(f"expected {text!r}, got {t.text if t else 'end of line'!r}")
        self.i += 1
        return t

    def aggregate(self) -> _Agg:
        start = self.expect("{")
        typ = ""
        a, b = self.peek(), self.peek(1)
        if a is not None and a.kind == "name" and b is not None and b.text == ":":
            typ = a.text.upper()
            self.i += 2
        items: dict[str, object] = {}
        while True:
            t = self.peek()
            if t is not None and t.text == "}" and not items:
                break
            if t is None or t.kind != "name":
                raise self.error("expected a component name in the aggregate")
            self.i += 1
            key = t.text.upper()
            if self.peek() is not None and self.peek().text == "[":  # type: ignore[union-attr]
                self.expect("[")
                self.expect("]")
                key += "[]"
            items[key] = self.value()
            t = self.peek()
            if t is not None and t.text == ",":
                self.i += 1
                continue
            break
        end = self.expect("}")
        return _Agg(typ, items, start.start, end.end)

    def value(self) -> object:
        t = self.peek()
        if t is None:
            raise self.error("expected a value")
        if t.text == "{":
            return self.aggregate()
        if t.text == "#":
            self.i += 1
            n = self.peek()
            if n is None or n.kind != "name":
                raise self.error("expected an enumeration value after '#'")
            self.i += 1
            return ("enum", n)
        if t.text in "+-" and self.peek(1) is not None and self.peek(1).kind == "num":  # type: ignore[union-attr]
            raise self.error("a space between the sign and the number")
        if t.kind in ("num", "str", "name"):
            self.i += 1
            return (t.kind, t)
        raise self.error(f"unexpected {t.text!r} in an aggregate")

    def reference(self) -> tuple[str, Token]:
        """``NAME`` or ``NAME[index]`` → (upper-case name, first token)."""
        t = self.peek()
        if t is None or t.kind != "name":
            raise self.error("expected a position (a name or {…})")
        self.i += 1
        name = t.text.upper()
        if self.peek() is not None and self.peek().text == "[":  # type: ignore[union-attr]
            self.i += 1
            idx = []
            while self.peek() is not None and self.peek().text != "]":  # type: ignore[union-attr]
                idx.append(self.peek().text)  # type: ignore[union-attr]
                self.i += 1
            self.expect("]")
            name += "[" + "".join(idx) + "]"
        return name, t


@dataclass
class KrlConfig:
    """Status and turn numbers of an E6POS/POS and how they follow the joints."""

    file: int
    s: Num | None
    t: Num | None

    def mismatch(self, q: np.ndarray) -> str:
        """Where the program's S/T describe another configuration than the joints ``q``
        the compensation solved for (``""`` if they agree)."""
        out = []
        if self.t is not None:
            bits = int(self.t.value)
            bad = [f"A{i + 1}" for i in range(min(6, q.size)) if bool(bits >> i & 1) != (q[i] < 0)]
            if bad:
                out.append(f"T {self.t.text} says another sign of {', '.join(bad)}")
        if self.s is not None and q.size >= 5 and bool(int(self.s.value) & 4) != (q[4] <= 0):
            out.append(f"S {self.s.text} says another sign of A5")
        return "; ".join(out)

    def agrees(self, Q: np.ndarray) -> np.ndarray:
        """``(K,)``: which joint vectors ``Q (K, n)`` the S/T numbers describe."""
        ok = np.ones(len(Q), dtype=bool)
        if self.t is not None:
            m = min(6, Q.shape[1])
            bits = (int(self.t.value) >> np.arange(m)) & 1
            ok &= np.all((Q[:, :m] < 0) == bits.astype(bool), axis=1)
        if self.s is not None and Q.shape[1] >= 5:
            ok &= (Q[:, 4] <= 0) == bool(int(self.s.value) & 4)
        return ok

    def edits(self, q_nominal: np.ndarray, q: np.ndarray) -> dict[tuple[int, int], str]:
        """Bits flipped where the compensated joints changed side of zero (module doc)."""
        out: dict[tuple[int, int], str] = {}
        if self.t is not None:
            flip = sum(1 << i for i in range(min(6, q.size))
                       if (q_nominal[i] < 0) != (q[i] < 0))
            if flip:
                out[(self.file, self.t.start)] = _bits(self.t, int(self.t.value) ^ flip)
        if self.s is not None and q.size >= 5 and (q_nominal[4] <= 0) != (q[4] <= 0):
            out[(self.file, self.s.start)] = _bits(self.s, int(self.s.value) ^ 4)
        return out


def _bits(num: Num, value: int) -> str:
    if num.text.startswith("'"):
        digits = len(num.text) - 3
        return f"'B{value:0{digits}b}'"
    return str(value)


def _int_num(f: SourceFile, tok: Token) -> Num:
    """A status/turn value: an integer or a ``'B0101'`` binary literal."""
    if tok.kind == "str" and re.fullmatch(r"'[Bb][01]+'", tok.text):
        return Num(tok.start, tok.end, tok.text, float(int(tok.text[2:-1], 2)))
    if tok.kind == "num" and re.fullmatch(r"\d+", tok.text):
        return Num(tok.start, tok.end, tok.text, float(tok.text))
    raise f.error(tok.start, f"status/turn must be an integer or 'B…', got {tok.text!r}")


class _Reader:
    def __init__(self, files: list[SourceFile]) -> None:
        self.files = files
        self.program = Program("krl", files, resolution=(1e-3, 1e-3, 1e-6))
        self.defs: dict[str, Target] = {}     # position variables by upper-case name
        self.frame_vars: dict[str, tuple[int, _Agg]] = {}  # FRAME variables (aggregates)
        self.fdat: dict[str, tuple[str | None, str | None]] = {}
        self.notes: list[str] = []
        self.base: str | None = None
        self.base_set = False
        self.tool: str | None = None
        self.tool_set = False

    # -------------------------------------------------------------- aggregates → targets
    def target_of(self, fi: int, agg: _Agg, name: str, p: _Parser) -> Target | None:
        f = self.files[fi]
        keys = set(agg.items)
        if keys & set(POSE_KEYS):
            missing = [k for k in POSE_KEYS if k not in agg.items]
            if missing:
                raise f.error(agg.start, f"{name}: a partial position (no {', '.join(missing)}):"
                              " compensation needs X, Y, Z, A, B and C")
            nums = [self.num(fi, agg.items[k], k, p) for k in POSE_KEYS]
            s = self.config_num(fi, agg.items.get("S"), p)
            t = self.config_num(fi, agg.items.get("T"), p)
            cfg = KrlConfig(fi, s, t) if (s or t) else None
            return Target(name, fi, agg.start, "pose", nums, "kuka", config=cfg,
                          extra=[n for n in (s, t) if n is not None])
        if keys & set(AXIS_KEYS):
            present = [k for k in AXIS_KEYS if k in agg.items]
            if present != list(AXIS_KEYS[:len(present)]):
                raise f.error(agg.start, f"{name}: axis values must be A1…An in order")
            nums = [self.num(fi, agg.items[k], k, p) for k in present]
            return Target(name, fi, agg.start, "joints", nums)
        return None

    def num(self, fi: int, item: object, key: str, p: _Parser) -> Num:
        if not (isinstance(item, tuple) and item[0] == "num"):
            tok = item[1] if isinstance(item, tuple) else None
            raise p.error(f"component {key} must be a number", tok)  # type: ignore[arg-type]
        tok = item[1]
        return self.files[fi].number(tok.start, tok.end)

    def config_num(self, fi: int, item: object, p: _Parser) -> Num | None:
        if item is None:
            return None
        if not isinstance(item, tuple):
            raise p.error("status/turn must be a number")
        return _int_num(self.files[fi], item[1])

    def frame_of(self, fi: int, agg: _Agg, what: str) -> np.ndarray:
        f = self.files[fi]
        missing = [k for k in POSE_KEYS if k not in agg.items]
        if missing:
            raise f.error(agg.start, f"{what}: a frame needs X, Y, Z, A, B and C (no "
                          f"{', '.join(missing)})")
        vals = []
        for k in POSE_KEYS:
            it = agg.items[k]
            if not (isinstance(it, tuple) and it[0] == "num"):
                raise f.error(agg.start, f"{what}: component {k} must be a number")
            vals.append(float(it[1].text))
        return pose_from_notation(np.array(vals), "kuka")

    # -------------------------------------------------------------- statements
    def declarations(self, fi: int) -> None:
        """Pass 1: position and frame variables, FDATs, in both files."""
        f = self.files[fi]
        for off, code in _code_lines(f):
            if "=" not in code or "{" not in code:
                continue
            toks = _tokens(f, off, code)
            p = _Parser(f, toks)
            typ = self.decl_prefix(p)
            t = p.peek()
            if t is None or t.kind != "name":
                continue
            name, first = p.reference()
            if p.peek() is None or p.peek().text != "=":  # type: ignore[union-attr]
                continue
            p.i += 1
            if p.peek() is None or p.peek().text != "{":  # type: ignore[union-attr]
                continue
            agg = p.aggregate()
            if p.peek() is not None:
                raise p.error("unexpected text after the aggregate")
            if typ == "FDAT" or agg.type == "FDAT":
                self.fdat[name] = self.fdat_frames(fi, agg)
                continue
            if name.startswith(("BASE_DATA[", "TOOL_DATA[")) or name in ("$BASE", "$TOOL"):
                continue  # executable: pass 2
            if typ in POSITION_TYPES or agg.type in POSITION_TYPES or typ is None:
                if typ == "FRAME" or agg.type == "FRAME":
                    self.frame_vars[name] = (fi, agg)
                tg = self.target_of(fi, agg, first.text + name[len(first.text):], p)
                if tg is not None:
                    tg.used = False
                    self.defs[name] = tg
                    self.program.targets.append(tg)

    def decl_prefix(self, p: _Parser) -> str | None:
        """Skip ``DECL [GLOBAL] TYPE`` (or a bare ``TYPE``); the type or None."""
        t = p.peek()
        if t is None:
            return None
        up = t.text.upper()
        if up == "DECL":
            p.i += 1
            t = p.peek()
            if t is not None and t.text.upper() == "GLOBAL":
                p.i += 1
                t = p.peek()
            if t is None or t.kind != "name":
                raise p.error("expected a type after DECL")
            p.i += 1
            return t.text.upper()
        if up in POSITION_TYPES or up in ("FDAT", "PDAT", "LDAT"):
            nxt = p.peek(1)
            if nxt is not None and nxt.kind == "name":
                p.i += 1
                return up
        return None

    def fdat_frames(self, fi: int, agg: _Agg) -> tuple[str | None, str | None]:
        def number(key: str) -> int | None:
            it = agg.items.get(key)
            if it is None:
                return None
            if not (isinstance(it, tuple) and it[0] == "num"):
                raise self.files[fi].error(agg.start, f"FDAT {key} must be a number")
            return int(float(it[1].text))

        ipo = agg.items.get("IPO_FRAME")
        if isinstance(ipo, tuple) and ipo[0] == "enum" and ipo[1].text.upper() == "TCP":
            raise self.files[fi].error(ipo[1].start, "IPO_FRAME #TCP (a fixed tool, the "
                                       "part on the robot) is not supported")
        tool, base = number("TOOL_NO"), number("BASE_NO")
        return (None if tool is None else _data("TOOL", tool),
                None if base is None else _data("BASE", base))

    def statements(self, fi: int) -> None:
        """Pass 2: frames set and motions, in program order (the ``.src``)."""
        f = self.files[fi]
        for off, code in _code_lines(f):
            if not code.strip():
                continue
            toks = _tokens(f, off, code)
            if not toks:
                continue
            p = _Parser(f, toks)
            head = toks[0].text.upper()
            if head in MOTIONS:
                p.i = 1
                self.motion(fi, p, head)
            elif head in RELATIVE:
                self.notes.append(f"{self.program.where(fi, toks[0].start)}: {head} is "
                                  "relative: left as it is")
            elif head in ("$BASE", "$TOOL") and len(toks) > 1 and toks[1].text == "=":
                p.i = 2
                self.set_frame(fi, p, head)
            elif head in ("BASE_DATA", "TOOL_DATA") and "=" in code:
                name, _ = p.reference()
                p.expect("=")
                agg = p.aggregate()
                m = self.frame_of(fi, agg, name)
                (self.program.frames if head == "BASE_DATA" else self.program.tools)[name] = m
            elif head == "FDAT_ACT" and len(toks) >= 3 and toks[1].text == "=":
                p.i = 2
                name, tok = p.reference()
                fd = self.fdat.get(name)
                if fd is None:
                    raise f.error(tok.start, f"FDAT {name} is not declared in the program")
                self.tool, self.base = fd
                self.tool_set = self.base_set = True
            elif head == "BAS" and len(toks) >= 5 and toks[1].text == "(" and \
                    toks[2].text == "#" and toks[3].text.upper() in ("BASE", "TOOL"):
                which = toks[3].text.upper()
                if len(toks) < 7 or toks[4].text != "," or toks[5].kind != "num":
                    raise f.error(toks[3].start, f"BAS(#{which}, n): expected a number")
                n = int(float(toks[5].text))
                if which == "BASE":
                    self.base, self.base_set = _data("BASE", n), True
                else:
                    self.tool, self.tool_set = _data("TOOL", n), True
            elif head in self.defs and len(toks) > 2 and toks[1].text == ".":
                raise f.error(toks[0].start, f"{toks[0].text}.{toks[2].text}=…: a component of "
                              "a target changed at run time cannot be compensated")
            elif "{" in code and head not in ("DECL",) and not self.is_decl(toks):
                self.stray(fi, toks)

    def is_decl(self, toks: list[Token]) -> bool:
        """A line pass 1 read (a declaration or assignment of a position)."""
        p = _Parser(self.files[0], toks)
        self.decl_prefix(p)
        t = p.peek()
        return t is not None and t.kind == "name" and t.text.upper() in \
            {k.split("[")[0] for k in (*self.defs, *self.fdat, *self.frame_vars)}

    def stray(self, fi: int, toks: list[Token]) -> None:
        """An aggregate with position components where no target is expected."""
        p = _Parser(self.files[fi], toks)
        for k, t in enumerate(toks):
            if t.text == "{":
                p.i = k
                try:
                    agg = p.aggregate()
                except ProgramError:
                    continue
                if set(agg.items) & (set(POSE_KEYS) | set(AXIS_KEYS)):
                    raise self.files[fi].error(t.start, "a position where the reader expects "
                                               "none (only motions, declarations and "
                                               "frame assignments are compensated)")

    def set_frame(self, fi: int, p: _Parser, head: str) -> None:
        f = self.files[fi]
        t = p.peek()
        if t is None:
            raise p.error(f"{head}= what?")
        what = "BASE" if head == "$BASE" else "TOOL"
        if t.text == "{":
            agg = p.aggregate()
            line = f.position(agg.start)[0]
            name = f"{head} (line {line})"
            m = self.frame_of(fi, agg, head)
            (self.program.frames if what == "BASE" else self.program.tools)[name] = m
        elif t.kind == "name":
            name, tok = p.reference()
            if name == "$NULLFRAME" or name == "$WORLD":
                name = "$NULLFRAME"
                table = self.program.frames if what == "BASE" else self.program.tools
                table[name] = np.eye(4)
            elif name.startswith(f"{what}_DATA["):
                pass
            elif name in self.frame_vars:
                vfi, agg = self.frame_vars[name]
                m = self.frame_of(vfi, agg, name)
                (self.program.frames if what == "BASE" else self.program.tools)[name] = m
                tg = self.defs.get(name)
                if tg is not None:  # a frame, not a target
                    self.program.targets.remove(tg)
                    del self.defs[name]
            else:
                raise f.error(tok.start, f"{head}={name}: not a frame the reader knows "
                              "(an aggregate, BASE_DATA[n]/TOOL_DATA[n], $NULLFRAME or a "
                              "FRAME variable of the program)")
        else:
            raise p.error(f"{head}=: expected a frame")
        if p.peek() is not None:
            raise p.error(f"unexpected text after the {head} assignment")
        if what == "BASE":
            self.base, self.base_set = name, True
        else:
            self.tool, self.tool_set = name, True

    def motion(self, fi: int, p: _Parser, head: str) -> None:
        count = 2 if head in ("CIRC", "SCIRC") else 1
        for k in range(count):
            t = p.peek()
            if t is None:
                raise p.error(f"{head}: expected a position")
            if t.text == "{":
                agg = p.aggregate()
                line = self.files[fi].position(agg.start)[0]
                tg = self.target_of(fi, agg, f"{head} line {line}", p)
                if tg is None:
                    raise self.files[fi].error(agg.start, f"{head}: the aggregate is no "
                                               "position (X…C or A1…)")
                self.program.targets.append(tg)
            else:
                name, tok = p.reference()
                tg = self.defs.get(name)
                if tg is None:
                    self.notes.append(f"{self.program.where(fi, tok.start)}: {tok.text} is not "
                                      "declared in the program ($config.dat?): left as it is")
                    tg = None
            if tg is not None:
                self.use(tg, fi, p.toks[0].start)
            if k + 1 < count:
                p.expect(",")

    def use(self, tg: Target, fi: int, offset: int) -> None:
        base = self.base if self.base_set else "$BASE"
        tool = self.tool if self.tool_set else "$TOOL"
        tg.use(base, tool, self.files[fi], fi, offset, lambda b, t: f"base {b} and tool {t}",
               frames_matter=tg.kind == "pose")


def _data(what: str, n: int) -> str:
    return "$NULLFRAME" if n == 0 else f"{what}_DATA[{n}]"


def read_krl(path: str | Path) -> tuple[Program, list[str]]:
    """Read a KRL program: the ``.src`` and the ``.dat`` of the same name beside it.

    Parameters
    ----------
    path : str or Path
        The ``.src`` (a ``.dat`` alone is read as well: its positions, none used).

    Returns
    -------
    program : Program
        Files ``[src, dat]`` (or one), targets, frames and tools it defines.
    notes : list of str
        Things left as they are (relative motions, positions not in the program).

    Raises
    ------
    ProgramError
        Unreadable file or unknown syntax inside a position, a motion or a frame.
    """
    src = Path(path)
    files = [SourceFile.read(src)]
    if src.suffix.lower() == ".src":
        for cand in src.parent.iterdir() if src.parent.is_dir() else []:
            if cand.stem == src.stem and cand.suffix.lower() == ".dat":
                files.append(SourceFile.read(cand))
                break
    r = _Reader(files)
    for fi in reversed(range(len(files))):  # the .dat first: its declarations
        r.declarations(fi)
    if src.suffix.lower() == ".src":
        r.statements(0)
    nulls = r.program
    nulls.frames.setdefault("$NULLFRAME", np.eye(4))
    nulls.tools.setdefault("$NULLFRAME", np.eye(4))
    r.program.targets.sort(key=lambda t: (t.file, t.offset))
    return r.program, r.notes
