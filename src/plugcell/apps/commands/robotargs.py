"""The robot options every command shares: ``--robot`` and the URDF/xacro import options.

::

    --robot NAME|FILE            shipped name, .toml, .urdf, .xacro or .urdf.xacro file
    --robot-arg NAME=VALUE       xacro argument (repeatable), e.g. ur_type=ur10
    --package-path DIR           folder holding ROS packages (repeatable;
                                 also $PLUGCELL_PACKAGE_PATH, colon-separated)
    --base-link LINK             first link of the chain (default: the URDF's root)
    --tip-link LINK              last link of the chain, the TCP (default: the end of
                                 the only actuated chain)

:func:`add_robot_args` adds them to a parser, :func:`robot_source_of` reads them
into a :class:`~plugcell.io.robots.RobotSource` and :func:`load_robot_of` loads the
robot, turning every description error into the command's one-line error.
"""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING, Any

from plugcell.apps.cli import CommandError

if TYPE_CHECKING:
    from plugcell.io.robots import RobotSource
    from plugcell.kinematics.description import RobotDescription

ROBOT_HELP = ("shipped robot name (see 'plugcell kin robots'), a description file (.toml) "
              "or a URDF/xacro file (.urdf, .xacro, .urdf.xacro)")


def add_robot_args(parser: Any, *, required: bool = False, default: str | None = None,
                   help: str = ROBOT_HELP) -> None:
    """Add ``--robot`` and the import options to ``parser`` (a parser or argument group)."""
    parser.add_argument("--robot", required=required, default=default, help=help)
    parser.add_argument("--robot-arg", action="append", default=[], metavar="NAME=VALUE",
                        help="xacro argument of a .xacro robot, e.g. ur_type=ur10 (repeatable)")
    parser.add_argument("--package-path", action="append", default=[], metavar="DIR",
                        help="folder holding ROS packages for $(find PKG) (repeatable; also "
                        "$PLUGCELL_PACKAGE_PATH, colon-separated)")
    parser.add_argument("--base-link", metavar="LINK",
                        help="URDF robot: first link of the chain (default: the root link)")
    parser.add_argument("--tip-link", metavar="LINK",
                        help="URDF robot: last link of the chain, the TCP (default: the end "
                        "of the only actuated chain)")


def parse_robot_args(pairs: list[str]) -> dict[str, str]:
    """``["ur_type=ur10", ...]`` → ``{"ur_type": "ur10"}`` (ValueError naming the bad one)."""
    out: dict[str, str] = {}
    for pair in pairs:
        name, sep, value = pair.partition("=")
        name = name.strip()
        if name.endswith(":"):  # ur_type:=ur10, as xacro writes it
            name = name[:-1]
        if not sep or not name:
            raise ValueError(f"--robot-arg {pair!r}: expected NAME=VALUE, e.g. ur_type=ur10")
        out[name] = value
    return out


def robot_source_of(args: argparse.Namespace, ref: str | None = None) -> RobotSource:
    """The :class:`RobotSource` the options describe (``ref`` overrides ``--robot``)."""
    from plugcell.io.robots import RobotSource

    r = ref if ref is not None else args.robot
    try:
        xargs = parse_robot_args(getattr(args, "robot_arg", None) or [])
    except ValueError as exc:
        raise CommandError(str(exc)) from None
    return RobotSource(str(r), xargs, tuple(getattr(args, "package_path", None) or []),
                       getattr(args, "base_link", None), getattr(args, "tip_link", None))


def load_robot_of(args: argparse.Namespace, ref: str | None = None) -> RobotDescription:
    """Load the robot the options name; any description error is the command's error."""
    from plugcell.kinematics.errors import DescriptionError

    src = robot_source_of(args, ref)
    try:
        return src.load()
    except DescriptionError as exc:
        raise CommandError(str(exc)) from None


def robot_file_of(args: argparse.Namespace) -> str:
    """``--robot`` as one string another process can load (a name or a file path).

    A shipped name or a ``.toml`` file is returned as given.  A URDF/xacro robot is
    imported and written as a description file
    ``$PLUGCELL_HOME/robots/NAME-HASH.toml`` (HASH: of its content, so each distinct
    import is its own file and a re-import reuses it), whose path is returned: the
    robot service and its simulated controller take a robot as one string.
    """
    import hashlib
    import os
    import tempfile

    from plugcell.framework.journal import plugcell_home
    from plugcell.io.robots import description_to_toml

    src = robot_source_of(args)
    if not src.is_urdf:
        load_robot_of(args)  # a bad name, file or option is the command's error now
        return str(args.robot)
    desc = load_robot_of(args)
    text = description_to_toml(desc, f"imported by plugcell from {src.ref}\n"
                                     f"options: {' '.join(src.argv()[2:])}")
    digest = hashlib.sha256(text.encode()).hexdigest()[:12]
    path = plugcell_home() / "robots" / f"{desc.name}-{digest}.toml"
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        if not path.exists():  # written whole, then renamed: a reader never sees half
            fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".tmp")
            with os.fdopen(fd, "w", encoding="utf-8") as f:
                f.write(text)
            os.replace(tmp, path)
    except OSError as exc:
        raise CommandError(f"{path}: cannot write the imported robot: "
                           f"{exc.strerror or exc}") from None
    return str(path)
