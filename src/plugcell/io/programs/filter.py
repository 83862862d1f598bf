"""Compensate a program's targets: frames composed, the model inverted, numbers rewritten.

For a Cartesian target written ``P`` in its program's frame ``BASE`` with tool
``TOOL`` (flange → TCP) the robot-base-frame target is ``T = BASE · P``; it is
compensated as ``plugcell compensate --user-frame BASE --tool TOOL`` does
(:func:`plugcell.compensation.program.commanded_poses`), and written back in the
program's own frame, ``P' = BASE⁻¹ · T_nominal(q) · TOOL``, in the program's own
notation, nearest its old numbers (:func:`plugcell.io.units.notation_from_pose`).
Joint targets are kept, or — ``joints="compensate"`` — replaced by the compensated
joints of the pose the controller's nominal model puts them at, ``T = T_nominal(q) ·
TOOL``, solved from their own joints.

The arm configuration compensated is the program's: the nominal inverse kinematics
starts from home (as ``plugcell compensate``); a target whose configuration numbers
(KRL status/turn, RAPID confdata, Fanuc CONFIG turns: the dialect's ``config.agrees``)
describe another solution is solved again from that solution's other turns (joints 1,
4, 6 ± 2π, exact) and from the flipped wrist (one batched inverse kinematics), and
compensated from the first that fits (``TargetReport.seed``); none fitting, it keeps
home's and the report says so.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numpy as np

from plugcell.compensation.model_based import CompensationResult, nominal_joints
from plugcell.compensation.pose_model import NominalModel, PoseModel
from plugcell.compensation.program import CommandedPoses, commanded_poses
from plugcell.io.programs.core import Program, ProgramError, Target, new_text
from plugcell.io.units import NOTATIONS, notation_from_pose, pose_from_notation
from plugcell.kinematics.transforms import invert, so3_log

__all__ = ["FilterResult", "MissingFramesError", "TargetReport", "filter_targets",
           "missing_frames"]


class MissingFramesError(ProgramError):
    """Frames or tools the targets use that neither the program nor the caller define.

    Attributes
    ----------
    bases, tools : list of str
        The missing names, in the order first used.
    """

    def __init__(self, path: str, bases: list[str], tools: list[str]) -> None:
        self.bases, self.tools = bases, tools
        parts = [f"base {b!r} (--base '{b}=…')" for b in bases]
        parts += [f"tool {t!r} (--tool '{t}=…')" for t in tools]
        super().__init__(path, 0, 0, "frames used by its targets are neither in the program "
                         "nor on the command line: " + ", ".join(parts))


@dataclass
class TargetReport:
    """What happened to one target.

    Attributes
    ----------
    target : Target
        The target.
    where : str
        ``path:line:column``.
    ok : bool
        Compensated (or, joints kept, nothing to do).
    reason : str
        Why not, or a note (``not used by a motion``; ``configuration: …`` when the
        program's status/turn, confdata or CONFIG name another arm configuration than the
        joints the compensation solved for).
    before, after : (k,) ndarray
        The numbers as written and as written now (notation units; joints in degrees).
    dp_mm : float
        How far the commanded TCP moved, mm (0 for joints kept).
    dr_deg : float
        How far it turned, degrees.
    q : (n,) ndarray or None
        Joints the robot reaches the target with, rad (``None`` if not compensated).
    payload_kg : float
        Payload it was compensated for.
    compensated : bool
        It went through the compensation (failed or not).
    seed : (n,) ndarray or None
        The seed of the nominal inverse kinematics that gave the program's configuration
        (``None``: the home configuration, as ``plugcell compensate``).
    """

    target: Target
    where: str
    ok: bool
    reason: str
    before: np.ndarray
    after: np.ndarray
    dp_mm: float = 0.0
    dr_deg: float = 0.0
    q: np.ndarray | None = None
    payload_kg: float = 0.0
    compensated: bool = False
    seed: np.ndarray | None = None


@dataclass
class FilterResult:
    """Per-target reports and the edits that rewrite the program.

    Attributes
    ----------
    reports : list of TargetReport
        In program order.
    edits : dict of (int, int) to str
        ``(file, offset) → text`` for :meth:`Program.render`.
    """

    reports: list[TargetReport] = field(default_factory=list)
    edits: dict[tuple[int, int], str] = field(default_factory=dict)

    @property
    def failed(self) -> list[TargetReport]:
        """Targets that could not be compensated."""
        return [r for r in self.reports if not r.ok]


def missing_frames(program: Program, bases: Mapping[str, np.ndarray],
                   tools: Mapping[str, np.ndarray], joints: str = "keep"
                   ) -> tuple[list[str], list[str]]:
    """Names of the frames and tools the targets to compensate need and nobody defines
    (a joint target needs its tool only when it is compensated, never a frame)."""
    mb: list[str] = []
    mt: list[str] = []
    for t in program.targets:
        if not t.used or (t.kind == "joints" and joints == "keep"):
            continue
        parts = [] if t.kind == "joints" else [t.base] if t.base is None or \
            t.base not in program.composites else [p for p, _ in program.composites[t.base]]
        for b in parts:
            if b is not None and b not in program.frames and b not in bases and b not in mb:
                mb.append(b)
        name = t.tool if t.tool is not None else "<tool>"
        if name not in program.tools and name not in tools and name not in mt:
            mt.append(name)
    return mb, mt


def filter_targets(program: Program, model_for_tool: Callable[[np.ndarray], PoseModel],
                   *, bases: Mapping[str, np.ndarray] | None = None,
                   tools: Mapping[str, np.ndarray] | None = None,
                   payload_kg: float = 0.0, joints: str = "keep",
                   tol: float = 1e-6) -> FilterResult:
    """Compensate every used target of ``program`` (module docstring).

    Parameters
    ----------
    program : Program
        A program read by a dialect's reader.
    model_for_tool : callable
        ``TOOL → PoseModel``: the identified model with that tool point.
    bases, tools : mapping of str to (4, 4) ndarray, m
        Frames and tools given by the caller (command line), over the program's own.
    payload_kg : float
        Payload carried.
    joints : {"keep", "compensate"}
        What to do with joint targets.
    tol : float
        Convergence of the compensation (m and rad).

    Returns
    -------
    FilterResult

    Raises
    ------
    MissingFramesError
        A used target's frame or tool is not defined.
    """
    bases, tools = _resolved_frames(program, bases, tools, joints)
    out = FilterResult()
    used = [t for t in program.targets if t.used and (t.kind == "pose" or joints != "keep")]
    tool_names = sorted({_tool(t) for t in used})
    tool_of = {n: i for i, n in enumerate(tool_names)}
    tool_mats = np.array([tools[n] for n in tool_names]).reshape(-1, 4, 4)
    idx = np.array([tool_of[_tool(t)] for t in used], dtype=int)
    B, P, desc = _targets(program, used, bases, model_for_tool, tool_mats, idx)
    T = B @ P
    reports: dict[int, TargetReport] = {}
    if used:
        cmd, seeds = _commanded(used, model_for_tool, T, idx, tool_mats, payload_kg, tol, desc)
        for i, report in enumerate(_reports(program, used, B, T, cmd, seeds, model_for_tool,
                                            tool_mats, idx, payload_kg, out.edits)):
            reports[id(used[i])] = report
    for t in program.targets:
        r = reports.get(id(t))
        if r is None:
            note = ("not used by a motion: left as it is" if not t.used
                    else "joint target: kept")
            r = TargetReport(t, program.where(t.file, t.offset), True, note, t.values,
                             t.values)
        out.reports.append(r)
    if program.post is not None:
        program.post(program, out.reports, out.edits)  # type: ignore[operator]
    return out


def _resolved_frames(program: Program, bases: Mapping[str, np.ndarray] | None,
                     tools: Mapping[str, np.ndarray] | None, joints: str
                     ) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Every frame and tool by name: the caller's over the program's, and each composite
    frame ``A:B⁻¹…`` multiplied out (MissingFramesError if a used one is defined nowhere)."""
    bases = {**program.frames, **(bases or {})}
    tools = {**program.tools, **(tools or {})}
    mb, mt = missing_frames(program, bases, tools, joints)
    if mb or mt:
        raise MissingFramesError(str(program.files[0].path), mb, mt)
    for name, parts in program.composites.items():
        M = np.eye(4)
        for part, inverted in parts:
            M = M @ (invert(bases[part]) if inverted else bases[part])
        bases[name] = M
    return bases, tools


