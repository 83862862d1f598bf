"""The robot description file schema: a document (a TOML table, a dict) ↔ a
:class:`~plugcell.kinematics.RobotDescription`.

The schema is declared once, as :mod:`msgspec` Structs (:class:`RobotFile` and its
tables): which keys a table takes, which are required, their types, vector lengths
and finite numbers.  ``msgspec.convert`` checks a document against it and names the
first problem's place (``$.links[3].alpha``); :func:`document_from_dict` turns that
into a :class:`~plugcell.kinematics.errors.DescriptionError` in the file's own words
(``links[3].alpha: expected a number, got 'x'``).  :func:`description_from_document`
then applies what a type cannot say (a fixed joint needs ``theta``, ``beta`` only
with ``hayati``, limits only on actuated joints, lower below upper…) and converts
the file's units — lengths in metres, angles in **degrees**, masses in kg — to the
model's SI radians.  The model checks its own physical consistency (parents,
loops, couplings, limits against ``home``) when it is built, and reports it at the
same file locations.

The other way, :func:`description_to_dict` writes a description as the dictionary of
a file (``plugcell kin describe``, PARAMS.json's ``description``, twin scenarios,
:func:`plugcell.io.robots.description_to_toml`); it loads back to the same robot.

Like Pinocchio's ``buildModelFromUrdf`` next to its ``Model``, the parser lives here
and the model in :mod:`plugcell.kinematics.description`, which reads no file format.
The format is documented in ``docs/robot-description.md``; files are read by
:mod:`plugcell.io.robots`.
"""

from __future__ import annotations

import math
import re
import sys
from collections.abc import Mapping, Sequence
from typing import Annotated, Any, Final, Literal

import msgspec
import numpy as np
from msgspec import UNSET, Meta, UnsetType

from plugcell.kinematics.description import (
    JOINT_TYPES,
    Box,
    CoupledLimit,
    FourBarLoop,
    JointCoupling,
    Link,
    PointMass,
    RobotDescription,
    check_rigid,
)
from plugcell.kinematics.errors import DescriptionError
from plugcell.kinematics.rotations import matrix_to_rpy, rpy_to_matrix, zyz_to_matrix

__all__ = [
    "FORMAT_VERSION",
    "BoxTable",
    "CoupledLimitTable",
    "CouplingTable",
    "LinkTable",
    "LoopTable",
    "PointMassTable",
    "RobotFile",
    "TransformTable",
    "description_from_dict",
    "description_from_document",
    "description_to_dict",
    "document_from_dict",
    "document_of",
]

#: Description file format version understood here (``format_version`` key).
FORMAT_VERSION: Final = 1

_DEG = math.pi / 180.0
_MAX = sys.float_info.max

# ================================================================================ schema
#: A finite number (an int is accepted, a bool is not).
Number = Annotated[float, Meta(ge=-_MAX, le=_MAX)]
#: A non-empty string (names of links, joints, readings).
Name = Annotated[str, Meta(min_length=1)]
Vec3 = tuple[Number, Number, Number]
#: ``[lower, upper]``.
Pair = tuple[Number, Number]
Row4 = tuple[Number, Number, Number, Number]
#: Joint types, as :data:`plugcell.kinematics.description.JOINT_TYPES`.
JointType = Literal["actuated", "prismatic", "passive", "fixed"]
LoopType = Literal["parallelogram", "fourbar"]


