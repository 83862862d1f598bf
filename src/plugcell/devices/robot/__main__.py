"""``python -m plugcell.devices.robot``: the robot service's legacy command line.

A program, not a library: ``plugcell serve robot`` with the flags of issue 6
(``--sim``/``--line``, ``--robot``, ``--payload-kg``, ``--speed``, ...),
translated into its ``--param`` options and run by the ``plugcell`` command line.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from plugcell.apps.commands.deprecated import DeprecatedName
from plugcell.apps.commands.robotargs import add_robot_args, robot_source_of


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m plugcell.devices.robot --name R --sim [...]``: ``plugcell serve robot``
    with the flags of issue 6, translated into its ``--param`` options."""
    p = argparse.ArgumentParser(
        prog="python -m plugcell.devices.robot",
        description="Run the robot service (thesis 7.2) with a simulated or a real controller.",
    )
    p.add_argument("--name", default=None, help="service name (default ROBOT)")
    how = p.add_mutually_exclusive_group(required=True)
    how.add_argument("--sim", action="store_true", help="start a simulated controller (twin)")
    how.add_argument("--line", "--controller", dest="line", action=DeprecatedName,
                     old=("--controller",), metavar="HOST:PORT",
                     help="connect to a real controller over the line protocol "
                     "(--controller is its old name)")
    add_robot_args(p, default="smart_h4",
                   help="robot of the simulated controller: name, .toml or URDF/xacro file")
    p.add_argument("--payload-kg", type=float, default=0.0)
    p.add_argument("--speed", type=float, default=1.0, help="simulated seconds per real second")
    p.add_argument("--seed", type=int, default=0, help="twin seed of the simulated controller")
    p.add_argument("--library", action="append", default=[], help="folder of robot programs")
    p.add_argument("--cell", default=None)
    p.add_argument("--no-journal", action="store_true")
    p.add_argument("--log-level", default="WARNING")
    args = p.parse_args(argv)
    forward = ["serve", "robot", "--log-level", args.log_level]
    if args.name:
        forward += ["--name", args.name]
    if args.cell:
        forward += ["--cell", args.cell]
    if args.no_journal:
        forward.append("--no-journal")
    params = {"sim": "true"} if args.sim else {"line": args.line}
    if args.sim:
        forward += robot_source_of(args).argv()  # --robot and its URDF options, as given
        params.update(payload_kg=repr(args.payload_kg), speed=repr(args.speed),
                      seed=str(args.seed))
    if args.library:
        params["library"] = ",".join(args.library)
    for key, value in params.items():
        forward += ["--param", f"{key}={value}"]
    from plugcell.apps.cli import main as cli_main

    return cli_main(forward)



if __name__ == "__main__":
    sys.exit(main())