def _targets(program: Program, used: list[Target], bases: Mapping[str, np.ndarray],
             model_for_tool: Callable[[np.ndarray], PoseModel], tool_mats: np.ndarray,
             idx: np.ndarray) -> tuple[np.ndarray, np.ndarray, object]:
    """Each target's frame ``B`` and pose in it ``P`` (``(N, 4, 4)``, m): a pose read in
    its notation, a joint target the nominal model's pose (``B = I``: joints are in no
    frame); and the robot description (None without joint targets)."""
    N = len(used)
    P = np.empty((N, 4, 4))
    B = np.tile(np.eye(4), (N, 1, 1))
    for i, t in enumerate(used):
        if t.base is not None and t.kind == "pose":
            B[i] = bases[t.base]
    for notation in {t.notation for t in used if t.kind == "pose"}:
        sel = [i for i, t in enumerate(used) if t.kind == "pose" and t.notation == notation]
        P[sel] = pose_from_notation(np.array([used[i].values for i in sel]), notation)
    jsel = [i for i, t in enumerate(used) if t.kind == "joints"]
    desc = None
    if jsel:
        desc = model_for_tool(tool_mats[0]).description
        for i in jsel:
            q = used[i].values * _unit(used[i], desc)
            if q.shape != (desc.n_readings,):
                raise program.files[used[i].file].error(
                    used[i].offset, f"{used[i].name}: {q.size} joints for a robot with "
                    f"{desc.n_readings}")
            P[i] = NominalModel(desc, tool_mats[idx[i]]).pose(q)[0]
    return B, P, desc


