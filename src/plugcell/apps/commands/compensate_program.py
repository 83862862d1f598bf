"""``plugcell compensate --program``: a robot program in, the same program out, compensated.

    plugcell compensate --params PARAMS.json --program IN [--out OUT] [--dialect D]
                        [--base NAME=…] [--tool NAME=…] [--partial] [--report REPORT.csv]
                        [--measure-order PLAN.csv] [--joint-targets keep|compensate]

Reads the program (:mod:`plugcell.io.programs`), composes each target with its frame
and tool, compensates it as ``plugcell compensate --targets`` would, and writes the
program back with only the targets' numbers changed
(:mod:`plugcell.io.programs.filter`).  Nothing is written when a target fails (unless
``--partial``: failing targets keep their numbers), when the syntax is unknown
(file:line:column) or when a frame or tool is missing (the list of them).
See docs/robot-program-compensation.md.
"""

from __future__ import annotations

import argparse
import csv
import io
import math
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from plugcell.apps.cli import CommandError


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The program options of ``plugcell compensate``."""
    p.add_argument("--dialect", choices=("krl", "urscript", "rapid", "fanuc", "pdl2", "gcode"),
                   default=None,
                   help="program dialect (default: from the suffix: .src .script .mod/.prg "
                        ".ls .pdl .nc/.ngc/.gcode/.tap)")
    p.add_argument("--angles", choices=("kuka", "fanuc", "comau"), default="kuka",
                   help="G-code: how A, B, C turn the tool (kuka: Rz(A)Ry(B)Rx(C), default; "
                        "fanuc: W, P, R about fixed X, Y, Z; comau: ZYZ); also the notation "
                        "of its --base/--tool")
    p.add_argument("--base", action="append", default=[], metavar="NAME=VALUES",
                   help="a frame the program uses but does not define (repeatable), in the "
                        "dialect's notation: KRL X,Y,Z,A,B,C (mm, deg); RAPID x,y,z,q1,q2,q3,"
                        "q4; URScript x,y,z,rx,ry,rz (m, rad); Fanuc X,Y,Z,W,P,R (mm, deg); "
                        "PDL2 X,Y,Z,A,B,C (mm, deg, ZYZ); G-code: a work offset G54…, "
                        "X,Y,Z,A,B,C in --angles")
    p.add_argument("--partial", action="store_true",
                   help="write the program even if targets fail (they keep their numbers)")
    p.add_argument("--report", type=Path, default=None,
                   help="CSV report, one row a target (nominal vs compensated, region)")
    p.add_argument("--measure-order", type=Path, default=None, metavar="PLAN.csv",
                   help="write a plan file (plugcell plan's format) of the joints the "
                        "compensated program visits, in program order")
    p.add_argument("--joint-targets", choices=("keep", "compensate"), default="keep",
                   help="joint targets (E6AXIS, jointtarget, movej([...])): keep them "
                        "(default) or compensate the pose they reach nominally")


def _named(values: list[str], option: str, notation: str) -> dict[str, np.ndarray]:
    from plugcell.io.units import NOTATIONS, UnitsError, pose_from_notation

    out: dict[str, np.ndarray] = {}
    k = NOTATIONS[notation][0]
    for text in values:
        name, eq, rest = text.rpartition("=")
        if not eq or not name.strip():
            raise CommandError(f"{option}: expected NAME=v1,…,v{k}, got {text!r}")
        try:
            vals = [float(s) for s in rest.split(",")]
        except ValueError:
            raise CommandError(f"{option} {name}: expected {k} numbers, got {rest!r}") from None
        if len(vals) != k:
            raise CommandError(f"{option} {name}: expected {k} numbers ({notation} notation), "
                               f"got {len(vals)}")
        try:
            out[name.strip()] = pose_from_notation(np.array(vals), notation)
        except UnitsError as exc:
            raise CommandError(f"{option} {name}: {exc}") from None
    return out


def _outputs(program: Any, out: Path) -> list[Path]:
    """Where each of the program's files goes: ``out`` (a folder — an existing one or a
    name without a suffix — gets the same names; else its stem with each file's suffix)."""
    if out.is_dir() or not out.suffix:
        return [out / f.path.name for f in program.files]
    return [out] + [out.with_suffix(f.path.suffix) for f in program.files[1:]]


