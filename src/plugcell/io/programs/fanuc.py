"""Fanuc TP (ASCII ``.ls``): the ``/POS`` section's points and the motions that use them.

What is read (everything else passes through as it is):

* **points** ``P[n]`` / ``P[n:"comment"]`` of ``/POS``, group ``GP1``: Cartesian
  (``UF : u, UT : t, CONFIG : '…', X = … mm, Y, Z, W = … deg, P, R``) or joint
  (``J1 = … deg`` …); other groups (a positioner, a rail) are kept;
* **motions** of ``/MN`` — ``J``, ``L``, ``C`` (its second point on the ``:`` line after
  it), ``A`` — that use them.  ``PR[n]`` position registers live in the controller
  (not in the ``.ls``): left as they are, noted; so is a motion with ``Offset`` or
  ``Tool_Offset`` (its point is compensated as written, the offset is not).

A point's frame and tool are its own ``UF`` and ``UT`` numbers — ``UFRAME[u]`` and
``UTOOL[t]`` of the controller, which a ``.ls`` does not hold: give them with
``--base 'UFRAME[1]=X,Y,Z,W,P,R' --tool 'UTOOL[1]=…'`` (``UF 0`` is the world frame).
Poses are mm and ``W, P, R`` degrees about the fixed X, Y, Z axes (notation ``fanuc``).
Numbers right-aligned in a padded field (``X =  1002.938  mm``) stay aligned.  The
``CONFIG`` string's turn numbers of J1, J4, J6 follow the joints: they change by the
turns (boundaries at ±180° + k·360°) the compensated joints crossed from the nominal
ones; the flip/up/top letters are kept.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from plugcell.io.programs.core import Num, Program, SourceFile, Target

__all__ = ["read_fanuc"]

_POINT = re.compile(r"^[ \t]*P\[(\d+)(?::\s*(?:\"[^\"\r\n]*\"|[^\]\r\n]*))?\][ \t]*\{", re.M)
_GROUP = re.compile(r"GP(\d+)[ \t]*:")
_NUM = r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?"
_FIELD = re.compile(r"(?P<key>[XYZWPR]|[JE]\d+)[ \t]*=(?P<pad>[ \t]*)(?P<num>" + _NUM
                    + r")[ \t]*(?P<unit>mm|deg)[ \t]*,?")
_UFUT = re.compile(r"(?P<key>UF|UT)[ \t]*:[ \t]*(?P<val>\w+)[ \t]*,?")
_CONFIG = re.compile(r"CONFIG[ \t]*:[ \t]*'(?P<body>[^'\r\n]*)'[ \t]*,?")
_MOTION = re.compile(r"^[ \t]*\d*:[ \t]*(?P<type>[JLCA])?[ \t]*(?P<reg>P|PR)\[(?P<n>\d+)"
                     r"(?::[^\]]*)?\](?P<rest>[^\r\n]*)", re.M)
CART = ("X", "Y", "Z", "W", "P", "R")


@dataclass
class FanucConfig:
    """The turn numbers of a CONFIG string and how they follow J1, J4, J6."""

    file: int
    turns: list[Num]

    def mismatch(self, q: np.ndarray) -> str:
        """Where the turn numbers name other turns than the joints ``q`` (``""``: none)."""
        bad = [f"turn of J{j + 1} = {num.text} (joint in turn "
               f"{math.floor((q[j] + math.pi) / (2 * math.pi))})"
               for num, j in zip(self.turns, (0, 3, 5), strict=False)
               if j < q.size and int(num.value) != math.floor((q[j] + math.pi) / (2 * math.pi))]
        return "; ".join(bad)

    def agrees(self, Q: np.ndarray) -> np.ndarray:
        """``(K,)``: which joint vectors ``Q (K, n)`` the turn numbers describe."""
        ok = np.ones(len(Q), dtype=bool)
        for num, j in zip(self.turns, (0, 3, 5), strict=False):
            if j < Q.shape[1]:
                ok &= np.floor((Q[:, j] + np.pi) / (2 * np.pi)) == int(num.value)
        return ok

    def edits(self, q_nominal: np.ndarray, q: np.ndarray) -> dict[tuple[int, int], str]:
        """Turns changed by the ±180° + k·360° boundaries the joints crossed."""
        out: dict[tuple[int, int], str] = {}
        for num, j in zip(self.turns, (0, 3, 5), strict=False):
            if j >= q.size:
                continue
            d = (math.floor((q[j] + math.pi) / (2 * math.pi))
                 - math.floor((q_nominal[j] + math.pi) / (2 * math.pi)))
            if d:
                out[(self.file, num.start)] = str(int(num.value) + d)
        return out


def _block_end(text: str, start: int) -> int:
    end = text.find("};", start)
    return len(text) if end < 0 else end


def _point(f: SourceFile, m: re.Match[str]) -> Target | None:
    """The target of one ``P[n]{ … };`` block (its GP1 part)."""
    text = f.text
    body_start = m.end()
    body_end = _block_end(text, body_start)
    groups = list(_GROUP.finditer(text, body_start, body_end))
    if not groups:
        raise f.error(body_start, f"P[{m[1]}]: no group (GP1:) in the point")
    g1 = next((g for g in groups if g[1] == "1"), None)
    if g1 is None:
        return None
    nxt = [g.start() for g in groups if g.start() > g1.start()]
    seg_end = nxt[0] if nxt else body_end
    fields, ufut, turns = _gp1_fields(f, m, g1.end(), seg_end)
    name = "P[" + m[1] + "]"
    if all(k in fields for k in CART):
        extra_keys = [k for k in fields if k not in CART and not k.startswith("E")]
        if extra_keys:
            raise f.error(g1.end(), f"{name}: joint and Cartesian values mixed")
        if "UF" not in ufut or "UT" not in ufut:
            raise f.error(g1.end(), f"{name}: a Cartesian point needs UF and UT")
        base = None if ufut["UF"] == "0" else f"UFRAME[{ufut['UF']}]"
        tool = f"UTOOL[{ufut['UT']}]"
        return Target(name, 0, m.start(1) - 2, "pose", [fields[k] for k in CART], "fanuc",
                      base=base, tool=tool, used=False,
                      config=FanucConfig(0, turns) if turns else None, extra=turns)
    joints = [k for k in fields if k.startswith("J")]
    if joints and not any(k in fields for k in CART):
        order = sorted(joints, key=lambda k: int(k[1:]))
        if order != [f"J{i}" for i in range(1, len(order) + 1)]:
            raise f.error(g1.end(), f"{name}: joint values must be J1…Jn")
        tool = f"UTOOL[{ufut['UT']}]" if "UT" in ufut else None
        return Target(name, 0, m.start(1) - 2, "joints", [fields[k] for k in order],
                      tool=tool, used=False)
    missing = [k for k in CART if k not in fields]
    raise f.error(g1.end(), f"{name}: a partial position (no {', '.join(missing)})")


def _gp1_fields(f: SourceFile, m: re.Match[str], pos: int,
                seg_end: int) -> tuple[dict[str, Num], dict[str, str], list[Num]]:
    """The fields of a point's GP1 part (text ``pos``–``seg_end`` of point ``m``).

    Returns
    -------
    fields : dict
        ``X … R`` (mm, deg) or ``J1 … Jn``, ``E1 …`` values by key, as numbers in the text.
    ufut : dict
        ``"UF"``/``"UT"`` → the frame and tool numbers given.
    turns : list of Num
        The ``CONFIG`` string's turn numbers (J1, J4, J6), if it is given.
    """
    text = f.text
    fields: dict[str, Num] = {}
    ufut: dict[str, str] = {}
    turns: list[Num] = []
    while True:
        while pos < seg_end and text[pos] in " \t\r\n":
            pos += 1
        if pos >= seg_end:
            break
        mm = _FIELD.match(text, pos)
        if mm is not None:
            key = mm["key"]
            if key in fields:
                raise f.error(pos, f"P[{m[1]}]: {key} given twice")
            unit = "mm" if key in ("X", "Y", "Z") else "deg"
            if key in CART and mm["unit"] != unit:
                raise f.error(mm.start("unit"), f"P[{m[1]}]: {key} in {mm['unit']}, "
                              f"expected {unit}")
            fields[key] = f.number(mm.start("num"), mm.end("num"), pad=len(mm["pad"]))
            pos = mm.end()
            continue
        mu = _UFUT.match(text, pos)
        if mu is not None:
            if not mu["val"].isdigit():
                raise f.error(mu.start("val"), f"P[{m[1]}]: {mu['key']} : {mu['val']} — only "
                              "a frame number is supported")
            ufut[mu["key"]] = mu["val"]
            pos = mu.end()
            continue
        mc = _CONFIG.match(text, pos)
        if mc is not None:
            turns.extend(_config_turns(f, mc, m[1]))
            pos = mc.end()
            continue
        raise f.error(pos, f"P[{m[1]}]: unknown text in the point: "
                      f"{text[pos:pos + 20].splitlines()[0]!r}")
    return fields, ufut, turns


def _config_turns(f: SourceFile, mc: re.Match[str], n: str) -> list[Num]:
    """The turn numbers of the ``CONFIG : 'N U T, 0, 0, 0'`` match ``mc`` in point ``P[n]``:
    the integers after the flip/up/top letters, each with its place in the text."""
    out: list[Num] = []
    a = mc.start("body")
    parts = mc["body"].split(",")
    off = a + len(parts[0]) + 1
    for part in parts[1:]:
        lead = len(part) - len(part.lstrip())
        tok = part.strip()
        if not re.fullmatch(r"[+-]?\d+", tok):
            raise f.error(off + lead, f"P[{n}]: CONFIG turn must be an integer, "
                          f"got {tok!r}")
        out.append(Num(off + lead, off + lead + len(tok), tok, float(tok)))
        off += len(part) + 1
    return out


def read_fanuc(path: str | Path) -> tuple[Program, list[str]]:
    """Read a Fanuc TP ASCII program (module docstring).

    Parameters
    ----------
    path : str or Path
        The ``.ls`` file.

    Returns
    -------
    program : Program
        Its points (frames and tools are the controller's: ``UFRAME[u]``, ``UTOOL[t]``).
    notes : list of str
        Motions left as they are.

    Raises
    ------
    ProgramError
        Unreadable file, or unknown syntax in a point (file:line:column).
    """
    f = SourceFile.read(Path(path))
    prog = Program("fanuc", [f], resolution=(1e-3, 1e-3, 1e-6))
    prog.frames["UFRAME[0]"] = np.eye(4)
    text = f.text
    pos_at = re.search(r"^/POS\b", text, re.M)
    mn_at = re.search(r"^/MN\b", text, re.M)
    if pos_at is None or mn_at is None:
        raise f.error(0, "not a TP program: no /MN or /POS section")
    points: dict[str, Target] = {}
    for m in _POINT.finditer(text, pos_at.end()):
        t = _point(f, m)
        if t is not None:
            if t.name in points:
                raise f.error(m.start(), f"{t.name} declared twice")
            points[t.name] = t
            prog.targets.append(t)
    notes: list[str] = []
    for m in _MOTION.finditer(text, mn_at.end(), pos_at.start()):
        where = prog.where(0, m.start("reg"))
        if m["reg"] == "PR":
            notes.append(f"{where}: PR[{m['n']}] is a position register of the controller: "
                         "left as it is")
            continue
        t = points.get(f"P[{m['n']}]")
        if t is None:
            raise f.error(m.start("reg"), f"P[{m['n']}] is not in /POS")
        if re.search(r"\b(Offset|Tool_Offset)\b", m["rest"]):
            notes.append(f"{where}: P[{m['n']}] with an offset: the point is compensated, "
                         "the offset is not")
        t.used = True
        t.uses.append((0, m.start("reg")))
    return prog, notes
