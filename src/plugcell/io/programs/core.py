"""The dialect-independent model of a robot program: its bytes and its targets' numbers.

A program is its files' original bytes plus, per Cartesian (or joint) target, where each
of its numbers lies in those bytes and how it is written.  Writing a program back
replaces only those numbers' bytes: comments, folds, indentation, line endings and
every other byte stay as they were.  Files are decoded as Latin-1, so a character
offset *is* a byte offset and any encoding (UTF-8, Windows-1252 of a controller)
comes back byte for byte.

A number is rewritten in the style it was written in — sign (an explicit ``+``),
digits after the point, exponent (``E+03``), leading zeros, a field padded with
spaces (:class:`NumberStyle`) — with more digits after the point only when its own
would lose the correction (:data:`RESOLUTION` of the dialect).  A number whose new
value is within half that resolution of the old is left byte for byte as it was.
"""

from __future__ import annotations

import bisect
import math
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = [
    "FrameRef",
    "Num",
    "NumberStyle",
    "Program",
    "ProgramError",
    "SourceFile",
    "Target",
]

_NUMBER = re.compile(
    r"(?P<sign>[+-]?)(?P<int>\d*)(?:(?P<dot>\.)(?P<frac>\d*))?"
    r"(?:(?P<e>[eE])(?P<esign>[+-]?)(?P<exp>\d+))?\Z")


class ProgramError(ValueError):
    """A program that cannot be read or compensated; the message names file:line:column.

    Attributes
    ----------
    path : str
        The file.
    line, column : int
        1-based position of the offending text (0 when the whole file is meant).
    """

    def __init__(self, path: str, line: int, column: int, message: str) -> None:
        self.path, self.line, self.column = path, line, column
        where = f"{path}:{line}:{column}" if line else path
        super().__init__(f"{where}: {message}")


@dataclass(frozen=True)
class NumberStyle:
    """How a number is written: ``[sign]int[.frac][e[sign]exp]`` (module docstring).

    Attributes
    ----------
    plus : bool
        A ``+`` before positive numbers.
    int_digits : int
        Minimum digits before the point (leading zeros, ``007.5``: 3); 0 for ``.5``.
    dot : bool
        A decimal point is written.
    frac : int
        Digits after the point.
    exp : str
        ``""`` (no exponent), ``"e"`` or ``"E"``.
    exp_plus : bool
        ``E+03`` rather than ``E03``.
    exp_digits : int
        Minimum exponent digits.
    """

    plus: bool = False
    int_digits: int = 1
    dot: bool = True
    frac: int = 3
    exp: str = ""
    exp_plus: bool = False
    exp_digits: int = 1

    @classmethod
    def of(cls, text: str) -> NumberStyle:
        """The style of a number as written (``text`` must match the number syntax).

        Raises
        ------
        ValueError
            ``text`` is no decimal number.
        """
        m = _NUMBER.match(text)
        if m is None or not (m["int"] or m["frac"]):
            raise ValueError(f"not a number: {text!r}")
        ints = m["int"]
        int_digits = len(ints) if ints.startswith("0") and len(ints) > 1 else min(len(ints), 1)
        return cls(plus=m["sign"] == "+", int_digits=int_digits, dot=bool(m["dot"]),
                   frac=len(m["frac"] or ""), exp=m["e"] or "", exp_plus=m["esign"] == "+",
                   exp_digits=len(m["exp"] or "") or 1)

    def format(self, value: float, min_frac: int = 0) -> str:
        """``value`` written in this style, with at least ``min_frac`` digits after the point.

        Parameters
        ----------
        value : float
            A finite number.
        min_frac : int
            Fewer digits than this after the point are not written (the resolution).

        Returns
        -------
        str
        """
        frac = max(self.frac, min_frac)
        if self.exp:
            mant, _, ex = f"{abs(value):.{frac}e}".partition("e")
            e = int(ex)
            mant_txt = mant if (self.dot or frac) else mant.split(".")[0]
            es = ("-" if e < 0 else "+" if self.exp_plus else "") + str(abs(e)).zfill(
                self.exp_digits)
            body = f"{mant_txt}{self.exp}{es}"
            zero = float(mant) == 0.0
        else:
            body = f"{abs(value):.{frac}f}"
            zero = float(body) == 0.0
            ip, _, fp = body.partition(".")
            bare = self.int_digits == 0 and ip == "0" and fp
            ip = "" if bare else ip.zfill(self.int_digits)
            body = ip + ("." + fp if fp else ("." if self.dot else ""))
        sign = "-" if value < 0 and not zero else ("+" if self.plus else "")
        return sign + body


@dataclass
class Num:
    """One number of a target in its file: where, as written, and its value.

    Attributes
    ----------
    start, end : int
        Offsets of its text in the file (``text = file.text[start:end]``).
    text : str
        As written.
    value : float
        Its value.
    pad : int
        Spaces before it that belong to a fixed-width field (Fanuc ``X =  1234.5``): a
        longer new number takes them, a shorter one leaves more.
    virtual : bool
        Not written in the file: a modal value a G-code line inherits (its ``value``);
        never rewritten in place (the dialect inserts a word when it must change).
    """

    start: int
    end: int
    text: str
    value: float
    pad: int = 0
    virtual: bool = False


