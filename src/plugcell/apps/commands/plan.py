"""``plugcell plan``: choose the poses of a calibration campaign (docs/planning.md).

    plugcell plan --robot R --poses N --out PLAN.csv [--candidates M | --from FILE]
                  [--criterion I|D|A|E|O] [--model 1-5] [--payloads-kg 0,18,36]
                  [--tracker x,y,z] [--line-of-sight-deg A] [--volume cx,cy,cz,sx,sy,sz]
                  [--probe x,y,z,r,p,y] [--program FILE] [--json]

Candidates are drawn within the joint and coupled limits with the target in the
working volume and facing the tracker (or read with ``--from``: a plan file of allowed
configurations or a measurement file of poses already measured — then BASE and PROBE
come from its measurements); ``N`` of them are chosen to maximise the criterion of the
identification Jacobian (:mod:`plugcell.calibration.planning`).  The plan file is what
``plugcell twin measure --plan`` reads (with ``--from`` a measurement file: the chosen
rows with their measurements, ready for ``plugcell calibrate``); ``--program`` writes
the values of the
``calibration`` robot program (one file per payload).  Bad input ends with a clear
message and exit code 2.
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from plugcell.apps.cli import CommandError
from plugcell.apps.commands.deprecated import DeprecatedName
from plugcell.apps.commands.files import write_text
from plugcell.apps.commands.robotargs import add_robot_args, load_robot_of

#: Default line-of-sight acceptance of a T-MAC (deg).
DEFAULT_ACCEPTANCE_DEG = 45.0
#: Most configurations one run of calibration.pdl takes (its ARRAY[200] OF JOINTPOS).
PROGRAM_MAX_CONFIGS = 200


def configure(p: argparse.ArgumentParser) -> None:
    """Add the ``plan`` options to its parser (declared in :mod:`plugcell.apps.cli`)."""
    p.description = (
        "Choose N poses that determine the parameters of a calibration model best "
                    "(I-, D-, A-, E-optimal or noise amplification index O), among candidates "
                    "within the joint limits, in the working volume and visible from the "
                    "tracker; writes a plan file for 'plugcell twin measure --plan' and the "
                    "calibration robot program.")
    add_robot_args(p, required=True)
    p.add_argument("--poses", type=int, required=True, metavar="N", help="poses to plan")
    p.add_argument("--out", type=Path, required=True, help="plan file (CSV) to write")
    src = p.add_mutually_exclusive_group()
    src.add_argument("--candidates", type=int, default=5000, metavar="M",
                     help="candidates to draw (default 5000)")
    src.add_argument("--from", dest="from_file", type=Path, metavar="FILE",
                     help="choose among these configurations: a plan file or a measurement "
                          "file (poses already measured)")
    p.add_argument("--criterion", default="I",
                   help="I (default: mean prediction variance over the candidates), D, A, E "
                        "or O (noise amplification index)")
    p.add_argument("--model", default="5", help="1-5 or a model name (default 5, full)")
    p.add_argument("--payloads-kg", "--payloads", dest="payloads", action=DeprecatedName,
                   old=("--payloads",), metavar="KG,KG,…",
                   help="payload masses of the campaign, kg (default: 0,18,36 for model 5, "
                        "else 0; --payloads is its old name)")
    p.add_argument("--tracker", metavar="X,Y,Z",
                   help="tracker position in the robot base frame, mm (default: the twin's "
                        "cell for a robot with a twin; else no line-of-sight test)")
    p.add_argument("--line-of-sight-deg", type=float, default=DEFAULT_ACCEPTANCE_DEG,
                   metavar="A", help="largest angle between the target's facing axis (its z) "
                                     "and the direction to the tracker (default 45)")
    p.add_argument("--volume", metavar="CX,CY,CZ,SX,SY,SZ",
                   help="working volume (box centre and size, mm; default: the description's; "
                        "'none': no volume test)")
    p.add_argument("--probe", metavar="X,Y,Z,R,P,Y",
                   help="target on the flange, mm and fixed X-Y-Z degrees (default: the twin's "
                        "T-MAC for a robot with a twin, else the description's tool)")
    p.add_argument("--rot", choices=("rpy", "zyz", "xyz"), default="rpy",
                   help="orientation convention of a --from measurement file (default rpy)")
    p.add_argument("--position-only", action="store_true",
                   help="the tracker measures positions only (3 rows a pose)")
    p.add_argument("--noise-mm", type=float, default=0.1,
                   help="measurement noise per row for the predicted σ (default 0.1)")
    p.add_argument("--seed", type=int, default=0, help="seed of the candidate draw (default 0)")
    p.add_argument("--program", type=Path, metavar="FILE",
                   help="also write the calibration program's values (JSON ACTIVATE data; "
                        "one file per payload)")
    p.add_argument("--program-value", action="append", default=[], metavar="NAME=VALUE",
                   help="one more value of the program's ACTIVATE data, e.g. base_est=x,y,z,"
                        "a,b,c or identify=… (repeatable; docs/robot-programs.md)")
    p.add_argument("--json", action="store_true", help="print the plan summary as JSON")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")
    p.set_defaults(func=_run)


# ---------------------------------------------------------------------- argument parsing
def _numbers(text: str, what: str, count: tuple[int, ...]) -> list[float]:
    try:
        vals = [float(x) for x in text.split(",")]
    except ValueError:
        raise CommandError(f"--{what}: expected {' or '.join(map(str, count))} numbers "
                           f"separated by commas, got {text!r}") from None
    if len(vals) not in count or not all(math.isfinite(v) for v in vals):
        raise CommandError(f"--{what}: expected {' or '.join(map(str, count))} finite numbers, "
                           f"got {text!r}")
    return vals


def _payloads(text: str | None, payload_model: bool) -> list[float]:
    if text is None:
        return [0.0, 18.0, 36.0] if payload_model else [0.0]
    vals = _numbers(text, "payloads", tuple(range(1, 33)))
    if any(v < 0 for v in vals):
        raise CommandError(f"--payloads-kg: masses must be ≥ 0 kg, got {text!r}")
    if payload_model and max(vals) <= 0:
        raise CommandError("--payloads-kg: model 5 identifies payload compliance; give at least "
                           "one payload > 0 kg (the thesis: 0,18,36)")
    return sorted(set(vals))


def _say(args: argparse.Namespace, text: str) -> None:
    if not args.quiet:
        print(f"plan: {text}", file=sys.stderr, flush=True)


#: Rms misfit (mm) of measurements to the robot's nominal kinematics above which ``--from``
#: data are taken for another robot's: an uncalibrated robot is off by a few mm.
MISFIT_LIMIT_MM = 25.0


def _check_dropped(args: argparse.Namespace, robot: str, dropped: dict[str, int],
                   measured: bool) -> None:
    """Say how many configurations of ``--from`` were left out and why; refuse when most
    are outside the robot's joint limits (another robot's file)."""
    given = dropped.get("given", 0)
    left_out = {k: v for k, v in dropped.items() if k != "given"}
    if not given or not left_out:
        return
    why = ", ".join(f"{v} outside the {k}" for k, v in left_out.items())
    total = sum(left_out.values())
    what = "measured poses" if measured else "configurations"
    if 2 * left_out.get("limits", 0) > given:
        raise CommandError(f"--from {args.from_file}: {left_out['limits']} of its {given} "
                           f"{what} are outside the joint limits of robot {robot!r} — a file "
                           "of another robot? give its --robot")
    print(f"plan: warning: {total} of the {given} {what} of {args.from_file} left out ({why})",
          file=sys.stderr, flush=True)


def _twin_cell(robot: str) -> tuple[np.ndarray, np.ndarray] | None:
    """The twin's tracker position (m, robot frame) and T-MAC (PROBE) when it has one."""
    from plugcell.kinematics.rotations import rpy_to_matrix
    from plugcell.sim.twin.scenario import ScenarioError, TwinProfile

    try:
        prof = TwinProfile.load(robot)
    except ScenarioError:
        return None
    probe = np.eye(4)
    probe[:3, :3] = rpy_to_matrix(*prof.probe_rpy)
    probe[:3, 3] = prof.probe_position
    return np.asarray(prof.tracker_position, float), probe


