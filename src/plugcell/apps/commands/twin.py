"""``plugcell twin``: the digital twin's error budget and simulated measurement campaigns."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from plugcell.apps.cli import CommandError
from plugcell.apps.commands.deprecated import DeprecatedName
from plugcell.apps.commands.progress import ProgressBar
from plugcell.apps.commands.robotargs import add_robot_args
from plugcell.apps.commands.twin_robot import add_robot_sides


def configure(p: argparse.ArgumentParser) -> None:
    """Add the ``twin`` options to its parser (declared in :mod:`plugcell.apps.cli`)."""
    p.description = "The simulated robot whose truth calibration must discover."
    tw = p.add_subparsers(dest="twin_command", metavar="SUBCOMMAND", required=True)
    add_report_parser(tw)
    add_measure_parser(tw)
    add_nests_parser(tw)
    add_robot_sides(tw, add_twin_options, _rsi, _egm)


def add_twin_options(q: argparse.ArgumentParser) -> None:
    """Add the options every ``twin`` subcommand has: the robot, the seed, the scenario."""
    add_robot_args(q, default="smart_h4",
                   help="shipped robot name (default: smart_h4), a description file "
                   "(.toml) or a URDF/xacro file; a robot without a twin profile of its "
                   "own gets an estimated one (docs/twin.md)")
    q.add_argument("--seed", type=int, default=0,
                   help="seed of the twin's hidden errors (default: 0)")
    q.add_argument(
        "--scenario", type=Path, help="scenario JSON file (overrides --robot/--seed)"
    )


def add_report_parser(tw: argparse._SubParsersAction) -> None:
    """Add ``twin report``: the twin's error budget."""
    r = tw.add_parser(
        "report",
        help="the twin's error budget",
        description="Nominal accuracy and deflections of the twin in its working "
        "volume (thesis 8.2): computed, not tabulated.",
    )
    add_twin_options(r)
    r.add_argument("--poses", type=int, default=300, help="random poses (default: 300)")
    r.add_argument("--json", action="store_true", help="print JSON")
    r.set_defaults(func=_report)


def add_measure_parser(tw: argparse._SubParsersAction) -> None:
    """Add ``twin measure``: a simulated calibration campaign into a measurement file."""
    m = tw.add_parser(
        "measure",
        help="simulate a calibration campaign into a measurement file",
        description="Move the twin through random poses in the working volume and "
        "measure each with the simulated laser tracker (1 s).",
    )
    add_twin_options(m)
    add_measure_pose_options(m)
    m.add_argument(
        "--duration",
        type=float,
        default=1.0,
        help="tracker measuring time per pose in s (default: 1)",
    )
    m.add_argument(
        "--rot",
        choices=("rpy", "zyz", "xyz"),
        default="rpy",
        help="orientation convention of rx,ry,rz (default: rpy)",
    )
    m.add_argument("--mode", choices=("6dof", "3dof"), default="6dof",
                   help="measure the T-MAC pose (6dof, default) or the reflector's position "
                        "(3dof)")
    m.add_argument(
        "--temperature-c",
        metavar="T|FROM:TO",
        help="the hall's temperature (°C) during the campaign, one value or a linear sweep "
        "FROM:TO over the poses: the twin's cell drifts with it (arm lengths, BASE; "
        "docs/twin.md) and the file gets a temperature_c column (calibrate --thermal)",
    )
    m.add_argument("--out", type=Path, required=True, help="measurement CSV to write")
    m.add_argument("--quiet", action="store_true", help="no progress output")
    m.set_defaults(func=_measure)


def add_measure_pose_options(q: argparse.ArgumentParser) -> None:
    """Add which poses ``twin measure`` measures (random, a scan or a plan), their payload
    and the seed of their draw."""
    which = q.add_mutually_exclusive_group(required=True)
    which.add_argument("--poses", type=int, help="number of random poses in the working volume")
    which.add_argument("--scan", type=int, metavar="N",
                       help="N poses of a surface scan: a horizontal patch of the working "
                            "volume at one constant tool orientation")
    which.add_argument("--plan", type=Path, metavar="PLAN.csv",
                       help="measure the poses of a plan file (plugcell plan), each with its "
                            "payload; --payload-kg is the payload of rows without one")
    q.add_argument(
        "--payload-kg",
        "--payload",
        dest="payload",
        action=DeprecatedName,
        old=("--payload",),
        type=float,
        default=0.0,
        metavar="KG",
        help="payload mass in kg (default: 0), mounted off the flange centre (as calibrate's "
             "and compensate's --payload-kg; --payload is its old name)",
    )
    q.add_argument(
        "--pose-seed",
        type=int,
        default=None,
        help="seed of the pose draw (default: --seed + 1); use another for validation",
    )


