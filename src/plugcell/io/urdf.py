"""URDF and xacro files → :class:`~plugcell.kinematics.RobotDescription`.

The parser side of the import (like Pinocchio's ``buildModelFromUrdf``): xacro
expansion with the ROS ``xacro`` package (from PyPI, no ROS installation needed),
URDF parsing with ``yourdfpy`` (meshes are never loaded, so missing mesh files do
not matter), the chain from the base link to the tip link, and then the exact
DH/Hayati conversion of :mod:`plugcell.kinematics.joint_chain`.

``$(find PKG)`` in a xacro file resolves to a folder named ``PKG`` in (in this
order) the ``package_paths`` given, the directories of the environment variable
``PLUGCELL_PACKAGE_PATH`` (colon-separated), the file's own package (the nearest
folder above the file with a ``package.xml``) and the folders beside it.

Every error is a :class:`~plugcell.kinematics.errors.DescriptionError` whose
location starts with the file name and names the element:
``m20ia.xacro: xacro: unknown package 'fanuc_resources' (looked in: ...)``,
``robot.urdf: joint 'j7': floating joints cannot be part of a robot's chain``.
"""

from __future__ import annotations

import contextlib
import io
import math
import os
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from xml.parsers.expat import ExpatError

import numpy as np

from plugcell.io.errors import RobotNotFoundError
from plugcell.kinematics.description import RobotDescription
from plugcell.kinematics.errors import DescriptionError
from plugcell.kinematics.joint_chain import ChainJoint, JointChain, description_from_chain

__all__ = [
    "PACKAGE_PATH_ENV",
    "URDF_SUFFIXES",
    "ImportedRobot",
    "PackageResolver",
    "expand_xacro",
    "import_urdf",
    "is_urdf_path",
    "parse_urdf",
]

#: Environment variable with extra package directories (colon-separated).
PACKAGE_PATH_ENV = "PLUGCELL_PACKAGE_PATH"
#: File name endings read as URDF (``.urdf``) or xacro (the others).
URDF_SUFFIXES: tuple[str, ...] = (".urdf", ".xacro", ".urdf.xacro")
#: ROS-Industrial's all-zeros tool frame: the default tip where the chain branches.
TOOL0 = "tool0"


def is_urdf_path(name: str | os.PathLike[str]) -> bool:
    """Whether ``name`` ends like a URDF or xacro file.

    Parameters
    ----------
    name : str or os.PathLike
        A file name or path (need not exist).

    Returns
    -------
    bool
        True when it ends, case-insensitively, in one of :data:`URDF_SUFFIXES`
        (``.urdf``, ``.xacro``).
    """
    return str(name).lower().endswith(URDF_SUFFIXES)


# =============================================================================== packages
@dataclass(frozen=True)
class PackageResolver:
    """Finds ROS package folders without ROS (``$(find PKG)``, ``package://PKG/``).

    Package ``PKG`` is a sub-folder named ``PKG`` of one of :meth:`search_dirs`.

    Attributes
    ----------
    package_paths : tuple of Path
        Directories searched first (``--package-path``).
    source : Path or None
        The file being read; the folder above its own package (the nearest folder
        with a ``package.xml``) is searched last.
    """

    package_paths: tuple[Path, ...] = ()
    source: Path | None = None

    def search_dirs(self) -> list[Path]:
        """Directories whose sub-folder ``PKG`` is package ``PKG``, in search order.

        Returns
        -------
        list of Path
            ``package_paths``, then the entries of ``$PLUGCELL_PACKAGE_PATH``
            (colon-separated), then the parent of :meth:`own_package` if any.
        """
        dirs = [Path(p) for p in self.package_paths]
        env = os.environ.get(PACKAGE_PATH_ENV, "")
        dirs += [Path(p) for p in env.split(":") if p]
        own = self.own_package()
        if own is not None:
            dirs.append(own.parent)
        return dirs

    def own_package(self) -> Path | None:
        """The nearest folder above the source file that holds a ``package.xml``.

        Returns
        -------
        Path or None
            That folder (resolved), or ``None`` without ``source`` or such a folder.
        """
        if self.source is None:
            return None
        for d in Path(self.source).resolve().parents:
            if (d / "package.xml").is_file():
                return d
        return None

    def find(self, package: str) -> Path:
        """The folder of a ROS package.

        Parameters
        ----------
        package : str
            The package name (no ``/``, not ``.`` or ``..``).

        Returns
        -------
        Path
            The first ``DIR/package`` folder of :meth:`search_dirs`, resolved.

        Raises
        ------
        LookupError
            An invalid name, or no such folder (the message lists where it looked).
        """
        if not package or "/" in package or package in (".", ".."):
            raise LookupError(f"invalid package name {package!r}")
        dirs = self.search_dirs()
        for d in dirs:
            p = d / package
            if p.is_dir():
                return p.resolve()
        where = ", ".join(str(d) for d in dirs) or "nowhere: give --package-path DIR"
        raise LookupError(f"unknown package {package!r} (looked in: {where})")


