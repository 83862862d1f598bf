"""The measurement file: joint readings and tracker measurements, one pose a row.

Format (used by the twin, the calibrator, the services and the docs)::

    # comment lines start with '#'
    j1,j2,j3,j4,j5,j6,x,y,z,rx,ry,rz,payload_kg
    10.0,-80.0,-150.0,0.0,30.0,0.0,1712.43,-12.80,1203.55,179.9,0.2,-90.1,36

* ``j1..jn`` — joint readings in **degrees** (a prismatic joint: **mm**) as the
  controller reports them, in the robot description's reading order (for the Smart
  H4: θ1, θ2, θ2', θ4, θ5, θ6; for a description with a joint ``coupling``, its
  ``readings``, e.g. Fanuc J1..J6).
* ``x, y, z`` — measured reflector position in **mm** in the tracker frame.
* ``rx, ry, rz`` — optional measured orientation in **degrees**; the convention is
  a property of the file set by the reader/writer (``rpy`` = fixed X-Y-Z, default;
  ``zyz``; ``xyz`` intrinsic).
* ``payload_kg`` — optional payload carried during the measurement.
* ``temperature_c`` — optional temperature (°C) at the measurement; when present,
  every row must have it (an empty cell is refused, naming the line): the learned
  residual layer and a thermal term use it as a feature.

Inside the program everything is SI: radians and metres.  Errors name the file,
the row (1-based line number in the file) and the column.
"""

from __future__ import annotations

import io
import re
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from plugcell.io.csvtable import table_number, table_rows
from plugcell.io.text_files import read_text
from plugcell.io.units import MM_PER_M, joints_from_si, joints_to_si

ROTATION_CONVENTIONS = ("rpy", "zyz", "xyz")
_JOINT_COLUMN = re.compile(r"^j([1-9][0-9]*)$")
#: The columns a measurement file may have besides its joint readings ``j1..jn``.
MEASUREMENT_COLUMNS = ("x", "y", "z", "rx", "ry", "rz", "payload_kg", "temperature_c")
class MeasurementFileError(ValueError):
    """A measurement file that cannot be read; the message names file, row and column."""


@dataclass(frozen=True)
class MeasurementSet:
    """Poses of one calibration or validation campaign, in SI units.

    ``len(m)`` is the number of poses N.  The file readers convert into these units
    (:func:`parse_measurements`), the writers out of them (:func:`format_measurements`).

    Attributes
    ----------
    joints : (N, n) ndarray, rad
        Joint readings in the robot description's reading order (a prismatic joint: m,
        when read with its ``joint_scale``).
    positions : (N, 3) ndarray, m
        Measured reflector positions in the tracker frame.
    angles : (N, 3) ndarray, rad, or None
        Measured orientations in the convention ``rotation``; ``None`` when the
        campaign measured positions only.
    rotation : str
        The angles' convention: ``"rpy"`` (fixed X-Y-Z, default), ``"zyz"`` or
        ``"xyz"`` (intrinsic); kept even when ``angles`` is ``None``.
    payload_kg : (N,) ndarray, kg, or None
        Payload carried at each pose.
    temperature_c : (N,) ndarray, °C, or None
        Temperature at each measurement.

    Raises
    ------
    ValueError
        ``joints`` not two-dimensional, another array of the wrong shape, or an
        unknown ``rotation``.
    """

    joints: np.ndarray
    positions: np.ndarray
    angles: np.ndarray | None = None
    rotation: str = "rpy"
    payload_kg: np.ndarray | None = None
    temperature_c: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.joints.ndim != 2:
            raise ValueError(f"joints must be (N, n), got shape {self.joints.shape}")
        n = self.joints.shape[0]
        if self.positions.shape != (n, 3):
            raise ValueError(f"positions must be ({n}, 3), got {self.positions.shape}")
        if self.angles is not None and self.angles.shape != (n, 3):
            raise ValueError(f"angles must be ({n}, 3), got {self.angles.shape}")
        if self.payload_kg is not None and self.payload_kg.shape != (n,):
            raise ValueError(f"payload_kg must be ({n},), got {self.payload_kg.shape}")
        if self.temperature_c is not None and self.temperature_c.shape != (n,):
            raise ValueError(f"temperature_c must be ({n},), got {self.temperature_c.shape}")
        if self.rotation not in ROTATION_CONVENTIONS:
            raise ValueError(
                f"rotation convention {self.rotation!r} unknown; use one of {ROTATION_CONVENTIONS}"
            )

    def __len__(self) -> int:
        return int(self.joints.shape[0])

    @property
    def n_joints(self) -> int:
        """The number n of joint readings a pose (columns of ``joints``)."""
        return int(self.joints.shape[1])

    @property
    def has_orientation(self) -> bool:
        """Whether the campaign measured orientations (``angles`` is not ``None``)."""
        return self.angles is not None

    def subset(self, index: np.ndarray | slice) -> MeasurementSet:
        """The poses selected by ``index``, every per-pose array indexed alike.

        Parameters
        ----------
        index : (N,) bool ndarray, int ndarray or slice
            A boolean mask over the poses, pose indices, or a slice.

        Returns
        -------
        MeasurementSet
            The selected poses, same ``rotation``.
        """
        return MeasurementSet(
            joints=self.joints[index],
            positions=self.positions[index],
            angles=None if self.angles is None else self.angles[index],
            rotation=self.rotation,
            payload_kg=None if self.payload_kg is None else self.payload_kg[index],
            temperature_c=None if self.temperature_c is None else self.temperature_c[index],
        )


