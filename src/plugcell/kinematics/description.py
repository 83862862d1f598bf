"""Robot descriptions: immutable, validated models of a robot's structure.

A robot is *data*.  :class:`RobotDescription` holds the DH/Hayati rows (one
:class:`Link` per link, each with its joint type), which joints are actuated and
in which order the controller reports them, the flange link, closed loops
(:class:`FourBarLoop`), joint limits (also on joint *differences*,
:class:`CoupledLimit`), BASE and tool transforms, masses (for the digital twin),
joint stiffnesses and a home pose.

:meth:`RobotDescription.from_dict` builds one from the plain dictionary of a
description file (lengths in metres, angles in **degrees**, masses in kg; the
format is documented in ``docs/robot-description.md``) and reports every problem
as a :class:`~plugcell.kinematics.errors.DescriptionError` whose location is a
path into that dictionary (``links[3].alpha``).  Inside the model all angles are
radians.  This module does no file I/O; :mod:`plugcell.io.robots` reads files.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from plugcell.kinematics.errors import DescriptionError
from plugcell.kinematics.parameters import GeometricParameters
from plugcell.kinematics.rotations import matrix_to_rpy, rpy_to_matrix, zyz_to_matrix

Array = NDArray[np.float64]

#: Joint types.  ``actuated``: θ = reading + offset; ``passive``: θ from a loop
#: closure (+ offset); ``fixed``: θ is a constant.
JOINT_TYPES: tuple[str, ...] = ("actuated", "passive", "fixed")
#: Parent name of the first link: the robot base frame F0.
ROOT = "base"
#: Description file format version understood by :meth:`RobotDescription.from_dict`.
FORMAT_VERSION = 1
#: Coupled limits of a loop must keep the arm–crank angle at least this far (rad)
#: from a multiple of π, where the parallelogram collapses.
LOOP_MARGIN = math.radians(1.0)

__all__ = [
    "FORMAT_VERSION",
    "JOINT_TYPES",
    "ROOT",
    "Box",
    "CoupledLimit",
    "FourBarLoop",
    "Link",
    "PointMass",
    "RobotDescription",
]

_DEG = math.pi / 180.0


# =============================================================================== model
@dataclass(frozen=True)
class Link:
    """One DH + Hayati link (thesis eqs. A.2, B.1), SI units, angles in radians.

    The link frame F_i is ``F_parent · Rz(θ) Tz(d) Tx(a) Rx(α) Ry(β)``.  ``theta``
    is an offset added to the joint reading (actuated), to the loop-closure angle
    (passive) or the constant angle (fixed, e.g. Smart H4 link 3: −83°).
    ``hayati`` marks links whose β is a meaningful (identifiable) parameter;
    ``mass`` (kg) and ``com`` (m, in the link's own frame F_i) feed the twin.
    """

    name: str
    parent: str
    joint: str
    theta: float
    d: float
    a: float
    alpha: float
    beta: float = 0.0
    hayati: bool = False
    mass: float = 0.0
    com: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @property
    def is_actuated(self) -> bool:
        return self.joint == "actuated"

    @property
    def is_passive(self) -> bool:
        return self.joint == "passive"

    @property
    def is_fixed(self) -> bool:
        return self.joint == "fixed"


@dataclass(frozen=True)
class FourBarLoop:
    """A planar parallelogram (four-bar) loop closed at a virtually cut joint (thesis 6.1).

    ``arm`` and ``crank`` are the two actuated links on a common axis (Smart H4:
    ``"2"``, a = 1.05, off the flange chain; ``"2'"``, a = 0.45); ``coupler``
    (``"3'"``) and ``follower`` (``"4'"``) carry the passive joints.  The end frame
    of ``follower`` must coincide, in the loop plane, with the end frame of
    ``arm`` (constraints 6.4–6.5).  Nominally a_coupler = a_arm, a_follower = a_crank.
    """

    arm: str
    crank: str
    coupler: str
    follower: str

    @property
    def driven(self) -> tuple[str, str]:
        return (self.arm, self.crank)

    @property
    def passive(self) -> tuple[str, str]:
        return (self.coupler, self.follower)

    @property
    def links(self) -> tuple[str, str, str, str]:
        return (self.arm, self.crank, self.coupler, self.follower)


@dataclass(frozen=True)
class CoupledLimit:
    """``lower ≤ q[first] − q[second] ≤ upper`` on joint readings (radians)."""

    joints: tuple[str, str]
    lower: float
    upper: float


@dataclass(frozen=True)
class PointMass:
    """A lumped mass (kg) at ``com`` (m, in frame ``link``) — e.g. a counterweight."""

    name: str
    link: str
    mass: float
    com: tuple[float, float, float]


@dataclass(frozen=True)
class Box:
    """Axis-aligned box in the robot base frame: ``center`` and edge lengths ``size`` (m)."""

    center: tuple[float, float, float]
    size: tuple[float, float, float]

    @property
    def lower(self) -> Array:
        return np.asarray(self.center) - 0.5 * np.asarray(self.size)

    @property
    def upper(self) -> Array:
        return np.asarray(self.center) + 0.5 * np.asarray(self.size)

    def contains(self, p: Any) -> NDArray[np.bool_]:
        """Which points ``(..., 3)`` lie inside (boundary included)."""
        p = np.asarray(p, dtype=float)
        return np.all((p >= self.lower - 1e-12) & (p <= self.upper + 1e-12), axis=-1)


def _ro(x: Any, shape: tuple[int, ...]) -> Array:
    arr = np.array(x, dtype=float)
    if arr.shape != shape:
        raise ValueError(f"expected shape {shape}, got {arr.shape}")
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class RobotDescription:
    """Immutable, validated description of a robot (see module docstring).

    Construction validates the structure and raises ``DescriptionError`` with a
    file-style location (``links[2].parent``, ``loops[0].coupler``…).
    ``joint_limits`` is ``(n_actuated, 2)`` radians in ``actuated`` order;
    ``stiffness`` ``(n_actuated,)`` N·m/rad or ``None``; ``home`` ``(n_actuated,)``
    radians — the documented default seed of inverse kinematics.
    """

    name: str
    links: tuple[Link, ...]
    actuated: tuple[str, ...]
    flange: str
    loops: tuple[FourBarLoop, ...]
    base: Array
    tool: Array
    joint_limits: Array
    stiffness: Array | None = None
    notes: str = ""
    coupled_limits: tuple[CoupledLimit, ...] = ()
    home: Array | None = None
    point_masses: tuple[PointMass, ...] = ()
    working_volume: Box | None = None
    # derived (filled in __post_init__)
    _index: dict[str, int] = field(default_factory=dict, init=False, repr=False)
    _chain: tuple[int, ...] = field(default=(), init=False, repr=False)

    # ------------------------------------------------------------------ validation
    def __post_init__(self) -> None:
        S = object.__setattr__
        S(self, "links", tuple(self.links))
        S(self, "actuated", tuple(self.actuated))
        S(self, "loops", tuple(self.loops))
        S(self, "coupled_limits", tuple(self.coupled_limits))
        S(self, "point_masses", tuple(self.point_masses))
        if not isinstance(self.name, str) or not self.name:
            raise DescriptionError("name", "must be a non-empty string")
        self._check_links()
        index = {lk.name: i for i, lk in enumerate(self.links)}
        S(self, "_index", index)
        self._check_actuated(index)
        chain = self._check_flange(index)
        S(self, "_chain", chain)
        self._check_loops(index, chain)
        n = len(self.actuated)
        for key in ("base", "tool"):
            try:
                T = _ro(getattr(self, key), (4, 4))
            except ValueError as exc:
                raise DescriptionError(key, str(exc)) from None
            _check_rigid(T, key)
            S(self, key, T)
        try:
            lim = _ro(self.joint_limits, (n, 2))
        except ValueError as exc:
            raise DescriptionError("joint_limits", str(exc)) from None
        for j, name in enumerate(self.actuated):
            lo, hi = lim[j]
            loc = f"links[{index[name]}].limits"
            if not (np.isfinite(lo) and np.isfinite(hi)):
                raise DescriptionError(loc, "limits must be finite")
            if not lo < hi:
                raise DescriptionError(
                    loc,
                    f"lower limit {math.degrees(lo):g}° must be below upper {math.degrees(hi):g}°",
                )
        S(self, "joint_limits", lim)
        if self.stiffness is not None:
            try:
                k = _ro(self.stiffness, (n,))
            except ValueError as exc:
                raise DescriptionError("stiffness", str(exc)) from None
            for j, name in enumerate(self.actuated):
                if not (np.isfinite(k[j]) and k[j] > 0):
                    raise DescriptionError(
                        f"links[{index[name]}].stiffness", f"must be positive, got {k[j]!r}"
                    )
            S(self, "stiffness", k)
        self._check_coupled(index)
        self._check_home()
        for i, pm in enumerate(self.point_masses):
            if pm.link not in index:
                raise DescriptionError(f"point_masses[{i}].link", f"unknown link {pm.link!r}")
            if not (math.isfinite(pm.mass) and pm.mass >= 0):
                raise DescriptionError(f"point_masses[{i}].mass", "must be ≥ 0")
        if self.working_volume is not None and not all(s > 0 for s in self.working_volume.size):
            raise DescriptionError("working_volume.size", "edge lengths must be positive")

    def _check_links(self) -> None:
        if not self.links:
            raise DescriptionError("links", "at least one link is required")
        seen: dict[str, int] = {}
        for i, lk in enumerate(self.links):
            loc = f"links[{i}]"
            if not isinstance(lk.name, str) or not lk.name:
                raise DescriptionError(f"{loc}.name", "must be a non-empty string")
            if lk.name == ROOT:
                raise DescriptionError(f"{loc}.name", f"{ROOT!r} is reserved for the base frame")
            if lk.name in seen:
                raise DescriptionError(
                    f"{loc}.name", f"duplicate link name {lk.name!r} (also links[{seen[lk.name]}])"
                )
            if lk.joint not in JOINT_TYPES:
                raise DescriptionError(
                    f"{loc}.joint", f"expected one of {list(JOINT_TYPES)}, got {lk.joint!r}"
                )
            if i == 0:
                if lk.parent != ROOT:
                    raise DescriptionError(
                        f"{loc}.parent",
                        f"the first link must have parent {ROOT!r}, got {lk.parent!r}",
                    )
            elif lk.parent == ROOT:
                raise DescriptionError(
                    f"{loc}.parent", f"only the first link may hang from {ROOT!r} (one root)"
                )
            elif lk.parent not in seen:
                if any(o.name == lk.parent for o in self.links[i + 1 :]):
                    reason = f"parent {lk.parent!r} is listed after this link (list parents first)"
                else:
                    reason = f"unknown parent link {lk.parent!r}"
                raise DescriptionError(f"{loc}.parent", reason)
            for key in ("theta", "d", "a", "alpha", "beta", "mass"):
                v = getattr(lk, key)
                if not math.isfinite(v):
                    raise DescriptionError(f"{loc}.{key}", f"must be finite, got {v!r}")
            if lk.mass < 0:
                raise DescriptionError(f"{loc}.mass", f"must be ≥ 0, got {lk.mass!r}")
            if len(lk.com) != 3 or not all(math.isfinite(c) for c in lk.com):
                raise DescriptionError(f"{loc}.com", "expected 3 finite numbers")
            if not lk.hayati and lk.beta != 0.0:
                raise DescriptionError(f"{loc}.beta", "beta is non-zero but hayati is false")
            seen[lk.name] = i

    def _check_actuated(self, index: dict[str, int]) -> None:
        seen: set[str] = set()
        for j, name in enumerate(self.actuated):
            loc = f"actuated[{j}]"
            if name not in index:
                raise DescriptionError(loc, f"unknown link {name!r}")
            if not self.links[index[name]].is_actuated:
                raise DescriptionError(
                    loc,
                    f"link {name!r} has joint {self.links[index[name]].joint!r}, not 'actuated'",
                )
            if name in seen:
                raise DescriptionError(loc, f"link {name!r} listed twice")
            seen.add(name)
        for i, lk in enumerate(self.links):
            if lk.is_actuated and lk.name not in seen:
                raise DescriptionError(
                    "actuated", f"actuated link {lk.name!r} (links[{i}]) is missing from the list"
                )

    def _check_flange(self, index: dict[str, int]) -> tuple[int, ...]:
        if self.flange not in index:
            raise DescriptionError("flange", f"unknown link {self.flange!r}")
        chain: list[int] = []
        i = index[self.flange]
        while True:
            chain.append(i)
            parent = self.links[i].parent
            if parent == ROOT:
                break
            i = index[parent]
        return tuple(reversed(chain))

    def _check_loops(self, index: dict[str, int], chain: tuple[int, ...]) -> None:
        on_chain = set(chain)
        used: dict[str, str] = {}
        for k, loop in enumerate(self.loops):
            loc = f"loops[{k}]"
            for role in ("arm", "crank", "coupler", "follower"):
                name = getattr(loop, role)
                if name not in index:
                    raise DescriptionError(f"{loc}.{role}", f"unknown link {name!r}")
                if name in used:
                    raise DescriptionError(
                        f"{loc}.{role}", f"link {name!r} is already used in {used[name]}"
                    )
                used[name] = f"{loc}.{role}"
            L = {
                r: self.links[index[getattr(loop, r)]]
                for r in ("arm", "crank", "coupler", "follower")
            }
            for role in ("arm", "crank"):
                if not L[role].is_actuated:
                    raise DescriptionError(
                        f"{loc}.{role}", f"link {L[role].name!r} must be actuated"
                    )
            for role in ("coupler", "follower"):
                if not L[role].is_passive:
                    raise DescriptionError(
                        f"{loc}.{role}", f"link {L[role].name!r} must be passive"
                    )
            if L["arm"].parent != L["crank"].parent:
                raise DescriptionError(
                    f"{loc}.arm",
                    f"arm {L['arm'].name!r} and crank {L['crank'].name!r} must share a parent "
                    f"(coaxial driven joints); parents are {L['arm'].parent!r}, "
                    f"{L['crank'].parent!r}",
                )
            if L["coupler"].parent != L["crank"].name:
                raise DescriptionError(
                    f"{loc}.coupler", f"the coupler's parent must be the crank {L['crank'].name!r}"
                )
            if L["follower"].parent != L["coupler"].name:
                raise DescriptionError(
                    f"{loc}.follower",
                    f"the follower's parent must be the coupler {L['coupler'].name!r}",
                )
            if index[L["arm"].name] in on_chain:
                raise DescriptionError(
                    f"{loc}.arm", f"the arm {L['arm'].name!r} must be off the flange chain"
                )
            if index[L["follower"].name] not in on_chain:
                raise DescriptionError(
                    f"{loc}.follower",
                    f"the follower {L['follower'].name!r} must be on the chain to the flange",
                )
            for role in ("arm", "crank", "coupler", "follower"):
                lk = L[role]
                if abs(lk.alpha) > 1e-12 or abs(lk.beta) > 1e-12:
                    raise DescriptionError(
                        f"links[{index[lk.name]}]",
                        f"loop link {lk.name!r} must be planar nominally (alpha = beta = 0)",
                    )
            for role in ("coupler", "follower"):
                if abs(L[role].d) > 1e-12:
                    raise DescriptionError(
                        f"links[{index[L[role].name]}].d", f"loop {role} must have d = 0 nominally"
                    )
            if abs(L["arm"].d - L["crank"].d) > 1e-12:
                raise DescriptionError(
                    f"links[{index[L['arm'].name]}].d", "arm and crank must have the same d"
                )
            for a_role, b_role in (("coupler", "arm"), ("follower", "crank")):
                if abs(L[a_role].a - L[b_role].a) > 1e-9:
                    raise DescriptionError(
                        f"links[{index[L[a_role].name]}].a",
                        f"only parallelogram loops are supported: the {a_role}'s a "
                        f"({L[a_role].a:g} m) must equal the {b_role}'s ({L[b_role].a:g} m)",
                    )
            for role in ("crank", "coupler", "follower", "arm"):
                if L[role].a <= 0:
                    raise DescriptionError(
                        f"links[{index[L[role].name]}].a", "loop link lengths must be positive"
                    )
        for i, lk in enumerate(self.links):
            if lk.is_passive and lk.name not in used:
                raise DescriptionError(
                    f"links[{i}].joint", f"passive link {lk.name!r} belongs to no loop"
                )
            if lk.is_actuated and i not in on_chain and lk.name not in used:
                raise DescriptionError(
                    f"links[{i}]",
                    f"actuated link {lk.name!r} is neither on the chain to the flange "
                    "nor a loop arm",
                )

    def _check_coupled(self, index: dict[str, int]) -> None:
        act = {n: j for j, n in enumerate(self.actuated)}
        for k, cl in enumerate(self.coupled_limits):
            loc = f"coupled_limits[{k}]"
            if len(cl.joints) != 2:
                raise DescriptionError(f"{loc}.joints", "expected two joint names")
            for m, name in enumerate(cl.joints):
                if name not in act:
                    raise DescriptionError(
                        f"{loc}.joints[{m}]", f"{name!r} is not an actuated joint"
                    )
            if cl.joints[0] == cl.joints[1]:
                raise DescriptionError(f"{loc}.joints", "the two joints must differ")
            if not (math.isfinite(cl.lower) and math.isfinite(cl.upper)) or not cl.lower < cl.upper:
                raise DescriptionError(f"{loc}", "min must be below max (finite)")
        for k, loop in enumerate(self.loops):
            ia, ic = index[loop.arm], index[loop.crank]
            off = self.links[ia].theta - self.links[ic].theta
            found = False
            for m, cl in enumerate(self.coupled_limits):
                if set(cl.joints) != {loop.arm, loop.crank}:
                    continue
                found = True
                lo, hi = cl.lower, cl.upper
                if cl.joints[0] != loop.arm:  # limit on crank − arm
                    lo, hi = -hi, -lo
                lo, hi = lo + off, hi + off
                kk = math.floor(lo / math.pi)
                if not (
                    lo >= kk * math.pi + LOOP_MARGIN and hi <= (kk + 1) * math.pi - LOOP_MARGIN
                ):
                    raise DescriptionError(
                        f"coupled_limits[{m}]",
                        f"the range of {loop.arm} − {loop.crank} lets the loop collapse: the angle "
                        f"between arm and crank spans "
                        f"[{math.degrees(lo):g}°, {math.degrees(hi):g}°], "
                        f"which must stay at least {math.degrees(LOOP_MARGIN):g}° inside "
                        f"(k·180°, (k+1)·180°)",
                    )
            if not found:
                raise DescriptionError(
                    "coupled_limits",
                    f"loops[{k}] needs a coupled limit on {loop.arm} − {loop.crank} that keeps "
                    f"sin({loop.arm} − {loop.crank}) away from 0",
                )

    def _check_home(self) -> None:
        n = len(self.actuated)
        lim = self.joint_limits
        if self.home is None:
            home = lim.mean(axis=1)
            where = "home (default: mid-range; give 'home' explicitly)"
        else:
            home = np.array(self.home, dtype=float).reshape(-1)
            if home.shape != (n,):
                raise DescriptionError(
                    "home", f"expected {n} numbers (one per actuated joint), got {home.size}"
                )
            where = "home"
        for j, name in enumerate(self.actuated):
            if not lim[j, 0] <= home[j] <= lim[j, 1]:
                raise DescriptionError(
                    f"{where}[{j}]",
                    f"joint {name} = {math.degrees(home[j]):g}° is outside its limits "
                    f"[{math.degrees(lim[j, 0]):g}°, {math.degrees(lim[j, 1]):g}°]",
                )
        act = {nm: j for j, nm in enumerate(self.actuated)}
        for cl in self.coupled_limits:
            v = home[act[cl.joints[0]]] - home[act[cl.joints[1]]]
            if not cl.lower <= v <= cl.upper:
                raise DescriptionError(
                    where,
                    f"{cl.joints[0]} − {cl.joints[1]} = {math.degrees(v):g}° violates the coupled "
                    f"limit [{math.degrees(cl.lower):g}°, {math.degrees(cl.upper):g}°]",
                )
        home = np.array(home, dtype=float)
        home.setflags(write=False)
        object.__setattr__(self, "home", home)

    # ------------------------------------------------------------------ queries
    @property
    def n_actuated(self) -> int:
        return len(self.actuated)

    @property
    def n_links(self) -> int:
        return len(self.links)

    @property
    def link_names(self) -> tuple[str, ...]:
        return tuple(lk.name for lk in self.links)

    def index(self, name: str) -> int:
        """Position of link ``name`` in :attr:`links` (and in parameter arrays)."""
        try:
            return self._index[name]
        except KeyError:
            raise KeyError(f"unknown link {name!r}; links are {list(self.link_names)}") from None

    def link(self, name: str) -> Link:
        return self.links[self.index(name)]

    def joint_index(self, name: str) -> int:
        """Position of actuated link ``name`` in the joint vector ``q``."""
        try:
            return self.actuated.index(name)
        except ValueError:
            raise KeyError(
                f"{name!r} is not an actuated joint; joints are {list(self.actuated)}"
            ) from None

    @property
    def chain(self) -> tuple[int, ...]:
        """Link indices from the root to the flange (thesis chain 1-2'-3'-4'-3-4-5-6)."""
        return self._chain

    @property
    def passive(self) -> tuple[str, ...]:
        """Passive link names, in loop order (coupler, follower of each loop)."""
        return tuple(n for loop in self.loops for n in loop.passive)

    def nominal_parameters(self) -> GeometricParameters:
        """The description's DH + Hayati rows, BASE and tool as a parameter set."""
        return GeometricParameters(
            link_names=self.link_names,
            theta=[lk.theta for lk in self.links],
            d=[lk.d for lk in self.links],
            a=[lk.a for lk in self.links],
            alpha=[lk.alpha for lk in self.links],
            beta=[lk.beta for lk in self.links],
            base=self.base,
            tool=self.tool,
        )

    def limit_violations(self, q: Any, tol: float = 0.0) -> list[str]:
        """Human-readable list of limit violations of one configuration ``q`` (radians)."""
        q = np.asarray(q, dtype=float)
        out = []
        for j, name in enumerate(self.actuated):
            lo, hi = self.joint_limits[j]
            if not lo - tol <= q[j] <= hi + tol:
                out.append(
                    f"joint {name} = {math.degrees(q[j]):.4f}° outside "
                    f"[{math.degrees(lo):g}°, {math.degrees(hi):g}°]"
                )
        for cl in self.coupled_limits:
            v = q[self.joint_index(cl.joints[0])] - q[self.joint_index(cl.joints[1])]
            if not cl.lower - tol <= v <= cl.upper + tol:
                out.append(
                    f"{cl.joints[0]} − {cl.joints[1]} = {math.degrees(v):.4f}° outside "
                    f"[{math.degrees(cl.lower):g}°, {math.degrees(cl.upper):g}°]"
                )
        return out

    def within_limits(self, q: Any, tol: float = 1e-9) -> NDArray[np.bool_]:
        """Mask ``(...)``: configurations ``(..., n)`` inside joint and coupled limits."""
        q = np.asarray(q, dtype=float)
        lo, hi = self.joint_limits[:, 0], self.joint_limits[:, 1]
        ok = np.all((q >= lo - tol) & (q <= hi + tol), axis=-1)
        for cl in self.coupled_limits:
            v = q[..., self.joint_index(cl.joints[0])] - q[..., self.joint_index(cl.joints[1])]
            ok &= (v >= cl.lower - tol) & (v <= cl.upper + tol)
        return ok

    # ------------------------------------------------------------------ dict form
    @classmethod
    def from_dict(cls, data: Any) -> RobotDescription:
        """Build and validate a description from a file dictionary (metres, degrees, kg).

        Every problem raises :class:`DescriptionError` with a path-like location;
        no other exception escapes for any input.
        """
        return _parse(data)

    def to_dict(self) -> dict[str, Any]:
        """The file dictionary of this description (inverse of :meth:`from_dict`)."""
        act = {n: j for j, n in enumerate(self.actuated)}
        links = []
        for lk in self.links:
            d: dict[str, Any] = {
                "name": lk.name,
                "parent": lk.parent,
                "joint": lk.joint,
                "theta": math.degrees(lk.theta),
                "d": lk.d,
                "a": lk.a,
                "alpha": math.degrees(lk.alpha),
            }
            if lk.hayati:
                d["hayati"] = True
                d["beta"] = math.degrees(lk.beta)
            d["mass"] = lk.mass
            d["com"] = list(lk.com)
            if lk.name in act:
                j = act[lk.name]
                d["limits"] = [math.degrees(x) for x in self.joint_limits[j]]
                if self.stiffness is not None:
                    d["stiffness"] = float(self.stiffness[j])
            links.append(d)
        out: dict[str, Any] = {
            "format_version": FORMAT_VERSION,
            "name": self.name,
            "notes": self.notes,
            "actuated": list(self.actuated),
            "flange": self.flange,
            "home": [math.degrees(x) for x in (self.home if self.home is not None else [])],
            "base": _transform_to_dict(self.base),
            "tool": _transform_to_dict(self.tool),
            "links": links,
            "loops": [
                {"arm": lp.arm, "crank": lp.crank, "coupler": lp.coupler, "follower": lp.follower}
                for lp in self.loops
            ],
            "coupled_limits": [
                {
                    "joints": list(c.joints),
                    "min": math.degrees(c.lower),
                    "max": math.degrees(c.upper),
                }
                for c in self.coupled_limits
            ],
            "point_masses": [
                {"name": p.name, "link": p.link, "mass": p.mass, "com": list(p.com)}
                for p in self.point_masses
            ],
        }
        if self.working_volume is not None:
            out["working_volume"] = {
                "center": list(self.working_volume.center),
                "size": list(self.working_volume.size),
            }
        return out


def _check_rigid(T: Array, loc: str) -> None:
    R = T[:3, :3]
    if not np.all(np.isfinite(T)):
        raise DescriptionError(loc, "transform must be finite")
    if np.abs(R @ R.T - np.eye(3)).max() > 1e-6 or np.linalg.det(R) < 0:
        raise DescriptionError(loc, "rotation part is not a proper rotation matrix")
    if np.abs(T[3] - [0, 0, 0, 1]).max() > 1e-12:
        raise DescriptionError(loc, "last row must be [0, 0, 0, 1]")


def _transform_to_dict(T: Array) -> dict[str, Any]:
    rpy = matrix_to_rpy(T[:3, :3])
    return {"xyz": [float(x) for x in T[:3, 3]], "rpy": [math.degrees(x) for x in rpy]}


# =============================================================================== parsing
_TOP_KEYS = {
    "format_version",
    "name",
    "notes",
    "actuated",
    "flange",
    "home",
    "base",
    "tool",
    "links",
    "loops",
    "coupled_limits",
    "point_masses",
    "working_volume",
}
_LINK_KEYS = {
    "name",
    "parent",
    "joint",
    "theta",
    "d",
    "a",
    "alpha",
    "beta",
    "hayati",
    "mass",
    "com",
    "limits",
    "stiffness",
}
_LOOP_KEYS = {"type", "arm", "crank", "coupler", "follower"}
_COUPLED_KEYS = {"joints", "min", "max"}
_PM_KEYS = {"name", "link", "mass", "com"}
_TRANSFORM_KEYS = {"xyz", "rpy", "zyz", "matrix"}


def _typename(v: Any) -> str:
    return repr(v) if isinstance(v, (str, int, float, bool)) else type(v).__name__


def _table(v: Any, loc: str, allowed: set[str]) -> Mapping[str, Any]:
    if not isinstance(v, Mapping):
        raise DescriptionError(loc, f"expected a table, got {_typename(v)}")
    for key in v:
        if not isinstance(key, str):
            raise DescriptionError(loc, f"keys must be strings, got {key!r}")
        if key not in allowed:
            raise DescriptionError(
                f"{loc}.{key}" if loc else key,
                f"unknown key (allowed: {', '.join(sorted(allowed))})",
            )
    return v


def _sub(loc: str, key: str) -> str:
    return f"{loc}.{key}" if loc else key


def _req(t: Mapping[str, Any], key: str, loc: str) -> Any:
    if key not in t:
        raise DescriptionError(_sub(loc, key), "missing required key")
    return t[key]


def _num(v: Any, loc: str) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise DescriptionError(loc, f"expected a number, got {_typename(v)}")
    x = float(v)
    if not math.isfinite(x):
        raise DescriptionError(loc, f"expected a finite number, got {v!r}")
    return x


def _str(v: Any, loc: str) -> str:
    if not isinstance(v, str):
        raise DescriptionError(loc, f"expected a string, got {_typename(v)}")
    if not v:
        raise DescriptionError(loc, "must not be empty")
    return v


def _bool(v: Any, loc: str) -> bool:
    if not isinstance(v, bool):
        raise DescriptionError(loc, f"expected true or false, got {_typename(v)}")
    return v


def _list(v: Any, loc: str) -> Sequence[Any]:
    if isinstance(v, (str, bytes, Mapping)) or not isinstance(v, Sequence):
        raise DescriptionError(loc, f"expected an array, got {_typename(v)}")
    return v


def _vec(v: Any, n: int, loc: str) -> list[float]:
    seq = _list(v, loc)
    if len(seq) != n:
        raise DescriptionError(loc, f"expected {n} numbers, got {len(seq)}")
    return [_num(x, f"{loc}[{i}]") for i, x in enumerate(seq)]


def _opt(t: Mapping[str, Any], key: str, default: Any) -> Any:
    return t.get(key, default)


def _parse_transform(v: Any, loc: str) -> Array:
    t = _table(v, loc, _TRANSFORM_KEYS)
    if "matrix" in t:
        if set(t) - {"matrix"}:
            raise DescriptionError(loc, "give either 'matrix' or 'xyz' with 'rpy'/'zyz', not both")
        rows = _list(t["matrix"], f"{loc}.matrix")
        if len(rows) != 4:
            raise DescriptionError(f"{loc}.matrix", f"expected 4 rows, got {len(rows)}")
        T = np.array([_vec(r, 4, f"{loc}.matrix[{i}]") for i, r in enumerate(rows)])
        _check_rigid(T, f"{loc}.matrix")
        return T
    xyz = _vec(t["xyz"], 3, f"{loc}.xyz") if "xyz" in t else [0.0, 0.0, 0.0]
    if "rpy" in t and "zyz" in t:
        raise DescriptionError(loc, "give one of 'rpy' or 'zyz', not both")
    T = np.eye(4)
    if "rpy" in t:
        r = _vec(t["rpy"], 3, f"{loc}.rpy")
        T[:3, :3] = rpy_to_matrix(*(x * _DEG for x in r))
    elif "zyz" in t:
        r = _vec(t["zyz"], 3, f"{loc}.zyz")
        T[:3, :3] = zyz_to_matrix(*(x * _DEG for x in r))
    T[:3, 3] = xyz
    return T


def _parse(data: Any) -> RobotDescription:
    top = _table(data, "", _TOP_KEYS)
    if "format_version" in top:
        fv = top["format_version"]
        if isinstance(fv, bool) or not isinstance(fv, int) or fv != FORMAT_VERSION:
            raise DescriptionError(
                "format_version",
                f"unsupported format version {_typename(fv)} (expected {FORMAT_VERSION})",
            )
    name = _str(_req(top, "name", ""), "name")
    notes_v = _opt(top, "notes", "")
    if isinstance(notes_v, str):
        notes = notes_v
    else:
        seq = _list(notes_v, "notes")
        parts = []
        for i, s in enumerate(seq):
            if not isinstance(s, str):
                raise DescriptionError(f"notes[{i}]", f"expected a string, got {_typename(s)}")
            parts.append(s)
        notes = "\n".join(parts)

    raw_links = _list(_req(top, "links", ""), "links")
    links: list[Link] = []
    limits: dict[str, tuple[float, float]] = {}
    stiff: dict[str, float] = {}
    for i, raw in enumerate(raw_links):
        loc = f"links[{i}]"
        t = _table(raw, loc, _LINK_KEYS)
        lname = _str(_req(t, "name", loc), f"{loc}.name")
        parent = _str(_req(t, "parent", loc), f"{loc}.parent")
        joint = _str(_req(t, "joint", loc), f"{loc}.joint")
        if joint not in JOINT_TYPES:
            raise DescriptionError(
                f"{loc}.joint", f"expected one of {list(JOINT_TYPES)}, got {joint!r}"
            )
        if joint == "fixed":
            theta = _num(_req(t, "theta", loc), f"{loc}.theta")
        else:
            theta = _num(_opt(t, "theta", 0.0), f"{loc}.theta")
        d = _num(_req(t, "d", loc), f"{loc}.d")
        a = _num(_req(t, "a", loc), f"{loc}.a")
        alpha = _num(_req(t, "alpha", loc), f"{loc}.alpha")
        hayati = _bool(_opt(t, "hayati", False), f"{loc}.hayati")
        beta = _num(_opt(t, "beta", 0.0), f"{loc}.beta")
        if "beta" in t and not hayati:
            raise DescriptionError(f"{loc}.beta", "beta requires hayati = true")
        mass = _num(_opt(t, "mass", 0.0), f"{loc}.mass")
        if mass < 0:
            raise DescriptionError(f"{loc}.mass", f"must be ≥ 0, got {mass:g}")
        com = tuple(_vec(_opt(t, "com", [0.0, 0.0, 0.0]), 3, f"{loc}.com"))
        if joint == "actuated":
            lim = _vec(_req(t, "limits", loc), 2, f"{loc}.limits")
            if not lim[0] < lim[1]:
                raise DescriptionError(
                    f"{loc}.limits", f"lower limit {lim[0]:g} must be below upper limit {lim[1]:g}"
                )
            limits[lname] = (lim[0] * _DEG, lim[1] * _DEG)
            if "stiffness" in t:
                k = _num(t["stiffness"], f"{loc}.stiffness")
                if k <= 0:
                    raise DescriptionError(f"{loc}.stiffness", f"must be positive, got {k:g}")
                stiff[lname] = k
        else:
            for key in ("limits", "stiffness"):
                if key in t:
                    raise DescriptionError(f"{loc}.{key}", f"only actuated joints take {key!r}")
        links.append(
            Link(
                name=lname,
                parent=parent,
                joint=joint,
                theta=theta * _DEG,
                d=d,
                a=a,
                alpha=alpha * _DEG,
                beta=beta * _DEG,
                hayati=hayati,
                mass=mass,
                com=(com[0], com[1], com[2]),
            )
        )

    raw_act = _list(_req(top, "actuated", ""), "actuated")
    actuated = tuple(_str(v, f"actuated[{j}]") for j, v in enumerate(raw_act))
    flange = _str(_req(top, "flange", ""), "flange")

    loops = []
    for k, raw in enumerate(_list(_opt(top, "loops", []), "loops")):
        loc = f"loops[{k}]"
        t = _table(raw, loc, _LOOP_KEYS)
        typ = _str(_opt(t, "type", "parallelogram"), f"{loc}.type")
        if typ not in ("parallelogram", "fourbar"):
            raise DescriptionError(f"{loc}.type", f"expected 'parallelogram', got {typ!r}")
        roles = {
            r: _str(_req(t, r, loc), f"{loc}.{r}") for r in ("arm", "crank", "coupler", "follower")
        }
        loops.append(FourBarLoop(**roles))

    coupled = []
    for k, raw in enumerate(_list(_opt(top, "coupled_limits", []), "coupled_limits")):
        loc = f"coupled_limits[{k}]"
        t = _table(raw, loc, _COUPLED_KEYS)
        js = _list(_req(t, "joints", loc), f"{loc}.joints")
        if len(js) != 2:
            raise DescriptionError(f"{loc}.joints", f"expected 2 joint names, got {len(js)}")
        j0, j1 = (_str(v, f"{loc}.joints[{m}]") for m, v in enumerate(js))
        lo = _num(_req(t, "min", loc), f"{loc}.min")
        hi = _num(_req(t, "max", loc), f"{loc}.max")
        if not lo < hi:
            raise DescriptionError(loc, f"min {lo:g} must be below max {hi:g}")
        coupled.append(CoupledLimit((j0, j1), lo * _DEG, hi * _DEG))

    pms = []
    for k, raw in enumerate(_list(_opt(top, "point_masses", []), "point_masses")):
        loc = f"point_masses[{k}]"
        t = _table(raw, loc, _PM_KEYS)
        pm_name = _str(_req(t, "name", loc), f"{loc}.name")
        pm_link = _str(_req(t, "link", loc), f"{loc}.link")
        pm_mass = _num(_req(t, "mass", loc), f"{loc}.mass")
        if pm_mass < 0:
            raise DescriptionError(f"{loc}.mass", f"must be ≥ 0, got {pm_mass:g}")
        c = _vec(_req(t, "com", loc), 3, f"{loc}.com")
        pms.append(PointMass(pm_name, pm_link, pm_mass, (c[0], c[1], c[2])))

    box = None
    if "working_volume" in top:
        t = _table(top["working_volume"], "working_volume", {"center", "size"})
        c = _vec(_req(t, "center", "working_volume"), 3, "working_volume.center")
        s = _vec(_req(t, "size", "working_volume"), 3, "working_volume.size")
        for i, x in enumerate(s):
            if x <= 0:
                raise DescriptionError(f"working_volume.size[{i}]", f"must be positive, got {x:g}")
        box = Box((c[0], c[1], c[2]), (s[0], s[1], s[2]))

    base = _parse_transform(top["base"], "base") if "base" in top else np.eye(4)
    tool = _parse_transform(top["tool"], "tool") if "tool" in top else np.eye(4)

    # order limits by the actuated list (unknown names are reported by the model)
    n = len(actuated)
    jl = np.zeros((n, 2))
    for j, nm in enumerate(actuated):
        jl[j] = limits.get(nm, (-math.pi, math.pi))
    stiffness = None
    if stiff:
        missing = [nm for nm in actuated if nm in limits and nm not in stiff]
        if missing:
            i = next(i for i, lk in enumerate(links) if lk.name == missing[0])
            raise DescriptionError(
                f"links[{i}].stiffness",
                "missing: give a stiffness for every actuated joint or for none",
            )
        stiffness = np.array([stiff.get(nm, 1.0) for nm in actuated])

    home = None
    if "home" in top:
        seq = _list(top["home"], "home")  # length checked against `actuated` by the model
        home = np.array([_num(x, f"home[{i}]") for i, x in enumerate(seq)]) * _DEG

    return RobotDescription(
        name=name,
        links=tuple(links),
        actuated=actuated,
        flange=flange,
        loops=tuple(loops),
        base=base,
        tool=tool,
        joint_limits=jl,
        stiffness=stiffness,
        notes=notes,
        coupled_limits=tuple(coupled),
        home=home,
        point_masses=tuple(pms),
        working_volume=box,
    )
