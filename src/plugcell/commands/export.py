"""``plugcell export`` — the calibrated robot in a format other tools read.

::

    plugcell export --params PARAMS.json --format urdf|ur-kinematics|toml --out FILE
                    [--include-base] [--include-probe] [--serial-equivalent] [--json]

The robot is the one PARAMS.json records (``robot_source``: the file and xacro
arguments it was loaded from; ``description``: what was calibrated); ``--robot``
(with the URDF options) overrides it.  What the format cannot carry goes into
``FILE.extra.json`` next to it, and the command says so (docs/robot-description.md,
"Export").
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from plugcell.commands.robotargs import add_robot_args


def configure(p: argparse.ArgumentParser) -> None:
    """Add the ``export`` options to its parser (declared in :mod:`plugcell.cli`)."""
    p.description = (
        "Export a calibration (PARAMS.json of plugcell calibrate): 'urdf' (the "
        "source URDF with calibrated joint origins, links/meshes/limits kept), "
        "'ur-kinematics' (default_kinematics.yaml of ur_description) or 'toml' (plugcell's "
        "description with the calibrated values). What the format cannot carry goes into "
        "OUT.extra.json.")
    p.add_argument("--params", type=Path, required=True, help="PARAMS.json of plugcell calibrate")
    p.add_argument("--format", required=True, choices=("urdf", "ur-kinematics", "toml"))
    p.add_argument("--out", type=Path, required=True, help="file to write")
    p.add_argument("--include-base", action="store_true",
                   help="urdf: add BASE as a root link 'measurement' (the tracker frame)")
    p.add_argument("--include-probe", action="store_true",
                   help="urdf: add PROBE (the measured target) as a link 'probe' on the tip")
    p.add_argument("--serial-equivalent", action="store_true",
                   help="loop robot calibrated with --model serial: export its serial chain")
    p.add_argument("--json", action="store_true", help="print a JSON summary")
    add_robot_args(p, help="robot (name, .toml, .urdf, .xacro) instead of the one PARAMS.json "
                   "records")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    from plugcell.calibration.result import CalibrationResult
    from plugcell.cli import CommandError
    from plugcell.commands.robotargs import load_robot_of, robot_source_of
    from plugcell.io.export import ExportError, export_calibration
    from plugcell.io.robots import RobotSource, description_of_params
    from plugcell.kinematics.errors import DescriptionError

    try:
        d = json.loads(args.params.read_text(encoding="utf-8"))
    except OSError as exc:
        raise CommandError(f"{args.params}: cannot read: {exc.strerror or exc}") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise CommandError(f"{args.params}: not valid JSON: {exc}") from None
    if not isinstance(d, dict):
        raise CommandError(f"{args.params}: expected a JSON object written by plugcell calibrate")
    try:
        if args.robot is not None:
            desc = load_robot_of(args)
            source: RobotSource | None = robot_source_of(args)
        else:
            desc = description_of_params(d, str(args.params))
            source = (RobotSource.from_dict(d["robot_source"]) if "robot_source" in d
                      else RobotSource(str(d.get("robot", ""))))
        result = CalibrationResult.from_dict(d, desc)
    except DescriptionError as exc:
        raise CommandError(str(exc)) from None
    except (KeyError, TypeError, ValueError) as exc:
        what = f"missing key {exc}" if isinstance(exc, KeyError) else str(exc)
        raise CommandError(f"{args.params}: not a plugcell calibration: {what}") from None
    try:
        out = export_calibration(result, desc, args.format, source=source,
                                 params_path=args.params.name, include_base=args.include_base,
                                 include_probe=args.include_probe,
                                 serial_equivalent=args.serial_equivalent)
    except ExportError as exc:
        raise CommandError(f"{args.params}: cannot export as {args.format}: {exc}") from None
    except DescriptionError as exc:
        raise CommandError(f"{args.params}: the robot's source URDF: {exc} (give the robot "
                           "again with --robot FILE and its options)") from None
    written = [str(args.out)]
    _write(args.out, out.text)
    side_path = None
    if out.side is not None:
        side_path = args.out.parent / (args.out.name + ".extra.json")
        _write(side_path, json.dumps(out.side, indent=2) + "\n")
        written.append(str(side_path))
    if args.json:
        print(json.dumps({"out": str(args.out), "format": args.format,
                          "side_file": None if side_path is None else str(side_path),
                          "not_in_main_file": (out.side or {}).get("not_in_main_file", []),
                          "notes": list(out.notes)}, indent=2))
        return 0
    print(f"wrote {args.out} ({args.format}, robot {result.robot}, model {result.config.name})")
    for n in out.notes:
        print(f"  note: {n}")
    if out.side is not None:
        print(f"wrote {side_path}: what {args.format} cannot carry —")
        for r in out.side["not_in_main_file"]:
            print(f"  - {r}")
    return 0


def _write(path: Path, text: str) -> None:
    from plugcell.cli import CommandError

    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
    except OSError as exc:
        raise CommandError(f"{path}: cannot write: {exc.strerror or exc}") from None