# ---------------------------------------------------------------------- the command
def _run(args: argparse.Namespace) -> int:
    from plugcell.calibration.configs import model_config
    from plugcell.calibration.planning import PlanningError, PosePlanner, planning_keys

    t0 = time.perf_counter()
    desc = load_robot_of(args)
    scale = desc.reading_scale()  # files hold degrees, and mm for a prismatic joint
    try:
        cfg = model_config(args.model)
    except ValueError as exc:
        raise CommandError(f"--model: {exc}") from None
    _check_options(args)
    payloads = _payloads(args.payloads, cfg.payload)
    volume = _volume(args, desc)
    base, probe, tracker = _frames(args, desc)
    source = _read_from(args, desc, scale)
    model = _model(args, desc, cfg, payloads, source, base, probe)
    try:
        cands, what = _candidates(args, desc.name, model, cfg, payloads, source, volume,
                                  tracker)
        keys = planning_keys(model, np.unique(cands.payload_kg),
                             position_only=args.position_only)
        planner = PosePlanner(model, keys, criterion=args.criterion,
                              position_only=args.position_only, noise_m=args.noise_mm / 1e3)
        _say(args, f"choosing {args.poses} of {what} for the {len(keys)} identifiable of "
                   f"the {len(model.space)} parameters of model {cfg.number} (the rest "
                   f"depend on them or on nothing measured; criterion {planner.criterion})")
        plan = planner.plan(cands, args.poses)
    except PlanningError as exc:
        raise CommandError(str(exc)) from None
    summary = _summary(plan, model, desc.name, cfg, what, time.perf_counter() - t0)
    if source.measured is not None:
        _write_measured(args.out, source.mset, cands.source[plan.index], summary,
                        args.from_file, scale)
    else:
        _write_plan(args.out, plan, summary, scale)
    written = [str(args.out)]
    if args.program is not None:
        written += _write_program(args.program, plan, scale, args.program_value)
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print(_text(summary))
        print("wrote " + ", ".join(written))
    return 0


