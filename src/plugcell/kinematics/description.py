"""Robot descriptions: immutable, validated models of a robot's structure.

A robot is *data*.  :class:`RobotDescription` holds the DH/Hayati rows (one
:class:`Link` per link, each with its joint type), which joints are actuated and
in which order the controller reports them, the flange link, closed loops
(:class:`FourBarLoop`), joint limits (also on joint *differences*,
:class:`CoupledLimit`), BASE and tool transforms, masses (for the digital twin),
joint stiffnesses, a home pose and, optionally, the vendor's joint convention
(:class:`JointCoupling`: kinematic joints = M · readings + offset).

Everything here is SI with angles in radians, and the model takes and returns
arrays and objects only.  Building one validates its physical consistency (one
root, parents listed first, loops that close, an injective coupling, ``home``
inside the limits…) and reports every problem as a
:class:`~plugcell.kinematics.errors.DescriptionError` whose location is where the
value sits in a description file (``links[3].alpha``), so a file loader can pass it
on unchanged.  This module reads no file format: the file schema (the dictionary
of a TOML file ↔ a description, with its units) is :mod:`plugcell.io.robot_schema`,
and :mod:`plugcell.io.robots` reads the files.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from plugcell.kinematics.errors import DescriptionError
from plugcell.kinematics.parameters import GeometricParameters

Array = NDArray[np.float64]

#: Joint types.  ``actuated``: θ = reading + offset (revolute); ``prismatic``:
#: d = reading + offset, θ constant (a linear axis, e.g. a track); ``passive``: θ
#: from a loop closure (+ offset); ``fixed``: θ is a constant.
JOINT_TYPES: tuple[str, ...] = ("actuated", "prismatic", "passive", "fixed")
#: Parent name of the first link: the robot base frame F0.
ROOT = "base"
#: Coupled limits of a loop must keep the arm–crank angle at least this far (rad)
#: from a multiple of π, where the parallelogram collapses.
LOOP_MARGIN = math.radians(1.0)
#: Kinds of :class:`FourBarLoop`: the nominal parallelogram, or any four-bar that
#: assembles (a calibrated loop: unequal sides, twists, offsets).
LOOP_KINDS: tuple[str, ...] = ("parallelogram", "fourbar")
#: A ``"fourbar"`` loop must assemble with ``|cos θ_fol|`` at most this over its range
#: (the follower angle's sine stays ≥ ~0.045, far from the collapse of
#: :data:`~plugcell.kinematics.closure.MIN_SIN`).
FOURBAR_MAX_COS = 0.999
#: A coupling matrix whose smallest singular value is below this (relative to the
#: largest) is singular: readings could not be recovered from kinematic joints.
COUPLING_RANK_TOL = 1e-9

__all__ = [
    "JOINT_TYPES",
    "LOOP_KINDS",
    "ROOT",
    "Box",
    "CoupledLimit",
    "FourBarLoop",
    "JointCoupling",
    "Link",
    "PointMass",
    "RobotDescription",
    "check_rigid",
]

_DEG = math.pi / 180.0


# =============================================================================== model
@dataclass(frozen=True)
class Link:
    """One DH + Hayati link (thesis eqs. A.2, B.1), SI units, angles in radians.

    The link frame F_i in its parent's frame is (eq. 4.13/B.1,
    :func:`~plugcell.kinematics.transforms.dh_hayati`)::

        T_i^parent = Rz(θ_i) · Tz(d_i) · Tx(a_i) · Rx(α_i) · Ry(β_i)

    with, by joint type,

    * ``actuated`` (revolute): θ_i = θ_kin,j + ``theta``, d_i = ``d``;
    * ``prismatic``: θ_i = ``theta``, d_i = θ_kin,j + ``d`` (θ_kin,j in metres);
    * ``passive``: θ_i = (loop-closure angle) + ``theta`` (:class:`FourBarLoop`);
    * ``fixed``: θ_i = ``theta`` (e.g. Smart H4 link 3: −83°),

    where θ_kin,j is the link's kinematic joint (:meth:`RobotDescription.kinematic_joints`).
    β = 0 gives the plain Denavit–Hartenberg link (A.2).

    Attributes
    ----------
    name : str
        Link name, unique, not ``"base"`` (:data:`ROOT`).
    parent : str
        Name of the parent link, ``"base"`` for the first link only.
    joint : str
        Joint type, one of :data:`JOINT_TYPES`.
    theta : float, rad
        DH joint angle offset θ (the constant angle of a fixed or prismatic joint).
    d : float, m
        DH offset along z (the offset a prismatic reading is added to).
    a : float, m
        DH length along x.
    alpha : float, rad
        DH twist about x.
    beta : float, rad
        Hayati twist about y; non-zero only if ``hayati``.
    hayati : bool
        β is a meaningful (identifiable) parameter of this link (a near-parallel joint axis).
    mass : float, kg
        Link mass, ≥ 0 (for the digital twin's gravity model).
    com : (3,) tuple of float, m
        Centre of mass in the link's own frame F_i.
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
        """Driven by a joint reading (revolute ``actuated`` or ``prismatic``)."""
        return self.joint in ("actuated", "prismatic")

    @property
    def is_prismatic(self) -> bool:
        """A linear joint: its reading adds to ``d`` (metres), ``theta`` is constant."""
        return self.joint == "prismatic"

    @property
    def is_passive(self) -> bool:
        """Its angle comes from a loop closure (a :class:`FourBarLoop` coupler or follower)."""
        return self.joint == "passive"

    @property
    def is_fixed(self) -> bool:
        """A constant angle ``theta``: no joint variable."""
        return self.joint == "fixed"


@dataclass(frozen=True)
class FourBarLoop:
    """A planar parallelogram (four-bar) loop closed at a virtually cut joint (thesis 6.1).

    ``arm`` and ``crank`` are the two actuated links on a common axis (Smart H4:
    ``"2"``, a = 1.05 m, off the flange chain; ``"2'"``, a = 0.45 m); ``coupler``
    (``"3'"``) and ``follower`` (``"4'"``) carry the passive joints.  The end frame
    of ``follower`` must coincide, in the loop plane, with the end frame of
    ``arm`` (constraints 6.4–6.5)::

        a_crank·e(θ_crank) + a_cpl·e(θ_crank + θ_cpl)
            + a_fol·e(θ_crank + θ_cpl + θ_fol) = a_arm·e(θ_arm),   e(φ) = (cos φ, sin φ)

    with θ_arm, θ_crank the DH angles of arm and crank (kinematic joint + ``theta``) and
    θ_cpl, θ_fol the closure angles (the coupler's and follower's DH angles are these
    plus their ``theta``).  A loop of ``kind`` ``"parallelogram"`` (a nominal
    description) must be one (a_coupler = a_arm, a_follower = a_crank, planar: α = β = 0,
    coupler and follower d = 0, arm and crank the same d), whose solution is eq. (6.10):
    θ_cpl = θ_arm − θ_crank, θ_fol = π − θ_arm + θ_crank
    (:func:`~plugcell.kinematics.closure.nominal_closure`).  A loop of ``kind``
    ``"fourbar"`` (a calibrated or measured robot) keeps the geometry it is given —
    unequal opposite sides, twists α, β and offsets d on its links: the passive angles
    are those of the exact planar four-bar of its lengths a
    (:func:`~plugcell.kinematics.closure.fourbar_closure`, the branch continuous with the
    parallelogram), and α, β, d act on the open chain; it must assemble over the whole
    range its coupled limit allows.  Either closure is defined while
    ``sin(θ_arm − θ_crank) ≠ 0``, which a :class:`CoupledLimit` on the arm and crank
    readings must guarantee (:data:`LOOP_MARGIN`).

    Attributes
    ----------
    arm : str
        Actuated link off the flange chain, sharing its parent with ``crank``.
    crank : str
        Actuated (revolute) link the coupler hangs from.
    coupler : str
        Passive link, child of ``crank``.
    follower : str
        Passive link, child of ``coupler``, on the chain to the flange.
    kind : str
        One of :data:`LOOP_KINDS`: ``"parallelogram"`` (default; the nominal, planar
        parallelogram is required) or ``"fourbar"`` (any geometry that assembles).
    """

    arm: str
    crank: str
    coupler: str
    follower: str
    kind: str = "parallelogram"

    @property
    def driven(self) -> tuple[str, str]:
        """``(arm, crank)``: the loop's actuated links."""
        return (self.arm, self.crank)

    @property
    def passive(self) -> tuple[str, str]:
        """``(coupler, follower)``: the loop's passive links."""
        return (self.coupler, self.follower)

    @property
    def links(self) -> tuple[str, str, str, str]:
        """``(arm, crank, coupler, follower)``."""
        return (self.arm, self.crank, self.coupler, self.follower)


@dataclass(frozen=True)
class CoupledLimit:
    """A limit on the difference of two revolute joint readings,
    ``lower ≤ q[joints[0]] − q[joints[1]] ≤ upper``.

    A parallelogram loop needs one on its arm and crank readings, keeping the
    arm–crank angle inside ``(k·π + LOOP_MARGIN, (k+1)·π − LOOP_MARGIN)``.

    Attributes
    ----------
    joints : (str, str)
        The two reading names (actuated link names without a coupling); not prismatic.
    lower : float, rad
        Smallest allowed difference, finite.
    upper : float, rad
        Largest allowed difference, finite, above ``lower``.
    """

    joints: tuple[str, str]
    lower: float
    upper: float


@dataclass(frozen=True, eq=False)
class JointCoupling:
    """The controller's joint readings → the kinematic joint variables (a vendor convention).

    ``θ_kin = matrix · readings + offset`` with ``matrix`` ``(n_actuated, n_readings)``
    (rows in the description's ``actuated`` order, columns in ``readings`` order) and
    ``offset`` ``(n_actuated,)`` radians.  θ_kin is what the DH rows see before the
    link's own ``theta`` offset is added.  Covers a J2/J3 interaction (Fanuc:
    θ3 = −J2 − J3), reversed directions (−1), zero offsets and gear couplings of
    wrist axes (fractional entries); ``n_readings < n_actuated`` maps several
    kinematic joints on one reading (URDF ``mimic``).  The map must be injective
    (full column rank) so readings can be recovered from kinematic joints.

    Validated by :class:`RobotDescription` (shapes, finite values, rank); errors
    name the file keys ``coupling.readings``, ``coupling.matrix``, ``coupling.offsets``.

    Parameters
    ----------
    readings : sequence of str
        Names of the controller's joint readings, unique, non-empty (column order).
    matrix : (n_actuated, n_readings) array_like
        ``M = ∂θ_kin/∂q``, dimensionless (rad per rad); stored read-only.
    offset : (n_actuated,) array_like, rad
        Constant added to each kinematic joint; stored read-only.

    Raises
    ------
    DescriptionError
        Empty or duplicate reading names, non-numeric values, a matrix that is not 2-D
        or an offset that is not 1-D (the remaining checks are the description's).
    """

    readings: tuple[str, ...]
    matrix: Array
    offset: Array

    def __post_init__(self) -> None:
        S = object.__setattr__
        S(self, "readings", tuple(self.readings))
        seen: dict[str, int] = {}
        for j, name in enumerate(self.readings):
            if not isinstance(name, str) or not name:
                raise DescriptionError(f"coupling.readings[{j}]", "must be a non-empty string")
            if name in seen:
                raise DescriptionError(
                    f"coupling.readings[{j}]",
                    f"duplicate reading name {name!r} (also readings[{seen[name]}])",
                )
            seen[name] = j
        if not self.readings:
            raise DescriptionError("coupling.readings", "at least one reading is required")
        try:
            M = np.array(self.matrix, dtype=float)
            off = np.array(self.offset, dtype=float)
        except (TypeError, ValueError) as exc:
            raise DescriptionError("coupling.matrix", f"expected numbers: {exc}") from None
        if M.ndim != 2:
            raise DescriptionError("coupling.matrix", f"expected a 2-D matrix, got {M.ndim}-D")
        if off.ndim != 1:
            raise DescriptionError("coupling.offsets", f"expected a vector, got {off.ndim}-D")
        M.setflags(write=False)
        off.setflags(write=False)
        S(self, "matrix", M)
        S(self, "offset", off)

    @property
    def n_readings(self) -> int:
        """Number of joint readings (columns of ``matrix``)."""
        return len(self.readings)

    def kinematic(self, readings: Any) -> Array:
        """Kinematic joints of joint readings, ``θ_kin = M · q + offset``.

        Parameters
        ----------
        readings : (..., n_readings) array_like, rad
            Joint readings q, in ``readings`` order.

        Returns
        -------
        (..., n_actuated) array, rad
            θ_kin, in the description's ``actuated`` order.
        """
        r = np.asarray(readings, dtype=float)
        return r @ self.matrix.T + self.offset

    def readings_of(self, kinematic: Any) -> Array:
        """Joint readings of kinematic joints, the least-squares inverse
        ``q = M⁺ (θ_kin − offset)`` (M⁺ the Moore–Penrose pseudo-inverse).

        Exact when θ_kin is in the map's range (always for a square, invertible M);
        otherwise the readings whose kinematic joints are nearest in the 2-norm.

        Parameters
        ----------
        kinematic : (..., n_actuated) array_like, rad
            Kinematic joints θ_kin.

        Returns
        -------
        (..., n_readings) array, rad
            Joint readings q.
        """
        k = np.asarray(kinematic, dtype=float)
        return (k - self.offset) @ self._left_inverse().T

    def _left_inverse(self) -> Array:
        L = self.__dict__.get("_pinv")
        if L is None:
            L = np.linalg.pinv(self.matrix)
            L.setflags(write=False)
            object.__setattr__(self, "_pinv", L)
        return L  # type: ignore[no-any-return]


@dataclass(frozen=True)
class PointMass:
    """A lumped mass (kg) at ``com`` (m, in frame ``link``) — e.g. a counterweight.

    Attributes
    ----------
    name : str
        Label (messages, the twin).
    link : str
        The link whose frame F_i carries it.
    mass : float, kg
        Mass, ≥ 0.
    com : (3,) tuple of float, m
        Position in the link frame F_i.
    """

    name: str
    link: str
    mass: float
    com: tuple[float, float, float]


@dataclass(frozen=True)
class Box:
    """Axis-aligned box in the robot base frame, ``{p : |p − center| ≤ size / 2}`` per axis.

    Attributes
    ----------
    center : (3,) tuple of float, m
        Centre, robot base frame.
    size : (3,) tuple of float, m
        Edge lengths along x, y, z (positive in a description).
    """

    center: tuple[float, float, float]
    size: tuple[float, float, float]

    @property
    def lower(self) -> Array:
        """``(3,)`` m: the lowest corner, ``center − size / 2``."""
        return np.asarray(self.center) - 0.5 * np.asarray(self.size)

    @property
    def upper(self) -> Array:
        """``(3,)`` m: the highest corner, ``center + size / 2``."""
        return np.asarray(self.center) + 0.5 * np.asarray(self.size)

    def contains(self, p: Any) -> NDArray[np.bool_]:
        """Which points lie inside, ``lower ≤ p ≤ upper`` on every axis (boundary included,
        with a 1e-12 m tolerance).

        Parameters
        ----------
        p : (..., 3) array_like, m
            Points in the robot base frame.

        Returns
        -------
        (...) bool array
            True inside the box.
        """
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

    Joint *readings* ``q`` (what the controller reports, what files, programs and
    services carry) are ``(..., n_readings)`` in :attr:`reading_names` order; the
    *kinematic* joints θ_kin (one per actuated link, ``actuated`` order) are
    ``coupling.matrix · q + coupling.offset`` — or ``q`` itself without a
    ``coupling``, where readings and kinematic joints are the same thing
    (:meth:`kinematic_joints`, :meth:`readings`).  ``joint_limits``
    ``(n_readings, 2)`` radians, ``home`` ``(n_readings,)`` radians (the
    documented default seed of inverse kinematics) and ``coupled_limits`` are on
    the readings; ``stiffness`` ``(n_actuated,)`` N·m/rad (or ``None``) is per
    actuated link.  A prismatic reading, its limits and home value are in metres.

    The flange pose in the robot base frame F0 is the product of the link transforms
    along :attr:`chain` (:class:`Link`), ``T_n^0 = Π_{i ∈ chain} T_i^parent(θ_i, d_i)``
    (eq. 6.1), the passive angles from the loop closure (:class:`FourBarLoop`); the
    tool point is ``T_n^0 · tool`` and, in the world (metrology) frame,
    ``BASE · T_n^0 · tool`` (:func:`~plugcell.kinematics.forward`).

    Parameters
    ----------
    name : str
        Robot name, non-empty.
    links : sequence of Link
        The links, parents listed before their children, one root (parent ``"base"``).
    actuated : sequence of str
        Every actuated and prismatic link, in kinematic joint (θ_kin) order.
    flange : str
        The link whose frame is the flange.
    loops : sequence of FourBarLoop
        Closed loops.
    base : (4, 4) array_like, m
        BASE: the robot base frame F0 in the world (metrology) frame, a rigid transform.
    tool : (4, 4) array_like, m
        The tool point in the flange frame, a rigid transform.
    joint_limits : (n_readings, 2) array_like, rad (m for prismatic)
        ``[lower, upper]`` per reading, finite, ``lower < upper``.
    stiffness : (n_actuated,) array_like, N·m/rad, optional
        Joint stiffness per actuated link, positive.
    notes : str
        Free text (provenance).
    coupled_limits : sequence of CoupledLimit
        Limits on reading differences; one per loop is required.
    home : (n_readings,) array_like, rad (m for prismatic), optional
        Home readings, inside every limit (default: mid-range of ``joint_limits``).
    point_masses : sequence of PointMass
        Extra lumped masses for the twin.
    working_volume : Box, optional
        Where the robot works (robot base frame).
    coupling : JointCoupling, optional
        Readings → kinematic joints; ``None``: the readings are the kinematic joints.

    Attributes
    ----------
    base, tool : (4, 4) array, m
        As given, read-only.
    joint_limits : (n_readings, 2) array
        As given, read-only.
    stiffness : (n_actuated,) array or None
        As given, read-only.
    home : (n_readings,) array
        The home readings (the default filled in), read-only.

    Raises
    ------
    DescriptionError
        The first inconsistency found, at its file location (e.g. ``links[2].parent``):
        names, parents, joint types, a flange off the tree, a loop that is not a
        closable parallelogram or lacks its coupled limit, a non-rigid BASE/tool, limit
        or shape errors, a singular or overflowing coupling, ``home`` outside the limits.
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
    coupling: JointCoupling | None = None
    # derived (filled in __post_init__)
    _index: dict[str, int] = field(default_factory=dict, init=False, repr=False)
    _chain: tuple[int, ...] = field(default=(), init=False, repr=False)
    _parents: tuple[int, ...] = field(default=(), init=False, repr=False)
    _prismatic: NDArray[np.bool_] = field(default_factory=lambda: np.zeros(0, bool),
                                          init=False, repr=False)
    _revolute: tuple[NDArray[np.intp], NDArray[np.intp]] = field(
        default=(np.zeros(0, np.intp), np.zeros(0, np.intp)), init=False, repr=False)
    _loop_indices: tuple[tuple[int, ...], ...] = field(default=(), init=False, repr=False)

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
        self._derive_tree(index)
        self._check_coupling()
        n = self.n_readings
        for key in ("base", "tool"):
            try:
                T = _ro(getattr(self, key), (4, 4))
            except ValueError as exc:
                raise DescriptionError(key, str(exc)) from None
            check_rigid(T, key)
            S(self, key, T)
        try:
            lim = _ro(self.joint_limits, (n, 2))
        except ValueError as exc:
            raise DescriptionError("joint_limits", str(exc)) from None
        for j in range(n):
            lo, hi = lim[j]
            loc = self._limit_location(j)
            if not (np.isfinite(lo) and np.isfinite(hi)):
                raise DescriptionError(loc, "limits must be finite")
            if not lo < hi:
                raise DescriptionError(
                    loc,
                    f"lower limit {self._fmt(j, lo)} must be below upper {self._fmt(j, hi)}",
                )
        S(self, "joint_limits", lim)
        if self.coupling is not None:
            with np.errstate(over="ignore", invalid="ignore"):
                kin_lim = self.kinematic_limits()
            bad = np.flatnonzero(~np.all(np.isfinite(kin_lim), axis=1))
            if bad.size:
                raise DescriptionError(
                    f"coupling.matrix[{int(bad[0])}]",
                    "values too large: the joint angles the reading limits allow overflow",
                )
        if self.stiffness is not None:
            try:
                k = _ro(self.stiffness, (len(self.actuated),))
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

    def _check_coupling(self) -> None:
        c = self.coupling
        if c is None:
            return
        for i, lk in enumerate(self.links):
            if lk.is_prismatic:
                raise DescriptionError(
                    f"links[{i}].joint",
                    "a joint coupling of a robot with prismatic joints is not supported",
                )
        if not isinstance(c, JointCoupling):
            raise DescriptionError("coupling", f"expected a JointCoupling, got {type(c).__name__}")
        n_a, n_r = len(self.actuated), c.n_readings
        M, off = c.matrix, c.offset
        if M.shape != (n_a, n_r):
            raise DescriptionError(
                "coupling.matrix",
                f"expected {n_a}×{n_r} (one row per actuated joint {list(self.actuated)}, one "
                f"column per reading {list(c.readings)}), got {M.shape[0]}×{M.shape[1]}",
            )
        if off.shape != (n_a,):
            raise DescriptionError(
                "coupling.offsets",
                f"expected {n_a} numbers (one per actuated joint), got {off.size}",
            )
        for r in range(n_a):
            for j in range(n_r):
                if not math.isfinite(M[r, j]):
                    raise DescriptionError(
                        f"coupling.matrix[{r}][{j}]", f"must be finite, got {M[r, j]!r}"
                    )
            if not math.isfinite(off[r]):
                raise DescriptionError(f"coupling.offsets[{r}]", f"must be finite, got {off[r]!r}")
        for j in range(n_r):
            if not np.any(M[:, j] != 0.0):
                raise DescriptionError(
                    "coupling.matrix",
                    f"reading {c.readings[j]!r} (column {j}) moves no joint: "
                    "the column is all zero",
                )
        sv = np.linalg.svd(M, compute_uv=False)
        if n_r > n_a or sv[-1] <= COUPLING_RANK_TOL * max(sv[0], 1.0):
            rank = int(np.sum(sv > COUPLING_RANK_TOL * max(sv[0], 1.0)))
            raise DescriptionError(
                "coupling.matrix",
                f"singular: rank {rank} < {n_r} readings, so different readings give the same "
                "joint angles and the readings cannot be recovered (inverse kinematics, "
                "compensation) — the map from readings to joints must be injective",
            )

    def _limit_location(self, j: int) -> str:
        """File location of the limits of reading ``j``."""
        if self.coupling is not None:
            return f"coupling.limits[{j}]"
        return f"links[{self._index[self.actuated[j]]}].limits"

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

    def _derive_tree(self, index: dict[str, int]) -> None:
        """What forward kinematics asks every call, made once (read-only) from the
        checked links, joints and loops: the parents' positions, the prismatic mask, the
        revolute joints' links and each loop's link and joint positions."""
        S = object.__setattr__
        S(self, "_parents", tuple(index.get(lk.parent, -1) for lk in self.links))
        prismatic = np.array([self.links[index[n]].is_prismatic for n in self.actuated],
                             dtype=bool)
        revolute = (np.flatnonzero(~prismatic),
                    np.array([index[n] for n, p in zip(self.actuated, prismatic, strict=True)
                              if not p], dtype=np.intp))
        for a in (prismatic, *revolute):
            a.setflags(write=False)
        S(self, "_prismatic", prismatic)
        S(self, "_revolute", revolute)
        S(self, "_loop_indices", tuple(
            (*(index[n] for n in loop.links), self.actuated.index(loop.arm),
             self.actuated.index(loop.crank)) for loop in self.loops))

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
            L = _loop_roles(loc, loop, self.links, index, used)
            _check_loop_topology(loc, L, index, on_chain)
            if loop.kind == "fourbar":  # any geometry; assembly: _check_coupled
                continue
            _check_parallelogram(L, index)
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
        act = {n: j for j, n in enumerate(self.reading_names)}
        what = "a joint reading" if self.coupling is not None else "an actuated joint"
        for k, cl in enumerate(self.coupled_limits):
            loc = f"coupled_limits[{k}]"
            if len(cl.joints) != 2:
                raise DescriptionError(f"{loc}.joints", "expected two joint names")
            for m, name in enumerate(cl.joints):
                if name not in act:
                    raise DescriptionError(f"{loc}.joints[{m}]", f"{name!r} is not {what}")
                if self.prismatic_readings[act[name]]:
                    raise DescriptionError(f"{loc}.joints[{m}]",
                                           f"{name!r} is prismatic (coupled limits are on angles)")
            if cl.joints[0] == cl.joints[1]:
                raise DescriptionError(f"{loc}.joints", "the two joints must differ")
            if not (math.isfinite(cl.lower) and math.isfinite(cl.upper)) or not cl.lower < cl.upper:
                raise DescriptionError(f"{loc}", "min must be below max (finite)")
        for k, loop in enumerate(self.loops):
            i, j, off = self.loop_readings(k)
            ri, rj = self.reading_names[i], self.reading_names[j]
            found = False
            for m, cl in enumerate(self.coupled_limits):
                if set(cl.joints) != {ri, rj}:
                    continue
                found = True
                lo, hi = cl.lower, cl.upper
                if cl.joints[0] != ri:  # limit on reading j − reading i
                    lo, hi = -hi, -lo
                lo, hi = lo + off, hi + off
                kk = math.floor(lo / math.pi)
                if not (
                    lo >= kk * math.pi + LOOP_MARGIN and hi <= (kk + 1) * math.pi - LOOP_MARGIN
                ):
                    raise DescriptionError(
                        f"coupled_limits[{m}]",
                        f"the range of {ri} − {rj} lets the loop collapse: the angle "
                        f"between arm and crank spans "
                        f"[{math.degrees(lo):g}°, {math.degrees(hi):g}°], "
                        f"which must stay at least {math.degrees(LOOP_MARGIN):g}° inside "
                        f"(k·180°, (k+1)·180°)",
                    )
                if loop.kind == "fourbar":
                    self._check_assembly(k, m, lo, hi)
            if not found:
                raise DescriptionError(
                    "coupled_limits",
                    f"loops[{k}] needs a coupled limit on {ri} − {rj} that keeps "
                    f"sin({loop.arm} − {loop.crank}) away from 0",
                )

    def _check_assembly(self, k: int, m: int, lo: float, hi: float) -> None:
        """A ``"fourbar"`` loop ``k`` must assemble for every arm − crank angle in
        ``[lo, hi]`` (rad), the range coupled limit ``m`` allows.

        The closure depends on Δ = θ_arm − θ_crank only, through
        ``|r|² = a_arm² + a_crank² − 2·a_arm·a_crank·cos Δ``, which is monotonic on
        ``[lo, hi]`` (inside (k·π, (k+1)·π)), so ``cos θ_fol = (|r|² − a_cpl² −
        a_fol²) / (2·a_cpl·a_fol)`` is extreme at the two ends: both must have
        ``|cos θ_fol| ≤`` :data:`FOURBAR_MAX_COS`.
        """
        loop = self.loops[k]
        la, lc, l3, l4 = (self.links[self._index[n]].a for n in loop.links)
        for delta in (lo, hi):
            r2 = la * la + lc * lc - 2.0 * la * lc * math.cos(delta)
            c4 = (r2 - l3 * l3 - l4 * l4) / (2.0 * l3 * l4)
            if not abs(c4) <= FOURBAR_MAX_COS:
                raise DescriptionError(
                    f"coupled_limits[{m}]",
                    f"loops[{k}] (fourbar) cannot be assembled at arm − crank = "
                    f"{math.degrees(delta):g}°, inside this limit: the gap between the crank "
                    f"and arm ends is {math.sqrt(r2):.6g} m, the coupler ({l3:.6g} m) and "
                    f"follower ({l4:.6g} m) close it only with cos θ_fol = {c4:.6g} "
                    f"(|cos| must stay ≤ {FOURBAR_MAX_COS:g})",
                )

    def loop_readings(self, k: int) -> tuple[int, int, float]:
        """Readings ``(i, j)`` and constant ``c`` with ``θ_arm − θ_crank = q_i − q_j + c``.

        θ are the DH angles (kinematic joint + the link's ``theta``) of loop ``k``'s
        arm and crank.  Without a coupling ``i, j`` are the arm and crank themselves and
        ``c = theta_arm − theta_crank``; with one, the arm − crank row of the matrix,
        ``M[arm] − M[crank]``, must be ``e_i − e_j`` (the difference of two readings), and
        ``c = theta_arm − theta_crank + offset[arm] − offset[crank]``.

        Parameters
        ----------
        k : int
            Index into :attr:`loops`.

        Returns
        -------
        i, j : int
            Positions of the two readings in ``q``.
        c : float, rad
            The constant.

        Raises
        ------
        DescriptionError
            At ``coupling.matrix``, when the arm − crank row is not a difference of two
            readings.
        """
        loop = self.loops[k]
        ka, kc = self.actuated.index(loop.arm), self.actuated.index(loop.crank)
        c = self.links[self._index[loop.arm]].theta - self.links[self._index[loop.crank]].theta
        if self.coupling is None:
            return ka, kc, c
        M, off = self.coupling.matrix, self.coupling.offset
        row = M[ka] - M[kc]
        nz = np.flatnonzero(np.abs(row) > 1e-12)
        if len(nz) == 2 and np.allclose(np.sort(row[nz]), [-1.0, 1.0], rtol=0.0, atol=1e-12):
            i = int(nz[np.argmax(row[nz])])
            j = int(nz[np.argmin(row[nz])])
            return i, j, c + float(off[ka] - off[kc])
        raise DescriptionError(
            "coupling.matrix",
            f"loops[{k}]: the arm − crank angle ({loop.arm} − {loop.crank}) must be the "
            f"difference of two readings (rows {ka} − {kc} = {row.tolist()}), so a coupled "
            "limit on those readings can keep the parallelogram from collapsing",
        )

    def _check_home(self) -> None:
        n = self.n_readings
        lim = self.joint_limits
        if self.home is None:
            home = lim.mean(axis=1)
            where = "home (default: mid-range; give 'home' explicitly)"
        else:
            home = np.array(self.home, dtype=float).reshape(-1)
            if home.shape != (n,):
                per = "joint reading" if self.coupling is not None else "actuated joint"
                raise DescriptionError(
                    "home", f"expected {n} numbers (one per {per}), got {home.size}"
                )
            where = "home"
        for j, name in enumerate(self.reading_names):
            if not lim[j, 0] <= home[j] <= lim[j, 1]:
                raise DescriptionError(
                    f"{where}[{j}]",
                    f"joint {name} = {self._fmt(j, home[j])} is outside its limits "
                    f"[{self._fmt(j, lim[j, 0])}, {self._fmt(j, lim[j, 1])}]",
                )
        act = {nm: j for j, nm in enumerate(self.reading_names)}
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
        """Number of kinematic joints θ_kin (actuated and prismatic links)."""
        return len(self.actuated)

    @property
    def n_links(self) -> int:
        """Number of links."""
        return len(self.links)

    @property
    def link_names(self) -> tuple[str, ...]:
        """Link names, in :attr:`links` order."""
        return tuple(self._index)

    @property
    def revolute_links(self) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
        """``(j, i)``: the revolute actuated joints' positions ``j`` in θ_kin and their
        links' positions ``i`` in :attr:`links` (``θ_i += θ_kin,j``; read-only)."""
        return self._revolute

    @property
    def loop_indices(self) -> tuple[tuple[int, int, int, int, int, int], ...]:
        """Per loop, the positions ``(arm, crank, coupler, follower)`` of its links in
        :attr:`links` and ``(arm, crank)`` in θ_kin."""
        return self._loop_indices  # type: ignore[return-value]

    @property
    def parent_indices(self) -> tuple[int, ...]:
        """Position of every link's parent in :attr:`links` (−1 for the root, the first)."""
        return self._parents

    def index(self, name: str) -> int:
        """Position of link ``name`` in :attr:`links` (and in parameter arrays).

        Parameters
        ----------
        name : str
            A link name.

        Returns
        -------
        int
            Its index.

        Raises
        ------
        KeyError
            Unknown link (the message lists the links).
        """
        try:
            return self._index[name]
        except KeyError:
            raise KeyError(f"unknown link {name!r}; links are {list(self.link_names)}") from None

    def link(self, name: str) -> Link:
        """The link called ``name``.

        Parameters
        ----------
        name : str
            A link name.

        Returns
        -------
        Link
            The link.

        Raises
        ------
        KeyError
            Unknown link.
        """
        return self.links[self.index(name)]

    def joint_index(self, name: str) -> int:
        """Position of reading ``name`` in the joint-reading vector ``q``.

        Without a coupling the readings are the actuated links, so ``name`` is an
        actuated link name (:meth:`actuated_index`).

        Parameters
        ----------
        name : str
            A reading name (:attr:`reading_names`).

        Returns
        -------
        int
            Its column in ``q``.

        Raises
        ------
        KeyError
            Not a reading (the message lists the readings).
        """
        try:
            return self.reading_names.index(name)
        except ValueError:
            raise KeyError(
                f"{name!r} is not a joint reading; readings are {list(self.reading_names)}"
            ) from None

    def actuated_index(self, name: str) -> int:
        """Position of actuated link ``name`` in the kinematic joint vector θ_kin.

        Parameters
        ----------
        name : str
            An actuated (or prismatic) link name.

        Returns
        -------
        int
            Its position in :attr:`actuated`.

        Raises
        ------
        KeyError
            Not an actuated link.
        """
        try:
            return self.actuated.index(name)
        except ValueError:
            raise KeyError(
                f"{name!r} is not an actuated joint; joints are {list(self.actuated)}"
            ) from None

    # ------------------------------------------------------------------ readings
    @property
    def reading_names(self) -> tuple[str, ...]:
        """Names of the joint readings, in ``q`` order (the ``actuated`` links if uncoupled)."""
        return self.coupling.readings if self.coupling is not None else self.actuated

    @property
    def n_readings(self) -> int:
        """Length of a joint-reading vector ``q``."""
        return len(self.reading_names)

    @property
    def reading_jacobian(self) -> Array:
        """``∂θ_kin/∂q`` ``(n_actuated, n_readings)``, dimensionless: the coupling matrix
        M, or the identity without a coupling (read-only)."""
        if self.coupling is not None:
            return self.coupling.matrix
        eye = np.eye(self.n_actuated)
        eye.setflags(write=False)
        return eye

    def kinematic_joints(self, q: Any) -> Array:
        """Kinematic joints θ_kin ``(..., n_actuated)`` of readings ``q`` ``(..., n_readings)``.

        ``θ_kin = M · q + offset`` (the :class:`JointCoupling`); ``q`` itself (as a
        float array) without a coupling.

        Parameters
        ----------
        q : (..., n_readings) array_like, rad (m for prismatic)
            Joint readings, :attr:`reading_names` order.

        Returns
        -------
        (..., n_actuated) array, rad (m for prismatic)
            θ_kin, :attr:`actuated` order.
        """
        q = np.asarray(q, dtype=float)
        if self.coupling is None:
            return q
        return self.coupling.kinematic(q)

    def readings(self, theta: Any) -> Array:
        """Joint readings ``(..., n_readings)`` of kinematic joints θ_kin ``(..., n_actuated)``.

        ``q = M⁺ (θ_kin − offset)`` — exact when θ_kin is reachable by the coupling
        (always when M is square); otherwise the readings whose kinematic joints are
        nearest in the least-squares sense.  Identity without a coupling.

        Parameters
        ----------
        theta : (..., n_actuated) array_like, rad (m for prismatic)
            Kinematic joints θ_kin, :attr:`actuated` order.

        Returns
        -------
        (..., n_readings) array, rad (m for prismatic)
            Joint readings q.
        """
        theta = np.asarray(theta, dtype=float)
        if self.coupling is None:
            return theta
        return self.coupling.readings_of(theta)

    @property
    def periodic_readings(self) -> NDArray[np.bool_]:
        """``(n_readings,)`` bool: where adding 2π to the reading leaves the robot's pose
        unchanged — column j of M is integer (``M[:, j] ∈ ℤ^n``, every kinematic joint it
        drives moves by a whole number of turns) and the reading is not prismatic."""
        M = self.reading_jacobian
        return np.all(np.abs(M - np.round(M)) < 1e-12, axis=0) & ~self.prismatic_readings

    @property
    def prismatic_readings(self) -> NDArray[np.bool_]:
        """``(n_readings,)``: which readings are lengths (prismatic joints, metres)."""
        if self.coupling is not None:  # couplings of prismatic joints are refused
            return np.zeros(self.n_readings, dtype=bool)
        return np.array([self.links[self._index[n]].is_prismatic for n in self.actuated],
                        dtype=bool)

    @property
    def prismatic_links(self) -> NDArray[np.bool_]:
        """``(n_actuated,)``: which actuated links are prismatic (``actuated`` order;
        read-only, made once)."""
        return self._prismatic

    def reading_scale(self, units: str = "robot") -> Array:
        """SI per unit of each reading, ``q_SI = scale · q_units``.

        Parameters
        ----------
        units : {"robot", "file"}
            ``"robot"``: degrees and millimetres (command line, measurement files);
            ``"file"``: degrees and metres (description files).

        Returns
        -------
        (n_readings,) array
            π/180 (rad per degree) for a revolute reading; 1e-3 (``"robot"``) or 1
            (``"file"``) m per unit for a prismatic one.

        Raises
        ------
        KeyError
            Unknown ``units``.
        """
        length = {"robot": 1e-3, "file": 1.0}[units]
        return np.where(self.prismatic_readings, length, _DEG)

    def _fmt(self, j: int, v: float, digits: int | None = None) -> str:
        """Reading ``j``'s value ``v`` (SI) for a message: degrees or millimetres."""
        if self.prismatic_readings[j]:
            x, unit = v * 1e3, " mm"
        else:
            x, unit = math.degrees(v), "°"
        return (f"{x:.{digits}f}" if digits is not None else f"{x:g}") + unit

    def kinematic_limits(self) -> Array:
        """``(n_actuated, 2)``: the box of kinematic joints θ_kin the reading limits allow.

        Interval arithmetic on ``θ_kin = M·q + offset``::

            θ_kin,min,r = Σ_j min(M_rj·q_min,j, M_rj·q_max,j) + offset_r
            θ_kin,max,r = Σ_j max(M_rj·q_min,j, M_rj·q_max,j) + offset_r

        (each bound is attained, the box encloses the image); the joint limits
        themselves without a coupling.

        Returns
        -------
        (n_actuated, 2) array, rad (m for prismatic)
            ``[lower, upper]`` per kinematic joint (read-only).
        """
        c = self.coupling
        if c is None:
            return self.joint_limits
        M, off = c.matrix, c.offset
        lo, hi = self.joint_limits[:, 0], self.joint_limits[:, 1]
        klo = np.minimum(M * lo, M * hi).sum(axis=1) + off
        khi = np.maximum(M * lo, M * hi).sum(axis=1) + off
        out = np.stack([klo, khi], axis=1)
        out.setflags(write=False)
        return out

    def uncoupled(self) -> RobotDescription:
        """The same robot with its kinematic joints as readings (no coupling).

        Links, loops, BASE, tool, masses and stiffnesses are kept; limits are the
        box enclosing the image of the reading limits, a loop's coupled limit is
        moved onto arm − crank (shifted by ``offset[arm] − offset[crank]``); other
        coupled limits are dropped (they are on readings, which this robot no longer
        has); ``home`` is θ_kin of the home readings.  Without a
        coupling this is ``self``.  Calibration builds its models on it.

        Returns
        -------
        RobotDescription
            The uncoupled description (computed once, then cached).
        """
        if self.coupling is None:
            return self
        cached = self.__dict__.get("_uncoupled")
        if cached is not None:
            return cached  # type: ignore[no-any-return]
        coupled = []
        for k, loop in enumerate(self.loops):
            i, j, cst = self.loop_readings(k)
            ri, rj = self.reading_names[i], self.reading_names[j]
            for cl in self.coupled_limits:
                if set(cl.joints) == {ri, rj}:
                    a, b = (cl.lower, cl.upper) if cl.joints[0] == ri else (-cl.upper, -cl.lower)
                    shift = cst - (
                        self.links[self._index[loop.arm]].theta
                        - self.links[self._index[loop.crank]].theta
                    )
                    coupled.append(CoupledLimit((loop.arm, loop.crank), a + shift, b + shift))
                    break
        kin = RobotDescription(
            name=self.name,
            links=self.links,
            actuated=self.actuated,
            flange=self.flange,
            loops=self.loops,
            base=self.base,
            tool=self.tool,
            joint_limits=self.kinematic_limits(),
            stiffness=self.stiffness,
            notes=self.notes,
            coupled_limits=tuple(coupled),
            home=self.kinematic_joints(self.home),
            point_masses=self.point_masses,
            working_volume=self.working_volume,
        )
        object.__setattr__(self, "_uncoupled", kin)
        return kin

    @property
    def chain(self) -> tuple[int, ...]:
        """Link indices from the root to the flange (thesis chain 1-2'-3'-4'-3-4-5-6)."""
        return self._chain

    @property
    def passive(self) -> tuple[str, ...]:
        """Passive link names, in loop order (coupler, follower of each loop)."""
        return tuple(n for loop in self.loops for n in loop.passive)

    def nominal_parameters(self) -> GeometricParameters:
        """The description's DH + Hayati rows, BASE and tool as a parameter set.

        Returns
        -------
        GeometricParameters
            ``theta``, ``alpha``, ``beta`` (rad), ``d``, ``a`` (m) per link in
            :attr:`links` order, ``base`` and ``tool`` (4, 4) m.  Made once, then the
            same (immutable: read-only arrays) object: forward kinematics without
            parameters asks for it every call.
        """
        made = self.__dict__.get("_nominal")
        if made is None:
            made = GeometricParameters(
                link_names=self.link_names,
                theta=[lk.theta for lk in self.links],
                d=[lk.d for lk in self.links],
                a=[lk.a for lk in self.links],
                alpha=[lk.alpha for lk in self.links],
                beta=[lk.beta for lk in self.links],
                base=self.base,
                tool=self.tool,
            )
            object.__setattr__(self, "_nominal", made)
        return made

    def limit_violations(self, q: Any, tol: float = 0.0) -> list[str]:
        """Human-readable list of limit violations of one reading vector.

        Checks ``q_min,j − tol ≤ q_j ≤ q_max,j + tol`` for every reading and
        ``lower − tol ≤ q_a − q_b ≤ upper + tol`` for every :class:`CoupledLimit`.

        Parameters
        ----------
        q : (n_readings,) array_like, rad (m for prismatic)
            Joint readings.
        tol : float, rad (m for prismatic)
            Slack allowed beyond each limit.

        Returns
        -------
        list of str
            One message per violated limit (degrees or mm); empty if none.
        """
        q = np.asarray(q, dtype=float)
        out = []
        for j, name in enumerate(self.reading_names):
            lo, hi = self.joint_limits[j]
            if not lo - tol <= q[j] <= hi + tol:
                out.append(
                    f"joint {name} = {self._fmt(j, q[j], 4)} outside "
                    f"[{self._fmt(j, lo)}, {self._fmt(j, hi)}]"
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
        """Which reading vectors lie inside the joint and the coupled limits (the test of
        :meth:`limit_violations`, vectorised).

        Parameters
        ----------
        q : (..., n_readings) array_like, rad (m for prismatic)
            Joint readings.
        tol : float, rad (m for prismatic)
            Slack allowed beyond each limit.

        Returns
        -------
        (...) bool array
            True where every limit holds.
        """
        q = np.asarray(q, dtype=float)
        lo, hi = self.joint_limits[:, 0], self.joint_limits[:, 1]
        ok = np.all((q >= lo - tol) & (q <= hi + tol), axis=-1)
        for cl in self.coupled_limits:
            v = q[..., self.joint_index(cl.joints[0])] - q[..., self.joint_index(cl.joints[1])]
            ok &= (v >= cl.lower - tol) & (v <= cl.upper + tol)
        return ok


def _loop_roles(
    loc: str,
    loop: FourBarLoop,
    links: tuple[Link, ...],
    index: dict[str, int],
    used: dict[str, str],
) -> dict[str, Link]:
    """The links playing the loop's four roles, each checked for its kind of joint.

    A loop's type is one of :data:`LOOP_KINDS`; each role names a known link not used by
    another loop (``used``, link name → ``loops[k].role``, is updated); the arm and the
    crank are revolute and actuated, the coupler and the follower passive.

    Returns
    -------
    dict
        Role (``"arm"``, ``"crank"``, ``"coupler"``, ``"follower"``) → its link.

    Raises
    ------
    DescriptionError
        Located at ``loc`` (``loops[k]``) and the role.
    """
    if loop.kind not in LOOP_KINDS:
        raise DescriptionError(f"{loc}.type", f"unknown loop type {loop.kind!r} "
                               f"(expected one of {', '.join(LOOP_KINDS)})")
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
        r: links[index[getattr(loop, r)]]
        for r in ("arm", "crank", "coupler", "follower")
    }
    for role in ("arm", "crank"):
        if L[role].is_prismatic:
            raise DescriptionError(
                f"{loc}.{role}", f"link {L[role].name!r} must be revolute, not prismatic"
            )
        if not L[role].is_actuated:
            raise DescriptionError(
                f"{loc}.{role}", f"link {L[role].name!r} must be actuated"
            )
    for role in ("coupler", "follower"):
        if not L[role].is_passive:
            raise DescriptionError(
                f"{loc}.{role}", f"link {L[role].name!r} must be passive"
            )
    return L


def _check_loop_topology(
    loc: str, L: dict[str, Link], index: dict[str, int], on_chain: set[int]
) -> None:
    """Check how a loop's links hang together and on the chain to the flange.

    Arm and crank share a parent (coaxial driven joints); the coupler hangs on the
    crank and the follower on the coupler; the arm is off the flange chain
    (``on_chain``, link indices), the follower on it; the four lengths ``a`` (m) are
    positive.  ``L``: role → link, as :func:`_loop_roles` returns.

    Raises
    ------
    DescriptionError
        Located at ``loc`` (``loops[k]``) and the role, or at the link's ``a``.
    """
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
    for role in ("crank", "coupler", "follower", "arm"):
        if not L[role].a > 0:
            raise DescriptionError(
                f"links[{index[L[role].name]}].a", "loop link lengths must be positive"
            )


def _check_parallelogram(L: dict[str, Link], index: dict[str, int]) -> None:
    """Check a parallelogram loop's nominal geometry (thesis eq. 6.10 holds exactly).

    All four links planar (``α = β = 0``), ``d = 0`` on the coupler and the follower,
    ``d_arm = d_crank``, and opposite sides equal: ``a_coupler = a_arm``,
    ``a_follower = a_crank`` (to 1e-9 m).  ``L``: role → link.

    Raises
    ------
    DescriptionError
        Located at the offending link's field; a calibrated (non-parallel) loop is
        ``type = "fourbar"``.
    """
    for role in ("arm", "crank", "coupler", "follower"):
        lk = L[role]
        if abs(lk.alpha) > 1e-12 or abs(lk.beta) > 1e-12:
            raise DescriptionError(
                f"links[{index[lk.name]}]",
                f"loop link {lk.name!r} must be planar nominally (alpha = beta = 0) "
                f"in a parallelogram; a calibrated loop is type = \"fourbar\"",
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
                f"({L[a_role].a:g} m) must equal the {b_role}'s ({L[b_role].a:g} m) "
                "(a calibrated loop is type = \"fourbar\")",
            )


def check_rigid(T: Array, loc: str) -> None:
    """Check that ``T`` is a rigid transform (finite, a proper rotation, last row 0 0 0 1).

    Parameters
    ----------
    T : ndarray, shape (4, 4)
        The homogeneous transform (metres).
    loc : str
        Location named by the error (``"base"``, ``"tool.matrix"``).

    Raises
    ------
    DescriptionError
        At ``loc``, saying which of the three conditions fails.
    """
    R = T[:3, :3]
    if not np.all(np.isfinite(T)):
        raise DescriptionError(loc, "transform must be finite")
    if np.abs(R @ R.T - np.eye(3)).max() > 1e-6 or np.linalg.det(R) < 0:
        raise DescriptionError(loc, "rotation part is not a proper rotation matrix")
    if np.abs(T[3] - [0, 0, 0, 1]).max() > 1e-12:
        raise DescriptionError(loc, "last row must be [0, 0, 0, 1]")