def run(args: argparse.Namespace) -> int:
    """``plugcell compensate --program`` (module docstring)."""
    from plugcell.apps.commands.files import check_region_of, read_compensation_model
    from plugcell.compensation import IdentifiedModel
    from plugcell.io.programs import NOTATION, ProgramError, dialect_of, read_program
    from plugcell.io.programs.filter import filter_targets

    if not args.tol > 0:
        raise CommandError(f"--tol must be > 0, got {args.tol}")
    if args.out is None and args.measure_order is None and args.report is None:
        raise CommandError("--program: give --out (the compensated program), --report or "
                           "--measure-order")
    result = read_compensation_model(args.params, args, not args.physical_only)
    layer = result.residual_model
    if layer is not None and layer.uses_temperature and args.temperature_c is None:
        raise CommandError(f"{args.params}: its residual model uses the temperature: give "
                           "--temperature-c (or --physical-only)")
    try:
        dialect = dialect_of(args.program, args.dialect)
        program, notes = read_program(args.program, dialect, angles=args.angles)
    except ProgramError as exc:
        raise CommandError(f"{exc}; nothing written") from None
    notation = args.angles if dialect == "gcode" else NOTATION[dialect]
    bases = _named(args.base, "--base", notation)
    tools = _named(args.tool or [], "--tool", notation)
    if args.payload_kg is not None and not (math.isfinite(args.payload_kg)
                                            and args.payload_kg >= 0):
        raise CommandError(f"--payload-kg must be a mass ≥ 0 kg, got {args.payload_kg}")
    payload = result.model.payload_ref_kg if args.payload_kg is None else args.payload_kg
    outs = _outputs(program, args.out) if args.out is not None else []
    for o, f in zip(outs, program.files, strict=False):
        if o.resolve() == f.path.resolve():
            raise CommandError(f"{o}: --out would overwrite the program read: choose "
                               "another file")

    def model_for_tool(tool: np.ndarray) -> IdentifiedModel:
        return IdentifiedModel(result.model, tool, residual=layer,
                               temperature_c=args.temperature_c)

    t0 = time.perf_counter()
    try:
        fr = filter_targets(program, model_for_tool, bases=bases, tools=tools,
                            payload_kg=payload, joints=args.joint_targets, tol=args.tol)
    except ProgramError as exc:
        raise CommandError(f"{exc}; nothing written") from None
    dt = time.perf_counter() - t0
    comp = [r for r in fr.reports if r.compensated and r.ok]
    region = None
    if comp:
        q = np.array([r.q for r in comp])
        region = check_region_of(result, q, np.full(len(comp), payload))
    outside = set() if region is None else {id(comp[k]) for k in np.flatnonzero(region.outside)}
    if args.report is not None:
        _write_report(args.report, fr, comp, region)
    failed = fr.failed
    for n in notes:
        print(f"note: {n}", file=sys.stderr)
    _warn(args, failed, comp, region)
    written = []
    for o, txt in zip(outs, program.render(fr.edits), strict=False):  # (no --out: none)
        try:
            o.parent.mkdir(parents=True, exist_ok=True)
            o.write_bytes(txt.encode("latin-1"))
        except OSError as exc:
            raise CommandError(f"{o}: cannot write: {exc.strerror or exc}") from None
        written.append(str(o))
    if args.measure_order is not None:
        _write_plan(args.measure_order, result, fr, payload, args.program)
        written.append(str(args.measure_order))
    dp = [r.dp_mm for r in comp]
    print(f"{args.program}: {len(comp)} targets compensated with model {result.config.number} "
          f"({result.config.name}) in {dt:.2f} s"
          + (f": moved by {min(dp):.3f}…{max(dp):.3f} mm" if dp else "")
          + (f", {len(failed)} failed" if failed else "")
          + (f", {len(outside)} outside the calibrated region" if outside else "")
          + (f"; {len(fr.edits)} numbers changed" if outs else "")
          + (f"; wrote {', '.join(written)}" if written else ""))
    return 0