@dataclass
class SourceFile:
    """A program file: its path and its bytes, decoded 1:1 (Latin-1).

    Attributes
    ----------
    path : Path
        Where it was read from.
    text : str
        ``bytes.decode("latin-1")``: offset = byte offset.
    """

    path: Path
    text: str
    _lines: list[int] = field(default_factory=list, repr=False)

    @classmethod
    def read(cls, path: Path) -> SourceFile:
        """Read ``path`` (any encoding, any line endings).

        Raises
        ------
        ProgramError
            The file cannot be read.
        """
        try:
            data = Path(path).read_bytes()
        except OSError as exc:
            raise ProgramError(str(path), 0, 0, f"cannot read: {exc.strerror or exc}") from None
        return cls(Path(path), data.decode("latin-1"))

    def position(self, offset: int) -> tuple[int, int]:
        """1-based ``(line, column)`` of an offset (``\\n`` ends a line; ``\\r\\n`` too)."""
        if not self._lines:
            self._lines = [0] + [m.end() for m in re.finditer("\n", self.text)]
        k = bisect.bisect_right(self._lines, offset) - 1
        return k + 1, offset - self._lines[k] + 1

    def error(self, offset: int, message: str) -> ProgramError:
        """A :class:`ProgramError` at ``offset`` of this file."""
        line, col = self.position(offset)
        return ProgramError(str(self.path), line, col, message)

    def number(self, start: int, end: int, pad: int = 0) -> Num:
        """The :class:`Num` of ``text[start:end]``.

        Raises
        ------
        ProgramError
            The text is no finite decimal number.
        """
        t = self.text[start:end]
        m = _NUMBER.match(t)
        if m is None or not (m["int"] or m["frac"]):
            raise self.error(start, f"expected a number, got {t!r}")
        v = float(t)
        if not math.isfinite(v):
            raise self.error(start, f"not a finite number: {t!r}")
        return Num(start, end, t, v, pad)


@dataclass(frozen=True)
class FrameRef:
    """A frame or tool a target refers to, by the name the program uses.

    Attributes
    ----------
    name : str
        As the program says it (``BASE_DATA[2]``, ``wobj1``, ``UF 3``, ``tcp``).
    """

    name: str


@dataclass
class Target:
    """A target of a program (module docstring).

    Attributes
    ----------
    name : str
        Its name in the program (``XP1``, ``p10``) or where it stands (``line 12``).
    file : int
        Index of its file in :attr:`Program.files`.
    offset : int
        Where it starts in its file.
    kind : {"pose", "joints"}
        A Cartesian pose or joint positions.
    nums : list of Num
        Pose: the notation's numbers (x, y, z then the orientation); joints: one a joint.
    notation : str
        The pose notation (:data:`plugcell.io.units.NOTATIONS`).
    base : str or None
        The frame the pose is given in (``None``: the robot base frame).
    tool : str or None
        The tool (``None``: not known — the program must say or the command line).
    config : object or None
        The dialect's configuration numbers (status/turn, confdata) with its own update.
    uses : list of (int, int)
        ``(file, offset)`` of every motion using the target.
    used : bool
        A motion uses it (a declared point no motion uses has no known frame: it is left
        as it is).
    extra : list of Num
        Other numbers the dialect may rewrite (status and turn, confdata), in this file.
    unit : float or None
        Joints: SI per written unit (URScript: 1, radians); ``None``: the robot
        description's file units (degrees, mm).
    """

    name: str
    file: int
    offset: int
    kind: str
    nums: list[Num]
    notation: str = ""
    base: str | None = None
    tool: str | None = None
    config: object | None = None
    uses: list[tuple[int, int]] = field(default_factory=list)
    used: bool = True
    extra: list[Num] = field(default_factory=list)
    unit: float | None = None

    @property
    def values(self) -> np.ndarray:
        """The numbers' values as written, ``(k,)``."""
        return np.array([n.value for n in self.nums])

    def use(self, base: str | None, tool: str | None, source: SourceFile, file: int,
            offset: int, named: Callable[[str | None, str | None], str], *,
            frames_matter: bool = True) -> None:
        """A motion at ``offset`` of ``source`` (the program's file ``file``) uses the
        target with the frame ``base`` and the tool ``tool``: recorded.

        Parameters
        ----------
        base, tool : str or None
            The frame and tool the motion uses.
        source : SourceFile
            The file the motion stands in.
        file : int
            Its index in :attr:`Program.files`.
        offset : int
            Where the motion stands in it.
        named : callable
            ``named(base, tool)``: the pair the dialect's way, for the error.
        frames_matter : bool
            Refuse a second frame or tool (``False``: the last one is kept).

        Raises
        ------
        ProgramError
            An earlier motion used it with another frame or tool: one set of numbers
            cannot be compensated for both.
        """
        if frames_matter and self.uses and (self.base, self.tool) != (base, tool):
            raise source.error(offset, f"{self.name} is used with {named(base, tool)} here, "
                               f"with {named(self.base, self.tool)} before: one set of "
                               "numbers cannot be compensated for both")
        self.base, self.tool, self.used = base, tool, True
        self.uses.append((file, offset))