def add_nests_parser(tw: argparse._SubParsersAction) -> None:
    """Add ``twin nests``: the cell's reference nests measured by the simulated tracker."""
    n = tw.add_parser(
        "nests",
        help="measure the cell's reference nests (drift register / drift check)",
        description="Measure the reference nests fixed to the twin's foundation with the "
        "simulated tracker (3-DOF, tracker frame): the file drift register and drift check "
        "read.  At another --temperature-c the twin's BASE has drifted.",
    )
    add_twin_options(n)
    n.add_argument("--temperature-c", type=float, default=None, metavar="T",
                   help="the hall's temperature (°C; default: the reference 20 °C, no drift)")
    n.add_argument("--out", type=Path, required=True, help="nest file to write: name,x,y,z (mm)")
    n.set_defaults(func=_nests)


def _scenario(args: argparse.Namespace):
    from plugcell.apps.commands.robotargs import load_robot_of, robot_source_of
    from plugcell.io.robot_schema import description_to_dict
    from plugcell.kinematics.errors import DescriptionError
    from plugcell.sim.twin.scenario import ScenarioError, TwinScenario

    try:
        if args.scenario is not None:
            try:
                return TwinScenario.from_json(args.scenario.read_text())
            except OSError as exc:
                raise CommandError(f"{args.scenario}: cannot read: {exc.strerror}") from None
        source = robot_source_of(args)
        if source.is_urdf:  # the scenario carries the imported description itself
            desc = load_robot_of(args)
            return TwinScenario(robot=desc.name, seed=args.seed,
                                description=description_to_dict(desc))
        if any((source.args, source.package_paths, source.base_link, source.tip_link)):
            source.load()  # the options apply to URDF robots only: say so
        return TwinScenario(robot=args.robot, seed=args.seed)
    except (ScenarioError, DescriptionError) as exc:
        raise CommandError(str(exc)) from None


def _rsi(args: argparse.Namespace) -> int:
    from plugcell.apps.commands.twin_robot import run_rsi

    return run_rsi(args, _scenario(args))


def _egm(args: argparse.Namespace) -> int:
    from plugcell.apps.commands.twin_robot import run_egm

    return run_egm(args, _scenario(args))


#: The robot the thesis's figures (4.03 mm, 0.5/1.0 mm deflection, …) were measured on.
THESIS_ROBOT = "smart_h4"


def _report(args: argparse.Namespace) -> int:
    from plugcell.sim.twin.report import error_budget
    from plugcell.sim.twin.scenario import ScenarioError

    if args.poses < 10:
        raise CommandError(f"--poses must be at least 10, got {args.poses}")
    scenario = _scenario(args)
    bar = None if args.json else ProgressBar("error budget")
    try:
        budget = error_budget(scenario, poses=args.poses, progress=bar)
    except ScenarioError as exc:
        raise CommandError(str(exc)) from None
    if args.json:
        print(json.dumps(budget.as_dict(), indent=2))
        return 0
    rows = [
        ("nominal position error, mean (unloaded)", budget.nominal_mean_mm, "mm", "4.03"),
        ("nominal position error, max", budget.nominal_max_mm, "mm", ""),
        ("  geometric errors alone, mean", budget.geometric_only_mean_mm, "mm", ""),
        ("  reducer transmission error alone, mean", budget.transmission_only_mean_mm, "mm", ""),
        ("  link-mass deflection alone, mean", budget.gravity_only_mean_mm, "mm", ""),
        ("payload deflection 18 kg, mean", budget.deflection_18kg_mm, "mm", "0.5"),
        ("payload deflection 36 kg, mean", budget.deflection_36kg_mm, "mm", "1.0"),
        ("  share of link bending (36 kg)", 100 * budget.bending_share_36kg, "%", "~20"),
        ("repeatability, 1-σ per axis", budget.repeatability_sigma_mm, "mm", "res. ~0.05"),
        ("nominal orientation error, mean", budget.orientation_nominal_mean_deg, "deg", ""),
    ]
    print(
        f"Twin of {budget.robot} (seed {budget.seed}), {budget.poses} poses in the working volume"
    )
    if budget.robot != THESIS_ROBOT:  # the thesis measured the Smart H4 only
        print(f"{'':42s} {'twin':>10s}")
        for label, value, unit, _ in rows:
            print(f"{label:42s} {value:10.3f} {unit}")
        print(f"(the thesis's figures are of the {THESIS_ROBOT}: not shown for {budget.robot})")
        return 0
    print(f"{'':42s} {'twin':>10s}      {'thesis':>10s}")
    for label, value, unit, thesis in rows:
        print(f"{label:42s} {value:10.3f} {unit:4s} {thesis:>10s}")
    return 0


