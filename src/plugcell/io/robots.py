"""Robot description files (TOML) → :class:`~plugcell.kinematics.RobotDescription`.

The file format is documented in ``docs/robot-description.md``.  Shipped robots
live in the package directory ``plugcell/robots/`` and are addressed by bare
name (``"smart_h4"``); anything that looks like a path (contains a path
separator or ends in ``.toml``) is read as a file.  Every error names the file
and the key: ``smart_h4.toml: links[3].alpha: expected a number, got 'x'``.
"""

from __future__ import annotations

import os
import tomllib
from importlib import resources
from pathlib import Path

from plugcell.kinematics.description import RobotDescription
from plugcell.kinematics.errors import DescriptionError

__all__ = [
    "RobotNotFoundError",
    "available_robots",
    "load_robot",
    "load_robot_file",
    "robot_path",
]

SUFFIX = ".toml"


class RobotNotFoundError(DescriptionError, LookupError):
    """No shipped robot of that name, or no such file."""

    def __init__(self, message: str) -> None:
        super().__init__("", message)


def _robots_dir() -> Path:
    return Path(str(resources.files("plugcell") / "robots"))


def available_robots() -> list[str]:
    """Names of the robots shipped with plugcell (sorted)."""
    d = _robots_dir()
    if not d.is_dir():
        return []
    return sorted(p.stem for p in d.glob(f"*{SUFFIX}"))


def _looks_like_path(name: str) -> bool:
    return name.endswith(SUFFIX) or os.sep in name or (os.altsep is not None and os.altsep in name)


def robot_path(name_or_path: str | os.PathLike[str]) -> Path:
    """The file a robot name or path refers to (raises :class:`RobotNotFoundError`)."""
    if isinstance(name_or_path, os.PathLike) or _looks_like_path(str(name_or_path)):
        p = Path(name_or_path)
        if not p.is_file():
            raise RobotNotFoundError(f"robot description file not found: {p}")
        return p
    name = str(name_or_path)
    p = _robots_dir() / f"{name}{SUFFIX}"
    if not name or not p.is_file():
        avail = ", ".join(available_robots()) or "(none)"
        raise RobotNotFoundError(f"unknown robot {name!r}; available robots: {avail}")
    return p


def load_robot_file(path: str | os.PathLike[str]) -> RobotDescription:
    """Read and validate one description file; errors are prefixed with its name."""
    p = Path(path)
    label = p.name
    try:
        with p.open("rb") as fh:
            data = tomllib.load(fh)
    except FileNotFoundError:
        raise RobotNotFoundError(f"robot description file not found: {p}") from None
    except OSError as exc:
        raise DescriptionError(label, f"cannot read the file: {exc.strerror or exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise DescriptionError(label, f"invalid TOML: {exc}") from None
    except UnicodeDecodeError as exc:
        raise DescriptionError(label, f"invalid TOML: not UTF-8 ({exc.reason})") from None
    try:
        return RobotDescription.from_dict(data)
    except DescriptionError as exc:
        raise exc.with_prefix(label) from None


def load_robot(name_or_path: str | os.PathLike[str]) -> RobotDescription:
    """Load a shipped robot by name (``"smart_h4"``) or a description file by path."""
    return load_robot_file(robot_path(name_or_path))