def _check_options(args: argparse.Namespace) -> None:
    """The options' own ranges and pairings (CommandError naming the option)."""
    if args.poses < 1:
        raise CommandError(f"--poses must be positive, got {args.poses}")
    if args.program_value and args.program is None:
        raise CommandError("--program-value is a value of the program --program writes: "
                           "give --program FILE too")
    for v in args.program_value:
        if not re.fullmatch(r"[A-Za-z_]\w*=.*", v, re.S):
            raise CommandError(f"--program-value must be NAME=VALUE (a program variable), "
                               f"got {v!r}")
    if args.from_file is None and args.candidates < 1:
        raise CommandError(f"--candidates must be positive, got {args.candidates}")
    if not (args.noise_mm > 0 and math.isfinite(args.noise_mm)):
        raise CommandError(f"--noise-mm must be positive, got {args.noise_mm}")
    if not (0 < args.line_of_sight_deg <= 180):
        raise CommandError(f"--line-of-sight-deg must be in (0, 180], got "
                           f"{args.line_of_sight_deg}")


def _volume(args: argparse.Namespace, desc: Any) -> Any:
    """The working volume the poses keep to: the robot's, ``--volume`` or none."""
    from plugcell.kinematics import Box

    if args.volume is None:
        return desc.working_volume
    if args.volume.strip().lower() == "none":
        return None
    v = _numbers(args.volume, "volume", (6,))
    if min(v[3:]) <= 0:
        raise CommandError(f"--volume: the sizes must be positive, got {args.volume!r}")
    return Box(tuple(x / 1e3 for x in v[:3]), tuple(x / 1e3 for x in v[3:]))


