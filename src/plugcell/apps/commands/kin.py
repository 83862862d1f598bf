"""``plugcell kin`` — forward/inverse kinematics of a described robot.

::

    plugcell kin fk --robot smart_h4 --joints 0,-90,-187,0,90,0
    plugcell kin ik --robot smart_h4 --pose 1500,0,1200,0,90,0 [--seed 0,-90,-187,0,90,0]
    plugcell kin robots
    plugcell kin describe --robot smart_h4 [--format toml]
    plugcell kin describe --robot ur.urdf.xacro --robot-arg ur_type=ur10 --robot-arg name=ur10

Joint values in degrees (millimetres for a prismatic joint; description order),
positions in millimetres,
orientations as Comau Euler ZYZ angles (A, B, C) in degrees; the printed 4×4
matrix ``T`` is the flange pose in the robot base frame, in metres (``T_tcp``: the tool,
printed when the description has one — for a URDF robot its tip link).  FK evaluates
any configuration the loop can assemble and *reports* limit violations in
``warnings``; IK only returns solutions inside the limits.
"""

from __future__ import annotations

import argparse
import json
import math
import re
from typing import Any

import numpy as np

from plugcell.apps.cli import CommandError
from plugcell.apps.commands.deprecated import DeprecatedName
from plugcell.apps.commands.robotargs import add_robot_args, load_robot_of
from plugcell.apps.commands.subcommands import add_subcommands
from plugcell.io.robot_schema import description_to_dict
from plugcell.io.robots import available_robots
from plugcell.kinematics import (
    KinematicsError,
    RobotDescription,
    forward,
    inverse,
    matrix_to_pose,
    pose_to_matrix,
)

#: Accept values such as ``-10,20`` after ``--joints`` (Python < 3.13 argparse
#: would take them for an option).
_NEGATIVE_VALUE = re.compile(r"^-\.?\d")


def configure(kin: argparse.ArgumentParser) -> None:
    """Add the ``kin`` options to its parser (declared in :mod:`plugcell.apps.cli`)."""
    sub = add_subcommands(
        kin, "Forward and inverse kinematics of a described robot (see docs/kinematics.md).",
        "kin_command")

    fk = sub.add_parser(
        "fk",
        help="forward kinematics: flange pose for joint values",
        description="Print the flange pose in the robot base frame as JSON.",
    )
    add_robot_args(fk, required=True)
    fk.add_argument("--joints", required=True,
                    help="j1,...,jn in degrees (prismatic: mm), description order")
    fk.add_argument(
        "--closure",
        choices=("fourbar", "nominal"),
        default="fourbar",
        help="loop closure: exact planar four-bar (default) or the parallelogram formula (6.10)",
    )
    fk.set_defaults(func=_cmd_fk)

    ik = sub.add_parser(
        "ik",
        help="inverse kinematics: joint values for a flange pose",
        description="Print joint values (degrees) that put the flange at the pose, as JSON.",
    )
    add_robot_args(ik, required=True)
    ik.add_argument("--pose", required=True, help="x,y,z (mm),A,B,C (Comau ZYZ, degrees)")
    ik.add_argument("--start", "--seed", dest="start", action=DeprecatedName, old=("--seed",),
                    help="joints to start the search from: j1,...,jn in degrees (prismatic: "
                         "mm; default: the robot's home pose); --seed is its old name")
    ik.add_argument("--closure", choices=("fourbar", "nominal"), default="fourbar")
    ik.set_defaults(func=_cmd_ik)

    robots = sub.add_parser("robots", help="list the shipped robot descriptions")
    robots.set_defaults(func=_cmd_robots)

    describe = sub.add_parser(
        "describe",
        help="print a robot description (file units: m, deg, kg) as JSON or TOML",
        description="Print a robot description in file form — for a URDF/xacro robot, what "
        "was imported. '--format toml' is a description file that loads back unchanged.",
    )
    add_robot_args(describe, required=True)
    describe.add_argument("--format", choices=("json", "toml"), default=None,
                          help="toml (plugcell's description file; the default for a "
                          ".urdf/.xacro robot: what was imported) or json (the default "
                          "otherwise)")
    describe.set_defaults(func=_cmd_describe)

    for p in (fk, ik):
        if hasattr(p, "_negative_number_matcher"):
            p._negative_number_matcher = _NEGATIVE_VALUE


# ----------------------------------------------------------------------------- helpers
def _robot(args: argparse.Namespace) -> RobotDescription:
    return load_robot_of(args)


