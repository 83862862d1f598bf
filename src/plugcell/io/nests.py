"""Reference-nest files of the drift watch: one nest a row, positions in mm.

Format::

    # comment lines start with '#'
    name,x,y,z
    N1,1520.31,-840.07,12.55

``name``: a unique label (CSV-quoted when it holds a comma or a quote); ``x, y, z``:
the nest's position in mm — measured by the tracker (tracker frame) for
:func:`read_nests`, or in the robot base frame in a registration file written by
``plugcell drift register``.  At least 3 nests (the drift watch's 6-DOF fit also needs
them off one line: that is checked by the fit, not here).  Errors name the file, the
line and the column.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

from plugcell.io.csvtable import table_number, table_rows
from plugcell.io.text_files import read_text
from plugcell.io.units import MM_PER_M

__all__ = ["NestFileError", "format_nests", "parse_nests", "read_nests"]

HEADER = ("name", "x", "y", "z")


class NestFileError(ValueError):
    """A nest file that cannot be read (the message names file, line and column)."""



def parse_nests(text: str, name: str = "<nests>") -> tuple[list[str], np.ndarray]:
    """The nests of a nest file's text: names, and positions converted mm → m.

    Parameters
    ----------
    text : str
        The file's text: the header ``name,x,y,z`` then one nest a row, ``x, y, z`` in
        mm (module docstring); ``#`` comment lines and blank lines are passed over.
    name : str
        The file's name, for error messages.

    Returns
    -------
    names : list of str, length K
        The nests' labels, in file order (stripped, unique).
    positions : (K, 3) ndarray, m
        The nests' positions, in the frame the file was written in (tracker frame for a
        measured nest file, robot base frame for a registration file); the mm → m
        conversion happens here.

    Raises
    ------
    NestFileError
        Wrong header, a row without exactly 4 values, an empty or repeated name, a cell
        that is not a finite number, or fewer than 3 nests (the drift watch's minimum;
        collinear nests are refused by the drift fit,
        :func:`plugcell.metrology.drift.estimate_base_drift`, not here).
    """
    rows = table_rows(text, name, NestFileError)
    line_no, header = rows[0]
    if tuple(h.strip() for h in header) != HEADER:
        raise NestFileError(f"{name}: line {line_no}: header must be 'name,x,y,z', got "
                            f"{','.join(h.strip() for h in header)!r}")
    names: list[str] = []
    pos = []
    for line_no, row in rows[1:]:
        if len(row) != 4:
            raise NestFileError(f"{name}: line {line_no}: expected 4 values, got {len(row)}")
        label = row[0].strip()
        if not label:
            raise NestFileError(f"{name}: line {line_no}, column 'name': empty")
        if label in names:
            raise NestFileError(f"{name}: line {line_no}: nest {label!r} named twice")
        xyz = [table_number(cell, name, line_no, col, NestFileError) / MM_PER_M
               for col, cell in zip(HEADER[1:], row[1:], strict=True)]
        names.append(label)
        pos.append(xyz)
    if len(names) < 3:
        raise NestFileError(f"{name}: {len(names)} nest(s); the drift watch needs at least 3")
    return names, np.array(pos)


def read_nests(path: str | Path) -> tuple[list[str], np.ndarray]:
    """Read a nest file (format in the module docstring; positions mm → m).

    Parameters
    ----------
    path : str or Path
        The file, UTF-8 text.

    Returns
    -------
    names : list of str, length K
        The nests' labels, in file order.
    positions : (K, 3) ndarray, m
        The nests' positions (:func:`parse_nests`).

    Raises
    ------
    NestFileError
        No such file, an unreadable or non-UTF-8 file, or any error of
        :func:`parse_nests`.
    """
    return parse_nests(read_text(path, NestFileError), str(Path(path)))


def format_nests(names: list[str], positions: np.ndarray, comments: tuple[str, ...] = ()) -> str:
    """Nest-file text of named positions, converted m → mm; the inverse of :func:`parse_nests`.

    Parameters
    ----------
    names : list of str, length K
        The nests' labels: unique, non-empty, without blanks around them, a line break
        or a leading ``#`` (what :func:`parse_nests` reads back unchanged); CSV-quoted
        when they hold a comma or a quote.
    positions : (K, 3) array_like, m
        The nests' positions, finite, K ≥ 3; written in mm with 6 decimals (nanometre
        resolution).
    comments : tuple of str
        Lines written first, each as ``# line`` (one per line of a comment).

    Returns
    -------
    str
        The file text: comments, the header ``name,x,y,z``, one row a nest.

    Raises
    ------
    ValueError
        What :func:`parse_nests` would refuse or change, with the nest's number
        (1-based): ``positions`` not of shape ``(len(names), 3)``; an empty, repeated
        or unreadable name; a non-finite position; fewer than 3 nests.
    """
    pos = np.asarray(positions, float)
    if pos.shape != (len(names), 3):
        raise ValueError(f"positions must be ({len(names)}, 3) for {len(names)} names, got "
                         f"{pos.shape}")
    seen: set[str] = set()
    for k, (n, p) in enumerate(zip(names, pos, strict=True), start=1):
        if not n:
            raise ValueError(f"nest {k}: empty name")
        if n != n.strip():
            raise ValueError(f"nest {k}: name {n!r} has blanks around it (read back stripped)")
        if "\n" in n or "\r" in n:
            raise ValueError(f"nest {k}: name {n!r} has a line break")
        if n.startswith("#"):
            raise ValueError(f"nest {k}: name {n!r} starts with '#' (read back as a comment)")
        if n in seen:
            raise ValueError(f"nest {k}: nest {n!r} named twice")
        seen.add(n)
        if not np.all(np.isfinite(p)):
            raise ValueError(f"nest {k}: position not finite: {p.tolist()}")
    if len(names) < 3:
        raise ValueError(f"{len(names)} nest(s); the drift watch needs at least 3")
    out = io.StringIO()
    for c in comments:
        for line in str(c).splitlines() or [""]:
            out.write(f"# {line}\n")
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(HEADER)
    for n, p in zip(names, pos, strict=True):
        writer.writerow([n, *(f"{v * MM_PER_M:.6f}" for v in p)])
    return out.getvalue()