def _parse_header(name: str, header: list[str]) -> tuple[int, dict[str, int]]:
    """The joint count and column indices of a header; ``name`` is ``"FILE: line L"``."""
    cols = [h.strip() for h in header]
    index: dict[str, int] = {}
    for i, col in enumerate(cols):
        if not col:
            raise MeasurementFileError(f"{name}: header column {i + 1} is empty")
        if col in index:
            raise MeasurementFileError(f"{name}: header names column {col!r} twice")
        index[col] = i
    joint_numbers = sorted(int(m.group(1)) for c in cols if (m := _JOINT_COLUMN.match(c)))
    if not joint_numbers:
        raise MeasurementFileError(f"{name}: header has no joint columns j1..jn: {cols}")
    if joint_numbers != list(range(1, len(joint_numbers) + 1)):
        raise MeasurementFileError(
            f"{name}: joint columns must be j1..j{len(joint_numbers)} without gaps, "
            f"got {[f'j{k}' for k in joint_numbers]}"
        )
    for col in ("x", "y", "z"):
        if col not in index:
            raise MeasurementFileError(f"{name}: header lacks the column {col!r}")
    rot = [c for c in ("rx", "ry", "rz") if c in index]
    if rot and len(rot) != 3:
        raise MeasurementFileError(f"{name}: orientation needs all of rx, ry, rz; found only {rot}")
    known = {f"j{k}" for k in joint_numbers} | set(MEASUREMENT_COLUMNS)
    unknown = [c for c in cols if c not in known]
    if unknown:
        raise MeasurementFileError(
            f"{name}: unknown columns {unknown}; expected j1..jn, x, y, z, "
            "optional rx, ry, rz, payload_kg and temperature_c"
        )
    return len(joint_numbers), index


def _data_values(name: str, header: list[str], data: list[tuple[int, list[str]]]) -> np.ndarray:
    """Read the data rows' cells as numbers, in the file's units (degrees, mm, kg, °C).

    Parameters
    ----------
    name : str
        The file's name, for error messages.
    header : list of str
        The header's column names (``ncol`` of them).
    data : list of (int, list of str)
        ``(line number, cells)`` of each data row.

    Returns
    -------
    (N, ncol) array
        ``values[r, c]``: row ``r``'s cell in column ``c``, finite.

    Raises
    ------
    MeasurementFileError
        No data rows; a row of the wrong length; a cell that is not a finite number (an
        empty ``temperature_c`` cell included), naming the line and the column.
    """
    if not data:
        raise MeasurementFileError(f"{name}: the file has a header but no data rows")
    ncol = len(header)
    values = np.empty((len(data), ncol))
    cols = [h.strip() for h in header]
    for r, (line_no, row) in enumerate(data):
        if len(row) != ncol:
            raise MeasurementFileError(
                f"{name}: line {line_no}: expected {ncol} values, got {len(row)}"
            )
        for c, cell in enumerate(row):
            if not cell.strip() and cols[c] == "temperature_c":
                raise MeasurementFileError(
                    f"{name}: line {line_no}, column 'temperature_c': missing value (a "
                    "temperature column must be complete; drop the column or the row)"
                )
            values[r, c] = table_number(cell, name, line_no, cols[c], MeasurementFileError)
    return values


