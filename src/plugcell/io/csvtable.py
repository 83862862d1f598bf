"""The CSV tables of plugcell's text files: rows with their line numbers, numbers checked.

Measurement files, plan files, nest files and compensation targets are comma-separated
tables with a header line; blank lines and lines starting with ``#`` are passed over,
``\\r\\n``, ``\\r`` and ``\\n`` all end a line.  :func:`table_rows` returns the rows that
count with their line numbers, :func:`table_number` one finite number of a cell; both
raise the file format's own error class with a message naming the file, the line and
the column.
"""

from __future__ import annotations

import csv
import io
import math


def table_rows(text: str, name: str, error: type[Exception]) -> list[tuple[int, list[str]]]:
    """The rows of a CSV table that count, with their 1-based line numbers, header first.

    Blank lines (every cell blank) and lines whose first cell starts with ``#`` are
    passed over; cells are returned as read (not stripped, not converted).  A row's
    line number is the line its record starts on, also after a quoted cell that spans
    several lines.

    Parameters
    ----------
    text : str
        The file's text; ``\\r\\n``, ``\\r`` and ``\\n`` all end a line.
    name : str
        The file's name, first word of every error message.
    error : type of Exception
        The file format's error class, raised with one message argument.

    Returns
    -------
    list of (int, list of str)
        ``[(line number, cells), …]``: the header row first, then the data rows; the
        line number (1-based) is that of the record's first line.

    Raises
    ------
    error
        ``"NAME: line L: …"`` on a CSV syntax error;
        ``"NAME: no header line (the file is empty)"`` when no line counts.
    """
    rows: list[tuple[int, list[str]]] = []
    reader = csv.reader(io.StringIO(text, newline=None))
    ended = 0  # the line the previous record ended on: a record starts on the next one
    try:
        for row in reader:
            line_no, ended = ended + 1, reader.line_num
            if not row or all(not c.strip() for c in row) or row[0].lstrip().startswith("#"):
                continue
            rows.append((line_no, row))
    except csv.Error as exc:
        raise error(f"{name}: line {reader.line_num}: {exc}") from None
    if not rows:
        raise error(f"{name}: no header line (the file is empty)")
    return rows


def table_number(cell: str, name: str, line_no: int, column: str,
                 error: type[Exception]) -> float:
    """The finite number in one cell of a CSV table (no unit conversion).

    Parameters
    ----------
    cell : str
        The cell's text (surrounding blanks allowed), as :func:`table_rows` returns it.
    name : str
        The file's name, for the error message.
    line_no : int
        1-based line number of the cell's row, for the error message.
    column : str
        The column's header name, for the error message.
    error : type of Exception
        The file format's error class.

    Returns
    -------
    float
        The number, in the file's unit of that column.

    Raises
    ------
    error
        ``"NAME: line L, column 'C': not a number: '…'"``, or ``… not finite: '…'``
        for ``nan``/``inf``.
    """
    try:
        v = float(cell)
    except ValueError:
        raise error(f"{name}: line {line_no}, column {column!r}: not a number: "
                    f"{cell.strip()!r}") from None
    if not math.isfinite(v):
        raise error(f"{name}: line {line_no}, column {column!r}: not finite: {cell.strip()!r}")
    return v