def _floats(text: str, n: int, option: str, what: str) -> np.ndarray:
    parts = [p.strip() for p in text.split(",")]
    if len(parts) != n or any(p == "" for p in parts):
        got = len([p for p in parts if p != ""])
        raise CommandError(
            f"{option}: expected {n} comma-separated numbers ({what}), got {got}: {text!r}"
        )
    out = []
    for i, p in enumerate(parts):
        try:
            v = float(p)
        except ValueError:
            raise CommandError(f"{option}: value {i + 1} ({p!r}) is not a number") from None
        if not math.isfinite(v):
            raise CommandError(f"{option}: value {i + 1} ({p!r}) is not finite")
        out.append(v)
    return np.array(out)


def _joint_names(desc: RobotDescription) -> str:
    units = " (mm for " + ", ".join(n for n, p in zip(desc.reading_names, desc.prismatic_readings,
                                                       strict=True) if p) + ")" \
        if desc.prismatic_readings.any() else ""
    return "joints " + ", ".join(desc.reading_names) + " in degrees" + units


def _dumps(obj: Any, indent: int = 0) -> str:
    """JSON with one line per matrix row and flat lists on one line."""
    pad = "  " * (indent + 1)
    if isinstance(obj, dict) and obj:
        items = [f"{pad}{json.dumps(k)}: {_dumps(v, indent + 1)}" for k, v in obj.items()]
        return "{\n" + ",\n".join(items) + "\n" + "  " * indent + "}"
    if isinstance(obj, list) and obj and all(isinstance(r, list) for r in obj):
        rows = [f"{pad}{json.dumps(r)}" for r in obj]
        return "[\n" + ",\n".join(rows) + "\n" + "  " * indent + "]"
    if isinstance(obj, list) and any(isinstance(r, (dict, list)) for r in obj):
        return json.dumps(obj, indent=2)
    return json.dumps(obj, ensure_ascii=False)


def _print(obj: dict[str, Any]) -> None:
    print(_dumps(obj))


def _r(x: float, nd: int = 9) -> float:
    v = round(float(x), nd)
    return 0.0 if v == 0 else v


# ----------------------------------------------------------------------------- commands
def _cmd_fk(args: argparse.Namespace) -> int:
    desc = _robot(args)
    qdeg = _floats(args.joints, desc.n_readings, "--joints", _joint_names(desc))
    q = qdeg * desc.reading_scale()
    try:
        fk = forward(desc, None, q, closure=args.closure)
    except KinematicsError as exc:
        raise CommandError(f"{desc.name}: {exc}") from None
    xyz, zyz = matrix_to_pose(fk.flange, "zyz")
    out: dict[str, Any] = {
        "robot": desc.name,
        "T": [[_r(v, 12) for v in row] for row in fk.flange],
        "pose_mm_zyz": [_r(v * 1e3, 6) for v in xyz] + [_r(math.degrees(v), 6) for v in zyz],
        "warnings": desc.limit_violations(q),
    }
    if not np.allclose(desc.tool, np.eye(4), atol=1e-12):  # e.g. a URDF's tip link (tool0)
        txyz, tzyz = matrix_to_pose(fk.tcp, "zyz")
        out["T_tcp"] = [[_r(v, 12) for v in row] for row in fk.tcp]
        out["tcp_mm_zyz"] = ([_r(v * 1e3, 6) for v in txyz]
                             + [_r(math.degrees(v), 6) for v in tzyz])
    if fk.passive_names:
        out["passive_deg"] = {
            name: _r(math.degrees(fk.passive[k]), 9) for k, name in enumerate(fk.passive_names)
        }
    _print(out)
    return 0


def _cmd_ik(args: argparse.Namespace) -> int:
    desc = _robot(args)
    pose = _floats(args.pose, 6, "--pose", "x,y,z in mm and A,B,C Comau ZYZ in degrees")
    seed = None
    if args.start is not None:
        seed = (_floats(args.start, desc.n_readings, "--start", _joint_names(desc))
                * desc.reading_scale())
    T = pose_to_matrix(pose[:3] * 1e-3, np.radians(pose[3:]), "zyz")
    try:
        res = inverse(desc, None, T, seed, closure=args.closure)
    except KinematicsError as exc:
        raise CommandError(f"{desc.name}: {exc}") from None
    _print(
        {
            "robot": desc.name,
            "joints": [_r(v, 9) for v in np.asarray(res.q) / desc.reading_scale()],
            "position_error_mm": float(f"{res.position_error * 1e3:.3g}"),
            "orientation_error_deg": float(f"{math.degrees(res.orientation_error):.3g}"),
        }
    )
    return 0


def _cmd_robots(args: argparse.Namespace) -> int:
    for name in available_robots():
        print(name)
    return 0


def _cmd_describe(args: argparse.Namespace) -> int:
    desc = _robot(args)
    fmt = args.format
    if fmt is None:
        from plugcell.io.urdf import is_urdf_path

        fmt = "toml" if is_urdf_path(args.robot) else "json"
    if fmt == "toml":
        from plugcell.io.robots import description_to_toml

        print(description_to_toml(desc), end="")
    else:
        _print(description_to_dict(desc))
    return 0