def parse_measurements(
    text: str,
    *,
    rotation: str = "rpy",
    name: str = "<measurements>",
    n_joints: int | None = None,
    joint_scale: np.ndarray | None = None,
) -> MeasurementSet:
    """Parse measurement-file text into a :class:`MeasurementSet`, converting to SI here.

    The file (module docstring) holds joint readings in degrees (prismatic: mm),
    positions ``x, y, z`` in mm and optional angles ``rx, ry, rz`` in degrees; they
    become rad (m), m and rad.  Columns may come in any order; ``payload_kg`` (kg) and
    ``temperature_c`` (°C) are taken as they are.

    Parameters
    ----------
    text : str
        The file's text.
    rotation : str
        Convention of the ``rx, ry, rz`` columns: ``"rpy"`` (default), ``"zyz"`` or
        ``"xyz"``; the file does not say it, the caller does.
    name : str
        The file's name, for error messages.
    n_joints : int, optional
        The robot's number of joint readings; when given, the file's joint columns must
        number exactly this.
    joint_scale : (n,) array_like, optional
        SI per file unit of each joint column (``desc.reading_scale()``: π/180 for
        degrees, 1e-3 for the mm of a prismatic joint); default π/180 for all.

    Returns
    -------
    MeasurementSet
        ``joints`` (N, n) rad (or m), ``positions`` (N, 3) m, ``angles`` (N, 3) rad or
        ``None``, ``payload_kg`` (N,) or ``None``, ``temperature_c`` (N,) or ``None``.

    Raises
    ------
    MeasurementFileError
        An unknown ``rotation``; an empty, repeated or unknown header column; joint
        columns missing or with gaps; no ``x, y, z``; only some of ``rx, ry, rz``; a
        joint count other than ``n_joints``; no data rows; a row of the wrong length; a
        cell that is not a finite number (an empty ``temperature_c`` cell included); a
        negative payload; a ``joint_scale`` that does not fit the joint columns.
    """
    if rotation not in ROTATION_CONVENTIONS:
        raise MeasurementFileError(
            f"{name}: rotation convention {rotation!r} unknown; use one of {ROTATION_CONVENTIONS}"
        )
    rows = table_rows(text, name, MeasurementFileError)
    header_line, header = rows[0]
    nj, index = _parse_header(f"{name}: line {header_line}", header)
    if n_joints is not None and nj != n_joints:
        raise MeasurementFileError(
            f"{name}: line {header_line}: the file has {nj} joint columns, the robot has {n_joints}"
        )
    data = rows[1:]
    values = _data_values(name, header, data)
    try:
        joints = joints_to_si(values[:, [index[f"j{k}"] for k in range(1, nj + 1)]],
                              joint_scale)
    except ValueError as exc:
        raise MeasurementFileError(f"{name}: line {header_line}: {exc}") from None
    positions = values[:, [index["x"], index["y"], index["z"]]] / MM_PER_M
    angles = None
    if "rx" in index:
        angles = np.deg2rad(values[:, [index["rx"], index["ry"], index["rz"]]])
    payload = None
    if "payload_kg" in index:
        payload = values[:, index["payload_kg"]]
        bad = np.flatnonzero(payload < 0)
        if bad.size:
            line_no = data[int(bad[0])][0]
            raise MeasurementFileError(
                f"{name}: line {line_no}, column 'payload_kg': negative mass {payload[bad[0]]}"
            )
    temperature = values[:, index["temperature_c"]] if "temperature_c" in index else None
    return MeasurementSet(joints, positions, angles, rotation, payload, temperature)


