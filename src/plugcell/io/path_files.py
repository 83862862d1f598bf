"""The path file of ``plugcell path run``: a TCP path as CSV rows, robot units, SI inside.

::

    # a 1 m line at 100 mm/s, its last 200 mm without the tracker
    x,y,z,a,b,c,speed,tracking
    1473.3,-231.7,2488.4,-60,30,-90,,
    1473.3,568.3,2488.4,-60,30,-90,100,1
    1473.3,768.3,2488.4,-60,30,-90,100,0

* A header line names the columns, in any order, case-insensitive: ``x, y, z`` (mm, the
  TCP's position in the robot base frame) are required; ``a, b, c`` (degrees, the pose's
  angles in the robot's convention, :mod:`plugcell.io.units`: Comau Z-Y-Z by default)
  come all three or not at all — without them the TCP keeps the orientation it has at
  the first point; ``speed`` (mm/s, > 0) is the TCP's speed along the segment that ends
  at this row (blank: the previous row's, on the first segment the default given to
  :func:`parse_path`); ``tracking`` (``1``/``0``, blank 1) says whether the tracker
  corrects that segment.  The first row is where the path starts: its ``speed`` and
  ``tracking`` are not used.
* Blank lines and lines starting with ``#`` are passed over (:mod:`plugcell.io.csvtable`).
* Consecutive rows must be at least 0.01 mm (or 0.01°) apart: a segment of length zero
  has no direction.

Every error is a :class:`PathFileError` whose message names the file, the line and
the column: ``path.csv: line 4, column 'speed': speed must be > 0 mm/s, got -5``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from plugcell.io.csvtable import table_number, table_rows
from plugcell.io.text_files import read_text
from plugcell.io.units import M_PER_MM, ROBOT_CONVENTION, UnitsError, pose_from_robot

Array = NDArray[np.float64]

__all__ = ["PATH_COLUMNS", "PathFile", "PathFileError", "parse_path", "read_path"]

#: The columns a path file may have (the first three are required).
PATH_COLUMNS = ("x", "y", "z", "a", "b", "c", "speed", "tracking")
#: Shortest segment (m) and smallest turn (rad) that count as a motion.
MIN_SEGMENT_M = 1e-5
MIN_TURN_RAD = np.radians(0.01)


class PathFileError(ValueError):
    """A path file that cannot be read; the message names the file, line and column."""


@dataclass(frozen=True)
class PathFile:
    """A path: its points and, per segment, the speed and whether the tracker corrects it.

    Attributes
    ----------
    poses : (N, 4, 4) array, m
        The TCP's poses in the robot base frame, ``N ≥ 2``; without angle columns the
        rotation of every pose is the identity and ``oriented`` is False.
    speeds : (N - 1,) array, m/s
        Segment ``i`` runs from ``poses[i]`` to ``poses[i + 1]`` at ``speeds[i]``.
    tracking : (N - 1,) bool array
        Whether the tracker corrects segment ``i``.
    lines : (N,) int array
        The file's line of each point (segment ``i`` is named by ``lines[i + 1]``).
    oriented : bool
        The file gives the orientation (``a, b, c``).
    """

    poses: Array
    speeds: Array
    tracking: NDArray[np.bool_]
    lines: NDArray[np.int64]
    oriented: bool

    @property
    def n_segments(self) -> int:
        return len(self.speeds)

    def lengths(self) -> Array:
        """Each segment's length (m), shape ``(N - 1,)``."""
        return np.linalg.norm(np.diff(self.poses[:, :3, 3], axis=0), axis=1)


def _columns(header: list[str], name: str, line: int) -> dict[str, int]:
    cols: dict[str, int] = {}
    for i, cell in enumerate(header):
        key = cell.strip().lower()
        if key not in PATH_COLUMNS:
            raise PathFileError(f"{name}: line {line}: unknown column {cell.strip()!r} "
                                f"(known: {', '.join(PATH_COLUMNS)})")
        if key in cols:
            raise PathFileError(f"{name}: line {line}: column {key!r} given twice")
        cols[key] = i
    missing = [c for c in ("x", "y", "z") if c not in cols]
    if missing:
        raise PathFileError(f"{name}: line {line}: missing column(s) {', '.join(missing)} "
                            "(x, y, z in mm are required)")
    angles = [c for c in ("a", "b", "c") if c in cols]
    if angles and len(angles) != 3:
        raise PathFileError(f"{name}: line {line}: columns a, b, c come together (got "
                            f"{', '.join(angles)})")
    return cols