def _commanded(used: list[Target], model_for_tool: Callable[[np.ndarray], PoseModel],
               T: np.ndarray, idx: np.ndarray, tool_mats: np.ndarray, payload_kg: float,
               tol: float, desc: object) -> tuple[CommandedPoses, dict[int, np.ndarray]]:
    """The compensated commands of the targets ``T`` (robot base frame), each in the
    program's arm configuration: a joint target's is its own joints, a pose's the one its
    configuration numbers name (:func:`_configured`); and the seeds that gave them."""
    cmd = commanded_poses(model_for_tool, T, idx, tool_mats, payload_kg, tol=tol)
    seeds: dict[int, np.ndarray] = {}
    jsel = [i for i, t in enumerate(used) if t.kind == "joints"]
    if jsel:
        js = np.array(jsel)
        jq = np.array([used[i].values * _unit(used[i], desc) for i in jsel])
        again = commanded_poses(model_for_tool, T[js], idx[js], tool_mats, payload_kg,
                                seed=jq, tol=tol)
        cmd = _replace(cmd, js, again)
        seeds.update({int(i): q for i, q in zip(js, jq, strict=True)})
    cmd, more = _configured(used, model_for_tool, T, idx, tool_mats, payload_kg, tol, cmd)
    seeds.update(more)
    return cmd, seeds