# =============================================================================== xacro
@contextlib.contextmanager
def _find_hook(resolver: PackageResolver) -> Iterator[None]:
    """Route xacro's ``$(find PKG)`` to ``resolver`` while expanding (restored after)."""
    from xacro import substitution_args

    saved = substitution_args._eval_find
    substitution_args._eval_find = lambda pkg: str(resolver.find(pkg))
    try:
        yield
    finally:
        substitution_args._eval_find = saved


def expand_xacro(path: Path, args: Mapping[str, str], resolver: PackageResolver) -> str:
    """The URDF text of a xacro file expanded with its arguments.

    Parameters
    ----------
    path : Path
        The xacro file.
    args : mapping of str to str
        xacro arguments (``name:=value`` on the xacro command line).
    resolver : PackageResolver
        Where ``$(find PKG)`` looks while expanding.

    Returns
    -------
    str
        The expanded URDF, pretty-printed XML (units as in URDF: m, rad).

    Raises
    ------
    DescriptionError
        Located at the file name (``x.xacro: xacro: …``, or ``x.xacro (in INCLUDED)``
        for an included file): a xacro error, an argument without value, an unknown
        package, an unreadable file or malformed XML.
    """
    import xacro

    label = path.name
    try:
        with _find_hook(resolver), contextlib.redirect_stdout(io.StringIO()):
            doc = xacro.process_file(str(path), mappings=dict(args))
        return str(doc.toprettyxml(indent="  "))
    except xacro.XacroException as exc:
        from xacro.substitution_args import ArgException

        inner = getattr(exc, "exc", None)
        msg = str(inner) if isinstance(inner, LookupError) else str(exc)
        if isinstance(inner, ArgException):
            msg = (f"the xacro argument {str(inner)!r} has no value: give "
                   f"--robot-arg {inner}=VALUE")
        where = _xacro_file()
        loc = label if where in (None, str(path)) else f"{label} (in {where})"
        raise DescriptionError(loc, f"xacro: {' '.join(msg.split())}") from None
    except OSError as exc:
        raise DescriptionError(label, f"cannot read: {exc.strerror or exc}") from None
    except ExpatError as exc:
        raise DescriptionError(label, f"malformed XML: {exc}") from None
    except Exception as exc:  # anything else xacro's evaluation raises
        where = _xacro_file()
        loc = label if where in (None, str(path)) else f"{label} (in {where})"
        raise DescriptionError(loc, f"xacro: {type(exc).__name__}: {exc}") from None


def _xacro_file() -> str | None:
    import xacro

    stack = getattr(xacro, "filestack", None)
    return str(stack[-1]) if stack else None