@dataclass(slots=True)
class Token:
    """A token of a program's text, as the dialects' readers cut it.

    Attributes
    ----------
    kind : str
        The reader's class of it (``num``, ``name``, ``str``, ``op`` …).
    text : str
        Its text.
    start, end : int
        Where it stands in its file (``text == file.text[start:end]``).
    """

    kind: str
    text: str
    start: int
    end: int


@dataclass
class Program:
    """A program: files, targets and the frames it defines (module docstring).

    Attributes
    ----------
    dialect : str
        ``krl``, ``urscript``, ``rapid``, …
    files : list of SourceFile
        Its files (KRL: the ``.src`` and its ``.dat``).
    targets : list of Target
        In the order they appear (declarations first for KRL's ``.dat``).
    frames : dict of str to (4, 4) ndarray
        Frames (bases, work objects, user frames) defined by the program, m.
    tools : dict of str to (4, 4) ndarray
        Tools (flange → TCP) defined by the program, m.
    composites : dict of str to list of (str, bool)
        Frames that are products of others, ``name → [(part, inverted), …]`` (PDL2's
        ``$BASE⁻¹ · $UFRAME``): resolved when every part is known.
    post : callable or None
        ``post(program, reports, edits)``: the dialect's last pass over the edits
        (G-code: modal words inserted where a line inherits a value that must change).
    resolution : tuple of float
        Smallest change written (length unit, angle unit, quaternion component) in the
        notation's units: below half of it a number is left as it was.
    """

    dialect: str
    files: list[SourceFile]
    targets: list[Target] = field(default_factory=list)
    frames: dict[str, np.ndarray] = field(default_factory=dict)
    tools: dict[str, np.ndarray] = field(default_factory=dict)
    resolution: tuple[float, float, float] = (1e-3, 1e-3, 1e-6)
    composites: dict[str, list[tuple[str, bool]]] = field(default_factory=dict)
    post: object | None = None

    def where(self, file: int, offset: int) -> str:
        """``path:line:column`` of an offset."""
        f = self.files[file]
        line, col = f.position(offset)
        return f"{f.path}:{line}:{col}"

    def line(self, t: Target) -> int:
        """The 1-based line of a target."""
        return self.files[t.file].position(t.offset)[0]

    def render(self, edits: dict[tuple[int, int], str]) -> list[str]:
        """The files' texts with the numbers at ``(file, start)`` replaced.

        Parameters
        ----------
        edits : dict of (int, int) to str
            ``(file index, Num.start)`` → new text (a :class:`Num` of this program).

        Returns
        -------
        list of str
            One text per file (encode with Latin-1 to get the bytes).
        """
        nums = {(t.file, n.start): n for t in self.targets for n in (*t.nums, *t.extra)
                if not n.virtual}
        out = []
        for i, f in enumerate(self.files):
            mine = sorted((s, txt) for (fi, s), txt in edits.items() if fi == i)
            parts, pos = [], 0
            for s, txt in mine:
                n = nums[(i, s)]
                a, b = n.start - n.pad, n.end
                if n.pad:
                    width = n.pad + len(n.text)
                    txt = txt.rjust(width) if len(txt) < width else " " + txt
                parts.append(f.text[pos:a])
                parts.append(txt)
                pos = b
            parts.append(f.text[pos:])
            out.append("".join(parts))
        return out


def min_frac(resolution: float) -> int:
    """Digits after the point that write ``resolution`` (1e-3 → 3)."""
    return max(0, math.ceil(-math.log10(resolution) - 1e-9))


def new_text(num: Num, value: float, resolution: float) -> str | None:
    """The text to write for ``num`` now worth ``value``; ``None`` to leave it as it is.

    Left as it is when ``|value − num.value| < resolution / 2``; otherwise written in
    its style (:class:`NumberStyle`) with at least the digits of ``resolution``.
    """
    if abs(value - num.value) < resolution / 2:
        return None
    t = num.text
    dot = t.find(".")
    ip = t[:dot].lstrip("-") if dot > 0 else ""
    if ip and t[0] != "+" and "e" not in t and "E" not in t and (ip == "0" or ip[0] != "0"):
        # the common style, -12.345: fixed point, no sign for positives, no leading zeros
        txt = f"{value:.{max(len(t) - dot - 1, min_frac(resolution))}f}"
        if float(txt) == 0.0:
            txt = txt.lstrip("-")
        return None if txt == t else txt
    txt = NumberStyle.of(t).format(value, min_frac(resolution))
    return None if txt == num.text else txt
