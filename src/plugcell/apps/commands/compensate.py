"""``plugcell compensate``: filter an offline program through an identified model (6.5.1).

    plugcell compensate --params PARAMS.json --targets TARGETS.csv [--out JOINTS.csv]
                        [--payload-kg M] [--rot zyz|rpy] [--user-frame X,Y,Z,A,B,C]
    plugcell compensate --params PARAMS.json --program IN --out OUT …   (a robot program:
                        :mod:`plugcell.apps.commands.compensate_program`)

``PARAMS.json`` is what ``plugcell calibrate`` writes
(:func:`plugcell.io.params.params_document`).  ``TARGETS.csv``: a
header line, ``#`` comments, one target per row::

    name,x,y,z,rx,ry,rz,payload_kg        (name and payload_kg optional)
    P1,1400,-900,800,0,90,0,36

positions in mm, angles in degrees in the ``--rot`` convention (Comau ZYZ by
default), poses of the tool point (default: the T-MAC/PROBE the model was
identified with) in the robot base frame — or in the user frame ``--user-frame``.
``JOINTS.csv`` (stdout without ``--out``; the summary then goes to stderr) gets one row
per target: ``name,j1..jn`` in degrees (the compensated joint targets for the
controller), ``iterations`` and the final model residual.
Errors name the file, the line and the column.
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
from plugcell.apps.commands.files import check_region_of, read_compensation_model
from plugcell.apps.commands.robotargs import add_robot_args

COLUMNS = ("x", "y", "z", "rx", "ry", "rz")
OPTIONAL = ("name", "payload_kg")


def configure(p: argparse.ArgumentParser) -> None:
    """Add the ``compensate`` options to its parser (declared in :mod:`plugcell.apps.cli`)."""
    p.description = (
        "Turn a program's Cartesian targets into the joint targets for which the "
        "identified model predicts them (nominal IK, then the model, ‖Δx‖ < 1e-6)."
    )
    p.add_argument("--params", type=Path, required=True,
                   help="identified parameters (PARAMS.json from plugcell calibrate)")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--targets", type=Path,
                     help="CSV: [name,]x,y,z,rx,ry,rz[,payload_kg] (mm, degrees)")
    src.add_argument("--program", type=Path,
                     help="a robot program (KRL .src+.dat, URScript .script, RAPID .mod/.prg, "
                          "Fanuc .ls, PDL2 .pdl) to compensate: "
                          "docs/robot-program-compensation.md")
    p.add_argument("--out", type=Path,
                   help="CSV of compensated joints to write (default: print it to stdout); "
                        "with --program: the compensated program (a folder: same names)")
    p.add_argument("--payload-kg", type=float, default=None, metavar="M",
                   help="payload carried (kg) for rows without a payload_kg column "
                        "(default: the payload the parameters were identified with)")
    p.add_argument("--rot", choices=("zyz", "rpy"), default="zyz",
                   help="angle convention of rx,ry,rz and of --user-frame/--tool "
                        "(default: zyz, Comau Euler)")
    p.add_argument("--user-frame", default=None, metavar="X,Y,Z,A,B,C",
                   help="the targets are in this user frame (its pose in the robot base frame, "
                        "mm and degrees)")
    p.add_argument("--tool", action="append", default=None, metavar="X,Y,Z,A,B,C",
                   help="compensated tool point in the flange frame (mm, degrees; default: the "
                        "identified PROBE, i.e. the T-MAC); with --program: NAME=VALUES, a "
                        "tool the program uses but does not define (repeatable)")
    add_robot_args(p, help="robot description (name, .toml, .urdf or .xacro) instead of the "
                   "one recorded in PARAMS")
    p.add_argument("--tol", type=float, default=1e-6, help="‖Δx‖ threshold (default 1e-6)")
    p.add_argument("--physical-only", action="store_true",
                   help="ignore a learned residual model recorded in PARAMS (hybrid model "
                        "by default when there is one)")
    p.add_argument("--temperature-c", type=float, default=None, metavar="T",
                   help="cell temperature (°C): for a residual model that uses it and a "
                        "model with the thermal term (default: its reference temperature)")
    from plugcell.apps.commands.compensate_program import add_arguments

    add_arguments(p)
    p.set_defaults(func=_run)


# ----------------------------------------------------------------------------- inputs
def _frame_arg(text: str, option: str, rot: str) -> np.ndarray:
    from plugcell.compensation import frame_matrix

    parts = [s.strip() for s in text.split(",")]
    try:
        vals = [float(s) for s in parts]
    except ValueError:
        raise CommandError(f"{option}: expected X,Y,Z,A,B,C numbers, got {text!r}") from None
    if len(vals) != 6 or not all(math.isfinite(v) for v in vals):
        raise CommandError(f"{option}: expected 6 finite numbers X,Y,Z,A,B,C, got {text!r}")
    return frame_matrix(np.array(vals[:3]) / 1e3, np.radians(vals[3:]), rot)


def parse_targets(text: str, name: str) -> tuple[list[str], np.ndarray, np.ndarray,
                                                  np.ndarray | None, list[int]]:
    """``(names, positions (N,3) m, angles (N,3) rad, payload (N,) or None, line numbers)``.

    Raises ``ValueError`` naming the file, line and column of the first bad cell.
    """
    from plugcell.io.csvtable import table_number, table_rows

    rows = table_rows(text, name, ValueError)
    header_line, header = rows[0]
    cols = [h.strip().lower() for h in header]
    for i, c in enumerate(cols):
        if cols.index(c) != i:
            raise ValueError(f"{name}: line {header_line}: column {c!r} appears twice")
    missing = [c for c in COLUMNS if c not in cols]
    if missing:
        raise ValueError(f"{name}: line {header_line}: the header lacks {missing}; expected "
                         "[name,]x,y,z,rx,ry,rz[,payload_kg]")
    unknown = [c for c in cols if c not in COLUMNS + OPTIONAL]
    if unknown:
        raise ValueError(f"{name}: line {header_line}: unknown columns {unknown}; expected "
                         "[name,]x,y,z,rx,ry,rz[,payload_kg]")
    data = rows[1:]
    if not data:
        raise ValueError(f"{name}: the file has a header but no targets")
    names, lines = [], []
    vals = np.empty((len(data), 6))
    pay = np.empty(len(data)) if "payload_kg" in cols else None
    for r, (line_no, row) in enumerate(data):
        if len(row) != len(cols):
            raise ValueError(f"{name}: line {line_no}: expected {len(cols)} values, got {len(row)}")
        lines.append(line_no)
        names.append(row[cols.index("name")].strip() if "name" in cols else f"{r + 1}")
        for c, col in enumerate(cols):
            if col == "name":
                continue
            v = table_number(row[c], name, line_no, col, ValueError)
            if col == "payload_kg":
                if v < 0:
                    raise ValueError(f"{name}: line {line_no}, column 'payload_kg': negative "
                                     f"mass {row[c].strip()!r}")
                pay[r] = v  # type: ignore[index]
            else:
                vals[r, COLUMNS.index(col)] = v
    return names, vals[:, :3] / 1e3, np.radians(vals[:, 3:]), pay, lines


# ----------------------------------------------------------------------------- run
def _run(args: argparse.Namespace) -> int:
    from plugcell.compensation import IdentifiedModel, filter_program

    if args.program is not None:
        from plugcell.apps.commands.compensate_program import run

        return run(args)
    extra = [o for o in ("base", "report", "measure_order") if getattr(args, o)]
    if extra or args.partial or args.dialect or args.joint_targets != "keep" \
            or args.angles != "kuka":
        raise CommandError("--base, --report, --measure-order, --partial, --dialect, "
                           "--joint-targets and --angles go with --program")
    if args.tool is not None and len(args.tool) > 1:
        raise CommandError("--tool: one tool for --targets")
    args.tool = None if args.tool is None else args.tool[0]
    if args.payload_kg is not None and not (math.isfinite(args.payload_kg)
                                            and args.payload_kg >= 0):
        raise CommandError(f"--payload-kg must be a mass ≥ 0 kg, got {args.payload_kg}")
    if not args.tol > 0:
        raise CommandError(f"--tol must be > 0, got {args.tol}")
    result = read_compensation_model(args.params, args, not args.physical_only)
    layer = result.residual_model
    _check_temperature(args, result)
    try:
        text = args.targets.read_text()
    except OSError as exc:
        raise CommandError(f"{args.targets}: cannot read: {exc.strerror or exc}") from None
    try:
        names, pos, ang, pay, lines = parse_targets(text, str(args.targets))
    except ValueError as exc:
        raise CommandError(str(exc)) from None
    user = None if args.user_frame is None else _frame_arg(args.user_frame, "--user-frame",
                                                           args.rot)
    tool = None if args.tool is None else _frame_arg(args.tool, "--tool", args.rot)
    default_m = result.model.payload_ref_kg if args.payload_kg is None else args.payload_kg
    payload = pay if pay is not None else np.full(len(names), default_m)
    model = IdentifiedModel(result.model, tool, residual=layer, temperature_c=args.temperature_c)
    t0 = time.perf_counter()
    res = filter_program(model, pos, ang, args.rot, user_frame=user, payload_kg=payload,
                         tol=args.tol, raise_errors=False)
    dt = time.perf_counter() - t0
    bad = np.flatnonzero(~res.ok)
    if bad.size:
        msgs = [f"{args.targets}: line {lines[k]} ({names[k]}): {res.reason[k]}" for k in bad[:5]]
        more = f"\n... and {bad.size - 5} more" if bad.size > 5 else ""
        raise CommandError(f"{bad.size} of {len(names)} targets cannot be compensated:\n"
                           + "\n".join(msgs) + more)
    notes = _undetermined(args, result, res.q, payload, names, lines, tool)
    region = check_region_of(result, res.q, payload)
    _write(args, result, names, res, payload, region)
    hybrid = ""
    if layer is not None:
        inside = model.in_domain(res.q, payload)
        if res.hybrid_fallback is not None:
            inside &= ~res.hybrid_fallback
        hybrid = (f" + learned residual ({int(inside.sum())} in its trained region, "
                  f"{int((~inside).sum())} physical only)")
    print(f"compensated {len(names)} targets with model {result.config.number} "
          f"({result.config.name}){hybrid} in {dt * 1e3:.1f} ms: at most "
          f"{int(res.iterations.max())} iterations, residual ≤ {float(res.residual.max()):.1e}"
          + ("" if args.out is None else f"; wrote {args.out}"),
          file=sys.stderr if args.out is None else sys.stdout)
    for n in notes:
        print(f"warning: {n}", file=sys.stderr)
    if region is not None and region.count:
        print(f"warning: {region.message('targets')}", file=sys.stderr)
        for k in np.flatnonzero(region.outside)[:5]:
            print(f"  {args.targets}: line {lines[k]} ({names[k]}): {region.reasons(int(k))}",
                  file=sys.stderr)
    return 0


def _check_temperature(args: argparse.Namespace, result: Any) -> None:
    """``--temperature-c`` is needed when the residual model uses the temperature, and
    refused when nothing of the calibration (thermal term, residual model) uses it."""
    from plugcell.calibration.model import THERMAL_KEY

    layer = result.residual_model
    if layer is not None and layer.uses_temperature and args.temperature_c is None:
        raise CommandError(f"{args.params}: its residual model uses the temperature: give "
                           "--temperature-c (or --physical-only)")
    if args.temperature_c is None:
        return
    if not math.isfinite(args.temperature_c):
        raise CommandError(f"--temperature-c must be a temperature in °C, got "
                           f"{args.temperature_c}")
    if THERMAL_KEY not in result.model.space and not (layer is not None
                                                     and layer.uses_temperature):
        raise CommandError(
            f"--temperature-c {args.temperature_c:g}: {args.params} has no thermal term "
            "(calibrate with --thermal and a temperature_c column) and no residual model "
            "that uses the temperature, so it cannot change the compensation; leave it "
            "out")


def _undetermined(args: argparse.Namespace, result: Any, q: np.ndarray, payload: np.ndarray,
                  names: list[str], lines: list[int], tool: np.ndarray | None) -> list[str]:
    """What the calibration poses did not determine (PARAMS.json ``undetermined``) against
    the compensated joints ``q``: with the PROBE position undetermined and no ``--tool``,
    targets whose tool orientation lies beyond the campaign's are refused (the tool point
    would be off by the unknown offset turned by that angle) and the rest get a warning;
    undetermined model parameters give a warning for targets beyond it.  Returns the
    warnings."""
    import math

    und = result.undetermined
    if und is None:
        return []
    m = result.model
    flange = np.linalg.inv(m.base()) @ m.predict(q, payload) @ np.linalg.inv(m.probe())
    angle = und.orientation_offset(flange[:, :3, :3])
    away = und.away(flange[:, :3, :3])
    held = f"the calibration held it within {math.degrees(und.orientation_spread_rad):.2g}°"
    if und.unknown("probe_position") and tool is None:
        if away.any():
            bad = np.flatnonzero(away)
            listed = "\n".join(f"{args.targets}: line {lines[k]} ({names[k]}): tool turned "
                                f"{math.degrees(angle[k]):.2f}° from the calibration's"
                                for k in bad[:5])
            more = f"\n... and {bad.size - 5} more" if bad.size > 5 else ""
            raise CommandError(
                f"{args.params}: the calibration poses did not determine the PROBE position "
                f"({held}); {bad.size} of {len(q)} targets turn the tool away from that "
                "orientation, where the compensated point would be off by the unknown offset: "
                "give the tool point with --tool X,Y,Z,A,B,C (or recalibrate with the "
                f"orientation varied by at least {math.degrees(und.required_spread_rad):.1f}°)"
                f":\n{listed}{more}")
        t = m.probe()[:3, 3] * 1e3
        return [f"the PROBE position was not determined by the calibration poses: the "
                f"compensated point is the kept PROBE ({t[0]:.1f}, {t[1]:.1f}, {t[2]:.1f} mm "
                "in the flange frame), right only for targets registered with the "
                "calibration's BASE (e.g. measured by the tracker) at its tool orientation; "
                "give --tool for any other"]
    if und.parameters and away.any():
        names_p = ", ".join(m.space[k].name for k in und.parameters)
        return [f"{int(away.sum())} of {len(q)} targets turn the tool up to "
                f"{math.degrees(float(angle.max())):.1f}° from the calibration's orientation "
                f"({held}), where parameters the poses did not determine ({names_p}) are "
                "not measured: the model extrapolates there"]
    return []


def _write(args: argparse.Namespace, result: Any, names: list[str], res: Any,
           payload: np.ndarray, region: Any = None) -> None:
    n = res.q.shape[1]
    q = res.q / result.model.structure.source.reading_scale()  # degrees (prismatic: mm)
    buf = io.StringIO()
    buf.write(f"# plugcell compensate: {len(names)} targets from {args.targets.name}, "
              f"parameters {args.params.name} (model {result.config.number}, robot "
              f"{result.robot}), angles {args.rot}\n")
    buf.write("# j1..jn: compensated joint targets (degrees, mm for a prismatic joint); "
              "residual: final ‖Δx‖ of the "
              "model (m, rad)\n")
    extra: list[str] = []
    if region is not None:
        buf.write("# outside_region: 1 where the model extrapolates (docs/planning.md); "
                  "region_distance_mm: to the nearest calibration pose\n")
        extra = ["outside_region", "region_distance_mm"]
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["name", *[f"j{k + 1}" for k in range(n)], "payload_kg", "iterations",
                "residual", *extra])
    for i, nm in enumerate(names):
        more = [] if region is None else [int(region.outside[i]),
                                          f"{region.distance_m[i] * 1e3:.1f}"]
        w.writerow([nm, *[f"{v:.6f}" for v in q[i]], f"{payload[i]:g}",
                    int(res.iterations[i]), f"{res.residual[i]:.2e}", *more])
    if args.out is None:
        sys.stdout.write(buf.getvalue())
        return
    try:
        args.out.write_text(buf.getvalue())
    except OSError as exc:
        raise CommandError(f"{args.out}: cannot write: {exc.strerror or exc}") from None