# =============================================================================== URDF
def parse_urdf(text: str, label: str) -> Any:
    """Parse URDF text into a ``yourdfpy.URDF`` (no meshes loaded).

    Before yourdfpy reads it, every ``<link>`` and ``<joint>`` is checked for a unique
    name, every joint for a type, known ``<parent>``/``<child>`` links and finite
    numbers in ``<origin xyz rpy>`` (m, rad), ``<axis xyz>`` and ``<limit lower upper>``
    (rad, or m for a prismatic joint).

    Parameters
    ----------
    text : str
        The URDF XML, root element ``<robot>``.
    label : str
        The file name, the start of error locations.

    Returns
    -------
    yourdfpy.URDF
        The parsed robot (no scene graph, no meshes).

    Raises
    ------
    DescriptionError
        Located at ``LABEL`` or ``LABEL: joint 'J'`` (with the element): malformed XML,
        a root other than ``<robot>``, a failed element check, or yourdfpy's error.
    """
    from lxml import etree
    from yourdfpy import URDF
    from yourdfpy.urdf import URDFError

    try:
        root = etree.fromstring(text.encode("utf-8"))
    except etree.XMLSyntaxError as exc:
        raise DescriptionError(label, f"malformed XML: {exc}") from None
    if root.tag != "robot":
        raise DescriptionError(label, f"not a URDF: the root element is <{root.tag}>, not <robot>")
    _check_elements(root, label)
    try:
        return URDF.load(
            io.BytesIO(text.encode("utf-8")),
            build_scene_graph=False,
            build_collision_scene_graph=False,
            load_meshes=False,
            load_collision_meshes=False,
            filename_handler=lambda fname: fname,
        )
    except (URDFError, ValueError, TypeError, KeyError, AttributeError) as exc:
        raise DescriptionError(label, f"invalid URDF: {exc}") from None


def _check_elements(root: Any, label: str) -> None:
    """Names, parents and numbers of links and joints (before yourdfpy reads them)."""
    links: set[str] = set()
    for el in root.findall("link"):
        name = el.get("name")
        if not name:
            raise DescriptionError(f"{label}: line {el.sourceline}: <link>", "has no name")
        if name in links:
            raise DescriptionError(f"{label}: link {name!r}", "defined twice")
        links.add(name)
    joints: set[str] = set()
    for el in root.findall("joint"):
        name = el.get("name")
        if not name:
            raise DescriptionError(f"{label}: line {el.sourceline}: <joint>", "has no name")
        loc = f"{label}: joint {name!r}"
        if name in joints:
            raise DescriptionError(loc, "defined twice")
        joints.add(name)
        if not el.get("type"):
            raise DescriptionError(loc, "has no type")
        for tag in ("parent", "child"):
            sub = el.find(tag)
            ref = None if sub is None else sub.get("link")
            if not ref:
                raise DescriptionError(loc, f"has no <{tag} link=...>")
            if ref not in links:
                raise DescriptionError(f"{loc}: <{tag}>", f"unknown link {ref!r}")
        for tag, attrs in (("origin", ("xyz", "rpy")), ("axis", ("xyz",)),
                           ("limit", ("lower", "upper"))):
            sub = el.find(tag)
            if sub is None:
                continue
            for attr in attrs:
                v = sub.get(attr)
                if v is None:
                    continue
                parts = v.split()
                n = 3 if tag != "limit" else 1
                try:
                    vals = [float(p) for p in parts]
                except ValueError:
                    vals = []
                if len(vals) != n or not all(math.isfinite(x) for x in vals):
                    raise DescriptionError(
                        f"{loc}: <{tag} {attr}>", f"expected {n} finite number(s), got {v!r}"
                    )


@dataclass(frozen=True, eq=False)
class ImportedRobot:
    """What :func:`import_urdf` read: the description and where it came from.

    Attributes
    ----------
    description : RobotDescription
        The converted model (DH/Hayati, SI, radians); its joint readings are the URDF
        joint positions (rad, m for prismatic joints) in chain order.
    urdf : str
        The (expanded) URDF text.
    base_link, tip_link : str
        The chain's ends.
    joints : tuple of str
        The chain's joint names in order, fixed ones included.
    source : Path
        The file read.
    args : mapping of str to str
        The xacro arguments used.
    chain : JointChain or None
        The joints as read (origins 4×4 in m, unit axes), from which the description
        was converted.
    """

    description: RobotDescription
    urdf: str
    base_link: str
    tip_link: str
    joints: tuple[str, ...]
    source: Path
    args: Mapping[str, str] = field(default_factory=dict)
    chain: JointChain | None = None


