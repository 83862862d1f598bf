"""``plugcell demo``: the main job on the embedded default (simulated devices).

It runs, in order, what plugcell can do end to end today and says where each
result went:

1. the digital twin's error budget (``plugcell twin report``);
2. a simulated calibration campaign of the Smart H4 twin carrying 36 kg — 150
   tracker measurements of 1 s in the working volume — and an independent
   validation campaign (``plugcell twin measure``);
3. when the calibration engine is installed, model 5 identified from the
   campaign and checked on the validation poses.

The full thesis demonstration over services (issue 9) grows into this command.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from plugcell.commands.progress import ProgressBar


def register(sub: Any) -> None:
    p = sub.add_parser(
        "demo", help="run the main job on simulated devices", description=__doc__.split("\n\n")[0]
    )
    p.add_argument(
        "--out",
        type=Path,
        default=Path("out/demo"),
        help="directory for the files it writes (default: out/demo)",
    )
    p.add_argument("--fast", action="store_true", help="fewer poses (what CI runs)")
    p.add_argument("--seed", type=int, default=0, help="seed of the twin (default: 0)")
    p.add_argument("--json", action="store_true", help="print the final table as JSON")
    p.set_defaults(func=_demo)


def _say(args: argparse.Namespace, text: str) -> None:
    if not args.json:
        print(text, flush=True)


def _demo(args: argparse.Namespace) -> int:
    from plugcell.cli import CommandError
    from plugcell.io.measurements import write_measurements
    from plugcell.twin.campaign import measure_poses, working_volume_joints
    from plugcell.twin.report import error_budget
    from plugcell.twin.robot import RobotTwin
    from plugcell.twin.scenario import TwinScenario
    from plugcell.twin.tracker import LaserTracker

    try:
        args.out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise CommandError(f"{args.out}: cannot create: {exc.strerror}") from None
    n_cal, n_val = (40, 20) if args.fast else (150, 60)
    t0 = time.monotonic()
    result: dict[str, Any] = {
        "seed": args.seed,
        "poses": {"calibration": n_cal, "validation": n_val},
    }

    _say(args, "== 1. The digital twin of the Smart H4 (error budget) ==")
    scenario = TwinScenario(robot="smart_h4", seed=args.seed)
    budget = error_budget(scenario, poses=100 if args.fast else 300)
    result["twin"] = budget.as_dict()
    _say(
        args,
        f"   nominal position error: mean {budget.nominal_mean_mm:.2f} mm "
        f"(thesis 4.03), max {budget.nominal_max_mm:.2f} mm",
    )
    _say(
        args,
        f"   payload deflection: {budget.deflection_18kg_mm:.2f} mm at 18 kg (thesis 0.5), "
        f"{budget.deflection_36kg_mm:.2f} mm at 36 kg (thesis 1.0)",
    )

    _say(args, f"== 2. Calibration campaign: {n_cal} poses, 36 kg, 1 s tracker measurements ==")
    loaded = scenario.with_payload(36.0)
    robot = RobotTwin(loaded)
    tracker = LaserTracker(seed=args.seed)
    profile = robot.reveal_truth().profile  # pose *planning* only: the working volume spread
    files = {}
    sim_total = 0.0
    for name, n, pose_seed in (("calibration", n_cal, 1), ("validation", n_val, 2)):
        joints = working_volume_joints(
            robot.description, profile, n, np.random.default_rng(1000 * args.seed + pose_seed)
        )
        bar = None if args.json else ProgressBar(f"   {name}", stream=sys.stdout)
        data, sim_s = measure_poses(robot, tracker, joints, progress=bar)
        sim_total += sim_s
        path = args.out / f"{name}.csv"
        write_measurements(path, data, comments=[f"plugcell demo {name} set, seed {args.seed}"])
        files[name] = str(path)
        _say(args, f"   wrote {path} ({n} poses, {sim_s / 60:.1f} min simulated)")
    result["files"] = files
    result["simulated_time_s"] = sim_total

    if importlib.util.find_spec("plugcell.commands.calibrate") is not None:
        _say(args, "== 3. Identification of model 5 (52 parameters) ==")
        from plugcell.cli import main as cli_main

        params = args.out / "params.json"
        code = cli_main(
            [
                "calibrate",
                "--robot",
                "smart_h4",
                "--model",
                "5",
                "--data",
                files["calibration"],
                "--validate",
                files["validation"],
                "--out",
                str(params),
            ]
        )
        if code != 0:
            raise CommandError("calibration failed (see above)")
        result["calibration"] = json.loads(params.read_text())
        for key in ("calibration", "validation"):
            stats = result["calibration"].get(key, {})
            if "mean_mm" in stats:
                _say(
                    args, f"   {key}: mean {stats['mean_mm']:.3f} mm, max {stats['max_mm']:.3f} mm"
                )
    else:
        _say(args, "== 3. (calibration engine not installed yet: skipped) ==")

    result["wall_time_s"] = time.monotonic() - t0
    (args.out / "demo.json").write_text(json.dumps(result, indent=2, default=float))
    if args.json:
        print(json.dumps(result, indent=2, default=float))
    else:
        print(
            f"done in {result['wall_time_s']:.1f} s wall, {sim_total / 60:.1f} min simulated; "
            f"results in {args.out}/demo.json"
        )
    return 0
