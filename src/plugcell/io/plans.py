"""The measurement-plan file: the joint configurations of a campaign, one pose a row.

Written by ``plugcell plan``, read by ``plugcell twin measure --plan`` and by
``plugcell plan --from`` (a file of allowed configurations)::

    # plugcell plan: robot smart_h4, model 5 (full), criterion D, 40 of 10002 candidates
    j1,j2,j3,j4,j5,j6,payload_kg
    -8.41,-63.2,-147.9,3.1,28.4,-5.0,0

* ``j1..jn`` — joint readings to move to, **degrees** (a prismatic joint: **mm**, read
  and written with the robot's ``joint_scale`` as in measurement files), in the robot
  description's reading order (the columns of a measurement file);
* ``payload_kg`` — optional payload to carry (a plan's rows are grouped by payload:
  one payload change per group).

A measurement file (docs/measurement-files.md) is a valid plan too: its ``x, y, z``,
``rx, ry, rz`` and ``temperature_c`` columns (every column of
:data:`plugcell.io.measurements.MEASUREMENT_COLUMNS` but ``payload_kg``) are read past,
so the poses of a campaign already measured can be planned from.  Inside the program
everything is SI (radians; metres for a prismatic joint).  Errors name the file, the
line and the column.
"""

from __future__ import annotations

import io
import re
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from plugcell.io.csvtable import table_number, table_rows
from plugcell.io.measurements import MEASUREMENT_COLUMNS
from plugcell.io.text_files import read_text
from plugcell.io.units import joints_from_si, joints_to_si

_JOINT_COLUMN = re.compile(r"^j([1-9][0-9]*)$")
#: Columns of a measurement file a plan reader passes over (all but ``payload_kg``).
PASSED_OVER = tuple(c for c in MEASUREMENT_COLUMNS if c != "payload_kg")

__all__ = ["MeasurementPlan", "PlanFileError", "format_plan", "parse_plan", "read_plan",
           "write_plan"]


class PlanFileError(ValueError):
    """A plan file that cannot be read; the message names file, line and column."""


@dataclass(frozen=True)
class MeasurementPlan:
    """The joint configurations of a measurement campaign, in SI units (radians).

    ``len(plan)`` is the number of poses N.

    Attributes
    ----------
    joints : (N, n) ndarray, rad
        Joint readings to move to, in the robot description's reading order (a
        prismatic joint: m, when read with its ``joint_scale``); N ≥ 1.
    payload_kg : (N,) ndarray, kg, or None
        Payload to carry at each pose; ``None`` when the plan does not say.

    Raises
    ------
    ValueError
        ``joints`` not two-dimensional with at least one row, or ``payload_kg`` not of
        shape ``(N,)``.
    """

    joints: np.ndarray
    payload_kg: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.joints.ndim != 2 or self.joints.shape[0] == 0:
            raise ValueError(f"joints must be (N, n) with N ≥ 1, got {self.joints.shape}")
        if self.payload_kg is not None and self.payload_kg.shape != (self.joints.shape[0],):
            raise ValueError(f"payload_kg must be ({self.joints.shape[0]},), "
                             f"got {self.payload_kg.shape}")

    def __len__(self) -> int:
        return int(self.joints.shape[0])


def _header(name: str, line_no: int, header: list[str]) -> tuple[list[int], int | None]:
    cols = [h.strip() for h in header]
    seen: set[str] = set()
    for i, c in enumerate(cols):
        if not c:
            raise PlanFileError(f"{name}: line {line_no}: header column {i + 1} is empty")
        if c in seen:
            raise PlanFileError(f"{name}: line {line_no}: header names column {c!r} twice")
        seen.add(c)
    joints = {int(m.group(1)): i for i, c in enumerate(cols) if (m := _JOINT_COLUMN.match(c))}
    if not joints:
        raise PlanFileError(f"{name}: line {line_no}: header has no joint columns j1..jn: "
                            f"{cols}")
    if sorted(joints) != list(range(1, len(joints) + 1)):
        raise PlanFileError(f"{name}: line {line_no}: joint columns must be j1..j{len(joints)} "
                            f"without gaps, got {[f'j{k}' for k in sorted(joints)]}")
    unknown = [c for c in cols if not _JOINT_COLUMN.match(c) and c not in MEASUREMENT_COLUMNS]
    if unknown:
        raise PlanFileError(f"{name}: line {line_no}: unknown columns {unknown}; expected "
                            f"j1..jn, optional payload_kg ({', '.join(PASSED_OVER)} of a "
                            "measurement file are passed over)")
    payload = cols.index("payload_kg") if "payload_kg" in cols else None
    return [joints[k] for k in range(1, len(joints) + 1)], payload


