"""The calibrated robot out: URDF, Universal Robots' kinematics file, plugcell TOML.

A calibration (:class:`~plugcell.calibration.CalibrationResult`) predicts the
measured target as ``BASE · F_n'(q + Δq) · PROBE`` (docs/calibration.md): the
calibrated DH/Hayati chain ``F_n'`` (the *geometric* model), BASE and PROBE, and
joint deflections Δq from compliance/payload terms.  The exports carry:

* ``toml`` — plugcell's description with the calibrated rows, ``base`` = BASE and
  ``tool`` = PROBE (``forward(...).world_tcp`` is the calibrated geometric model); a
  calibrated loop is a ``type = "fourbar"`` loop (its sides, twists and offsets kept,
  the exact four-bar closure), so it is exact for loop robots too;
* ``urdf`` — the source URDF (when the robot came from one; links, limits, inertias,
  meshes kept) with calibrated joint origins
  (:func:`~plugcell.kinematics.joint_chain.calibrated_origins`), else a URDF built
  from the calibrated rows; optionally BASE (a new root link ``measurement``) and
  PROBE (a link ``probe`` on the tip) as fixed joints;
* ``ur-kinematics`` — ``default_kinematics.yaml`` of Universal Robots' ROS
  description (x, y, z, roll, pitch, yaw of each joint origin) for a robot imported
  from ``ur_description``.

A URDF is a tree: for a calibration of a loop robot's loop family it is the
*closest tree* — the serial equivalent of eq. 6.3 fitted to the calibrated loop
(:func:`~plugcell.calibration.tree.closest_serial_tree`), its independent joints the
robot's readings (the cut joint as a ``mimic`` of the arm's reading plus the crank's
reading; crank, coupler and follower as mimic joints, exact for the nominal
parallelogram) — and its worst error against the loop is written into the file and
returned in ``notes``.  A ``--model serial`` calibration of a loop robot gives that
tree exactly (``serial_equivalent``).  ``ur-kinematics`` is for Universal Robots'
arms only.

What a format cannot carry (compliance and payload terms, the thermal term, a learned
residual layer, BASE/PROBE when not included, the flange offset a UR kinematics file
has no place for, the loop of a URDF) is returned as the *side* dictionary, written
next to the file.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from plugcell.calibration.determinacy import with_probe
from plugcell.calibration.model import THERMAL_KEY
from plugcell.io.robots import RobotSource, description_to_toml
from plugcell.kinematics.description import Link, RobotDescription
from plugcell.kinematics.parameters import GeometricParameters
from plugcell.kinematics.rotations import matrix_to_rpy
from plugcell.kinematics.transforms import dh_hayati, rot_z

__all__ = ["FORMATS", "UR_KINEMATICS_KEYS", "ExportError", "Exported", "export_calibration"]

FORMATS: tuple[str, ...] = ("urdf", "ur-kinematics", "toml")
#: Joint name (without tf_prefix) → section of ur_description's default_kinematics.yaml.
UR_KINEMATICS_KEYS: dict[str, str] = {
    "shoulder_pan_joint": "shoulder",
    "shoulder_lift_joint": "upper_arm",
    "elbow_joint": "forearm",
    "wrist_1_joint": "wrist_1",
    "wrist_2_joint": "wrist_2",
    "wrist_3_joint": "wrist_3",
}


class ExportError(ValueError):
    """The calibration cannot be exported in the asked form (the message says why)."""


@dataclass(frozen=True)
class Exported:
    """An exported calibration: the main file's text and what it cannot carry.

    Attributes
    ----------
    text : str
        The main file: URDF XML (m, rad), UR ``default_kinematics.yaml`` (m, rad) or
        plugcell TOML (m, degrees).
    side : dict or None
        The side dictionary (``format: plugcell-export-extra``), written next to the
        file: ``not_in_main_file`` (the reasons) and, as the case may be, ``base``,
        ``probe_in_tip``, ``tcp_in_tip``, ``flange_correction`` (each a frame
        ``{"matrix": 4×4 m, "xyz_mm": mm, "rpy_deg": degrees}``), ``compliance``
        (parameters with their units), ``payload_ref_kg``, ``reading_map``,
        ``coupling``, ``tip_link``; ``None`` when the file carries everything.
    notes : tuple of str
        Remarks for the user (e.g. a tip link added to take up the flange offset).
    """

    text: str
    side: dict[str, Any] | None
    notes: tuple[str, ...] = field(default_factory=tuple)


def _frame(T: np.ndarray) -> dict[str, Any]:
    return {"matrix": [[float(v) for v in row] for row in T],
            "xyz_mm": [float(v) * 1e3 for v in T[:3, 3]],
            "rpy_deg": [math.degrees(v) for v in matrix_to_rpy(T[:3, :3])]}


def _fmt(v: float) -> str:
    v = float(v)
    return "0" if v == 0 else repr(v)


def _origin_attrs(T: np.ndarray) -> dict[str, str]:
    rpy = matrix_to_rpy(T[:3, :3])
    return {"xyz": " ".join(_fmt(x) for x in T[:3, 3]), "rpy": " ".join(_fmt(x) for x in rpy)}


# =============================================================================== checks
def _geometry(result: Any, desc: RobotDescription, serial_equivalent: bool,
              fmt: str) -> tuple[RobotDescription, GeometricParameters, np.ndarray | None]:
    """The chain description, its calibrated parameters and the reading map (or None)."""
    structure = result.model.structure
    chain_desc = structure.desc
    gp = result.model.geometric_parameters()
    same = (chain_desc.link_names == desc.link_names
            and structure.reading_map.shape == (desc.n_actuated, desc.n_actuated)
            and np.allclose(structure.reading_map, np.eye(desc.n_actuated)))
    if desc.loops and fmt != "toml" and serial_equivalent and same:
        raise ExportError(
            f"--serial-equivalent: this calibration (model {result.config.name}) identified "
            "the loop itself; export it without --serial-equivalent (--format urdf: the "
            "closest tree, with its error; --format toml: exact), or calibrate with --model "
            "serial (or serial+gravity) to export the serial-equivalent chain")
    if not same and not serial_equivalent:
        raise ExportError("the calibrated chain is the serial equivalent of the robot "
                          "(its joints are not the readings); add --serial-equivalent")
    return chain_desc, gp, (None if same else np.asarray(structure.reading_map))


def _side(result: Any, params_path: str, fmt: str, reasons: list[str],
          extra: Mapping[str, Any], residual: Mapping[str, Any] | None = None
          ) -> dict[str, Any] | None:
    comp = []
    for key in result.model.compliance_keys:
        p = result.model.space[key]
        comp.append({"key": key, "name": p.name, "unit": p.unit, "kind": p.kind,
                     "value": result.model.value(key)})
    if comp:
        reasons.append("compliance/payload terms (joint deflections, docs/calibration.md) are "
                       "not geometry")
    thermal = None
    if THERMAL_KEY in result.model.space:
        thermal = {"kT_per_K": result.model.value(THERMAL_KEY),
                   "temperature_ref_c": result.model.temperature_ref_c}
        reasons.append("the thermal expansion κT (every length scales by 1 + κT·(T − T_ref)): "
                       "the file holds the geometry at T_ref")
    if residual is not None:
        reasons.append("the learned residual layer (PARAMS.json's residual_model"
                       + (f", {residual['file']}" if residual.get("file") else "")
                       + "): keep PARAMS.json with it for plugcell compensate")
    if not reasons:
        return None
    out: dict[str, Any] = {
        "format": "plugcell-export-extra", "format_version": 1, "params": params_path,
        "robot": result.robot, "model": result.config.name, "exported_format": fmt,
        "not_in_main_file": reasons, **extra,
    }
    if comp:
        out["compliance"] = comp
        out["payload_ref_kg"] = result.model.payload_ref_kg
    if thermal is not None:
        out["thermal"] = thermal
    if residual is not None:
        out["residual_model"] = dict(residual)
    return out


# =============================================================================== toml
def calibrated_description(desc: RobotDescription, gp: GeometricParameters, base: np.ndarray,
                           tool: np.ndarray, note: str) -> RobotDescription:
    """``desc`` with the calibrated rows of ``gp``, ``base`` = BASE and ``tool`` = PROBE.

    A link gets ``hayati = true`` when its calibrated β is non-zero; every loop becomes
    ``kind = "fourbar"`` (its calibrated sides, twists and offsets are kept, the passive
    angles are the exact four-bar closure's — what the calibration's model computes).

    Parameters
    ----------
    desc : RobotDescription
        The robot (SI, radians); masses, limits, loops and coupling are kept.
    gp : GeometricParameters
        Calibrated θ, d, a, α, β of every link (m, rad), looked up by link name.
    base : (4, 4) ndarray, m
        The calibrated BASE (robot base in the measurement frame).
    tool : (4, 4) ndarray, m
        The calibrated PROBE (measured target in the flange frame).
    note : str
        A line appended to the description's notes.

    Returns
    -------
    RobotDescription
        The calibrated description.

    Raises
    ------
    DescriptionError
        The calibrated geometry is no valid description (e.g. a parallelogram that is
        no longer one).
    """
    links = []
    for lk in desc.links:
        i = gp.index(lk.name)
        beta = float(gp.beta[i])
        links.append(Link(lk.name, lk.parent, lk.joint, float(gp.theta[i]), float(gp.d[i]),
                          float(gp.a[i]), float(gp.alpha[i]), beta, lk.hayati or beta != 0.0,
                          lk.mass, lk.com))
    notes = (desc.notes + "\n" if desc.notes else "") + note
    return RobotDescription(
        name=desc.name, links=tuple(links), actuated=desc.actuated, flange=desc.flange,
        loops=tuple(replace(lp, kind="fourbar") for lp in desc.loops), base=base, tool=tool,
        joint_limits=desc.joint_limits,
        stiffness=desc.stiffness, notes=notes, coupled_limits=desc.coupled_limits,
        home=desc.home, point_masses=desc.point_masses, working_volume=desc.working_volume,
        coupling=desc.coupling)


def _export_toml(result: Any, desc: RobotDescription, params_path: str,
                 serial_equivalent: bool, residual: Mapping[str, Any] | None) -> Exported:
    from plugcell.kinematics.errors import DescriptionError

    chain_desc, gp, rmap = _geometry(result, desc, serial_equivalent, "toml")
    note = (f"calibrated: {params_path} (model {result.config.name}); base = BASE, "
            "tool = PROBE of the calibration")
    try:  # the robot itself (its coupling and reading limits) unless the chain differs
        cal = calibrated_description(desc if rmap is None else chain_desc, gp,
                                     result.model.base(), result.model.probe(), note)
    except DescriptionError as exc:
        raise ExportError(
            f"the calibrated geometry is not a valid description ({exc}); a description "
            "file requires the nominal parallelogram — export the nominal description and "
            "keep PARAMS.json for the calibrated loop") from None
    reasons: list[str] = []
    extra: dict[str, Any] = {}
    if rmap is not None:
        reasons.append("the serial-equivalent chain's joints are reading_map @ readings")
        extra["reading_map"] = rmap.tolist()
    header = f"{cal.name}, calibrated by plugcell ({params_path}, model {result.config.name})"
    return Exported(description_to_toml(cal, header=header),
                    _side(result, params_path, "toml", reasons, extra, residual))


# =============================================================================== urdf
def _source_urdf(source: RobotSource | None, desc: RobotDescription) -> Any | None:
    """The re-imported source URDF of a URDF robot (None for other robots)."""
    if source is None or not source.is_urdf:
        return None
    imp = source.import_urdf()
    a, b = imp.description, desc
    same = (a.link_names == b.link_names and a.actuated == b.actuated
            and np.allclose(a.nominal_parameters().table(), b.nominal_parameters().table(),
                            atol=1e-12) and np.allclose(a.tool, b.tool, atol=1e-12))
    if not same:
        raise ExportError(f"{source.ref}: the robot it describes now differs from the one "
                          "that was calibrated (was the URDF or a xacro argument changed?)")
    return imp


def _set_origin(joint_el: Any, T: np.ndarray) -> None:
    from lxml import etree

    o = joint_el.find("origin")
    if o is None:
        o = etree.SubElement(joint_el, "origin")
    for k, v in _origin_attrs(T).items():
        o.set(k, v)


def _add_fixed(root: Any, name: str, parent: str, child: str, T: np.ndarray,
               new_link: str | None = None) -> None:
    from lxml import etree

    if new_link is not None:
        root.append(etree.Element("link", name=new_link))
    j = etree.SubElement(root, "joint", name=name, type="fixed")
    etree.SubElement(j, "origin", **_origin_attrs(T))
    etree.SubElement(j, "parent", link=parent)
    etree.SubElement(j, "child", link=child)


def _unique(root: Any, name: str) -> str:
    names = {el.get("name") for el in root.iter("link", "joint")}
    out, k = name, 1
    while out in names:
        k += 1
        out = f"{name}_{k}"
    return out


def _export_urdf(result: Any, desc: RobotDescription, source: RobotSource | None,
                 params_path: str, include_base: bool, include_probe: bool,
                 serial_equivalent: bool, seed: int,
                 residual: Mapping[str, Any] | None) -> Exported:
    from lxml import etree

    chain_desc, gp, rmap = _geometry(result, desc, serial_equivalent, "urdf")
    base_T, probe_T = result.model.base(), result.model.probe()
    tree = None
    if desc.loops and rmap is None:  # the calibrated loop: its closest tree, fitted
        from plugcell.calibration.tree import closest_serial_tree

        tree = closest_serial_tree(result.model, seed=seed)
        fitted = tree.result.model
        chain_desc, gp = fitted.structure.desc, fitted.geometric_parameters()
        rmap = np.asarray(fitted.structure.reading_map)
        base_T, probe_T = fitted.base(), fitted.probe()
    imp = _source_urdf(source, desc) if rmap is None else None
    notes: list[str] = []
    if imp is not None:
        root, base_link, tip_link = _calibrated_source(imp, desc, gp, notes)
        tip_from_flange = desc.tool
    else:
        root, base_link, tip_link = _generic_urdf(
            chain_desc, gp, result.robot, source=desc if desc.loops else None,
            reading_map=rmap)
        tip_from_flange = chain_desc.tool
    reasons: list[str] = []
    extra: dict[str, Any] = {}
    if imp is None and desc.coupling is not None:
        reasons.append("the joint coupling: the URDF's joints are the kinematic joints "
                       "θ = matrix · readings + offset")
        extra["coupling"] = {"readings": list(desc.coupling.readings),
                             "matrix": desc.coupling.matrix.tolist(),
                             "offset": desc.coupling.offset.tolist()}
    _add_base_and_probe(root, base_link, tip_link, base_T,
                        np.linalg.inv(tip_from_flange) @ probe_T, include_base, include_probe,
                        reasons, extra)
    if rmap is not None and not desc.loops:
        reasons.append("the serial-equivalent chain's joints are reading_map @ readings")
        extra["reading_map"] = rmap.tolist()
    extra["tip_link"] = tip_link
    if tree is not None:
        reasons.append(_TREE_REASON)
        extra["tree_error"] = [e.as_dict() for e in tree.errors]
        extra["tree_fit"] = {"poses": tree.fit_poses, "seed": tree.seed,
                             "model": "serial (eq. 6.3)"}
        for e in reversed(tree.errors):
            root.insert(0, etree.Comment(f" error of this tree vs the calibrated loop: "
                                         f"{e.line()} "))
        root.insert(0, etree.Comment(f" {_TREE_REASON} "))
        notes.extend(f"the tree's error vs the calibrated loop: {e.line()}"
                     for e in tree.errors)
    root.insert(0, etree.Comment(
        f" calibrated by plugcell: {params_path} (model {result.config.name}) "))
    text = etree.tostring(root, pretty_print=True, xml_declaration=True,
                          encoding="utf-8").decode("utf-8")
    return Exported(text, _side(result, params_path, "urdf", reasons, extra, residual),
                    tuple(notes))


def _calibrated_source(imp: Any, desc: RobotDescription, gp: GeometricParameters,
                       notes: list[str]) -> tuple[Any, str, str]:
    """The robot's own URDF with each joint origin the calibration changed rewritten
    (:func:`~plugcell.kinematics.joint_chain.calibrated_origins`); a flange offset no
    fixed joint can take up goes to a new tip link (noted).  Returns the XML root and the
    chain's base and tip links."""
    from lxml import etree

    from plugcell.kinematics.joint_chain import calibrated_origins

    root = etree.fromstring(imp.urdf.encode("utf-8"))
    co = calibrated_origins(imp.chain, desc, gp)
    joints = {el.get("name"): el for el in root.findall("joint")}
    for k, jt in enumerate(imp.chain.joints):
        if not np.allclose(co.origins[k], jt.origin, atol=0, rtol=0):
            _set_origin(joints[jt.name], co.origins[k])
    base_link, tip_link = imp.base_link, imp.tip_link
    if co.tip_joint is None and not np.allclose(co.residual, np.eye(4), atol=1e-15):
        new = _unique(root, f"{tip_link}_calibrated")
        _add_fixed(root, _unique(root, f"{tip_link}-{new}"), tip_link, new, co.residual,
                   new_link=new)
        notes.append(f"the calibrated tip is the new link {new!r} ({tip_link!r} has no "
                     "fixed joint to take up the flange's calibrated offset)")
        tip_link = new
    return root, base_link, tip_link


