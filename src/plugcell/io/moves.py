"""The moves file: a robot's moves one a line, in robot units, for ``plugcell motion plan``.

::

    # pick and place (mm, degrees; the pose angles in the robot's convention, Comau ZYZ)
    PTP  10, -80, 20, 30, 60, -20
    LIN  1750, 300, 1400, 0, 90, 0         blend=50
    CIRC 1800, 350, 1450; 1850, 300, 1500, 0, 90, 0   speed=0.5
    PTP  10, -80, 20, 30, 60, -20          blend=5 acc=0.8

* ``PTP j1, …, jn`` — joint readings, degrees (a prismatic joint: mm);
* ``LIN x, y, z, a, b, c`` — TCP pose in the robot base frame, mm and degrees in the
  robot's angle convention (:mod:`plugcell.io.units`);
* ``CIRC x, y, z; x, y, z, a, b, c`` — via point (mm), then the end pose;
* options: ``blend=R`` — blend radius, degrees for a PTP (joint space), mm for LIN and
  CIRC; ``speed=F`` and ``acc=F`` — overrides in (0, 1] of the limits.

Keywords are case-insensitive; ``#`` starts a comment; blank lines are passed over.
Each move carries its **line number**, which the planner's errors name (the program
line).  Everything is converted to SI here (:mod:`plugcell.io.units`); a malformed line
raises :class:`MovesFileError` naming the file, the line and what is wrong.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from plugcell.io.text_files import read_text
from plugcell.io.units import UnitsError, joints_to_si, pose_from_robot
from plugcell.kinematics.description import RobotDescription
from plugcell.motion.moves import CIRC, LIN, PTP, Move

__all__ = ["MovesFileError", "parse_moves", "read_moves"]

_LINE = re.compile(r"^\s*([A-Za-z]+)\b(.*)$")
_OPTION = re.compile(r"\s+([A-Za-z_]+)\s*=\s*(\S+)\s*$")
_OPTIONS = {"blend": "blend", "speed": "speed", "acc": "acceleration"}


class MovesFileError(ValueError):
    """A moves file that cannot be read; the message is ``NAME:LINE: reason``."""


def _numbers(text: str, where: str) -> np.ndarray:
    cells = [c.strip() for c in text.split(",")]
    if cells == [""]:
        raise MovesFileError(f"{where}: no values")
    try:
        vals = np.array([float(c) for c in cells])
    except ValueError:
        bad = next(c for c in cells if not _is_float(c))
        raise MovesFileError(f"{where}: {bad!r} is not a number") from None
    if not np.all(np.isfinite(vals)):
        raise MovesFileError(f"{where}: values must be finite")
    return vals


def _is_float(c: str) -> bool:
    try:
        float(c)
    except ValueError:
        return False
    return True


def _pose(text: str, where: str) -> np.ndarray:
    vals = _numbers(text, where)
    if vals.size != 6:
        raise MovesFileError(f"{where}: expected a pose of 6 numbers (x, y, z mm, a, b, c "
                             f"degrees), got {vals.size}")
    try:
        return pose_from_robot(vals)
    except UnitsError as exc:
        raise MovesFileError(f"{where}: {exc}") from None


def _split_options(rest: str, where: str) -> tuple[str, dict[str, float]]:
    opts: dict[str, float] = {}
    while True:
        m = _OPTION.search(rest)
        if not m:
            break
        key = m.group(1).lower()
        if key not in _OPTIONS:
            raise MovesFileError(f"{where}: unknown option {m.group(1)!r} (blend, speed, acc)")
        try:
            value = float(m.group(2))
        except ValueError:
            raise MovesFileError(f"{where}: {m.group(1)}={m.group(2)!r} is not a number") from None
        if not math.isfinite(value):
            raise MovesFileError(f"{where}: {m.group(1)} must be finite")
        if key == "blend" and value < 0.0:
            raise MovesFileError(f"{where}: blend must be a radius ≥ 0, got {m.group(2)}")
        opts[_OPTIONS[key]] = value
        rest = rest[:m.start()]
    if "=" in rest:
        raise MovesFileError(f"{where}: options (blend=…, speed=…, acc=…) come after the values")
    return rest, opts


def parse_moves(text: str, name: str, desc: RobotDescription) -> list[Move]:
    """The moves of a moves file's text (module docstring), in SI units.

    Parameters
    ----------
    text : str
        The file's text.
    name : str
        The file's name, first word of every error message.
    desc : RobotDescription
        The robot (number of joints, which are prismatic).

    Returns
    -------
    list of PTP, LIN, CIRC
        Each with ``line`` = its line number (1-based).

    Raises
    ------
    MovesFileError
        ``"NAME:LINE: reason"`` for the first malformed line; ``"NAME: no moves"``.
    """
    moves: list[Move] = []
    scale = desc.reading_scale()
    n = desc.n_readings
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.split("#", 1)[0].rstrip()
        if not line.strip():
            continue
        where = f"{name}:{number}"
        m = _LINE.match(line)
        if not m:
            raise MovesFileError(f"{where}: expected PTP, LIN or CIRC, got {line.strip()!r}")
        kind = m.group(1).upper()
        rest, opts = _split_options(" " + m.group(2).strip(), where)
        try:
            if kind == "PTP":
                q = _numbers(rest, where)
                if q.size != n:
                    raise MovesFileError(
                        f"{where}: PTP needs {n} joint values for {desc.name} "
                        f"({', '.join(desc.reading_names)}), got {q.size}")
                moves.append(PTP(target=joints_to_si(q, scale), line=number,
                                 **_scaled(opts, math.pi / 180.0)))
            elif kind == "LIN":
                moves.append(LIN(target=_pose(rest, where), line=number,
                                 **_scaled(opts, 1e-3)))
            elif kind == "CIRC":
                parts = rest.split(";")
                if len(parts) != 2:
                    raise MovesFileError(f"{where}: CIRC needs a via point and an end pose "
                                         "separated by ';' (x, y, z; x, y, z, a, b, c)")
                via = _numbers(parts[0], where)
                if via.size != 3:
                    raise MovesFileError(f"{where}: the via point needs 3 numbers (x, y, z "
                                         f"mm), got {via.size}")
                moves.append(CIRC(via=via * 1e-3, target=_pose(parts[1], where), line=number,
                                  **_scaled(opts, 1e-3)))
            else:
                raise MovesFileError(f"{where}: unknown move {m.group(1)!r} (PTP, LIN, CIRC)")
        except MovesFileError:
            raise
        except ValueError as exc:  # the move's own checks (a fraction, a radius)
            raise MovesFileError(f"{where}: {exc}") from None
    if not moves:
        raise MovesFileError(f"{name}: no moves")
    return moves


def _scaled(opts: dict[str, float], blend_unit: float) -> dict[str, float]:
    """The options with the blend radius in SI (``blend_unit``: SI per file unit)."""
    out = dict(opts)
    if "blend" in out:
        out["blend"] *= blend_unit
    return out


def read_moves(path: str | Path, desc: RobotDescription) -> list[Move]:
    """:func:`parse_moves` of a file.

    Parameters
    ----------
    path : str or Path
    desc : RobotDescription

    Returns
    -------
    list of PTP, LIN, CIRC

    Raises
    ------
    MovesFileError
        A malformed line, or a file that cannot be read.
    """
    return parse_moves(read_text(path, MovesFileError), str(Path(path)), desc)