def _flag(cell: str, name: str, line: int) -> bool | None:
    text = cell.strip()
    if not text:
        return None
    if text in ("1", "0"):
        return text == "1"
    raise PathFileError(f"{name}: line {line}, column 'tracking': expected 1 or 0, "
                        f"got {text!r}")


def parse_path(text: str, name: str = "path", *, speed_mm_s: float = 100.0,
               convention: str = ROBOT_CONVENTION) -> PathFile:
    """Read a path file's text (module docstring) into SI.

    Parameters
    ----------
    text : str
        The file's content.
    name : str
        The file's name, first word of every error message.
    speed_mm_s : float
        The first segment's speed when the file gives none (mm/s).
    convention : str
        The angle convention of ``a, b, c`` (``"zyz"``, ``"rpy"``, ``"prj"``).

    Returns
    -------
    PathFile

    Raises
    ------
    PathFileError
        Naming the file, the line and the column of the first problem.
    """
    rows = table_rows(text, name, PathFileError)
    (header_line, header), data = rows[0], rows[1:]
    cols = _columns(header, name, header_line)
    oriented = "a" in cols
    if len(data) < 2:
        raise PathFileError(f"{name}: a path needs at least 2 points, the file has "
                            f"{len(data)}")
    poses, speeds, tracking, lines = [], [], [], []
    speed = speed_mm_s
    for line, cells in data:
        if len(cells) != len(header):
            raise PathFileError(f"{name}: line {line}: {len(cells)} cells, the header has "
                                f"{len(header)}")

        def number(col: str, line: int = line, cells: list[str] = cells) -> float:
            return table_number(cells[cols[col]], name, line, col, PathFileError)

        values = [number(c) for c in ("x", "y", "z")]
        values += [number(c) for c in ("a", "b", "c")] if oriented else [0.0, 0.0, 0.0]
        try:
            T = pose_from_robot(values, convention if oriented else "rpy")
        except UnitsError as exc:
            raise PathFileError(f"{name}: line {line}: {exc}") from None
        if "speed" in cols and cells[cols["speed"]].strip():
            speed = number("speed")
            if speed <= 0:
                raise PathFileError(f"{name}: line {line}, column 'speed': speed must be "
                                    f"> 0 mm/s, got {speed:g}")
        flag = _flag(cells[cols["tracking"]], name, line) if "tracking" in cols else None
        if poses:
            _check_segment(poses[-1], T, name, line)
            speeds.append(speed * M_PER_MM)
            tracking.append(True if flag is None else flag)
        poses.append(T)
        lines.append(line)
    return PathFile(np.array(poses), np.array(speeds), np.array(tracking, dtype=bool),
                    np.array(lines, dtype=np.int64), oriented)


def _check_segment(T0: Array, T1: Array, name: str, line: int) -> None:
    move = float(np.linalg.norm(T1[:3, 3] - T0[:3, 3]))
    cos = (np.trace(T0[:3, :3].T @ T1[:3, :3]) - 1.0) / 2.0
    turn = float(np.arccos(np.clip(cos, -1.0, 1.0)))
    if move < MIN_SEGMENT_M and turn < MIN_TURN_RAD:
        raise PathFileError(f"{name}: line {line}: the same point as the row before "
                            "(a segment needs 0.01 mm or 0.01° of motion)")


def read_path(path: str | Path, **kwargs: object) -> PathFile:
    """:func:`parse_path` of a file (its name in the messages).

    Parameters
    ----------
    path : str or Path
        The file.
    **kwargs
        ``speed_mm_s``, ``convention`` (:func:`parse_path`).

    Returns
    -------
    PathFile

    Raises
    ------
    PathFileError
        The file cannot be read, or is malformed (file, line and column named).
    """
    name = Path(path).name
    return parse_path(read_text(path, PathFileError, name), name, **kwargs)  # type: ignore[arg-type]