def _add_base_and_probe(root: Any, base_link: str, tip_link: str, base_T: np.ndarray,
                        probe_in_tip: np.ndarray, include_base: bool, include_probe: bool,
                        reasons: list[str], extra: dict[str, Any]) -> None:
    """BASE as a fixed joint from a new root ``measurement`` link (``include_base``) and
    PROBE as one to a new ``probe`` link below the tip (``include_probe``); a frame left
    out goes to the side file (``extra``) with the reason."""
    from lxml import etree

    if include_base:
        if any(el.find("child") is not None and el.find("child").get("link") == base_link
               for el in root.findall("joint")):
            raise ExportError(f"--include-base: the chain starts at {base_link!r}, which is not "
                              "the URDF's root link (it would get two parents)")
        new = _unique(root, "measurement")
        _add_fixed(root, _unique(root, f"{new}-{base_link}"), new, base_link, base_T)
        root.insert(0, etree.Element("link", name=new))
    else:
        reasons.append("BASE (the robot base in the measurement frame): add --include-base")
        extra["base"] = _frame(base_T)
    if include_probe:
        new = _unique(root, "probe")
        _add_fixed(root, _unique(root, f"{tip_link}-{new}"), tip_link, new, probe_in_tip,
                   new_link=new)
    else:
        reasons.append(f"PROBE (the measured target in {tip_link!r}): add --include-probe")
        extra["probe_in_tip"] = _frame(probe_in_tip)


