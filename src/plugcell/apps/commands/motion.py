"""``plugcell motion`` — plan a robot's moves and write the sampled trajectory.

::

    plugcell motion plan --robot elbow6 --moves pick.moves [--start 10,-80,20,30,60,-20]
        [--cycle 0.004] [--out path.csv] [--joint-speed 120] [--speed 1000] …

The moves file (:mod:`plugcell.io.moves`) holds PTP, LIN and CIRC moves in robot units;
the trajectory (:mod:`plugcell.motion`) is checked before anything is written — joint
limits, joint speeds, singularities, reachability — and an error names the move's line.
The CSV has one row per interpolation cycle: ``t_s``, the joints ``j1..jn`` (degrees; a
prismatic joint: mm), the TCP ``x_mm, y_mm, z_mm, a_deg, b_deg, c_deg`` (the robot's
angle convention), the running ``move`` (its file line).  The limits are options in
robot units; their defaults are plausible for a 200 kg-class arm (our estimates, not a
vendor's machine data) — give your robot's.
"""

from __future__ import annotations

import argparse
import csv
import io
import math
import sys

import numpy as np

from plugcell.apps.cli import CommandError
from plugcell.apps.commands.robotargs import add_robot_args, load_robot_of
from plugcell.apps.commands.subcommands import add_subcommands
from plugcell.io.moves import MovesFileError, read_moves
from plugcell.io.units import robot_from_pose
from plugcell.motion import CartesianLimits, JointLimits, TrajectoryError, plan

