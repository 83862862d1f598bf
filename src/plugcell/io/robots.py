"""Robot description files (TOML, URDF, xacro) → :class:`~plugcell.kinematics.RobotDescription`.

The file format is documented in ``docs/robot-description.md``.  Shipped robots
live in the package directory ``plugcell/robots/`` and are addressed by bare
name (``"smart_h4"``); anything that looks like a path (contains a path
separator or ends in ``.toml``, ``.urdf`` or ``.xacro``) is read as a file —
URDF and xacro files through :mod:`plugcell.io.urdf`, TOML files through the
file schema of :mod:`plugcell.io.robot_schema`.  Every error names the file and
the key: ``smart_h4.toml: links[3].alpha: expected a number, got 'x'``.

:class:`RobotSource` is *where a robot comes from* (the name or path and, for
URDF/xacro, the xacro arguments, package directories and chain ends): one value
that loads the robot, is recorded in PARAMS.json and is passed to sub-processes.
"""

from __future__ import annotations

import os
import re
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from plugcell.io.errors import RobotNotFoundError
from plugcell.io.robot_schema import description_from_dict, description_to_dict
from plugcell.kinematics.description import RobotDescription
from plugcell.kinematics.errors import DescriptionError

__all__ = [
    "RobotNotFoundError",
    "RobotSource",
    "available_robots",
    "description_of_params",
    "description_to_toml",
    "load_robot",
    "load_robot_file",
    "robot_path",
]

SUFFIX = ".toml"


def _robots_dir() -> Path:
    return Path(str(resources.files("plugcell") / "robots"))


def available_robots() -> list[str]:
    """Names of the robots shipped with plugcell, sorted.

    Returns
    -------
    list of str
        The stems of the ``*.toml`` files of the package directory ``plugcell/robots/``
        (``["fanuc_m20ia", "smart_h4", …]``); empty if the directory is missing.
    """
    d = _robots_dir()
    if not d.is_dir():
        return []
    return sorted(p.stem for p in d.glob(f"*{SUFFIX}"))


def _looks_like_path(name: str) -> bool:
    from plugcell.io.urdf import is_urdf_path

    return (name.endswith(SUFFIX) or is_urdf_path(name) or os.sep in name
            or (os.altsep is not None and os.altsep in name))


def robot_path(name_or_path: str | os.PathLike[str]) -> Path:
    """The file a robot name or path refers to.

    Parameters
    ----------
    name_or_path : str or os.PathLike
        A shipped robot's bare name (``"smart_h4"``), or a path: any ``os.PathLike``, or
        a string ending in ``.toml``, ``.urdf``, ``.xacro`` or holding a path separator.

    Returns
    -------
    Path
        The existing file: ``plugcell/robots/NAME.toml`` for a name, the path as given
        (not resolved) otherwise.

    Raises
    ------
    RobotNotFoundError
        A path that is no file, or a name of no shipped robot (the message lists the
        shipped ones).
    """
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
    """Read and validate one TOML description file.

    The file's units (lengths m, angles degrees, masses kg, stiffness N·m/rad; layout
    in ``docs/robot-description.md``) become SI radians in
    :func:`plugcell.io.robot_schema.description_from_document`.

    Parameters
    ----------
    path : str or os.PathLike
        The ``.toml`` file (UTF-8).  URDF/xacro files are not read here: use
        :func:`load_robot`.

    Returns
    -------
    RobotDescription
        The validated model, in SI units with radians.

    Raises
    ------
    RobotNotFoundError
        No such file.
    DescriptionError
        Located at ``FILE.toml: key``: an unreadable file, invalid TOML or UTF-8, a
        schema error or an inconsistent robot.
    """
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
        return description_from_dict(data)
    except DescriptionError as exc:
        raise exc.with_prefix(label) from None