_TREE_REASON = (
    "the closed loop: a URDF is a tree, so this is the closest tree — the serial equivalent "
    "of eq. 6.3 fitted to the calibrated loop (the cut joint as a mimic of the arm's "
    "reading with multiplier -1 plus the crank's reading; the crank, coupler and follower "
    "as mimic joints, exact for the nominal parallelogram); the exact calibrated loop is "
    "the toml export")


def _dh(gp: GeometricParameters, name: str) -> np.ndarray:
    """``M = Tz(d) Tx(a) Rx(α) Ry(β)`` of link ``name`` (identity for ``"base"``)."""
    if name == "base":
        return np.eye(4)
    i = gp.index(name)
    return np.asarray(dh_hayati(np.array(0.0), np.array(gp.d[i]), np.array(gp.a[i]),
                                np.array(gp.alpha[i]), np.array(gp.beta[i])))


def _urdf_link(root: Any, name: str, lk: Link, M: np.ndarray) -> None:
    """A ``<link>`` with the lumped mass of ``lk`` (its com is in F_i: at ``M · com``)."""
    from lxml import etree

    link = etree.SubElement(root, "link", name=name)
    if lk.mass > 0:
        inert = etree.SubElement(link, "inertial")
        com = M @ np.array([*lk.com, 1.0])
        etree.SubElement(inert, "origin", xyz=" ".join(_fmt(x) for x in com[:3]), rpy="0 0 0")
        etree.SubElement(inert, "mass", value=_fmt(lk.mass))
        etree.SubElement(inert, "inertia", ixx="0", ixy="0", ixz="0", iyy="0", iyz="0",
                         izz="0")


