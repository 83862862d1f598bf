"""Robot programs as they are: read their targets, write them back with new numbers.

``read_program(path)`` picks the dialect from the file's suffix (or ``dialect=``) and
returns a :class:`~plugcell.io.programs.core.Program` — the files' bytes and every
target's numbers with their positions and styles — and the reader's notes.
:func:`~plugcell.io.programs.filter.filter_targets` compensates the targets and
:meth:`Program.render` writes the program back, only those numbers changed.
See docs/robot-program-compensation.md.

==========  =====================================  ===========================================
dialect     files                                  module
==========  =====================================  ===========================================
``krl``     KUKA ``.src`` (+ its ``.dat``)           :mod:`plugcell.io.programs.krl`
``urscript`` Universal Robots ``.script``           :mod:`plugcell.io.programs.urscript`
``rapid``   ABB ``.mod``, ``.prg``, ``.modx``        :mod:`plugcell.io.programs.rapid`
``fanuc``   Fanuc TP ASCII ``.ls``                  :mod:`plugcell.io.programs.fanuc`
``pdl2``    Comau PDL2 ``.pdl``                     :mod:`plugcell.io.programs.pdl2`
``gcode``   G-code ``.nc``, ``.ngc``, ``.gcode``, …   :mod:`plugcell.io.programs.gcode`
==========  =====================================  ===========================================
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from plugcell.io.programs.core import Program, ProgramError

__all__ = ["DIALECTS", "NOTATION", "Program", "ProgramError", "read_program"]


def _krl(path: Path) -> tuple[Program, list[str]]:
    from plugcell.io.programs.krl import read_krl

    return read_krl(path)


def _urscript(path: Path) -> tuple[Program, list[str]]:
    from plugcell.io.programs.urscript import read_urscript

    return read_urscript(path)


def _fanuc(path: Path) -> tuple[Program, list[str]]:
    from plugcell.io.programs.fanuc import read_fanuc

    return read_fanuc(path)


def _pdl2(path: Path) -> tuple[Program, list[str]]:
    from plugcell.io.programs.pdl2 import read_pdl2

    return read_pdl2(path)


def _gcode(path: Path, notation: str = "kuka") -> tuple[Program, list[str]]:
    from plugcell.io.programs.gcode import read_gcode

    return read_gcode(path, notation)


def _rapid(path: Path) -> tuple[Program, list[str]]:
    from plugcell.io.programs.rapid import read_rapid

    return read_rapid(path)


#: dialect → reader
DIALECTS: dict[str, Callable[[Path], tuple[Program, list[str]]]] = {
    "krl": _krl, "urscript": _urscript, "rapid": _rapid, "fanuc": _fanuc,
    "pdl2": _pdl2, "gcode": _gcode,
}
#: dialect → the pose notation of its frames given on the command line
NOTATION = {"krl": "kuka", "urscript": "ur", "rapid": "abb", "fanuc": "fanuc",
            "pdl2": "comau", "gcode": "kuka"}
_SUFFIX = {".src": "krl", ".dat": "krl", ".script": "urscript", ".urscript": "urscript",
           ".mod": "rapid", ".prg": "rapid", ".modx": "rapid", ".sys": "rapid", ".ls": "fanuc",
           ".pdl": "pdl2", ".nc": "gcode", ".ngc": "gcode", ".gcode": "gcode",
           ".tap": "gcode", ".cnc": "gcode"}


def dialect_of(path: Path, dialect: str | None = None) -> str:
    """The dialect of a program file: ``dialect`` if given, else by its suffix.

    Raises
    ------
    ProgramError
        Unknown suffix (and no dialect given) or unknown dialect.
    """
    if dialect is not None:
        if dialect not in DIALECTS:
            raise ProgramError(str(path), 0, 0, f"unknown dialect {dialect!r}; expected one "
                               f"of {sorted(DIALECTS)}")
        return dialect
    d = _SUFFIX.get(Path(path).suffix.lower())
    if d is None:
        raise ProgramError(str(path), 0, 0, f"cannot tell the dialect from the suffix "
                           f"{Path(path).suffix!r} (known: {', '.join(sorted(_SUFFIX))}); "
                           "give --dialect")
    return d


def read_program(path: str | Path, dialect: str | None = None, *, angles: str = "kuka"
                 ) -> tuple[Program, list[str]]:
    """Read a robot program (module docstring).

    Parameters
    ----------
    path : str or Path
        The program file (KRL: the ``.src``; its ``.dat`` is read too).
    dialect : str, optional
        A key of :data:`DIALECTS`; default from the suffix.
    angles : str
        G-code only: the notation of its ``A, B, C`` (``kuka``, ``fanuc``, ``comau``).

    Returns
    -------
    program : Program
        Files, targets, frames and tools.
    notes : list of str
        What the reader left as it is, and why.

    Raises
    ------
    ProgramError
        Unreadable file, unknown dialect, or syntax the reader does not know inside a
        target, a motion or a frame (file:line:column).
    """
    p = Path(path)
    d = dialect_of(p, dialect)
    if d == "gcode":
        return _gcode(p, angles)
    return DIALECTS[d](p)