def _reports(program: Program, used: list[Target], B: np.ndarray, T: np.ndarray,
             cmd: CommandedPoses, seeds: dict[int, np.ndarray],
             model_for_tool: Callable[[np.ndarray], PoseModel], tool_mats: np.ndarray,
             idx: np.ndarray, payload_kg: float, edits: dict[tuple[int, int], str]
             ) -> list[TargetReport]:
    """Each used target's report, its new numbers added to ``edits``: a pose back in its
    frame, ``P' = B⁻¹ · T_command``, in its notation nearest its old numbers; a joint
    target the compensated joints.  ``dp``, ``dr``: how far the command moved from the
    target in the robot base frame (the same rigid motion as in the program's frame)."""
    res = cmd.result
    Pc = invert(B) @ cmd.T_command
    after_all: list[np.ndarray | None] = [None] * len(used)
    for notation in {t.notation for t in used if t.kind == "pose"}:
        sel = [i for i, t in enumerate(used) if t.kind == "pose" and t.notation == notation]
        vals = notation_from_pose(Pc[sel], notation, np.array([used[i].values for i in sel]))
        for k, i in enumerate(sel):
            after_all[i] = vals[k]
    dp_all = np.linalg.norm(cmd.T_command[:, :3, 3] - T[:, :3, 3], axis=-1) * 1e3
    dr_all = np.degrees(np.linalg.norm(so3_log(
        cmd.T_command[:, :3, :3] @ np.swapaxes(T[:, :3, :3], -1, -2)), axis=-1))
    out = []
    for i, t in enumerate(used):
        good = bool(res.ok[i])
        after, note = t.values, ""
        if good:
            if t.kind == "pose":
                after = after_all[i]
                _edits(program, t, after, edits)
            else:
                after = res.q[i] / _unit(t, model_for_tool(tool_mats[idx[i]]).description)
                _edits(program, t, after, edits, joint=True)
            if t.config is not None:
                edits.update(t.config.edits(res.q_start[i], res.q[i]))  # type: ignore[attr-defined]
                bad = t.config.mismatch(res.q_start[i])  # type: ignore[attr-defined]
                if bad:
                    note = ("configuration: no solution of the nominal inverse kinematics "
                            f"has the program's arm configuration ({bad}); compensated "
                            "for the one from the home configuration")
        out.append(TargetReport(
            t, program.where(t.file, t.offset), good, note if good else str(res.reason[i]),
            t.values, after, float(dp_all[i]) if good else 0.0,
            float(dr_all[i]) if good else 0.0, res.q[i] if good else None, payload_kg,
            True, seeds.get(i)))
    return out


#: joints 1, 4, 6 turned by 0, ±2π: 27 shifts (the first none)
_SHIFTS = np.array([(k1, k4, k6) for k1 in (0, -1, 1) for k4 in (0, -1, 1)
                    for k6 in (0, -1, 1)], dtype=float) * 2 * np.pi


def _turns(q: np.ndarray, lim: np.ndarray) -> np.ndarray:
    """``q`` with joints 1, 4, 6 turned by ``0, ±2π`` — the same pose, other turn numbers —
    inside the limits (``q`` itself first), ``(K, n)``."""
    Q = np.repeat(q[None], len(_SHIFTS), axis=0)
    cols = [j for j in (0, 3, 5) if j < q.size]
    Q[:, cols] += _SHIFTS[:, :len(cols)]
    inside = np.all((lim[:, 0] - 1e-12 <= Q) & (lim[:, 1] + 1e-12 >= Q), axis=1)
    return Q[inside]


def _flip(q: np.ndarray, lim: np.ndarray) -> np.ndarray:
    """The wrist flipped, ``q4 + π, −q5, q6 + π`` (joints 4, 6 brought back inside their
    limits by a turn): a seed of the other wrist configuration."""
    c = q.copy()
    if c.size >= 6:
        c[3] += np.pi
        c[4] = -c[4]
        c[5] += np.pi
        for j in (3, 5):
            if c[j] > lim[j, 1]:
                c[j] -= 2 * np.pi
            if c[j] < lim[j, 0]:
                c[j] += 2 * np.pi
    return c