def _warn(args: argparse.Namespace, failed: list[Any], comp: list[Any], region: Any) -> None:
    """What the user must know before anything is written, on stderr: the targets that
    cannot be compensated (refused unless ``--partial``), those compensated for another
    arm configuration than the program names, those outside the calibrated region."""
    if failed:
        lines = [f"{r.where} ({r.target.name}): {r.reason}" for r in failed[:10]]
        more = f"\n... and {len(failed) - 10} more" if len(failed) > 10 else ""
        msg = (f"{len(failed)} of {len(comp) + len(failed)} targets cannot be compensated:\n"
               + "\n".join(lines) + more)
        if not args.partial:
            raise CommandError(msg + "\nnothing written (--partial writes the others)")
        print(f"warning: {msg}\n(--partial: they keep their numbers)", file=sys.stderr)
    mism = [r for r in comp if r.reason.startswith("configuration")]
    if mism:
        print(f"warning: {len(mism)} targets: no solution of the nominal inverse kinematics "
              "has the arm configuration the program names (status/turn, confdata, CONFIG); "
              "compensated for the one from the home configuration:", file=sys.stderr)
        for r in mism[:10]:
            print(f"  {r.where} ({r.target.name}): {r.reason.split('(', 1)[1].rsplit(')', 1)[0]}",
                  file=sys.stderr)
    if region is not None and region.count:
        print(f"warning: {region.message('targets')}", file=sys.stderr)
        for k in np.flatnonzero(region.outside)[:10]:
            r = comp[int(k)]
            print(f"  {r.where} ({r.target.name}): outside the calibrated region: "
                  f"{region.reasons(int(k))}", file=sys.stderr)


def _write_report(path: Path, fr: Any, comp: list[Any], region: Any) -> None:
    from plugcell.apps.commands.files import write_text

    idx = {id(r): k for k, r in enumerate(comp)}
    buf = io.StringIO()
    buf.write("# plugcell compensate --program: one row a target; before/after: the numbers "
              "as written (the program's notation); dp_mm, dr_deg: how far the commanded "
              "pose moved and turned; ik_seed_deg: where the nominal inverse kinematics "
              "started (home, or a seed of the program's arm configuration)\n")
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["name", "where", "kind", "status", "dp_mm", "dr_deg", "outside_region",
                "region_distance_mm", "before", "after", "ik_seed_deg", "reason"])
    for r in fr.reports:
        k = idx.get(id(r))
        out_r = dist = ""
        if k is not None and region is not None:
            out_r, dist = int(region.outside[k]), f"{region.distance_m[k] * 1e3:.1f}"
        status = ("failed" if not r.ok else "compensated" if r.compensated else "kept")
        w.writerow([r.target.name, r.where, r.target.kind, status, f"{r.dp_mm:.4f}",
                    f"{r.dr_deg:.5f}", out_r, dist,
                    " ".join(f"{v:.10g}" for v in r.before),
                    " ".join(f"{v:.10g}" for v in r.after),
                    "home" if r.seed is None else " ".join(f"{v:.3f}"
                                                           for v in np.degrees(r.seed)),
                    r.reason])
    write_text(path, buf.getvalue())


def _write_plan(path: Path, result: Any, fr: Any, payload: float, program: Path) -> None:
    """The joints the compensated program visits, in the order of its motions, each once."""
    from plugcell.apps.commands.files import write_text
    from plugcell.io.plans import MeasurementPlan, format_plan

    desc = result.model.structure.source
    visits = []
    for r in fr.reports:
        if r.q is not None:
            first = min(r.target.uses) if r.target.uses else (r.target.file, r.target.offset)
            visits.append((first, r.q))
        elif r.target.kind == "joints" and r.target.used and r.ok and \
                r.target.values.size == desc.n_readings:
            first = min(r.target.uses) if r.target.uses else (r.target.file, r.target.offset)
            unit = r.target.unit
            visits.append((first, r.target.values * (desc.reading_scale("file") if unit is None
                                                     else unit)))
    if not visits:
        raise CommandError(f"{program}: no target to measure (--measure-order)")
    visits.sort(key=lambda v: v[0])
    q = np.array([v[1] for v in visits])
    plan = MeasurementPlan(q, np.full(len(q), payload))
    write_text(path, format_plan(plan, comments=[
        f"plugcell compensate --measure-order: {len(q)} poses of {program.name} in program "
        f"order (compensated joints), robot {result.robot}"],
        joint_scale=desc.reading_scale("file")))