def _measure(args: argparse.Namespace) -> int:
    from plugcell.io.measurements import write_measurements
    from plugcell.sim.twin.campaign import (
        CampaignError,
        surface_scan_joints,
        working_volume_joints,
    )
    from plugcell.sim.twin.robot import RobotTwin
    from plugcell.sim.twin.scenario import ScenarioError
    from plugcell.sim.twin.thermal import ThermalDrift
    from plugcell.sim.twin.tracker import LaserTracker, TrackerError

    for opt in ("poses", "scan"):
        if getattr(args, opt) is not None and getattr(args, opt) < 1:
            raise CommandError(f"--{opt} must be positive, got {getattr(args, opt)}")
    if not (np.isfinite(args.payload) and args.payload >= 0):
        raise CommandError(f"--payload-kg must be a mass ≥ 0 kg, got {args.payload}")
    scenario = _scenario(args).with_payload(args.payload)
    pose_seed = scenario.seed + 1 if args.pose_seed is None else args.pose_seed
    try:
        robot = RobotTwin(scenario)
        tracker_seed = scenario.tracker_seed if scenario.tracker_seed is not None else scenario.seed
        tracker = LaserTracker(seed=tracker_seed)
        if args.plan is not None:
            joints, payloads = _plan_joints(args.plan, robot.description, args.payload)
        elif args.scan is not None:
            joints = surface_scan_joints(robot.description, robot.reveal_truth().profile,
                                         args.scan, np.random.default_rng(pose_seed))
            payloads = np.full(len(joints), args.payload)
        else:
            joints = working_volume_joints(
                robot.description,
                robot.reveal_truth().profile,
                args.poses,
                np.random.default_rng(pose_seed),
            )
            payloads = np.full(len(joints), args.payload)
        temperatures = _temperatures(args.temperature_c, len(joints))
        if temperatures is not None:
            robot.set_thermal_drift(ThermalDrift())
        bar = None if args.quiet else ProgressBar("measuring", stream=sys.stderr)
        data, sim_s = _measure_groups(scenario, robot, tracker, joints, payloads, args, bar,
                                      temperatures)
    except (ScenarioError, CampaignError, TrackerError, ValueError) as exc:
        raise CommandError(str(exc)) from None
    what = (f"{len(joints)} poses of plan {args.plan}" if args.plan is not None
            else f"{len(joints)} {'scan ' if args.scan else ''}poses, payload "
                 f"{args.payload:g} kg, pose seed {pose_seed}, {args.mode}")
    if temperatures is not None:
        what += f", hall at {args.temperature_c} °C"
    comments = [
        f"plugcell twin measure: robot {scenario.robot}, {what}",
        f"scenario: {scenario.to_json()}",
        f"simulated campaign time: {sim_s:.0f} s",
    ]
    try:
        write_measurements(args.out, data, comments=comments,
                           joint_scale=robot.description.reading_scale())
    except OSError as exc:
        raise CommandError(f"{args.out}: cannot write: {exc.strerror}") from None
    if not args.quiet:
        print(
            f"wrote {len(data)} poses to {args.out} (simulated time {sim_s / 60:.1f} min)",
            file=sys.stderr,
        )
    return 0


def _plan_joints(path: Path, desc: Any, default_payload: float) -> tuple[np.ndarray, np.ndarray]:
    """Joint targets and payloads of a plan file, checked against the robot's limits."""
    from plugcell.io.plans import PlanFileError, read_plan

    try:
        plan = read_plan(path, n_joints=desc.n_actuated, joint_scale=desc.reading_scale())
    except PlanFileError as exc:
        raise CommandError(str(exc)) from None
    bad = np.flatnonzero(~desc.within_limits(plan.joints))
    if bad.size:
        raise CommandError(f"{path}: {bad.size} row(s) outside the joint or coupled limits of "
                           f"{desc.name}, the first is row {int(bad[0]) + 1}")
    m = plan.payload_kg if plan.payload_kg is not None else np.full(len(plan), default_payload)
    return plan.joints, m