def _urdf_joint(root: Any, name: str, kind: str, T: np.ndarray, parent: str, child: str,
                limits: tuple[float, float] | None = None,
                mimic: tuple[str, float, float] | None = None) -> None:
    """A ``<joint>`` about its z axis; ``mimic = (joint, multiplier, offset)``."""
    from lxml import etree

    j = etree.SubElement(root, "joint", name=name, type=kind)
    etree.SubElement(j, "origin", **_origin_attrs(T))
    etree.SubElement(j, "parent", link=parent)
    etree.SubElement(j, "child", link=child)
    if kind != "fixed":
        etree.SubElement(j, "axis", xyz="0 0 1")
        lo, hi = limits if limits is not None else (-2.0 * math.pi, 2.0 * math.pi)
        etree.SubElement(j, "limit", lower=_fmt(lo), upper=_fmt(hi), effort="0", velocity="0")
    if mimic is not None:
        etree.SubElement(j, "mimic", joint=mimic[0], multiplier=_fmt(mimic[1]),
                         offset=_fmt(mimic[2]))


def _generic_urdf(desc: RobotDescription, gp: GeometricParameters, name: str, *,
                  source: RobotDescription | None = None,
                  reading_map: np.ndarray | None = None) -> tuple[Any, str, str]:
    """A URDF of DH/Hayati rows: link *i*'s frame is ``F_{i−1} Rz(q_i + θ_i)``.

    Joint *i*'s origin is ``M_parent · Rz(θ_i)`` with ``M = Tz(d) Tx(a) Rx(α) Ry(β)``
    of the parent row; the ``flange`` link is F_n and ``tool0`` the description's tool.

    With ``source`` (a loop robot) and ``desc`` its serial equivalent (eq. 6.3, joints
    ``q_desc = reading_map · θ_kin``), the URDF's independent joints are the kinematic
    joints of ``source`` (its readings, unless it has a coupling): a cut joint (row
    ``e_crank − e_arm``) becomes two coaxial joints — the link's own, a ``mimic`` of
    the arm's reading with multiplier −1, then one named
    after the crank's reading — so ``Rz(−q_arm) Rz(q_crank) = Rz(q_cut)`` exactly; and
    each loop's crank, coupler and follower hang off the arm's parent as mimic joints
    (the crank: ``q_crank``; the coupler ``θ_arm − θ_crank`` and the follower
    ``π − θ_arm + θ_crank``, each as a mimic of the arm's reading then one of the
    crank's), exact for the nominal parallelogram (eq. 6.10, ``source``'s nominal
    rows).  They carry the loop links' masses; they do not move the TCP.
    """
    from lxml import etree

    root = etree.Element("robot", name=name)
    base = "base_link"
    root.append(etree.Element("link", name=base))
    chain = set(desc.chain)
    # the URDF's joints are the source's kinematic joints (its readings unless it has
    # a coupling, which then goes to the side file)
    readings = None if source is None else source.actuated
    klim = None if source is None else source.kinematic_limits()

    def M(name: str) -> np.ndarray:
        return _dh(gp, name)

    names = {lk.name: f"link_{lk.name}" for lk in desc.links}
    for i, lk in enumerate(desc.links):
        if i not in chain:
            continue
        _urdf_link(root, names[lk.name], lk, M(lk.name))
        T = M(lk.parent) @ np.asarray(rot_z(gp.theta[gp.index(lk.name)]))
        kind = "prismatic" if lk.is_prismatic else ("revolute" if lk.is_actuated else "fixed")
        parent = base if lk.parent == "base" else names[lk.parent]
        if not lk.is_actuated:
            _urdf_joint(root, lk.name, kind, T, parent, names[lk.name])
            continue
        r = desc.actuated_index(lk.name)
        lim = tuple(desc.joint_limits[desc.joint_index(lk.name)])
        row = None if reading_map is None or readings is None else reading_map[r]
        if row is None or np.count_nonzero(row) == 1:
            jname = lk.name if row is None else readings[int(np.flatnonzero(row)[0])]  # type: ignore[index]
            _urdf_joint(root, jname, kind, T, parent, names[lk.name], lim)  # type: ignore[arg-type]
            continue
        assert source is not None and readings is not None and klim is not None
        arm, crank = int(np.argmin(row)), int(np.argmax(row))  # row = e_crank − e_arm
        mid = f"{names[lk.name]}_cut"
        root.append(etree.Element("link", name=mid))
        a_lo, a_hi = klim[arm]
        _urdf_joint(root, lk.name, kind, T, parent, mid, (-a_hi, -a_lo),
                    mimic=(readings[arm], -1.0, 0.0))
        _urdf_joint(root, readings[crank], kind, np.eye(4), mid, names[lk.name],
                    tuple(klim[crank]))  # type: ignore[arg-type]
    if source is not None:
        _loop_branches(root, source, gp, names)
    root.append(etree.Element("link", name="flange"))
    _add_fixed(root, "flange_joint", names[desc.flange], "flange", M(desc.flange))
    root.append(etree.Element("link", name="tool0"))
    _add_fixed(root, "tool0_joint", "flange", "tool0", desc.tool)
    return root, base, "tool0"