def _tree(urdf: Any, label: str) -> tuple[dict[str, Any], dict[str, list[Any]], list[str]]:
    """``parent_joint[link]``, ``child_joints[link]`` and the root links."""
    parent: dict[str, Any] = {}
    children: dict[str, list[Any]] = {lk.name: [] for lk in urdf.robot.links}
    for jt in urdf.robot.joints:
        if jt.child in parent:
            raise DescriptionError(
                f"{label}: link {jt.child!r}",
                f"is the child of joints {parent[jt.child].name!r} and {jt.name!r}: a closed "
                "loop (URDF describes trees; describe a parallelogram in plugcell's TOML format)",
            )
        parent[jt.child] = jt
        children[jt.parent].append(jt)
    # a cycle of joints leaves no root for the links on it
    for start in parent:
        seen = {start}
        lk = start
        while lk in parent:
            lk = parent[lk].parent
            if lk in seen:
                raise DescriptionError(
                    f"{label}: link {lk!r}",
                    f"lies on a closed loop of joints (through {parent[lk].name!r})",
                )
            seen.add(lk)
    roots = [lk.name for lk in urdf.robot.links if lk.name not in parent]
    return parent, children, roots


def _default_tip(children: dict[str, list[Any]], parent: dict[str, Any], start: str,
                 label: str) -> str:
    """End of the only actuated chain below ``start``.

    The deepest moving joint must have every other moving joint above it (else the
    robot branches: an error asking for ``--tip-link``); the tip is the single leaf
    fixed to its child link, else ``tool0`` if fixed to it, else the child link itself.
    """
    moving = [j for j in _descendant_joints(children, start) if j.type != "fixed"]
    if not moving:
        raise DescriptionError(label, "the robot has no moving joint (nothing to import)")

    def ancestors(link: str) -> list[str]:
        out = []
        while link != start and link in parent:
            out.append(parent[link].name)
            link = parent[link].parent
        return out

    last = max(moving, key=lambda j: len(ancestors(j.child)))
    above = set(ancestors(last.child))
    off = [j.name for j in moving if j.name not in above]
    if off:
        raise DescriptionError(
            label,
            f"the robot branches into several actuated chains (joints {last.name!r} and "
            f"{off[0]!r}); choose one with --tip-link LINK",
        )
    leaves = _fixed_leaves(children, last.child)
    if len(leaves) == 1:
        return leaves[0]
    if TOOL0 in _fixed_descendants(children, last.child):
        return TOOL0
    return str(last.child)


def _descendant_joints(children: dict[str, list[Any]], link: str) -> list[Any]:
    out: list[Any] = []
    stack = list(children.get(link, []))
    while stack:
        j = stack.pop()
        out.append(j)
        stack.extend(children.get(j.child, []))
    return out


def _fixed_descendants(children: dict[str, list[Any]], link: str) -> list[str]:
    return [j.child for j in _descendant_joints(children, link) if j.type == "fixed"]


def _fixed_leaves(children: dict[str, list[Any]], link: str) -> list[str]:
    out: list[str] = []
    stack = [link]
    while stack:
        lk = stack.pop()
        kids = [j for j in children.get(lk, []) if j.type == "fixed"]
        if not kids and not children.get(lk):
            out.append(lk)
        stack.extend(j.child for j in kids)
    return sorted(out)


def _origin(jt: Any) -> np.ndarray:
    T = np.eye(4) if jt.origin is None else np.array(jt.origin, dtype=float)
    return T


def _inertial(urdf: Any, link: str) -> tuple[float, np.ndarray]:
    lk = urdf.link_map[link]
    inert = lk.inertial
    if inert is None or inert.mass is None:
        return 0.0, np.zeros(3)
    origin = np.eye(4) if inert.origin is None else np.asarray(inert.origin, dtype=float)
    return float(inert.mass), origin[:3, 3].copy()


def _lumped(urdf: Any, children: dict[str, list[Any]], link: str,
            on_chain: set[str]) -> tuple[float, np.ndarray]:
    """Mass and centre of mass (link frame) of ``link`` and what is fixed to it off the chain."""
    total, moment = 0.0, np.zeros(3)
    stack: list[tuple[str, np.ndarray]] = [(link, np.eye(4))]
    while stack:
        lk, T = stack.pop()
        m, c = _inertial(urdf, lk)
        if m > 0:
            total += m
            moment += m * (T[:3, :3] @ c + T[:3, 3])
        for j in children.get(lk, []):
            if j.type == "fixed" and j.child not in on_chain:
                stack.append((j.child, T @ _origin(j)))
    return total, (moment / total if total > 0 else np.zeros(3))