def robot_identification(name_or_path: str | os.PathLike[str]) -> dict[str, str]:
    """The ``[identification]`` table of a robot's description file.

    Parameters
    ----------
    name_or_path : str or os.PathLike
        A shipped robot's name or a ``.toml`` file (:func:`robot_path`).

    Returns
    -------
    dict of str to str
        ``manufacturer``, ``model``, ``serial_number``, ``product_code`` (``""`` where
        the file does not say; all ``""`` for a URDF/xacro robot or a file without
        the table).

    Raises
    ------
    RobotNotFoundError
        No such robot or file.
    DescriptionError
        The file does not read or does not follow the schema (located at the key).
    """
    from plugcell.io.robot_schema import IdentificationTable, document_from_dict

    p = robot_path(name_or_path)
    table = IdentificationTable()
    if p.suffix == SUFFIX:
        try:
            with p.open("rb") as fh:
                data = tomllib.load(fh)
        except (OSError, tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
            raise DescriptionError(p.name, f"cannot read the file: {exc}") from None
        try:
            found = document_from_dict(data).identification
        except DescriptionError as exc:
            raise exc.with_prefix(p.name) from None
        if isinstance(found, IdentificationTable):
            table = found
    return {key: getattr(table, key) for key in IdentificationTable.__struct_fields__}


def load_robot(
    name_or_path: str | os.PathLike[str],
    *,
    args: Mapping[str, str] | None = None,
    package_paths: Sequence[str | os.PathLike[str]] = (),
    base_link: str | None = None,
    tip_link: str | None = None,
) -> RobotDescription:
    """Load a shipped robot by name (``"smart_h4"``) or a description file by path.

    A ``.urdf``/``.xacro`` path is imported (:func:`plugcell.io.urdf.import_urdf`)
    with the xacro ``args``, ROS ``package_paths`` and chain ends; these options are
    an error for any other robot.  The same as
    ``RobotSource(name_or_path, args, package_paths, base_link, tip_link).load()``.

    Parameters
    ----------
    name_or_path : str or os.PathLike
        A shipped robot's name, or a ``.toml``, ``.urdf`` or ``.xacro`` file
        (:func:`robot_path` says which is which).
    args : mapping of str to str, optional
        xacro arguments (``name:=value``), URDF/xacro only.
    package_paths : sequence of str or os.PathLike
        Directories holding ROS packages for ``$(find PKG)``, URDF/xacro only.
    base_link, tip_link : str, optional
        The chain's ends in a URDF; default the root link and the chain's single (or
        ``tool0``) tip.

    Returns
    -------
    RobotDescription
        The validated model, in SI units with radians (TOML files are in m and
        degrees, URDF in m and rad).

    Raises
    ------
    RobotNotFoundError
        No shipped robot of that name, or no such file.
    DescriptionError
        A file that is not a valid description (located at file and key or element), or
        URDF-only options given for a TOML robot.
    """
    return RobotSource(str(name_or_path), dict(args or {}),
                       tuple(str(p) for p in package_paths), base_link, tip_link).load()


@dataclass(frozen=True)
class RobotSource:
    """Where a robot comes from: ``ref`` (shipped name or file path) and import options.

    One value that loads the robot (:meth:`load`), is recorded in PARAMS.json
    (:meth:`to_dict`, :meth:`from_dict`) and is passed to sub-processes (:meth:`argv`).

    Attributes
    ----------
    ref : str
        A shipped robot's name or a ``.toml``/``.urdf``/``.xacro`` file path.
    args : mapping of str to str
        xacro arguments; URDF/xacro only.
    package_paths : tuple of str
        Directories holding ROS packages; URDF/xacro only.
    base_link, tip_link : str or None
        The chain's ends; URDF/xacro only, ``None`` for the default.
    """

    ref: str
    args: Mapping[str, str] = field(default_factory=dict)
    package_paths: tuple[str, ...] = ()
    base_link: str | None = None
    tip_link: str | None = None

    @property
    def is_urdf(self) -> bool:
        """Whether ``ref`` names a URDF or xacro file (:func:`~plugcell.io.urdf.is_urdf_path`)."""
        from plugcell.io.urdf import is_urdf_path

        return is_urdf_path(self.ref)

    def load(self) -> RobotDescription:
        """Load the robot this source names.

        Returns
        -------
        RobotDescription
            The validated model, in SI units with radians.

        Raises
        ------
        RobotNotFoundError
            No shipped robot of that name, or no such file.
        DescriptionError
            An invalid description (naming file and element), or URDF-only options
            (``args``, ``package_paths``, ``base_link``, ``tip_link``) on a TOML robot
            (located at the command-line option, e.g. ``--robot-arg``).
        """
        if self.is_urdf:
            return self.import_urdf().description
        extra = [opt for opt, v in (("--robot-arg", self.args),
                                    ("--package-path", self.package_paths),
                                    ("--base-link", self.base_link),
                                    ("--tip-link", self.tip_link)) if v]
        if extra:
            raise DescriptionError(
                extra[0], f"applies to .urdf/.xacro robots only, not to {self.ref!r}")
        return load_robot_file(robot_path(self.ref))

    def import_urdf(self) -> Any:
        """Import a URDF/xacro source (:func:`plugcell.io.urdf.import_urdf`).

        Returns
        -------
        ImportedRobot
            The description, the chain and the expanded URDF text.

        Raises
        ------
        DescriptionError
            The file cannot be expanded, parsed or converted (naming file and element).
        """
        from plugcell.io.urdf import import_urdf

        return import_urdf(self.ref, self.args, self.package_paths, self.base_link,
                           self.tip_link)

    def absolute(self) -> RobotSource:
        """The same source with file paths made absolute (to record or pass on).

        Returns
        -------
        RobotSource
            ``ref`` resolved if it looks like a path (a shipped name stays as it is),
            every ``package_paths`` entry resolved; the other fields copied.
        """
        ref = self.ref
        if _looks_like_path(ref):
            ref = str(Path(ref).resolve())
        return RobotSource(ref, dict(self.args), tuple(str(Path(p).resolve())
                                                       for p in self.package_paths),
                           self.base_link, self.tip_link)

    def to_dict(self) -> dict[str, Any]:
        """JSON form (``robot_source`` of PARAMS.json).

        Returns
        -------
        dict
            ``{"ref": …}`` plus ``args``, ``package_paths``, ``base_link`` and
            ``tip_link`` when they are set.
        """
        out: dict[str, Any] = {"ref": self.ref}
        if self.args:
            out["args"] = dict(self.args)
        if self.package_paths:
            out["package_paths"] = list(self.package_paths)
        if self.base_link:
            out["base_link"] = self.base_link
        if self.tip_link:
            out["tip_link"] = self.tip_link
        return out

    @classmethod
    def from_dict(cls, d: Any) -> RobotSource:
        """Inverse of :meth:`to_dict`.

        Parameters
        ----------
        d : Any
            A ``robot_source`` object of PARAMS.json (a mapping with a non-empty
            ``ref``); anything else is an error.

        Returns
        -------
        RobotSource
            The source; empty ``base_link``/``tip_link`` strings become ``None``.

        Raises
        ------
        DescriptionError
            Located at ``robot_source`` or its key: not a mapping, no ``ref``, ``args``
            not an object of strings, ``package_paths`` not a list of strings, or a link
            name that is not a string.
        """
        if not isinstance(d, Mapping) or not isinstance(d.get("ref"), str) or not d["ref"]:
            raise DescriptionError("robot_source", "expected an object with a non-empty 'ref'")
        args = d.get("args", {})
        paths = d.get("package_paths", [])
        if not (isinstance(args, Mapping) and all(isinstance(k, str) and isinstance(v, str)
                                                  for k, v in args.items())):
            raise DescriptionError("robot_source.args", "expected an object of strings")
        if not (isinstance(paths, list) and all(isinstance(p, str) for p in paths)):
            raise DescriptionError("robot_source.package_paths", "expected a list of strings")
        ends = {k: d.get(k) for k in ("base_link", "tip_link")}
        for k, v in ends.items():
            if v is not None and not isinstance(v, str):
                raise DescriptionError(f"robot_source.{k}", "expected a string")
        return cls(d["ref"], dict(args), tuple(paths), ends["base_link"] or None,
                   ends["tip_link"] or None)

    def argv(self, option: str = "--robot") -> list[str]:
        """Command-line options that give this source to another plugcell process.

        Parameters
        ----------
        option : str
            The option naming the robot, ``--robot`` by default.

        Returns
        -------
        list of str
            ``[option, ref]`` then ``--robot-arg K=V``, ``--package-path P``,
            ``--base-link``, ``--tip-link`` as set.
        """
        out = [option, self.ref]
        for k, v in self.args.items():
            out += ["--robot-arg", f"{k}={v}"]
        for p in self.package_paths:
            out += ["--package-path", p]
        if self.base_link:
            out += ["--base-link", self.base_link]
        if self.tip_link:
            out += ["--tip-link", self.tip_link]
        return out


def description_to_toml(desc: RobotDescription, header: str = "") -> str:
    """The description as a TOML description file (loads back to the same robot).

    Written through :func:`plugcell.io.robot_schema.description_to_dict`, so in the
    file's units (lengths m, angles degrees); empty ``notes``, ``loops``,
    ``coupled_limits`` and ``point_masses`` are left out, arrays of numbers are
    written on one line.

    Parameters
    ----------
    desc : RobotDescription
        The model (SI, radians).
    header : str
        Comment lines put at the top, without ``#`` (each line gets ``# ``).

    Returns
    -------
    str
        The TOML text (needs the ``tomli_w`` package).
    """
    import tomli_w

    d = description_to_dict(desc)
    if not d.get("notes"):
        d.pop("notes", None)
    for key in ("loops", "coupled_limits", "point_masses"):
        if not d.get(key):
            d.pop(key, None)
    lines = "".join(f"# {ln}\n" for ln in header.splitlines())
    return lines + _one_line_arrays(tomli_w.dumps(d))


_SCALAR_ARRAY = re.compile(r"\[\n((?:    [^\[\]{}\n]+,\n)+)\]")


def _one_line_arrays(text: str) -> str:
    """tomli-w writes an array an element a line; put arrays of scalars on one line."""
    return _SCALAR_ARRAY.sub(
        lambda m: "[" + ", ".join(x.strip().rstrip(",") for x in m.group(1).splitlines()) + "]",
        text)


def description_of_params(d: Mapping[str, Any], label: str = "PARAMS") -> RobotDescription:
    """The robot a calibration (PARAMS.json dictionary) was made for.

    The embedded ``description`` (written by ``plugcell calibrate``; file units, m
    and degrees) if present, else the ``robot_source`` it was loaded from, else the
    shipped robot named ``robot``.

    Parameters
    ----------
    d : mapping
        The PARAMS.json dictionary.
    label : str
        Where the dictionary comes from (its file name), the start of error locations.

    Returns
    -------
    RobotDescription
        The model, in SI units with radians.

    Raises
    ------
    DescriptionError
        Located at ``LABEL: description`` (or ``robot_source``, ``robot``): an invalid
        embedded description, a bad or unloadable source, or an unknown robot name
        (also when the dictionary names none).
    """
    try:
        if "description" in d:
            return description_from_dict(d["description"])
        if "robot_source" in d:
            return RobotSource.from_dict(d["robot_source"]).load()
        return load_robot(str(d.get("robot", "")))
    except DescriptionError as exc:
        key = "description" if "description" in d else (
            "robot_source" if "robot_source" in d else "robot")
        raise exc.with_prefix(f"{label}: {key}") from None