def _temperatures(text: str | None, n: int) -> np.ndarray | None:
    """``--temperature-c``: ``T`` or ``FROM:TO`` → the (n,) temperatures (°C), linear over
    the poses; ``None`` without the option."""
    if text is None:
        return None
    parts = text.split(":")
    try:
        values = [float(p) for p in parts]
    except ValueError:
        values = []
    if len(values) not in (1, 2) or not all(np.isfinite(values)):
        raise CommandError(f"--temperature-c must be T or FROM:TO in °C, got {text!r}")
    if any(not -50.0 <= v <= 100.0 for v in values):
        raise CommandError(f"--temperature-c {text}: a hall temperature in °C is within "
                           "-50…100 (a value in kelvin?)")
    return np.linspace(values[0], values[-1], n)


def _nests(args: argparse.Namespace) -> int:
    from plugcell.apps.commands.files import write_text
    from plugcell.io.nests import format_nests
    from plugcell.sim.twin.campaign import REFERENCE_NESTS, measure_nests
    from plugcell.sim.twin.robot import RobotTwin
    from plugcell.sim.twin.scenario import ScenarioError
    from plugcell.sim.twin.thermal import ThermalDrift
    from plugcell.sim.twin.tracker import LaserTracker

    scenario = _scenario(args)
    try:
        robot = RobotTwin(scenario)
    except ScenarioError as exc:
        raise CommandError(str(exc)) from None
    drift = ThermalDrift()
    t = drift.reference_c if args.temperature_c is None else args.temperature_c
    _temperatures(str(t), 1)  # the same check as twin measure's
    robot.set_thermal_drift(drift, t)
    tracker_seed = scenario.tracker_seed if scenario.tracker_seed is not None else scenario.seed
    measured = measure_nests(robot, LaserTracker(seed=tracker_seed))
    names = [f"N{k + 1}" for k in range(len(REFERENCE_NESTS))]
    write_text(args.out, format_nests(names, measured, (
        f"plugcell twin nests: robot {scenario.robot}, seed {scenario.seed}, hall at "
        f"{t:g} °C; tracker frame (mm)",)))
    print(f"wrote {len(names)} nests to {args.out} (hall at {t:g} °C)", file=sys.stderr)
    return 0


def _measure_groups(scenario: Any, robot: Any, tracker: Any, joints: np.ndarray,
                    payloads: np.ndarray, args: argparse.Namespace, bar: Any,
                    temperatures: np.ndarray | None = None):
    """Measure ``joints`` in order, changing the payload between runs of equal payload
    (the same robot — its hidden errors — carrying another mass)."""
    from plugcell.io.measurements import MeasurementSet
    from plugcell.sim.twin.campaign import measure_poses
    from plugcell.sim.twin.robot import RobotTwin

    change = np.flatnonzero(np.diff(payloads) != 0) + 1
    starts = np.r_[0, change]
    ends = np.r_[change, len(joints)]
    parts, sim_total = [], 0.0
    for s, e in zip(starts, ends, strict=True):
        m = float(payloads[s])
        twin = robot if m == robot.payload.mass else RobotTwin(scenario.with_payload(m))
        if twin is not robot and temperatures is not None:
            from plugcell.sim.twin.thermal import ThermalDrift

            twin.set_thermal_drift(ThermalDrift())

        def progress(i: int, n: int, s: int = int(s)) -> None:
            if bar is not None:
                bar(s + i, len(joints))

        data, sim_s = measure_poses(twin, tracker, joints[s:e], duration_s=args.duration,
                                    rotation=args.rot, progress=progress,
                                    mode=getattr(args, "mode", "6dof"),
                                    temperatures_c=None if temperatures is None
                                    else temperatures[s:e])
        parts.append(data)
        sim_total += sim_s
    if len(parts) == 1:
        return parts[0], sim_total
    return MeasurementSet(
        np.concatenate([p.joints for p in parts]), np.concatenate([p.positions for p in parts]),
        None if parts[0].angles is None else np.concatenate([p.angles for p in parts]),
        parts[0].rotation,
        np.concatenate([p.payload_kg for p in parts]),
        None if temperatures is None else np.asarray(temperatures, dtype=float)), sim_total