def chain_from_urdf(urdf: Any, label: str, base_link: str | None = None,
                    tip_link: str | None = None) -> tuple[JointChain, str, str]:
    """The :class:`JointChain` of a parsed URDF from ``base_link`` to ``tip_link``.

    The masses of links fixed to a chain link off the chain are lumped into it.

    Parameters
    ----------
    urdf : yourdfpy.URDF
        The robot (:func:`parse_urdf`).
    label : str
        The file name, the start of error locations.
    base_link : str, optional
        The chain's first link; default the URDF's single root link.
    tip_link : str, optional
        The chain's last link; default the end of the only actuated chain (its single
        fixed leaf, else ``tool0``, else the last moving joint's child link).

    Returns
    -------
    chain : JointChain
        The joints in order: origin (4, 4) m, axis (3,), limits rad (prismatic: m) or
        ``None`` for continuous and mimic joints, lumped mass kg and centre of mass
        (3,) m in the child link's frame, mimic ``(joint, multiplier, offset)``.
    base_link, tip_link : str
        The chain's ends as chosen.

    Raises
    ------
    DescriptionError
        Unknown links, several roots, a closed loop, a branching robot without
        ``tip_link``, a tip not below the base, a floating/planar/unknown joint on the
        chain, missing or empty limits, a zero axis, non-finite mimic numbers.
    """
    parent, children, roots = _tree(urdf, label)
    base_link, tip_link, path = _chain_path(parent, children, roots, label, base_link,
                                            tip_link)
    on_chain = {base_link, *(j.child for j in path)}
    joints = tuple(_chain_joint(urdf, children, jt, on_chain, label) for jt in path)
    return JointChain(name=str(urdf.robot.name or "robot"), joints=joints), base_link, tip_link


def _chain_path(parent: dict[str, Any], children: dict[str, list[Any]], roots: list[str],
                label: str, base_link: str | None, tip_link: str | None
                ) -> tuple[str, str, list[Any]]:
    """The chain's ends (given, or the defaults of :func:`chain_from_urdf`) and the URDF
    joints from base to tip, walked up from the tip through each link's parent joint."""
    links = set(children)
    for opt, v in (("--base-link", base_link), ("--tip-link", tip_link)):
        if v is not None and v not in links:
            raise DescriptionError(
                f"{label}: {opt} {v}",
                f"no link {v!r} in the URDF (links: {', '.join(sorted(links))})",
            )
    if base_link is None:
        if len(roots) != 1:
            raise DescriptionError(
                label, f"the URDF has {len(roots)} root links ({', '.join(roots)}); expected one"
            )
        base_link = roots[0]
    if tip_link is None:
        tip_link = _default_tip(children, parent, base_link, label)
    path: list[Any] = []
    lk = tip_link
    while lk != base_link:
        if lk not in parent:
            raise DescriptionError(
                f"{label}: --tip-link {tip_link}",
                f"link {tip_link!r} does not hang below the base link {base_link!r}",
            )
        path.append(parent[lk])
        lk = parent[lk].parent
    path.reverse()
    return base_link, tip_link, path