def read_measurements(
    path: str | Path, *, rotation: str = "rpy", n_joints: int | None = None,
    joint_scale: np.ndarray | None = None,
) -> MeasurementSet:
    """Read a measurement file into a :class:`MeasurementSet` (SI units).

    Parameters
    ----------
    path : str or Path
        The file, UTF-8 text (layout in the module docstring: degrees and mm).
    rotation : str
        Convention of the file's ``rx, ry, rz`` columns (:func:`parse_measurements`).
    n_joints : int, optional
        The robot's number of joint readings, checked when given.
    joint_scale : (n,) array_like, optional
        SI per file unit of each joint column; default π/180 (degrees) for all.

    Returns
    -------
    MeasurementSet
        The poses in rad and m (:func:`parse_measurements`).

    Raises
    ------
    MeasurementFileError
        No such file, not UTF-8, unreadable, or any error of
        :func:`parse_measurements`.
    """
    text = read_text(path, MeasurementFileError)
    return parse_measurements(text, rotation=rotation, name=str(Path(path)), n_joints=n_joints,
                              joint_scale=joint_scale)


def format_measurements(m: MeasurementSet, *, comments: Iterable[str] = (),
                        joint_scale: np.ndarray | None = None) -> str:
    """A :class:`MeasurementSet` as measurement-file text, converted SI → degrees and mm.

    Parameters
    ----------
    m : MeasurementSet
        The poses (rad, m).
    comments : iterable of str
        Written first as ``# …`` lines, one per line of each comment; a set with
        orientations adds ``# orientation convention: ROT`` (informative only: the
        reader does not parse it).
    joint_scale : (n,) array_like, optional
        SI per file unit of each joint column; joints are divided by it.  Default
        π/180 (degrees) for all.

    Returns
    -------
    str
        Header ``j1..jn,x,y,z`` then ``rx,ry,rz``, ``payload_kg``, ``temperature_c``
        when present; one row a pose, 9 significant digits.
    """
    out = io.StringIO()
    for c in comments:
        for line in str(c).splitlines() or [""]:
            out.write(f"# {line}\n")
    if m.angles is not None:
        out.write(f"# orientation convention: {m.rotation}\n")
    header = [f"j{k}" for k in range(1, m.n_joints + 1)] + ["x", "y", "z"]
    if m.angles is not None:
        header += ["rx", "ry", "rz"]
    if m.payload_kg is not None:
        header.append("payload_kg")
    if m.temperature_c is not None:
        header.append("temperature_c")
    out.write(",".join(header) + "\n")
    cols = [joints_from_si(m.joints, joint_scale), m.positions * MM_PER_M]
    if m.angles is not None:
        cols.append(np.rad2deg(m.angles))
    if m.payload_kg is not None:
        cols.append(m.payload_kg[:, None])
    if m.temperature_c is not None:
        cols.append(m.temperature_c[:, None])
    table = np.hstack(cols)
    for row in table:
        out.write(",".join(f"{v:.9g}" for v in row) + "\n")
    return out.getvalue()


def write_measurements(
    path: str | Path, m: MeasurementSet, *, comments: Iterable[str] = (),
    joint_scale: np.ndarray | None = None,
) -> None:
    """Write a measurement file; the inverse of :func:`read_measurements` (to 9 digits).

    Parameters
    ----------
    path : str or Path
        The file to write (replaced if it exists), UTF-8.
    m : MeasurementSet
        The poses (rad, m), written in degrees and mm (:func:`format_measurements`).
    comments : iterable of str
        Comment lines written first.
    joint_scale : (n,) array_like, optional
        SI per file unit of each joint column; default degrees.
    """
    Path(path).write_text(format_measurements(m, comments=comments, joint_scale=joint_scale),
                          encoding="utf-8")