def _loop_branches(root: Any, source: RobotDescription, gp: GeometricParameters,
                   names: dict[str, str]) -> None:
    """Each loop's crank, coupler and follower as mimic joints off the arm's parent
    (:func:`_generic_urdf`): nominal rows of ``source``, the arm's parent at its place in
    the tree (``gp``)."""
    from lxml import etree

    nom = source.nominal_parameters()
    ra_lim = source.kinematic_limits()
    for loop in source.loops:
        arm, crank = source.link(loop.arm), source.link(loop.crank)
        ra, rc = arm.name, crank.name  # the kinematic joints (= readings without a coupling)
        c = arm.theta - crank.theta  # θ_arm − θ_crank = q_arm − q_crank + c
        parent = "base_link" if crank.parent == "base" else names[crank.parent]
        at = gp if crank.parent == "base" or crank.parent in gp.link_names else nom
        steps = [  # (link, parent's M; the angle = ma·q_arm + mc·q_crank + off)
            (crank, _dh(at, crank.parent), 0.0, 1.0, 0.0),
            (source.link(loop.coupler), _dh(nom, crank.name), 1.0, -1.0, c),
            (source.link(loop.follower), _dh(nom, loop.coupler), -1.0, 1.0, math.pi - c),
        ]
        par = parent
        for lk, Mp, ma, mc, off in steps:
            T = Mp @ np.asarray(rot_z(lk.theta))
            child = f"link_{lk.name}"
            if ma == 0.0:
                _urdf_joint(root, f"{lk.name}_loop", "revolute", T, par, child,
                            tuple(ra_lim[source.actuated.index(lk.name)]),
                            mimic=(rc, mc, off))
            else:
                mid = f"{child}_{ra}"
                root.append(etree.Element("link", name=mid))
                _urdf_joint(root, lk.name, "revolute", T, par, mid, mimic=(ra, ma, off))
                _urdf_joint(root, f"{lk.name}_{rc}", "revolute", np.eye(4), mid, child,
                            mimic=(rc, mc, 0.0))
            _urdf_link(root, child, lk, _dh(nom, lk.name))
            par = child