def _chain_joint(urdf: Any, children: dict[str, list[Any]], jt: Any, on_chain: set[str],
                 label: str) -> ChainJoint:
    """One URDF joint of the chain as a :class:`ChainJoint`: its kind, origin, axis,
    limits (none for continuous and mimic joints), mimic and the mass lumped into its
    child link (:func:`_lumped`)."""
    loc = f"{label}: joint {jt.name!r}"
    kind = jt.type
    if kind in ("floating", "planar"):
        raise DescriptionError(
            loc, f"{kind} joints cannot be part of a robot's chain (choose --base-link "
            "below it)"
        )
    if kind not in ("revolute", "continuous", "prismatic", "fixed"):
        raise DescriptionError(loc, f"unknown joint type {kind!r}")
    mimic = None
    if jt.mimic is not None:
        mult = 1.0 if jt.mimic.multiplier is None else float(jt.mimic.multiplier)
        off = 0.0 if jt.mimic.offset is None else float(jt.mimic.offset)
        if not (math.isfinite(mult) and math.isfinite(off)):
            raise DescriptionError(f"{loc}: <mimic>", "multiplier and offset must be finite")
        mimic = (str(jt.mimic.joint), mult, off)
    limits = None
    if kind in ("revolute", "prismatic") and mimic is None:
        lim = jt.limit
        if lim is None or lim.lower is None or lim.upper is None:
            raise DescriptionError(loc, f"a {kind} joint needs <limit lower= upper=>")
        if not float(lim.lower) < float(lim.upper):
            raise DescriptionError(
                f"{loc}: <limit>",
                f"lower {lim.lower} must be below upper {lim.upper} (a joint that cannot "
                "move is a fixed joint)",
            )
        limits = (float(lim.lower), float(lim.upper))
    mass, com = _lumped(urdf, children, jt.child, on_chain)
    axis = np.array([1.0, 0.0, 0.0]) if jt.axis is None else np.asarray(jt.axis, dtype=float)
    if kind != "fixed" and not np.linalg.norm(axis) > 1e-12:
        raise DescriptionError(f"{loc}: <axis>", "must be a non-zero vector")
    return ChainJoint(
        name=jt.name,
        kind={"fixed": "fixed", "prismatic": "prismatic"}.get(kind, "revolute"),
        origin=_origin(jt),
        axis=axis,
        limits=limits,
        mass=mass,
        com=(float(com[0]), float(com[1]), float(com[2])),
        mimic=mimic,
    )


def import_urdf(
    path: str | os.PathLike[str],
    args: Mapping[str, str] | None = None,
    package_paths: Sequence[str | os.PathLike[str]] = (),
    base_link: str | None = None,
    tip_link: str | None = None,
) -> ImportedRobot:
    """Read a ``.urdf``/``.xacro`` file and convert its chain to a description.

    Parameters
    ----------
    path : path-like
        The URDF or xacro file (xacro when the name ends in ``.xacro``).
    args : mapping, optional
        xacro arguments (``{"ur_type": "ur10"}``); an error for a plain ``.urdf``.
    package_paths : sequence of path-like
        Directories holding ROS packages (folders named like the package).
    base_link, tip_link : str, optional
        Ends of the chain (defaults: the root link; the end of the only actuated
        chain — its single fixed leaf, else ``tool0``, else the last moving link).

    Returns
    -------
    ImportedRobot
        The description (DH/Hayati, joint readings = URDF joint positions in
        radians, chain order), the expanded URDF text and the chain's ends.

    Raises
    ------
    RobotNotFoundError
        No such file.
    DescriptionError
        Located at the file name: xacro arguments for a plain ``.urdf``, an unreadable
        or non-UTF-8 file, or any error of :func:`expand_xacro`, :func:`parse_urdf`,
        :func:`chain_from_urdf` or the DH/Hayati conversion.
    """
    p = Path(path)
    label = p.name
    args = dict(args or {})
    if not p.is_file():
        raise RobotNotFoundError(f"robot description file not found: {p}")
    resolver = PackageResolver(tuple(Path(x) for x in package_paths), p)
    if p.name.lower().endswith(".xacro"):
        text = expand_xacro(p, args, resolver)
    else:
        if args:
            raise DescriptionError(
                label, f"--robot-arg {next(iter(args))}: a plain .urdf file takes no xacro "
                "arguments"
            )
        try:
            text = p.read_text(encoding="utf-8")
        except OSError as exc:
            raise DescriptionError(label, f"cannot read: {exc.strerror or exc}") from None
        except UnicodeDecodeError as exc:
            raise DescriptionError(label, f"not UTF-8 text ({exc.reason})") from None
    urdf = parse_urdf(text, label)
    chain, base, tip = chain_from_urdf(urdf, label, base_link, tip_link)
    arg_text = " ".join(f"{k}:={v}" for k, v in args.items())
    notes = (f"imported from {p.name}{' ' + arg_text if arg_text else ''}: chain {base} → "
             f"{tip}; joint readings are the URDF joint positions; the tool is the tip link "
             "in the flange frame")
    chain = JointChain(chain.name, chain.joints, notes)
    try:
        desc = description_from_chain(chain)
    except DescriptionError as exc:
        raise exc.with_prefix(label) from None
    return ImportedRobot(desc, text, base, tip, tuple(j.name for j in chain.joints), p, args,
                         chain)