#: Default limits (robot units): per joint °/s, °/s², °/s³; the TCP mm/s…, °/s….
DEFAULTS = {"joint_speed": 120.0, "joint_acc": 400.0, "joint_jerk": 3000.0,
            "speed": 1000.0, "acc": 4000.0, "jerk": 40000.0,
            "angular_speed": 120.0, "angular_acc": 460.0, "angular_jerk": 4600.0}


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the ``motion`` sub-commands to its parser (declared in :mod:`plugcell.apps.cli`)."""
    sub = add_subcommands(
        parser, "Trajectories: plan moves with limits and blends (docs/motion.md).",
        "motion_command")
    p = sub.add_parser(
        "plan", help="check a moves file and write its trajectory sampled every cycle (CSV)",
        description="Plan the moves of a moves file (PTP, LIN, CIRC; docs/motion.md), check "
        "them before motion and write the joints and the TCP at every interpolation cycle.")
    add_robot_args(p, required=True)
    p.add_argument("--moves", required=True, metavar="FILE", help="the moves file")
    p.add_argument("--start", metavar="J1,…,JN",
                   help="joint readings at the start, degrees (default: the robot's home)")
    p.add_argument("--cycle", type=float, default=0.004, metavar="S",
                   help="interpolation cycle, s (default 0.004, KUKA RSI's #IPO_FAST)")
    p.add_argument("--out", metavar="FILE", help="CSV file to write (default: stdout)")
    for key, unit, what in (
            ("joint_speed", "°/s", "joint speed limit"),
            ("joint_acc", "°/s²", "joint acceleration limit"),
            ("joint_jerk", "°/s³", "joint jerk limit"),
            ("speed", "mm/s", "TCP speed limit"), ("acc", "mm/s²", "TCP acceleration limit"),
            ("jerk", "mm/s³", "TCP jerk limit"),
            ("angular_speed", "°/s", "TCP angular speed limit"),
            ("angular_acc", "°/s²", "TCP angular acceleration limit"),
            ("angular_jerk", "°/s³", "TCP angular jerk limit")):
        per_joint = key.startswith("joint")
        p.add_argument("--" + key.replace("_", "-"), default=str(DEFAULTS[key]),
                       metavar="V[,…]" if per_joint else "V",
                       help=f"{what}, {unit}{' (one value, or one per joint)' if per_joint else ''}"
                       f" (default {DEFAULTS[key]:g})")
    p.set_defaults(func=_cmd_plan)


def _values(text: str, option: str, n: int | None) -> np.ndarray:
    try:
        vals = np.array([float(v) for v in text.split(",")])
    except ValueError:
        raise CommandError(f"{option}: expected numbers, got {text!r}") from None
    if n is not None and vals.size == 1:
        vals = np.full(n, vals[0])
    if n is not None and vals.size != n:
        raise CommandError(f"{option}: expected 1 or {n} values, got {vals.size}")
    if not np.all(np.isfinite(vals)) or not np.all(vals > 0):
        raise CommandError(f"{option}: values must be positive, got {text!r}")
    return vals


def _limits(args: argparse.Namespace, n: int, scale: np.ndarray
            ) -> tuple[JointLimits, CartesianLimits]:
    joint = JointLimits(*(_values(getattr(args, k), "--" + k.replace("_", "-"), n) * scale
                          for k in ("joint_speed", "joint_acc", "joint_jerk")))
    lin = [float(_values(getattr(args, k), "--" + k, None)[0]) * 1e-3
           for k in ("speed", "acc", "jerk")]
    ang = [math.radians(float(_values(getattr(args, k), "--" + k.replace("_", "-"), None)[0]))
           for k in ("angular_speed", "angular_acc", "angular_jerk")]
    return joint, CartesianLimits(*lin, *ang)


def _cmd_plan(args: argparse.Namespace) -> int:
    desc = load_robot_of(args)
    n = desc.n_readings
    scale = desc.reading_scale()
    if not (math.isfinite(args.cycle) and args.cycle > 0):
        raise CommandError(f"--cycle must be a positive number of seconds, got {args.cycle}")
    if args.start is None:
        q0 = np.asarray(desc.home, dtype=float)
    else:
        try:
            start = np.array([float(v) for v in args.start.split(",")])
        except ValueError:
            raise CommandError(f"--start: expected {n} numbers, got {args.start!r}") from None
        if start.size != n or not np.all(np.isfinite(start)):
            raise CommandError(f"--start: expected {n} finite joint values for {desc.name} "
                         f"({', '.join(desc.reading_names)}), got {args.start!r}")
        q0 = start * scale
    joint, cart = _limits(args, n, scale)
    try:
        moves = read_moves(args.moves, desc)
    except MovesFileError as exc:
        raise CommandError(str(exc)) from None
    try:
        traj = plan(desc, q0, moves, joint, cart)
    except TrajectoryError as exc:
        raise CommandError(f"{args.moves}: {exc}") from None
    t = traj.cycle_times(args.cycle)
    sample = traj.sample(t, 0)
    tcp = traj.tcp(t)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["t_s", *(f"j{i + 1}" for i in range(n)), "x_mm", "y_mm", "z_mm", "a_deg",
                "b_deg", "c_deg", "move_line"])
    joints = sample.q / scale
    for i in range(t.size):
        pose = robot_from_pose(tcp[i])
        line = moves[int(sample.move[i])].line
        w.writerow([f"{t[i]:.6f}", *(f"{v:.9g}" for v in joints[i]),
                    *(f"{v:.9g}" for v in pose), line if line is not None else ""])
    if args.out:
        try:
            with open(args.out, "w", encoding="utf-8", newline="") as fh:
                fh.write(buf.getvalue())
        except OSError as exc:
            raise CommandError(f"--out {args.out}: {exc.strerror or exc}") from None
        stops = [moves[k].line for k, d in traj.blends.items() if d == 0.0]
        print(f"{desc.name}: {len(moves)} moves, {traj.duration:.3f} s, {t.size} cycles of "
              f"{args.cycle * 1e3:g} ms → {args.out}"
              + (f"; blends that stop exactly (limits): lines {stops}" if stops else ""),
              file=sys.stderr)
    else:
        sys.stdout.write(buf.getvalue())
    return 0
