"""The kinematic structure a calibration model is built on, and its candidate parameters.

Two *families* (thesis 8.2.3):

``loop``
    The robot as described: the flange chain runs through the parallelogram
    (Smart H4: 1-2'-3'-4'-3-4-5-6, eq. 6.2) and the passive angles come from the
    exact four-bar closure (appendix C).  The loop's own parameters (arm θ and a,
    crank, coupler and follower lengths) act through the closure (eqs. 6.16–6.22).
``serial``
    The "standardized" serial robot of eq. (6.3) (Schröer et al. 1997): the loop is
    ignored, the arm carries the forearm directly, and the cut joint's angle is the
    nominal-closure value ``π + θ_crank − θ_arm`` — a linear function of the joint
    readings (:attr:`KinematicStructure.reading_map`).  A robot without a loop is
    its own serial structure.

A description with a joint ``coupling`` (vendor convention, θ_kin = M·q + offset)
is calibrated on its kinematic joints: the structure's chain is built from
``desc.uncoupled()`` and the readings enter through ``desc.kinematic_joints``, so
the identified parameters (joint offsets Δθ included) are the same as for a
hand-converted description, while data, results and compensation keep the
readings exactly as the controller reports them.

The candidate error parameters (before the identifiability analysis removes the
redundant ones) are, per structure:

* BASE (eq. 6.24): ``a0, b0, α0, β0, θ0, d0`` — ``BASE = BASE_ref · Tx(a0) Ty(b0)
  Rx(α0) Ry(β0) Rz(θ0) Tz(d0)``, the errors relative to a reference BASE (the
  initial estimate), so any tracker placement is regular;
* every link on the flange chain: θ (actuated and fixed joints; a passive angle
  is not a parameter, the closure sets it), d, a, α, and β where consecutive
  axes are parallel (eq. 4.13; detected from the nominal geometry, or marked
  ``hayati`` in the description); the off-chain arm of a loop: θ and a;
* PROBE through the virtual frame 7 (6.2.2): ``T_tcp = F_n · Rx(−90°) · Rz(θ7)
  Tz(d7) Tx(a7) Rx(90° + α7) · PROBE_ref`` — with the flange link's own θ, d, a, α
  these span every small error of the flange-to-target transform.

Each candidate carries a priority; :mod:`plugcell.calibration.identifiability`
keeps, among parameters that explain the same pose error, the one listed first.
The order reproduces the thesis's choices (Table 6-2): BASE position and tilt;
actuated joint offsets; links outside loops and the PROBE frame (translations of
the flange link and frame 7 before their rotations, so that position-only data
keep the target offset as three translations); loop links;
translations along parallel axes (grouped into the last one, e.g. d3 stands for
d2' + d3' + d4' + d3); fixed-joint offsets (θ3 grouped into θ2'); BASE θ0 and d0
(grouped into θ1, d1).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from plugcell.calibration.parameters import ErrorParameter, geometric_parameter
from plugcell.kinematics import GeometricParameters, Link, RobotDescription
from plugcell.kinematics.parameters import FIELDS

Array = NDArray[np.float64]

FAMILIES: tuple[str, ...] = ("loop", "serial")

#: |sin α| below this marks consecutive parallel joint axes (Hayati β needed).
PARALLEL_TOL = 1e-6

#: Priority classes (first element of :attr:`ErrorParameter.priority`).
CLASS_BASE, CLASS_JOINT, CLASS_OPEN, CLASS_LOOP, CLASS_PARALLEL_D, CLASS_FIXED, CLASS_BASE_Z = (
    0, 1, 2, 3, 4, 5, 6,
)
CLASS_GRAVITY, CLASS_PAYLOAD, CLASS_HARMONIC, CLASS_THERMAL = 7, 8, 9, 10

__all__ = [
    "FAMILIES",
    "KinematicStructure",
    "StructureError",
    "kinematic_structure",
]


class StructureError(ValueError):
    """A description for which the requested structure cannot be built."""


@dataclass(frozen=True, eq=False)
class KinematicStructure:
    """The chain forward kinematics runs on, for one model family (module docstring).

    Attributes
    ----------
    family : str
        ``"loop"`` or ``"serial"``.
    source : RobotDescription
        The user's description (joint readings are in its reading order).
    desc : RobotDescription
        The description FK uses (``source.uncoupled()`` for the loop family and for
        robots without loops, i.e. ``source`` itself unless it has a joint coupling;
        the serial equivalent of eq. 6.3 for the serial family of a loop robot).
    reading_map : (n_desc, n_actuated) array
        Map from the source's kinematic joints θ_kin (= the readings without a
        coupling) to the joints of ``desc``: ``q_desc = reading_map · θ_kin``.
    base_name, probe_name : str
        Link names of the BASE ("0") and of the virtual PROBE frame ("7" after a
        flange "6").
    parallel : frozenset of str
        Chain links whose Hayati β is a candidate parameter.
    """

    family: str
    source: RobotDescription
    desc: RobotDescription
    reading_map: Array
    base_name: str
    probe_name: str
    parallel: frozenset[str]

    @property
    def n_readings(self) -> int:
        """Number of joint readings of the source description."""
        return self.source.n_readings

    @property
    def has_loops(self) -> bool:
        """Whether ``desc`` keeps closed loops (loop family of a loop robot)."""
        return bool(self.desc.loops)

    @property
    def reading_jacobian(self) -> Array:
        """``∂q_desc/∂q_reading = reading_map · M_coupling``, ``(n_desc, n_readings)``."""
        return self.reading_map @ self.source.reading_jacobian

    def joints(self, q_reading: ArrayLike, deflection: ArrayLike | None = None) -> Array:
        """``(..., n_desc)`` joint values of ``desc`` for readings ``(..., n_readings)``.

        ``q_desc = reading_map · (θ_kin(q) + Δθ)`` with θ_kin the source's kinematic
        joints (:meth:`RobotDescription.kinematic_joints`) and ``deflection`` Δθ
        ``(..., n_actuated)`` joint deflections (compliance), default none.

        Parameters
        ----------
        q_reading : (..., n_readings) array_like, rad
            Joint readings.
        deflection : (..., n_actuated) array_like, rad, optional
            Joint deflections Δθ.

        Returns
        -------
        (..., n_desc) array, rad
            Joint values of ``desc``.
        """
        k = self.source.kinematic_joints(np.asarray(q_reading, dtype=float))
        if deflection is not None:
            k = k + np.asarray(deflection, dtype=float)
        return k @ self.reading_map.T

    def nominal_parameters(self) -> GeometricParameters:
        """The nominal geometry of ``desc`` (m, rad)."""
        return self.desc.nominal_parameters()

    # ------------------------------------------------------------------ candidates
    def candidates(self) -> tuple[ErrorParameter, ...]:
        """Candidate geometric error parameters (BASE, links, PROBE frame), see module doc.

        BASE a0, b0, α0, β0 (first) and θ0, d0 (eq. 6.24); per chain link Δθ (not for
        passive links), Δd, Δa, Δα and, for parallel axes, Δβ (B.10); Δθ, Δa for an
        off-chain loop arm; PROBE Δθ7, Δd7, Δa7, Δα7 (6.2.2) — with their priorities.

        Returns
        -------
        tuple of ErrorParameter
            The candidates (m and rad).
        """
        desc = self.desc
        out: list[ErrorParameter] = []
        base_prio = -1
        for k, f in enumerate(("a", "b", "alpha", "beta")):
            out.append(geometric_parameter("base", self.base_name, f, (CLASS_BASE, base_prio, k)))
        loop_links = {n for lp in desc.loops for n in lp.links}
        chain = {desc.links[i].name for i in desc.chain}
        n_links = len(desc.links)
        for pos, lk in enumerate(desc.links):
            on_chain = lk.name in chain
            in_loop = lk.name in loop_links
            if not on_chain and not in_loop:
                continue
            fields: list[str]
            if on_chain:
                fields = ["d", "a", "alpha"]
                if not lk.is_passive:
                    fields.insert(0, "theta")
                if lk.name in self.parallel:
                    fields.append("beta")
            else:  # off-chain loop arm: only what the planar closure sees
                fields = ["theta", "a"]
            for f in fields:
                prio = (_class(lk, f, in_loop, self.parallel), pos, FIELDS.index(f))
                if lk.name == desc.flange and f in ("theta", "alpha"):
                    prio = (CLASS_OPEN, n_links + 1, FIELDS.index(f))  # tool rotations last
                out.append(geometric_parameter("link", lk.name, f, prio))
        for f in ("theta", "d", "a", "alpha"):
            pos = n_links + 1 if f in ("theta", "alpha") else n_links
            out.append(geometric_parameter("probe", self.probe_name, f,
                                           (CLASS_OPEN, pos, 5 + FIELDS.index(f))))
        for k, f in enumerate(("theta", "d")):
            out.append(
                geometric_parameter("base", self.base_name, f, (CLASS_BASE_Z, base_prio, k))
            )
        return tuple(out)


def _class(lk: Link, field: str, in_loop: bool, parallel: frozenset[str]) -> int:
    if field == "theta":
        return CLASS_FIXED if lk.is_fixed else CLASS_JOINT
    if field == "d" and (lk.name in parallel or in_loop):
        return CLASS_PARALLEL_D
    return CLASS_LOOP if in_loop else CLASS_OPEN


def _parallel_links(desc: RobotDescription) -> frozenset[str]:
    """Chain links (not the flange) whose next joint axis is parallel to their own."""
    out = set()
    for i in desc.chain:
        lk = desc.links[i]
        if lk.name == desc.flange:
            continue
        if lk.hayati or abs(math.sin(lk.alpha)) < PARALLEL_TOL:
            out.add(lk.name)
    return frozenset(out)


def _frame_names(desc: RobotDescription) -> tuple[str, str]:
    names = set(desc.link_names)
    base = "0" if "0" not in names else "base"
    try:
        probe = str(int(desc.flange) + 1)
    except ValueError:
        probe = "probe"
    if probe in names:
        probe = "probe"
    return base, probe


def _serial_equivalent(desc: RobotDescription) -> tuple[RobotDescription, Array]:
    """The serial robot of eq. (6.3): loops replaced by their arm + a coupled cut joint."""
    removed: set[str] = set()
    cut_of: dict[str, int] = {}
    for k, loop in enumerate(desc.loops):
        for name in (loop.arm, loop.coupler, loop.follower):
            lk = desc.link(name)
            if abs(lk.d) > 1e-12 or abs(lk.alpha) > 1e-12 or abs(lk.beta) > 1e-12:
                raise StructureError(
                    f"loop link {name!r} is not planar (d, α, β ≠ 0): the serial model of "
                    "eq. (6.3) needs a planar parallelogram"
                )
        removed |= {loop.crank, loop.coupler, loop.follower}
        children = [lk for lk in desc.links if lk.parent == loop.follower]
        if len(children) != 1:
            raise StructureError(
                f"loop follower {loop.follower!r} must carry exactly one link (the cut joint)"
            )
        cut_of[children[0].name] = k
    for lk in desc.links:
        if lk.name not in removed and lk.parent in removed and lk.name not in cut_of:
            raise StructureError(
                f"link {lk.name!r} hangs off loop link {lk.parent!r}: no serial equivalent"
            )
    links: list[Link] = []
    for lk in desc.links:
        if lk.name in removed:
            continue
        if lk.name in cut_of:
            loop = desc.loops[cut_of[lk.name]]
            arm, crank = desc.link(loop.arm), desc.link(loop.crank)
            lk = replace(
                lk,
                parent=loop.arm,
                joint="actuated",
                theta=lk.theta + math.pi + crank.theta - arm.theta,
            )
        links.append(lk)
    actuated = tuple(lk.name for lk in links if lk.is_actuated)
    src_index = {n: j for j, n in enumerate(desc.actuated)}
    M = np.zeros((len(actuated), desc.n_actuated))
    limits = np.zeros((len(actuated), 2))
    for r, name in enumerate(actuated):
        if name in cut_of:
            loop = desc.loops[cut_of[name]]
            M[r, src_index[loop.crank]] = 1.0
            M[r, src_index[loop.arm]] = -1.0
            limits[r] = (-2.0 * math.pi, 2.0 * math.pi)
        else:
            M[r, src_index[name]] = 1.0
            limits[r] = desc.joint_limits[src_index[name]]
    home = None if desc.home is None else M @ np.asarray(desc.home)
    kept = {lk.name for lk in links}
    serial = RobotDescription(
        name=f"{desc.name} (serial, eq. 6.3)",
        links=tuple(links),
        actuated=actuated,
        flange=desc.flange,
        loops=(),
        base=desc.base,
        tool=desc.tool,
        joint_limits=limits,
        notes="serial equivalent of a parallelogram robot (thesis eq. 6.3)",
        home=home,
        point_masses=tuple(pm for pm in desc.point_masses if pm.link in kept),
        working_volume=desc.working_volume,
    )
    return serial, M


def kinematic_structure(desc: RobotDescription, family: str) -> KinematicStructure:
    """Build the ``family`` structure (``"loop"`` or ``"serial"``) of ``desc``.

    A robot without loops has only the serial structure; asking for ``"loop"``
    returns it too (the loop family of a serial robot is the serial robot).  The
    serial family of a loop robot is its serial equivalent (eq. 6.3).

    Parameters
    ----------
    desc : RobotDescription
        The robot.
    family : {"loop", "serial"}
        The model family (thesis 8.2.3).

    Returns
    -------
    KinematicStructure
        The structure.

    Raises
    ------
    StructureError
        Unknown family (or a description the serial equivalent cannot be built of).
    """
    if family not in FAMILIES:
        raise StructureError(f"family must be one of {FAMILIES}, got {family!r}")
    kin = desc.uncoupled()
    if family == "serial" and desc.loops:
        fk_desc, M = _serial_equivalent(kin)
        fam = "serial"
    else:
        fk_desc, M = kin, np.eye(desc.n_actuated)
        fam = "loop" if desc.loops else "serial"
    M.setflags(write=False)
    base, probe = _frame_names(fk_desc)
    return KinematicStructure(
        family=fam,
        source=desc,
        desc=fk_desc,
        reading_map=M,
        base_name=base,
        probe_name=probe,
        parallel=_parallel_links(fk_desc),
    )