def _configured(used: list[Target], model_for_tool: Callable[[np.ndarray], PoseModel],
                T: np.ndarray, idx: np.ndarray, tool_mats: np.ndarray, payload_kg: float,
                tol: float, cmd: CommandedPoses) -> tuple[CommandedPoses, dict[int, np.ndarray]]:
    """Targets whose program names another arm configuration than the one the nominal
    inverse kinematics found from home (status/turn, confdata, CONFIG): the other turns of
    that solution (exact: joints 1, 4, 6 ± 2π) and the solution from the flipped wrist (one
    batched inverse kinematics for all of them) and its turns are tried; the first the
    program's configuration describes is compensated from it.  Others stay (warned)."""
    res = cmd.result
    bad = [i for i, t in enumerate(used) if t.config is not None and t.kind == "pose"
           and res.ok[i] and not t.config.agrees(res.q_start[i][None])[0]]  # type: ignore[attr-defined]
    if not bad:
        return cmd, {}
    redo: dict[int, np.ndarray] = {}
    flips: dict[int, list[int]] = {}
    for i in bad:
        cfg = used[i].config
        model = model_for_tool(tool_mats[idx[i]])
        lim = np.asarray(model.description.joint_limits)
        Q = _turns(res.q_start[i], lim)[1:]
        fit = np.flatnonzero(cfg.agrees(Q)) if len(Q) else []  # type: ignore[attr-defined]
        if len(fit):
            redo[i] = Q[fit[0]]
        else:
            flips.setdefault(int(idx[i]), []).append(i)
    for k, members in flips.items():  # one inverse kinematics per tool for the flips
        model = model_for_tool(tool_mats[k])
        lim = np.asarray(model.description.joint_limits)
        seeds = np.array([_flip(res.q_start[i], lim) for i in members])
        qs, ok, _ = nominal_joints(model, T[members], seeds)
        for i, qk, okk in zip(members, qs, ok, strict=True):
            if not okk:
                continue
            Q = _turns(qk, lim)
            fit = np.flatnonzero(used[i].config.agrees(Q)) if len(Q) else []  # type: ignore[union-attr]
            if len(fit):
                redo[i] = Q[fit[0]]
    if not redo:
        return cmd, {}
    sel = np.array(sorted(redo))
    again = commanded_poses(model_for_tool, T[sel], idx[sel], tool_mats, payload_kg,
                            seed=np.array([redo[i] for i in sel]), tol=tol)
    keep = again.result.ok
    chosen = {int(i): redo[int(i)] for i in sel[keep]}
    return _replace(cmd, sel, again, keep), chosen


def _replace(cmd: CommandedPoses, sel: np.ndarray, again: CommandedPoses,
             keep: np.ndarray | None = None) -> CommandedPoses:
    """``cmd`` with the targets ``sel`` (those of them ``keep`` says) taken from ``again``
    (their compensation from other seeds)."""
    keep = np.ones(len(sel), dtype=bool) if keep is None else keep
    sel = sel[keep]
    if not sel.size:
        return cmd
    res = cmd.result
    fields = ("q", "q_start", "converged", "within_limits", "iterations", "residual",
              "position_error", "orientation_error", "reason", "kind")
    merged = {f: getattr(res, f).copy() for f in fields}
    for f in fields:
        merged[f][sel] = getattr(again.result, f)[keep]
    hf = res.hybrid_fallback
    if hf is not None and again.result.hybrid_fallback is not None:
        hf = hf.copy()
        hf[sel] = again.result.hybrid_fallback[keep]
    T_cmd = cmd.T_command.copy()
    T_cmd[sel] = again.T_command[keep]
    return CommandedPoses(CompensationResult(**merged, hybrid_fallback=hf), T_cmd)


def _unit(t: Target, desc: object) -> np.ndarray:
    """SI per written unit of a joint target's numbers."""
    return desc.reading_scale("file") if t.unit is None else np.full(  # type: ignore[attr-defined]
        len(t.nums), t.unit)


def _tool(t: Target) -> str:
    return t.tool if t.tool is not None else "<tool>"


def _edits(program: Program, t: Target, values: np.ndarray,
           edits: dict[tuple[int, int], str], joint: bool = False) -> None:
    """The new texts of a target's numbers (unchanged ones are left out)."""
    if joint:
        res = [program.resolution[1]] * len(t.nums)
    else:
        n_len = 3
        ang = program.resolution[2] if NOTATIONS[t.notation][2] == "quat" else \
            program.resolution[1]
        res = [program.resolution[0]] * n_len + [ang] * (len(t.nums) - n_len)
    for n, v, r in zip(t.nums, values, res, strict=True):
        if n.virtual:
            continue
        txt = new_text(n, float(v), r)
        if txt is not None:
            edits[(t.file, n.start)] = txt
