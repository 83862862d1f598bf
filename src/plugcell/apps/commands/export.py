"""``plugcell export`` — the calibrated robot in a format other tools read.

::

    plugcell export --params PARAMS.json --format urdf|ur-kinematics|toml --out FILE
                    [--include-base] [--include-probe] [--serial-equivalent]
                    [--probe X,Y,Z,R,P,Y|FILE.json] [--json]

The robot is the one PARAMS.json records (``robot_source``: the file and xacro
arguments it was loaded from; ``description``: what was calibrated); ``--robot``
(with the URDF options) overrides it.  What the format cannot carry goes into
``FILE.extra.json`` next to it, and the command says so (docs/urdf.md, "Export").  A
loop robot (Smart H4) is exact as ``toml`` (a ``fourbar`` loop); its ``urdf`` is the
closest tree, whose worst error the command prints.  A calibration whose poses did not
determine the PROBE position (PARAMS.json ``undetermined``, e.g. a scan at constant tool
orientation) is refused unless ``--probe`` gives the target in the flange frame
(docs/calibration.md, *Identifiability*).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from plugcell.apps.cli import CommandError
from plugcell.apps.commands.files import write_text
from plugcell.apps.commands.robotargs import add_robot_args


def configure(p: argparse.ArgumentParser) -> None:
    """Add the ``export`` options to its parser (declared in :mod:`plugcell.apps.cli`)."""
    p.description = (
        "Export a calibration (PARAMS.json of plugcell calibrate): 'urdf' (the "
        "source URDF with calibrated joint origins, links/meshes/limits kept), "
        "'ur-kinematics' (default_kinematics.yaml of ur_description, UR arms only) or 'toml' "
        "(plugcell's description with the calibrated values, exact also for a loop robot). "
        "A loop robot's URDF is its closest tree, with its worst error printed and in the "
        "file. What the format cannot carry goes into OUT.extra.json.")
    p.add_argument("--params", type=Path, required=True, help="PARAMS.json of plugcell calibrate")
    p.add_argument("--format", required=True, choices=("urdf", "ur-kinematics", "toml"))
    p.add_argument("--out", type=Path, required=True, help="file to write")
    p.add_argument("--include-base", action="store_true",
                   help="urdf: add BASE as a root link 'measurement' (the tracker frame)")
    p.add_argument("--include-probe", action="store_true",
                   help="urdf: add PROBE (the measured target) as a link 'probe' on the tip")
    p.add_argument("--serial-equivalent", action="store_true",
                   help="loop robot calibrated with --model serial: export its serial chain")
    p.add_argument("--probe", metavar="X,Y,Z,R,P,Y|FILE.json",
                   help="the target (tool point) in the flange frame (mm, fixed-axis degrees, or "
                   "a JSON file as calibrate --probe) instead of the calibrated PROBE; needed "
                   "when the calibration poses did not determine the PROBE position")
    p.add_argument("--json", action="store_true", help="print a JSON summary")
    add_robot_args(p, help="robot (name, .toml, .urdf, .xacro) instead of the one PARAMS.json "
                   "records")
    p.set_defaults(func=_run)


#: The file name endings of each format (the first is the one to suggest).
EXTENSIONS = {"urdf": (".urdf", ".xml"), "ur-kinematics": (".yaml", ".yml"),
              "toml": (".toml",)}


def _check_extension(out: Path, fmt: str) -> None:
    """Refuse ``--out`` named for another format (``x.yaml`` with ``--format urdf``)."""
    suffix = out.suffix.lower()
    if suffix in EXTENSIONS[fmt]:
        return
    other = next((f for f, ends in EXTENSIONS.items() if suffix in ends), None)
    if other is not None:
        raise CommandError(f"--out {out}: a {suffix} file is --format {other}, not {fmt}: "
                           f"name it {out.with_suffix(EXTENSIONS[fmt][0]).name} or give "
                           f"--format {other}")
    print(f"warning: --out {out}: a {fmt} file usually ends in {EXTENSIONS[fmt][0]}",
          file=sys.stderr)


def _run(args: argparse.Namespace) -> int:
    from plugcell.apps.commands.calibrate import _frame
    from plugcell.apps.commands.files import read_calibration
    from plugcell.apps.commands.robotargs import robot_source_of
    from plugcell.io.export import ExportError, export_calibration
    from plugcell.io.robots import RobotSource
    from plugcell.kinematics.errors import DescriptionError

    _check_extension(args.out, args.format)
    d, result = read_calibration(args.params, args)
    if args.robot is not None:
        source: RobotSource | None = robot_source_of(args)
    else:
        try:
            source = (RobotSource.from_dict(d["robot_source"]) if "robot_source" in d
                      else RobotSource(str(d.get("robot", ""))))
        except DescriptionError as exc:
            raise CommandError(f"{args.params}: {exc}") from None
    desc = result.model.structure.source
    try:
        out = export_calibration(result, desc, args.format, source=source,
                                 params_path=args.params.name, include_base=args.include_base,
                                 include_probe=args.include_probe,
                                 serial_equivalent=args.serial_equivalent,
                                 residual_model=d.get("residual_model") or None,
                                 probe=None if args.probe is None else _frame(args.probe, "probe"))
    except ExportError as exc:
        raise CommandError(f"{args.params}: cannot export as {args.format}: {exc}") from None
    except DescriptionError as exc:
        raise CommandError(f"{args.params}: the robot's source URDF: {exc} (give the robot "
                           "again with --robot FILE and its options)") from None
    written = [str(args.out)]
    write_text(args.out, out.text)
    side_path = None
    if out.side is not None:
        side_path = args.out.parent / (args.out.name + ".extra.json")
        write_text(side_path, json.dumps(out.side, indent=2) + "\n")
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

