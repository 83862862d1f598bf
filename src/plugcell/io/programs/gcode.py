"""G-code for robot machining: G0/G1/G2/G3 with X Y Z and A B C, modal.

What is read (everything else passes through as it is — comments ``( … )`` and ``;``,
line numbers ``N``, feeds, spindle and M codes):

* **motions** ``G0``, ``G1``, ``G2``, ``G3`` (modal: a line with axis words and no G
  word moves in the last mode).  Each motion line is a target: the pose ``X, Y, Z`` mm
  and ``A, B, C`` degrees in the robot's angle convention (``--angles``, default KUKA's
  ``Rz(A)·Ry(B)·Rx(C)``), every word the line leaves out inherited from the lines above
  (A, B, C default 0: a 3-axis program's tool frame is parallel to the work offset);
* **the work offset** ``G54`` … ``G59`` (``G54.1 Pn`` → ``G54.1P1``) — the frame the
  program is in, given on the command line (``--base 'G54=X,Y,Z,A,B,C'``), and **the
  tool** ``Tn`` (``--tool 'T1=…'``; before any T word, ``TOOL``).

A compensated line writes its words in their own style; a value the line inherits but
whose compensated value differs (by half the resolution, 0.001 mm / 0.001°) is written
as a word appended after the line's last word (`` Z12.345``), in the style of that axis'
last word — the next lines then inherit the compensated value, as the controller does.
An arc's centre offsets ``I, J, K`` (read in all three axes, whatever the plane) move
with the arc: the centre first moves by the mean of the corrections of its start and
end points, ``c₀ = s + IJK + (δ_start + δ_end)/2``, then onto the plane of points
equidistant from the compensated start and end, ``c' = c₀ − ((c₀ − m)·n) n`` (``m`` their
midpoint, ``n`` the unit vector from start to end), so both ends lie on one circle again
(a controller checks the radii at both ends); ``IJK' = c' − s'``.

Refused at file:line:column: inches (``G20``), incremental coordinates (``G91``), arcs
by radius (``R``), canned cycles (``G81``–``G89``) and machine coordinates (``G53``).
Motions before every axis is known (the machine's start position) are left as they
are, noted.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from plugcell.io.programs.core import Num, NumberStyle, Program, SourceFile, Target, min_frac

__all__ = ["read_gcode"]

AXES = ("X", "Y", "Z", "A", "B", "C")
_WORD = re.compile(r"(?P<letter>[A-Za-z])[ \t]*(?P<num>[+-]?(?:\d+\.?\d*|\.\d+))")
_COMMENT = re.compile(r"\([^)\r\n]*\)|;[^\r\n]*")


@dataclass
class _Arc:
    prev: Target | None
    ijk: list[Num | None]


@dataclass
class _State:
    arcs: dict[int, _Arc] = field(default_factory=dict)
    anchor: dict[int, Num] = field(default_factory=dict)  # insertion point per target


def _words(f: SourceFile, start: int, line: str) -> tuple[list[tuple[str, Num]], int]:
    """The words of a line (comments blanked) and the offset after its last word."""
    code = _COMMENT.sub(lambda m: " " * len(m.group()), line)
    words = []
    end = start
    pos = 0
    body = code.rstrip("\r\n")
    while pos < len(body):
        if body[pos] in " \t/%":
            pos += 1
            continue
        m = _WORD.match(body, pos)
        if m is None:
            raise f.error(start + pos, f"expected a word (a letter and a number), got "
                          f"{body[pos:pos + 12].split()[0]!r}")
        a, b = m.span("num")
        words.append((m["letter"].upper(), f.number(start + a, start + b)))
        end = start + m.end()
        pos = m.end()
    return words, end


def read_gcode(path: str | Path, notation: str = "kuka") -> tuple[Program, list[str]]:
    """Read a G-code program (module docstring).

    Parameters
    ----------
    path : str or Path
        The ``.nc``/``.ngc``/``.gcode``/``.tap`` file.
    notation : str
        How ``A, B, C`` turn the tool: ``kuka`` (ZYX), ``fanuc`` (XYZ fixed) or ``comau``
        (ZYZ).

    Returns
    -------
    program : Program
        A target a motion line; frames ``G54``… and tools ``Tn`` come from the caller.
    notes : list of str
        Motions left as they are.

    Raises
    ------
    ProgramError
        Unreadable file or a construct the reader refuses (file:line:column).
    """
    f = SourceFile.read(Path(path))
    prog = Program("gcode", [f], resolution=(1e-3, 1e-3, 1e-6))
    st = _State()
    notes: list[str] = []
    mode: int | None = None
    offset = "G54"
    tool = "TOOL"
    modal: dict[str, Num | None] = {k: None for k in AXES}
    for k in ("A", "B", "C"):
        modal[k] = Num(0, 0, "", 0.0, virtual=True)
    prev: Target | None = None
    pos = 0
    for line in f.text.splitlines(keepends=True):
        start = pos
        pos += len(line)
        words, end = _words(f, start, line)
        if not words:
            continue
        motion_now, offset = _g_codes(f, words, offset)
        tool = next(("T" + n.text for w, n in reversed(words) if w == "T"), tool)
        if motion_now is not None:
            mode = motion_now
        axis_words = {w: n for w, n in words if w in AXES}
        if not axis_words:
            continue
        if mode is None:
            raise f.error(next(iter(axis_words.values())).start - 1,
                          "axis words before any G0/G1/G2/G3")
        if mode in (2, 3) and any(w == "R" for w, _ in words):
            raise f.error(next(n for w, n in words if w == "R").start - 1,
                          "an arc by radius (R) is not supported: give its centre (I J K)")
        modal.update(axis_words)
        missing = [k for k in AXES if modal[k] is None]
        if missing:
            notes.append(f"{prog.where(0, start)}: {', '.join(missing)} not known yet (the "
                         "machine's start position): left as it is")
            continue
        ijk_words = {w: n for w, n in words if w in ("I", "J", "K")}
        t = _motion(f, line, start, end, axis_words, modal, ijk_words, notation, offset, tool)
        st.anchor[id(t)] = t.extra[0]
        if mode in (2, 3):
            if not ijk_words:
                raise f.error(t.offset, "an arc without its centre (I J K)")
            st.arcs[id(t)] = _Arc(prev, [ijk_words.get(k) for k in ("I", "J", "K")])
        prog.targets.append(t)
        prev = t
    prog.post = lambda p, reports, edits: _post(p, reports, edits, st)
    return prog, notes


def _g_codes(f: SourceFile, words: list[tuple[str, Num]], offset: str
             ) -> tuple[int | None, str]:
    """The G words of a line: the motion mode it sets (G0–G3, None: none) and the work
    offset in force (G54…G59.9, G54.1 Pn); refused: G20 inches, G91 incremental, G53
    machine coordinates, G81–G89 canned cycles (file:line:column)."""
    motion_now = None
    for w, n in words:
        if w != "G":
            continue
        g = n.text.lstrip("+0") or "0"
        gv = float(n.text)
        if gv in (0, 1, 2, 3):
            motion_now = int(gv)
        elif gv == 20:
            raise f.error(n.start - 1, "G20: inches are not supported (G21, mm)")
        elif gv == 91:
            raise f.error(n.start - 1, "G91: incremental coordinates are not supported")
        elif gv == 53:
            raise f.error(n.start - 1, "G53: machine coordinates are not supported")
        elif 81 <= gv <= 89:
            raise f.error(n.start - 1, f"G{g}: canned cycles are not supported")
        elif 54 <= gv <= 59.9:
            offset = "G" + g
            if g == "54.1":
                p = next((m for v, m in words if v == "P"), None)
                offset += f"P{p.text}" if p is not None else ""
    return motion_now, offset


def _motion(f: SourceFile, line: str, start: int, end: int, axis_words: dict[str, Num],
            modal: dict[str, Num | None], ijk_words: dict[str, Num], notation: str,
            offset: str, tool: str) -> Target:
    """The target of a motion line: the axes it writes, the others at their modal values
    (virtual numbers, written at the line's end if they change); ``extra``: the line's
    end anchor, then its I J K."""
    nums = []
    for k in AXES:
        if k in axis_words:
            nums.append(axis_words[k])
        else:
            m = modal[k]
            assert m is not None
            nums.append(Num(end, end, "", m.value, virtual=True))
    anchor = Num(end, end, "", 0.0)
    t = Target(f"line {f.position(start)[0]}", 0, start + (len(line) - len(line.lstrip())),
               "pose", nums, notation, base=offset, tool=tool,
               extra=[anchor, *ijk_words.values()])
    t.uses.append((0, t.offset))
    return t


def _post(prog: Program, reports: list, edits: dict[tuple[int, int], str], st: _State) -> None:
    """Modal words: insert the values a line inherits but must change; move arc centres."""
    by_target = {id(r.target): r for r in reports}
    written: dict[int, float] = {}   # axis index → the value the controller holds
    style: dict[int, NumberStyle] = {}
    res = prog.resolution
    for t in prog.targets:
        r = by_target.get(id(t))
        after = r.after if r is not None else t.values
        ins = []
        for k, n in enumerate(t.nums):
            r_k = res[0] if k < 3 else res[1]
            if not n.virtual:
                txt = edits.get((t.file, n.start), n.text)
                written[k] = float(txt)
                style[k] = NumberStyle.of(txt)
                continue
            have = written.get(k, n.value)
            if abs(after[k] - have) >= r_k / 2:
                sty = style.get(k, NumberStyle())
                txt = sty.format(float(after[k]), min_frac(r_k))
                ins.append(f" {AXES[k]}{txt}")
                written[k] = float(txt)
        if ins:
            anchor = st.anchor[id(t)]
            edits[(t.file, anchor.start)] = "".join(ins)
        arc = st.arcs.get(id(t))
        if arc is not None and r is not None and r.ok and arc.prev is not None:
            rp = by_target.get(id(arc.prev))
            s_nom = arc.prev.values[:3]
            s_new = rp.after[:3] if rp is not None and rp.ok else s_nom
            e_new = np.asarray(after[:3], dtype=float)
            ijk = np.array([0.0 if n is None else n.value for n in arc.ijk])
            c0 = s_nom + ijk + ((s_new - s_nom) + (e_new - t.values[:3])) / 2
            chord = e_new - s_new
            if np.linalg.norm(chord) > 0:
                nvec = chord / np.linalg.norm(chord)
                c0 = c0 - np.dot(c0 - (s_new + e_new) / 2, nvec) * nvec
            new_ijk = c0 - s_new
            for k, n in enumerate(arc.ijk):
                if n is None:
                    continue
                v = float(new_ijk[k])
                if abs(v - n.value) >= res[0] / 2:
                    edits[(t.file, n.start)] = NumberStyle.of(n.text).format(v, min_frac(res[0]))