def parse_plan(text: str, *, name: str = "<plan>", n_joints: int | None = None,
               joint_scale: np.ndarray | None = None) -> MeasurementPlan:
    """Parse plan-file text into a :class:`MeasurementPlan`; joints deg (mm) → rad (m) here.

    Parameters
    ----------
    text : str
        The file's text (layout in the module docstring): a header with the joint
        columns ``j1..jn`` (degrees; a prismatic joint: mm) and optionally
        ``payload_kg`` (kg), in any order; the other columns of a measurement file
        (``x, y, z, rx, ry, rz, temperature_c``) must hold numbers and are dropped.
    name : str
        The file's name, for error messages.
    n_joints : int, optional
        The robot's number of joint readings; when given, the file's joint columns must
        number exactly this.
    joint_scale : (n,) array_like, optional
        SI per file unit of each joint column, as for measurement files
        (``desc.reading_scale()``: π/180 for degrees, 1e-3 for the mm of a prismatic
        joint); default π/180 for all.

    Returns
    -------
    MeasurementPlan
        ``joints`` (N, n) rad (a prismatic joint: m), ``payload_kg`` (N,) kg or ``None``.

    Raises
    ------
    PlanFileError
        Empty, repeated or unknown header columns, joint columns missing or with gaps,
        a joint count other than ``n_joints``, a ``joint_scale`` that does not fit the
        joint columns, no data rows, a row of the wrong length, a cell that is not a
        finite number, or a negative payload.
    """
    rows = table_rows(text, name, PlanFileError)
    (hline, header), data = rows[0], rows[1:]
    jcols, pcol = _header(name, hline, header)
    if n_joints is not None and len(jcols) != n_joints:
        raise PlanFileError(f"{name}: line {hline}: the file has {len(jcols)} joint columns, "
                            f"the robot has {n_joints}")
    try:
        joints_to_si(np.zeros((0, len(jcols))), joint_scale)  # checked before the rows
    except ValueError as exc:
        raise PlanFileError(f"{name}: line {hline}: {exc}") from None
    if not data:
        raise PlanFileError(f"{name}: the file has a header but no rows")
    cols = [h.strip() for h in header]
    values = np.empty((len(data), len(cols)))
    for r, (line_no, row) in enumerate(data):
        if len(row) != len(cols):
            raise PlanFileError(f"{name}: line {line_no}: expected {len(cols)} values, "
                                f"got {len(row)}")
        for c, cell in enumerate(row):
            values[r, c] = table_number(cell, name, line_no, cols[c], PlanFileError)
    payload = None
    if pcol is not None:
        payload = values[:, pcol]
        bad = np.flatnonzero(payload < 0)
        if bad.size:
            raise PlanFileError(f"{name}: line {data[int(bad[0])][0]}, column 'payload_kg': "
                                f"negative mass {payload[bad[0]]:g}")
    return MeasurementPlan(joints_to_si(values[:, jcols], joint_scale), payload)


def read_plan(path: str | Path, *, n_joints: int | None = None,
              joint_scale: np.ndarray | None = None) -> MeasurementPlan:
    """Read a plan file (or a measurement file) into a :class:`MeasurementPlan`.

    Parameters
    ----------
    path : str or Path
        The file, UTF-8 text (layout in the module docstring; joints in degrees).
    n_joints : int, optional
        The robot's number of joint readings, checked when given (:func:`parse_plan`).
    joint_scale : (n,) array_like, optional
        SI per file unit of each joint column; default π/180 (degrees) for all.

    Returns
    -------
    MeasurementPlan
        ``joints`` (N, n) rad (a prismatic joint: m), ``payload_kg`` (N,) kg or ``None``.

    Raises
    ------
    PlanFileError
        No such file, not UTF-8, unreadable, or any error of :func:`parse_plan`.
    """
    text = read_text(path, PlanFileError)
    return parse_plan(text, name=str(Path(path)), n_joints=n_joints, joint_scale=joint_scale)


def format_plan(plan: MeasurementPlan, *, comments: Iterable[str] = (),
                joint_scale: np.ndarray | None = None) -> str:
    """A plan as plan-file text, joints converted rad → deg, m → mm (10 significant digits).

    Parameters
    ----------
    plan : MeasurementPlan
        ``joints`` (N, n) rad, optional ``payload_kg`` (N,) kg.
    comments : iterable of str
        Written first as ``# …`` lines, one per line of each comment.
    joint_scale : (n,) array_like, optional
        SI per file unit of each joint column (as :func:`parse_plan`); joints are
        divided by it.  Default π/180 (degrees) for all.

    Returns
    -------
    str
        The header ``j1,…,jn`` (plus ``payload_kg`` when the plan has payloads) and one
        row a pose.

    Raises
    ------
    ValueError
        ``joint_scale`` neither a scalar nor of shape ``(n,)``, or not finite and
        non-zero.
    """
    out = io.StringIO()
    for c in comments:
        for line in str(c).splitlines() or [""]:
            out.write(f"# {line}\n")
    n = plan.joints.shape[1]
    header = [f"j{k}" for k in range(1, n + 1)]
    table = joints_from_si(plan.joints, joint_scale)
    if plan.payload_kg is not None:
        header.append("payload_kg")
        table = np.hstack([table, plan.payload_kg[:, None]])
    out.write(",".join(header) + "\n")
    for row in table:
        out.write(",".join(f"{v:.10g}" for v in row) + "\n")
    return out.getvalue()


def write_plan(path: str | Path, plan: MeasurementPlan, *, comments: Iterable[str] = (),
               joint_scale: np.ndarray | None = None) -> None:
    """Write a plan file; the inverse of :func:`read_plan` (to 1e-10 relative).

    Parameters
    ----------
    path : str or Path
        The file to write (replaced if it exists), UTF-8.
    plan : MeasurementPlan
        The poses, joints in rad (written in degrees, :func:`format_plan`).
    comments : iterable of str
        Comment lines written first.
    joint_scale : (n,) array_like, optional
        SI per file unit of each joint column; default degrees.

    Raises
    ------
    ValueError
        A ``joint_scale`` that does not fit (:func:`format_plan`).
    """
    Path(path).write_text(format_plan(plan, comments=comments, joint_scale=joint_scale),
                          encoding="utf-8")