class _Table(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    """A TOML table: unknown keys are errors."""


class TransformTable(_Table, kw_only=True):
    """``base``/``tool``: ``xyz`` (m) with ``rpy`` or ``zyz`` (°), or a 4×4 ``matrix``.

    Converted to a 4×4 transform (m) by :func:`description_from_document`; ``rpy``
    and ``zyz`` exclude each other, ``matrix`` excludes the three others.

    Attributes
    ----------
    xyz : (3,) tuple of float, m, optional
        Translation; default zero.
    rpy : (3,) tuple of float, degrees, optional
        Roll, pitch, yaw about the fixed X, Y, Z axes: ``R = Rz(yaw)·Ry(pitch)·Rx(roll)``.
    zyz : (3,) tuple of float, degrees, optional
        Z-Y-Z Euler angles (Comau A, B, C): ``R = Rz(a)·Ry(b)·Rz(c)``.
    matrix : (4, 4) tuple of rows, translation in m, optional
        A rigid homogeneous transform, row by row.
    """

    xyz: Vec3 | UnsetType = UNSET
    rpy: Vec3 | UnsetType = UNSET
    zyz: Vec3 | UnsetType = UNSET
    matrix: tuple[Row4, Row4, Row4, Row4] | UnsetType = UNSET


class LinkTable(_Table, kw_only=True):
    """One ``[[links]]`` entry: a DH + Hayati row (m, °), its joint, mass and limits.

    Attributes
    ----------
    name, parent : str
        The link, and its parent link (``"base"`` for the first).
    joint : str
        ``"actuated"``, ``"prismatic"``, ``"passive"`` or ``"fixed"``.
    theta : float, degrees, optional
        Joint offset (actuated, passive) or constant angle (fixed, prismatic);
        required for a fixed joint, else default 0.
    d, a : float, m
        DH offsets along z and x.
    alpha : float, degrees
        DH twist about x.
    hayati : bool, optional
        Whether the row has the Hayati rotation β about y; default false.
    beta : float, degrees, optional
        Hayati angle, only with ``hayati = true``; default 0.
    mass : float, kg
        Link mass, ≥ 0; default 0.
    com : (3,) tuple of float, m
        Centre of mass in the link's own frame; default the origin.
    limits : (2,) tuple of float, optional
        ``[lower, upper]`` of the joint reading: degrees (prismatic: m); required on
        actuated and prismatic joints without a ``[coupling]``, forbidden otherwise.
    stiffness : float, N·m/rad (prismatic: N/m), optional
        Joint stiffness, > 0; actuated joints only, all of them or none.
    """

    name: Name
    parent: Name
    joint: JointType
    theta: Number | UnsetType = UNSET  # required for fixed joints, else 0
    d: Number
    a: Number
    alpha: Number
    hayati: bool | UnsetType = UNSET
    beta: Number | UnsetType = UNSET  # only with hayati = true
    mass: Number = 0.0
    com: Vec3 = (0.0, 0.0, 0.0)
    limits: Pair | UnsetType = UNSET  # actuated joints without a coupling: required
    stiffness: Number | UnsetType = UNSET  # actuated joints: all or none


class LoopTable(_Table, kw_only=True):
    """One ``[[loops]]`` entry: a parallelogram's four links.

    Attributes
    ----------
    type : str, optional
        ``"parallelogram"`` (the default: the nominal, planar parallelogram) or
        ``"fourbar"`` (a calibrated loop: unequal sides, twists and offsets on its
        links, the exact four-bar closure), the
        :attr:`~plugcell.kinematics.description.FourBarLoop.kind`.
    arm, crank, coupler, follower : str
        Names of the loop's four links (``[[links]]`` names).
    """

    type: LoopType | UnsetType = UNSET
    arm: Name
    crank: Name
    coupler: Name
    follower: Name


class CoupledLimitTable(_Table, kw_only=True):
    """One ``[[coupled_limits]]`` entry: ``min ≤ joints[0] − joints[1] ≤ max`` (°).

    Attributes
    ----------
    joints : (2,) tuple of str
        The two joint readings whose difference is limited.
    lower, upper : float, degrees
        The file's keys ``min`` and ``max``; ``min < max``.
    """

    joints: tuple[Name, Name]
    lower: Number = msgspec.field(name="min")
    upper: Number = msgspec.field(name="max")


class PointMassTable(_Table, kw_only=True):
    """One ``[[point_masses]]`` entry: ``mass`` (kg) at ``com`` (m) in frame ``link``.

    Attributes
    ----------
    name : str
        The mass's label (e.g. a counterweight).
    link : str
        The link whose frame ``com`` is given in.
    mass : float, kg
        ≥ 0.
    com : (3,) tuple of float, m
        Position in that link's frame.
    """

    name: Name
    link: Name
    mass: Number
    com: Vec3


class BoxTable(_Table, kw_only=True):
    """``[working_volume]``: ``center`` and edge lengths ``size`` (m), base frame.

    Attributes
    ----------
    center : (3,) tuple of float, m
        The box's centre in the robot base frame.
    size : (3,) tuple of float, m
        Edge lengths along the base frame's x, y, z, all > 0 (checked by the model).
    """

    center: Vec3
    size: Vec3


class CouplingTable(_Table, kw_only=True):
    """``[coupling]``: kinematic joints = ``matrix`` · readings + ``offsets`` (°).

    Attributes
    ----------
    readings : list of str, length n_r
        Names of the joint readings (as the controller reports them, e.g. J1..J6).
    matrix : (n_actuated, n_r) list of rows of float
        Dimensionless map from readings to kinematic joints, one row per ``actuated``
        link.
    offsets : (n_actuated,) list of float, degrees, optional
        Added after the map; default 0.
    limits : (n_r, 2) list of float, degrees
        ``[lower, upper]`` of each reading (the actuated links then take no limits).
    """

    readings: list[Name]
    matrix: list[list[Number]]
    offsets: list[Number] | UnsetType = UNSET
    limits: list[Pair]


class IdentificationTable(_Table, kw_only=True):
    """``[identification]``: which robot this is (OPC UA DI/OPC 40010 identification;
    not used by the kinematics).

    Attributes
    ----------
    manufacturer, model, serial_number, product_code : str
        As on the robot's nameplate; empty when unknown.
    """

    manufacturer: str = ""
    model: str = ""
    serial_number: str = ""
    product_code: str = ""


class RobotFile(_Table, kw_only=True):
    """A whole description file (the order of the fields is the order written).

    Layout and units: ``docs/robot-description.md`` (lengths m, angles degrees, masses
    kg); :func:`description_from_document` converts to SI radians.

    Attributes
    ----------
    format_version : int
        Must be 1 (:data:`FORMAT_VERSION`).
    name : str
        The robot's name.
    notes : str or list of str
        Free text (a list is joined with line breaks).
    actuated : list of str
        The actuated links, in joint-reading order (without a coupling).
    flange : str
        The link whose frame is the flange.
    home : list of float, degrees (prismatic: m), optional
        One value per joint reading; default the middle of each range.
    base, tool : TransformTable, optional
        The robot base frame F0 in the world/metrology frame (BASE, eq. 6.23), and
        the TCP (or a probe) in the flange frame; default identity.
    links : list of LinkTable
        The DH + Hayati rows.
    loops : list of LoopTable
        Closed loops (parallelograms).
    coupled_limits : list of CoupledLimitTable
        Limits on differences of two readings.
    point_masses : list of PointMassTable
        Masses on links besides the links' own.
    coupling : CouplingTable, optional
        A vendor joint convention: readings ≠ kinematic joints.
    working_volume : BoxTable, optional
        The box the robot works in.
    identification : IdentificationTable, optional
        Manufacturer, model, serial number and product code (OPC UA identification).
    """

    format_version: Literal[1] = FORMAT_VERSION
    name: Name
    notes: str | list[str] = ""
    actuated: list[Name]
    flange: Name
    home: list[Number] | UnsetType = UNSET
    base: TransformTable | UnsetType = UNSET
    tool: TransformTable | UnsetType = UNSET
    links: list[LinkTable]
    loops: list[LoopTable] = []
    coupled_limits: list[CoupledLimitTable] = []
    point_masses: list[PointMassTable] = []
    coupling: CouplingTable | UnsetType = UNSET
    working_volume: BoxTable | UnsetType = UNSET
    identification: IdentificationTable | UnsetType = UNSET


#: The table type at a key (for the keys an "unknown key" message lists).
_TABLES: dict[str, type[_Table]] = {
    "": RobotFile,
    "links": LinkTable,
    "loops": LoopTable,
    "coupled_limits": CoupledLimitTable,
    "point_masses": PointMassTable,
    "working_volume": BoxTable,
    "coupling": CouplingTable,
    "base": TransformTable,
    "tool": TransformTable,
    "identification": IdentificationTable,
}


# ================================================================================ errors
def _typename(v: Any) -> str:
    return repr(v) if isinstance(v, (str, int, float, bool)) else type(v).__name__


def _sub(loc: str, key: str) -> str:
    return f"{loc}.{key}" if loc else key


_MISSING = object()
_AT = re.compile(r" - at `(\$[^`]*)`$")
_KEY_AT = re.compile(r" - at `key` in `(\$[^`]*)`$")
_STEP = re.compile(r"\.([A-Za-z_]\w*)|\[(\d+)\]")
_KINDS = {
    "float": "expected a number",
    "str": "expected a string",
    "bool": "expected true or false",
    "array": "expected an array",
    "str | array": "expected an array",
    "object": "expected a table",
}


def _steps(path: str) -> list[str | int]:
    """``$.links[3].com[1]`` → ``["links", 3, "com", 1]``."""
    return [int(i) if i else name for name, i in _STEP.findall(path[1:])]


def _location(steps: Sequence[str | int]) -> str:
    out = ""
    for s in steps:
        out = f"{out}[{s}]" if isinstance(s, int) else _sub(out, s)
    return out


def _value_at(data: Any, steps: Sequence[str | int]) -> Any:
    for s in steps:
        try:
            data = data[s]
        except (KeyError, IndexError, TypeError):
            return _MISSING
    return data


def _reason(msg: str, steps: list[str | int], v: Any) -> tuple[str, str]:
    """msgspec's message ``msg`` at ``steps`` (value ``v``) → (location, reason)."""
    loc = _location(steps)
    last = next((s for s in reversed(steps) if isinstance(s, str)), "")
    got = _typename(v)
    if m := re.fullmatch(r"Object missing required field `(.*)`", msg, re.S):
        return _sub(loc, m[1]), "missing required key"
    if m := re.fullmatch(r"Object contains unknown field `(.*)`", msg, re.S):
        table = _TABLES.get(last, RobotFile)
        allowed = sorted(f.encode_name for f in msgspec.structs.fields(table))
        return _sub(loc, m[1]), f"unknown key (allowed: {', '.join(allowed)})"
    if m := re.fullmatch(r"Expected `([^`]*)`, got `[^`]*`", msg):
        kind = _KINDS.get(m[1], f"expected {m[1]}")
        return loc, f"{kind}, got {got}"
    if m := re.fullmatch(r"Expected `array` of length (\d+), got (\d+)", msg):
        n, k = m[1], m[2]
        what = {"matrix": "rows", "joints": "joint names"}.get(str(steps[-1]), "numbers")
        return loc, f"expected {n} {what}, got {k}"
    if re.fullmatch(r"Expected `float` [<>]=.*|Number out of range", msg):
        return loc, f"expected a finite number, got {v!r}"
    if re.fullmatch(r"Expected `str` of length >= 1", msg):
        return loc, "must not be empty"
    if msg.startswith("Invalid enum value"):
        if v == "":
            return loc, "must not be empty"
        if last == "joint":
            return loc, f"expected one of {list(JOINT_TYPES)}, got {v!r}"
        return loc, f"expected 'parallelogram', got {v!r}"
    return loc, msg[:1].lower() + msg[1:]


def _error(exc: msgspec.ValidationError, data: Any) -> DescriptionError:
    """A :class:`DescriptionError` in the file's words for msgspec's ``exc`` on ``data``."""
    msg = str(exc)
    if m := _KEY_AT.search(msg):  # a key that is not a string
        steps = _steps(m[1])
        table = _value_at(data, steps)
        bad = next((k for k in table if not isinstance(k, str)), None) if isinstance(
            table, Mapping) else None
        return DescriptionError(_location(steps), f"keys must be strings, got {bad!r}")
    if m := _AT.search(msg):
        msg, steps = msg[: m.start()], _steps(m[1])
    else:
        steps = []
    if steps[:1] == ["format_version"]:
        fv = _value_at(data, steps)
        return DescriptionError(
            "format_version",
            f"unsupported format version {_typename(fv)} (expected {FORMAT_VERSION})",
        )
    return DescriptionError(*_reason(msg, steps, _value_at(data, steps)))


def _plain(v: Any) -> Any:
    """``v`` with every mapping a dict, every sequence a list and numbers of subclasses
    of ``float``/``int`` (numpy's float64) plain Python ones, as msgspec takes them."""
    if isinstance(v, Mapping):
        return {k: _plain(x) for k, x in v.items()}
    if isinstance(v, Sequence) and not isinstance(v, (str, bytes, bytearray)):
        return [_plain(x) for x in v]
    if isinstance(v, float) and type(v) is not float:
        return float(v)
    if isinstance(v, int) and not isinstance(v, bool) and type(v) is not int:
        return int(v)
    return v


# ================================================================================ reading
def document_from_dict(data: Any) -> RobotFile:
    """Check a document (the dictionary of a TOML file) against the file schema.

    Parameters
    ----------
    data : Mapping
        The parsed file (``tomllib.load``) or a dictionary of the same shape.

    Returns
    -------
    RobotFile
        The typed document, numbers and units as in the file.

    Raises
    ------
    DescriptionError
        The first problem, located at the key (``links[3].alpha: expected a number,
        got 'x'``; ``coupling.gear: unknown key (allowed: ...)``).
    """
    try:
        return msgspec.convert(_plain(data), RobotFile)
    except msgspec.ValidationError as exc:
        raise _error(exc, data) from None


def _transform(t: TransformTable, loc: str) -> np.ndarray:
    if not isinstance(t.matrix, UnsetType):
        if any(not isinstance(x, UnsetType) for x in (t.xyz, t.rpy, t.zyz)):
            raise DescriptionError(loc, "give either 'matrix' or 'xyz' with 'rpy'/'zyz', not both")
        T = np.array(t.matrix, dtype=float)
        check_rigid(T, f"{loc}.matrix")
        return T
    if not isinstance(t.rpy, UnsetType) and not isinstance(t.zyz, UnsetType):
        raise DescriptionError(loc, "give one of 'rpy' or 'zyz', not both")
    T = np.eye(4)
    if not isinstance(t.rpy, UnsetType):
        T[:3, :3] = rpy_to_matrix(*(x * _DEG for x in t.rpy))
    elif not isinstance(t.zyz, UnsetType):
        T[:3, :3] = zyz_to_matrix(*(x * _DEG for x in t.zyz))
    T[:3, 3] = (0.0, 0.0, 0.0) if isinstance(t.xyz, UnsetType) else t.xyz
    return T


def _limit_pair(lim: tuple[float, float], loc: str) -> tuple[float, float]:
    if not lim[0] < lim[1]:
        raise DescriptionError(loc, f"lower limit {lim[0]:g} must be below upper limit {lim[1]:g}")
    return lim


def _coupling(c: CouplingTable) -> tuple[JointCoupling, np.ndarray]:
    """``[coupling]`` → (the coupling, reading limits ``(n_readings, 2)`` rad)."""
    loc = "coupling"
    n_r = len(c.readings)
    if not c.matrix:
        raise DescriptionError(f"{loc}.matrix", "expected one row per actuated joint, got none")
    for r, row in enumerate(c.matrix):
        if len(row) != len(c.matrix[0]):
            raise DescriptionError(
                f"{loc}.matrix[{r}]",
                f"expected {len(c.matrix[0])} numbers like row 0 (one per reading), "
                f"got {len(row)}",
            )
    n_a = len(c.matrix)
    # the offsets' length is checked against `actuated` by the model
    offset = [0.0] * n_a if isinstance(c.offsets, UnsetType) else [x * _DEG for x in c.offsets]
    if len(c.limits) != n_r:
        raise DescriptionError(
            f"{loc}.limits",
            f"expected {n_r} [lower, upper] pairs (one per reading), got {len(c.limits)}",
        )
    lims = np.array([_limit_pair(x, f"{loc}.limits[{j}]") for j, x in enumerate(c.limits)],
                    dtype=float).reshape(n_r, 2) * _DEG
    matrix = np.array(c.matrix, dtype=float).reshape(n_a, -1)
    return JointCoupling(tuple(c.readings), matrix, np.array(offset)), lims


def _link(t: LinkTable, loc: str, coupled: bool) -> tuple[Link, tuple[float, float] | None]:
    """A ``[[links]]`` entry → (the link, its limits in SI if it has any)."""
    if isinstance(t.theta, UnsetType):
        if t.joint == "fixed":
            raise DescriptionError(f"{loc}.theta", "missing required key")
        theta = 0.0
    else:
        theta = t.theta
    hayati = False if isinstance(t.hayati, UnsetType) else t.hayati
    if not isinstance(t.beta, UnsetType) and not hayati:
        raise DescriptionError(f"{loc}.beta", "beta requires hayati = true")
    beta = 0.0 if isinstance(t.beta, UnsetType) else t.beta
    if t.mass < 0:
        raise DescriptionError(f"{loc}.mass", f"must be ≥ 0, got {t.mass:g}")
    limits = None
    if t.joint in ("actuated", "prismatic"):
        if coupled:
            if not isinstance(t.limits, UnsetType):
                raise DescriptionError(
                    f"{loc}.limits",
                    "with a [coupling] the joint limits are on the readings: give them in "
                    "coupling.limits",
                )
        else:
            if isinstance(t.limits, UnsetType):
                raise DescriptionError(f"{loc}.limits", "missing required key")
            lo, hi = _limit_pair(t.limits, f"{loc}.limits")
            unit = 1.0 if t.joint == "prismatic" else _DEG  # metres or degrees
            limits = (lo * unit, hi * unit)
        if not isinstance(t.stiffness, UnsetType) and t.stiffness <= 0:
            raise DescriptionError(f"{loc}.stiffness", f"must be positive, got {t.stiffness:g}")
    else:
        for key in ("limits", "stiffness"):
            if not isinstance(getattr(t, key), UnsetType):
                raise DescriptionError(f"{loc}.{key}", f"only actuated joints take {key!r}")
    link = Link(name=t.name, parent=t.parent, joint=t.joint, theta=theta * _DEG, d=t.d, a=t.a,
                alpha=t.alpha * _DEG, beta=beta * _DEG, hayati=hayati, mass=t.mass, com=t.com)
    return link, limits


def description_from_document(doc: RobotFile) -> RobotDescription:
    """Build the model of a checked document: the file's rules between keys, SI units.

    Parameters
    ----------
    doc : RobotFile
        A document (:func:`document_from_dict`); lengths in m, angles in degrees.

    Returns
    -------
    RobotDescription
        The validated model (SI, radians).

    Raises
    ------
    DescriptionError
        Located at the key: a rule between keys (``links[2].beta: beta requires
        hayati = true``) or, from the model, the robot's consistency (``links[2].parent:
        unknown parent link '7'``).
    """
    notes = doc.notes if isinstance(doc.notes, str) else "\n".join(doc.notes)
    coupling, reading_limits = (None, None) if isinstance(doc.coupling, UnsetType) else (
        _coupling(doc.coupling))
    links: list[Link] = []
    limits: dict[str, tuple[float, float]] = {}
    stiff: dict[str, float] = {}
    for i, t in enumerate(doc.links):
        link, lim = _link(t, f"links[{i}]", coupling is not None)
        links.append(link)
        if lim is not None:
            limits[t.name] = lim
        if link.is_actuated and not isinstance(t.stiffness, UnsetType):
            stiff[t.name] = t.stiffness
    actuated = tuple(doc.actuated)

    loops = [FourBarLoop(t.arm, t.crank, t.coupler, t.follower,
                         "parallelogram" if isinstance(t.type, UnsetType) else t.type)
             for t in doc.loops]
    coupled = _coupled_limits(doc)
    pms = _point_masses(doc)
    box = _working_volume(doc)
    base = np.eye(4) if isinstance(doc.base, UnsetType) else _transform(doc.base, "base")
    tool = np.eye(4) if isinstance(doc.tool, UnsetType) else _transform(doc.tool, "tool")
    # limits in `actuated` order (unknown names are reported by the model)
    if reading_limits is not None:
        jl = reading_limits
    else:
        jl = np.array([limits.get(nm, (-math.pi, math.pi)) for nm in actuated],
                      dtype=float).reshape(len(actuated), 2)
    return RobotDescription(
        name=doc.name,
        links=tuple(links),
        actuated=actuated,
        flange=doc.flange,
        loops=tuple(loops),
        base=base,
        tool=tool,
        joint_limits=jl,
        stiffness=_stiffness(links, stiff, actuated),
        notes=notes,
        coupled_limits=tuple(coupled),
        home=_home(doc, links, actuated, coupling),
        point_masses=tuple(pms),
        working_volume=box,
        coupling=coupling,
    )


def _coupled_limits(doc: RobotFile) -> list[CoupledLimit]:
    """``[[coupled_limits]]``: ``lower < Σ joints < upper``, degrees → radians."""
    coupled = []
    for k, t in enumerate(doc.coupled_limits):
        if not t.lower < t.upper:
            raise DescriptionError(f"coupled_limits[{k}]",
                                   f"min {t.lower:g} must be below max {t.upper:g}")
        coupled.append(CoupledLimit(t.joints, t.lower * _DEG, t.upper * _DEG))
    return coupled


def _point_masses(doc: RobotFile) -> list[PointMass]:
    """``[[point_masses]]``, each mass ≥ 0 kg."""
    pms = []
    for k, p in enumerate(doc.point_masses):
        if p.mass < 0:
            raise DescriptionError(f"point_masses[{k}].mass", f"must be ≥ 0, got {p.mass:g}")
        pms.append(PointMass(p.name, p.link, p.mass, p.com))
    return pms


def _working_volume(doc: RobotFile) -> Box | None:
    """``[working_volume]``: a box of positive sizes (None: not given)."""
    if isinstance(doc.working_volume, UnsetType):
        return None
    for i, x in enumerate(doc.working_volume.size):
        if x <= 0:
            raise DescriptionError(f"working_volume.size[{i}]", f"must be positive, got {x:g}")
    return Box(doc.working_volume.center, doc.working_volume.size)


def _stiffness(links: list[Link], stiff: dict[str, float], actuated: tuple[str, ...]
               ) -> np.ndarray | None:
    """The joint stiffnesses in ``actuated`` order: for every actuated joint or none."""
    if not stiff:
        return None
    declared = {lk.name for lk in links if lk.joint == "actuated"}
    missing = [nm for nm in actuated if nm in declared and nm not in stiff]
    if missing:
        i = next(i for i, lk in enumerate(links) if lk.name == missing[0])
        raise DescriptionError(
            f"links[{i}].stiffness",
            "missing: give a stiffness for every actuated joint or for none",
        )
    return np.array([stiff.get(nm, 1.0) for nm in actuated])


def _home(doc: RobotFile, links: list[Link], actuated: tuple[str, ...], coupling: Any
          ) -> np.ndarray | None:
    """``home`` in SI: prismatic readings in metres, the others degrees → radians (with a
    coupling, every reading in degrees); its length is checked by the model."""
    if isinstance(doc.home, UnsetType):
        return None
    home = np.array(doc.home, dtype=float)
    if coupling is not None:
        return home * _DEG
    kinds = {lk.name: lk.joint for lk in links}
    unit = [1.0 if kinds.get(nm) == "prismatic" else _DEG for nm in actuated]
    return home * (np.array(unit) if len(unit) == len(home) else _DEG)


def description_from_dict(data: Any) -> RobotDescription:
    """Build and validate a robot from the dictionary of a description file.

    Parameters
    ----------
    data : Mapping
        The file's dictionary (``tomllib.load``, the ``description`` of PARAMS.json,
        :func:`description_to_dict`): lengths in m, angles in degrees, masses in kg.

    Returns
    -------
    RobotDescription
        The validated model (SI, radians).

    Raises
    ------
    DescriptionError
        Every problem, whatever the input (no other exception escapes), with a
        path-like location into ``data`` (``links[3].alpha``).
    """
    return description_from_document(document_from_dict(data))


# ================================================================================ writing
def _f(xs: Any) -> list[float]:
    return [float(x) for x in xs]


def _transform_table(T: np.ndarray) -> TransformTable:
    rpy = matrix_to_rpy(T[:3, :3])
    x, y, z = _f(T[:3, 3])
    r, p, w = (math.degrees(a) for a in rpy)
    return TransformTable(xyz=(x, y, z), rpy=(r, p, w))


def document_of(desc: RobotDescription) -> RobotFile:
    """The file document of a robot (file units: m, degrees, kg).

    Parameters
    ----------
    desc : RobotDescription
        The robot.

    Returns
    -------
    RobotFile
        Its document; :func:`description_from_document` builds the same robot from it.
    """
    act = {n: j for j, n in enumerate(desc.actuated)}
    links = []
    for lk in desc.links:
        t = LinkTable(name=lk.name, parent=lk.parent, joint=lk.joint,  # type: ignore[arg-type]
                      theta=math.degrees(lk.theta), d=float(lk.d), a=float(lk.a),
                      alpha=math.degrees(lk.alpha), mass=float(lk.mass),
                      com=tuple(_f(lk.com)))  # type: ignore[arg-type]
        if lk.hayati:
            t.hayati, t.beta = True, math.degrees(lk.beta)
        if lk.name in act:
            j = act[lk.name]
            if desc.coupling is None:
                scale = 1.0 if lk.is_prismatic else 180.0 / math.pi
                lo, hi = (float(x) * scale for x in desc.joint_limits[j])
                t.limits = (lo, hi)
            if desc.stiffness is not None:
                t.stiffness = float(desc.stiffness[j])
        links.append(t)
    doc = RobotFile(
        format_version=FORMAT_VERSION,
        name=desc.name,
        notes=desc.notes,
        actuated=list(desc.actuated),
        flange=desc.flange,
        home=(_f(np.asarray(desc.home) / desc.reading_scale("file"))
              if desc.home is not None else []),
        base=_transform_table(desc.base),
        tool=_transform_table(desc.tool),
        links=links,
        loops=[LoopTable(type=UNSET if lp.kind == "parallelogram" else lp.kind,  # type: ignore[arg-type]
                         arm=lp.arm, crank=lp.crank, coupler=lp.coupler, follower=lp.follower)
               for lp in desc.loops],
        coupled_limits=[CoupledLimitTable(joints=c.joints, lower=math.degrees(c.lower),
                                          upper=math.degrees(c.upper))
                        for c in desc.coupled_limits],
        point_masses=[PointMassTable(name=p.name, link=p.link, mass=float(p.mass),
                                     com=tuple(_f(p.com)))  # type: ignore[arg-type]
                      for p in desc.point_masses],
    )
    if desc.coupling is not None:
        c = desc.coupling
        doc.coupling = CouplingTable(
            readings=list(c.readings),
            matrix=[_f(row) for row in c.matrix],
            offsets=[math.degrees(x) for x in c.offset],
            limits=[(math.degrees(lo), math.degrees(hi)) for lo, hi in desc.joint_limits],
        )
    if desc.working_volume is not None:
        wv = desc.working_volume
        doc.working_volume = BoxTable(center=tuple(_f(wv.center)),  # type: ignore[arg-type]
                                      size=tuple(_f(wv.size)))  # type: ignore[arg-type]
    return doc


def description_to_dict(desc: RobotDescription) -> dict[str, Any]:
    """The dictionary of a description file of ``desc`` (inverse of
    :func:`description_from_dict`).

    Parameters
    ----------
    desc : RobotDescription
        The robot.

    Returns
    -------
    dict
        Plain JSON/TOML values (lists, floats, strings) in file units (m, degrees,
        kg), keys in the order of :class:`RobotFile`; optional keys the robot does
        not use (``coupling``, ``working_volume``, ``hayati``, ``stiffness``) are left
        out.  ``description_from_dict(description_to_dict(desc))`` is the same robot.
    """
    out: dict[str, Any] = _lists(msgspec.to_builtins(document_of(desc)))
    return out


def _lists(v: Any) -> Any:
    """Tuples (vectors, pairs, rows) as lists, as a parsed file has them."""
    if isinstance(v, dict):
        return {k: _lists(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_lists(x) for x in v]
    return v