# =============================================================================== UR yaml
_OTHER_FORMATS = ("export --format urdf (its URDF with the calibrated joint origins) or "
                  "--format toml (plugcell's description)")


def _export_ur(result: Any, desc: RobotDescription, source: RobotSource | None,
               params_path: str, residual: Mapping[str, Any] | None) -> Exported:
    import yaml

    from plugcell.kinematics.joint_chain import calibrated_origins

    imp = _source_urdf(source, desc)
    if imp is None or desc.loops:
        what = (f"{desc.name} has a closed loop" if desc.loops
                else f"{desc.name} was not imported from a URDF")
        raise ExportError(
            "ur-kinematics is the default_kinematics.yaml of Universal Robots' ur_description "
            f"(the six joint origins of a UR arm), and {what}; export --format urdf (a URDF "
            "with the calibrated joints"
            + (", the closest tree of the loop with its error" if desc.loops else "")
            + ") or --format toml (plugcell's description, exact)")
    _geometry(result, desc, False, "ur-kinematics")
    co = calibrated_origins(imp.chain, desc, result.model.geometric_parameters(),
                            fixed_tip=False)
    sections: dict[str, dict[str, float]] = {}
    for k, jt in enumerate(imp.chain.joints):
        if jt.kind == "fixed":
            continue
        key = next((v for j, v in UR_KINEMATICS_KEYS.items() if jt.name.endswith(j)), None)
        if key is None:
            raise ExportError(f"joint {jt.name!r} is not a joint of ur_description "
                              f"(expected {', '.join(UR_KINEMATICS_KEYS)}): not a UR arm; "
                              f"{_OTHER_FORMATS}")
        T = co.origins[k]
        r, p, y = matrix_to_rpy(T[:3, :3])
        sections[key] = {"x": float(T[0, 3]), "y": float(T[1, 3]), "z": float(T[2, 3]),
                         "roll": float(r), "pitch": float(p), "yaw": float(y)}
    missing = set(UR_KINEMATICS_KEYS.values()) - set(sections)
    if missing:
        raise ExportError(f"the chain lacks ur_description joints for {sorted(missing)}: "
                          f"not a UR arm; {_OTHER_FORMATS}")
    digest = hashlib.sha256(json.dumps(sections, sort_keys=True).encode()).hexdigest()[:16]
    doc = {"kinematics": {**{k: sections[k] for k in UR_KINEMATICS_KEYS.values()},
                          "hash": f"plugcell_{digest}"}}
    text = (f"# calibrated by plugcell: {params_path} (model {result.config.name})\n"
            + yaml.safe_dump(doc, sort_keys=False))
    tip = imp.tip_link
    reasons = ["BASE (the robot base in the measurement frame)",
               f"the TCP: the measured target in {tip!r}, with the flange's calibrated offset "
               "across the last axis (which the kinematics file has no place for) folded in"]
    extra = {"base": _frame(result.model.base()),
             "tcp_in_tip": _frame(co.residual @ np.linalg.inv(desc.tool) @ result.model.probe()),
             "flange_correction": _frame(co.residual), "tip_link": tip}
    return Exported(text, _side(result, params_path, "ur-kinematics", reasons, extra, residual))