def _frames(args: argparse.Namespace, desc: Any
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """BASE (the tracker frame parallel to the robot's, at the tracker), PROBE and the
    tracker position (m, robot frame; None: unknown): the options', else the twin's."""
    from plugcell.kinematics.rotations import rpy_to_matrix

    twin = _twin_cell(desc.name)
    probe = twin[1] if twin is not None else np.asarray(desc.tool, float)
    if args.probe is not None:
        v = _numbers(args.probe, "probe", (6,))
        probe = np.eye(4)
        probe[:3, :3] = rpy_to_matrix(*np.radians(v[3:]))
        probe[:3, 3] = np.asarray(v[:3]) / 1e3
    tracker = None
    if args.tracker is not None:
        tracker = np.asarray(_numbers(args.tracker, "tracker", (3,))) / 1e3
    elif twin is not None and args.from_file is None:
        tracker = twin[0]
    base = np.eye(4)
    if tracker is not None:
        base[:3, 3] = -tracker
    return base, probe, tracker


class _Source:
    """The configurations of ``--from``: a plan file's or a measurement file's (then
    ``measured`` and ``mset`` too); all None without ``--from``."""

    def __init__(self, q: Any = None, payload_kg: Any = None, measured: Any = None,
                 mset: Any = None) -> None:
        self.q, self.payload_kg, self.measured, self.mset = q, payload_kg, measured, mset


def _read_from(args: argparse.Namespace, desc: Any, scale: Any) -> _Source:
    """Read ``--from``: a measurement file (it has x, y, z columns) or a plan file."""
    from plugcell.calibration import CalibrationData
    from plugcell.io.measurements import MeasurementFileError, read_measurements
    from plugcell.io.plans import PlanFileError, read_plan

    if args.from_file is None:
        return _Source()
    try:
        text = args.from_file.read_text(encoding="utf-8")
    except OSError as exc:
        raise CommandError(f"--from {args.from_file}: cannot read: "
                           f"{exc.strerror or exc}") from None
    header = next((ln for ln in text.splitlines()
                   if ln.strip() and not ln.lstrip().startswith("#")), "")
    try:
        if {"x", "y", "z"} <= {c.strip() for c in header.split(",")}:
            mset = read_measurements(args.from_file, rotation=args.rot,
                                     n_joints=desc.n_actuated, joint_scale=scale)
            return _Source(mset.joints, mset.payload_kg,
                           CalibrationData.from_measurements(mset), mset)
        pf = read_plan(args.from_file, n_joints=desc.n_actuated, joint_scale=scale)
        return _Source(pf.joints, pf.payload_kg)
    except (MeasurementFileError, PlanFileError) as exc:
        raise CommandError(str(exc)) from None


def _model(args: argparse.Namespace, desc: Any, cfg: Any, payloads: list[float],
           source: _Source, base: np.ndarray, probe: np.ndarray) -> Any:
    """The error model to plan for; with measured poses, BASE and PROBE estimated from
    them (refused when they do not fit the robot)."""
    from plugcell.calibration import CalibrationError, Calibrator, ErrorModel

    try:
        if source.measured is not None:
            base, probe, rms = Calibrator(desc, 1).initial_frames(source.measured)
            if rms * 1e3 > MISFIT_LIMIT_MM:
                raise CommandError(
                    f"--from {args.from_file}: the measurements do not fit robot {desc.name!r}: "
                    f"with its nominal kinematics and the best BASE and PROBE they are "
                    f"{rms * 1e3:.0f} mm rms off (an uncalibrated robot: a few mm; refused above "
                    f"{MISFIT_LIMIT_MM:g} mm) — measured on another robot? give its --robot")
            _say(args, f"BASE and PROBE estimated from {len(source.measured)} measured poses "
                       f"(rms misfit {rms * 1e3:.2f} mm)")
        model = ErrorModel.create(desc, cfg.family, gravity=cfg.gravity, payload=cfg.payload,
                                  base=base, probe=probe,
                                  payload_ref_kg=max(payloads) if cfg.payload else 0.0)
    except (CalibrationError, ValueError) as exc:
        raise CommandError(str(exc)) from None
    if cfg.gravity and not model.space.of_kind("gravity"):
        raise CommandError(f"model {cfg.number} ({cfg.name}) needs gravity deflection, but robot "
                           f"{desc.name!r} has neither a parallelogram nor link masses; "
                           "choose --model 1 or 2")
    return model


def _candidates(args: argparse.Namespace, robot: str, model: Any, cfg: Any,
                payloads: list[float], source: _Source, volume: Any,
                tracker: np.ndarray | None) -> tuple[Any, str]:
    """The candidate configurations: those of ``--from`` that pass the limits (and the
    options given), or ``--candidates`` drawn at random; and how to name them."""
    from plugcell.calibration.planning import (
        PlanningError,
        Visibility,
        filter_candidates,
        sample_candidates,
    )

    vis = None
    if tracker is not None:
        vis = Visibility(tuple(tracker), math.radians(args.line_of_sight_deg))
    if args.from_file is None:
        _say(args, f"drawing {args.candidates} candidates"
                   + (f" visible within {args.line_of_sight_deg:g}° from the tracker at "
                      f"{np.round(tracker * 1e3, 1).tolist()} mm" if vis else ""))
        cands = sample_candidates(model, args.candidates, payloads=payloads, volume=volume,
                                  visibility=vis, seed=args.seed)
        return cands, f"{len(cands)} candidates"
    own = source.payload_kg if args.payloads is None else None
    if source.measured is not None:
        if args.payloads is not None:
            raise PlanningError(f"--payloads-kg: the poses of {args.from_file} were "
                                "measured with their own payloads")
        own = source.measured.payload_kg
    if cfg.payload and own is not None and np.max(own) <= 0:
        raise PlanningError(f"--from {args.from_file}: every pose has payload 0; "
                            "model 5 needs payloads (give --payloads-kg)")
    cands = filter_candidates(
        model, source.q, payloads=payloads, payload_kg=own,
        volume=volume if args.volume is not None else None,
        visibility=vis if args.tracker is not None else None)
    _check_dropped(args, robot, cands.dropped, source.measured is not None)
    return cands, f"{len(cands)} candidates from {args.from_file}"


def _summary(plan: Any, model: Any, robot: str, cfg: Any, what: str,
             elapsed: float) -> dict[str, Any]:
    params = []
    for k, s in zip(plan.keys, plan.sigma, strict=True):
        p = model.space[k]
        scale, unit = {"m": (1e3, "mm"), "rad": (math.degrees(1.0), "deg")}.get(
            p.unit, (1.0, p.unit))
        params.append({"key": k, "name": p.name, "sigma": float(s * scale), "unit": unit})
    groups = [{"payload_kg": float(m), "poses": int(np.count_nonzero(plan.payload_kg == m))}
              for m in np.unique(plan.payload_kg)]
    return {
        "robot": robot, "model": {"number": cfg.number, "name": cfg.name,
                                  "parameters": len(model.space),
                                  "identifiable": len(plan.keys)},
        "poses": len(plan), "candidates": plan.n_candidates, "source": what,
        "criterion": plan.criterion, "value": plan.value,
        "condition_number": plan.condition_number, "exchanges": plan.exchanges,
        "noise_mm": plan.noise_m * 1e3, "payload_groups": groups,
        "unidentifiable": list(plan.unidentifiable), "predicted_sigma": params,
        "elapsed_s": elapsed,
    }


def _text(d: dict[str, Any]) -> str:
    groups = ", ".join(f"{g['poses']} at {g['payload_kg']:g} kg" for g in d["payload_groups"])
    worst = sorted(d["predicted_sigma"], key=lambda p: -p["sigma"] if p["unit"] == "mm" else 0)
    lines = [
        f"robot {d['robot']}, model {d['model']['number']} ({d['model']['name']}, "
        f"{d['model']['identifiable']} identifiable of its {d['model']['parameters']} "
        f"parameters): {d['poses']} poses of {d['candidates']} candidates ({groups})",
        f"  criterion {d['criterion']} = {d['value']:.6g} after {d['exchanges']} exchanges; "
        f"predicted κ = {d['condition_number']:.1f}; {d['elapsed_s']:.1f} s",
        f"  predicted σ for {d['noise_mm']:g} mm noise, largest lengths: " + ", ".join(
            f"{p['name']} {p['sigma']:.3g} {p['unit']}" for p in worst[:4]),
    ]
    if d["unidentifiable"]:
        lines.append("  warning: the candidates cannot determine " + ", ".join(
            d["unidentifiable"]) + " (left out)")
    if d["condition_number"] > 100:
        lines.append(f"  warning: κ = {d['condition_number']:.0f} > 100 (eq. 4.10): more poses "
                     "or a wider working volume")
    return "\n".join(lines)



def _write_plan(path: Path, plan: Any, d: dict[str, Any], scale: np.ndarray) -> None:
    from plugcell.io.plans import MeasurementPlan, format_plan

    comments = [
        f"plugcell plan: robot {d['robot']}, model {d['model']['number']} "
        f"({d['model']['name']}), criterion {d['criterion']}, {d['poses']} of "
        f"{d['candidates']} candidates",
        f"predicted: criterion {d['value']:.6g}, condition number {d['condition_number']:.1f}",
        "rows grouped by payload (one change per group), short joint moves within a group",
    ]
    write_text(path, format_plan(MeasurementPlan(plan.q, plan.payload_kg), comments=comments,
                                 joint_scale=scale))


def _write_measured(path: Path, m: Any, rows: np.ndarray, d: dict[str, Any],
                    source: Path, scale: np.ndarray) -> None:
    """Planning among poses already measured: the chosen rows of the measurement file,
    measurements included (a measurement file is a plan too) — ready for calibrate."""
    from plugcell.io.measurements import format_measurements

    comments = [
        f"plugcell plan: {d['poses']} of the {d['candidates']} measured poses of {source}, "
        f"robot {d['robot']}, model {d['model']['number']} ({d['model']['name']}), "
        f"criterion {d['criterion']}",
        f"predicted: criterion {d['value']:.6g}, condition number {d['condition_number']:.1f}",
    ]
    write_text(path, format_measurements(m.subset(rows), comments=comments,
                                         joint_scale=scale))


def _write_program(path: Path, plan: Any, scale: np.ndarray, extra: list[str]) -> list[str]:
    """The calibration program's values, one JSON ACTIVATE-data file per payload (and per
    200 configurations): ``["calibration", "configs=…", "n_configs=N", …]`` and then the
    ``extra`` values (``NAME=VALUE``)."""
    from plugcell.devices.robot.value_text import rows_text

    groups = []
    for m in np.unique(plan.payload_kg):
        q = plan.q[plan.payload_kg == m] / scale  # robot units: degrees, mm
        for i in range(0, len(q), PROGRAM_MAX_CONFIGS):
            groups.append((float(m), q[i:i + PROGRAM_MAX_CONFIGS]))
    written = []
    for g, (m, q) in enumerate(groups):
        target = path if len(groups) == 1 else path.with_name(
            f"{path.stem}-{g + 1}-{m:g}kg{path.suffix}")
        values = ["calibration", f"configs={rows_text(q)}", f"n_configs={len(q)}",
                  "duration_ms=1000", "route=TRUE", *extra]
        write_text(target, json.dumps(values) + "\n")
        written.append(f"{target} ({len(q)} poses, {m:g} kg)")
    return written