# =============================================================================== entry
def export_calibration(result: Any, desc: RobotDescription, fmt: str, *,
                       source: RobotSource | None = None, params_path: str = "PARAMS.json",
                       include_base: bool = False, include_probe: bool = False,
                       serial_equivalent: bool = False, seed: int = 0,
                       residual_model: Mapping[str, Any] | None = None,
                       probe: np.ndarray | None = None) -> Exported:
    """Export a calibration of robot ``desc`` as ``fmt`` (one of :data:`FORMATS`).

    Parameters
    ----------
    result : CalibrationResult
        The calibration (e.g. ``result_from_params(PARAMS, desc)``, :mod:`plugcell.io.params`).
    desc : RobotDescription
        The robot it was made for.
    fmt : str
        ``"urdf"``, ``"ur-kinematics"`` or ``"toml"``.
    source : RobotSource, optional
        Where the robot came from (a URDF source keeps its links, meshes, limits).
    params_path : str
        The calibration file's name, written in the file's header comment and the side
        dictionary.
    include_base, include_probe : bool
        URDF: add BASE (root link ``measurement``) and PROBE (link ``probe``).
    serial_equivalent : bool
        Allow exporting the serial-equivalent chain of a loop robot.
    seed : int
        URDF of a calibrated loop: seed of the configurations its closest tree is fitted
        and checked on (:func:`~plugcell.calibration.tree.closest_serial_tree`).
    residual_model : mapping, optional
        PARAMS.json's ``residual_model`` entry (a learned residual layer): no format
        carries it; the side dictionary names it.
    probe : (4, 4) ndarray, m, optional
        The target (tool point) in the flange frame, replacing the calibration's PROBE
        (:func:`~plugcell.calibration.determinacy.with_probe`: BASE re-expressed when the
        calibration did not determine the PROBE position).

    Returns
    -------
    Exported
        The file text (units of the format: URDF and UR yaml in m and rad, TOML in m
        and degrees) and the side dictionary of what it cannot carry.

    Raises
    ------
    ExportError
        The format cannot represent this calibration (the message says why): an
        unknown ``fmt``, a loop robot for URDF/UR without ``serial_equivalent``, a
        serial-equivalent chain not asked for, ``ur-kinematics`` for a robot not from
        ``ur_description``, a URDF source that changed since the calibration, BASE on
        a chain that does not start at the URDF's root, a PROBE position the calibration
        poses did not determine and no ``probe`` given (the exported tool would be a
        value nobody measured).
    DescriptionError
        A URDF ``source`` that can no longer be imported.
    """
    und = getattr(result, "undetermined", None)
    if probe is not None:
        result = replace(result, model=with_probe(result.model, probe, und))
    elif und is not None and und.unknown("probe_position"):
        raise ExportError(
            "the calibration poses did not determine the PROBE position (the tool "
            f"orientation varied by {math.degrees(und.orientation_spread_rad):.2g}° over the "
            f"campaign; {math.degrees(und.required_spread_rad):.1f}° would have): the "
            "exported tool and BASE would be values nobody measured; give the target in the "
            "flange frame (--probe X,Y,Z,R,P,Y in mm and degrees, or a JSON file), or "
            "calibrate with --probe")
    if fmt == "toml":
        return _export_toml(result, desc, params_path, serial_equivalent, residual_model)
    if fmt == "urdf":
        return _export_urdf(result, desc, source, params_path, include_base, include_probe,
                            serial_equivalent, seed, residual_model)
    if fmt == "ur-kinematics":
        return _export_ur(result, desc, source, params_path, residual_model)
    raise ExportError(f"unknown format {fmt!r}; expected one of {', '.join(FORMATS)}")
