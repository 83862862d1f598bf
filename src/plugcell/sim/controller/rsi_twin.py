"""``python -m plugcell.sim.controller.rsi_twin``: the twin as a KUKA robot streaming RSI.

A process that stands where a KUKA controller running plugcell's KRL program
(``plugcell rsi files``) stands: the dynamic twin (:class:`~plugcell.sim.twin.dynamics.
DynamicTwin`) behind the RSI robot side (:class:`~.rsi_robot.RsiRobot`), which sends its
``<Rob>`` packets to the sensor's address every cycle from ``RSI_ON`` on and applies the
answers.  It prints one line with its own address, then runs until SIGTERM/SIGINT or until
RSI stops (``Timeout`` late answers: exit status 3 with the reason, as the real controller
breaks off).

``python -m plugcell.sim.controller.rsi_twin --sensor 127.0.0.1:49152 [--robot smart_h4]
[--payload-kg M] [--seed S] [--mode absolute] [--timeout 100] [--bind HOST:PORT]``
"""

from __future__ import annotations

import sys
from collections.abc import Sequence

from plugcell.sim.controller.twin_process import TwinProcess, run_twin, twin_parser

__all__ = ["RsiTwinProcess", "main"]

PREFIX = "rsi-twin:"


class RsiTwinProcess(TwinProcess):
    """The twin's RSI side in a process of its own: ``RsiTwinProcess(sensor, *options)``."""

    def __init__(self, sensor: str, *options: str) -> None:
        super().__init__("plugcell.sim.controller.rsi_twin", PREFIX, sensor, *options)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the twin's RSI robot side (module docstring); the exit status."""
    p = twin_parser("python -m plugcell.sim.controller.rsi_twin",
                    "The dynamic twin as a KUKA controller streaming RSI to plugcell's "
                    "sensor side.")
    p.add_argument("--mode", choices=("absolute", "relative"), default="absolute",
                   help="RSI_ON(#ABSOLUTE) or #RELATIVE joint corrections (default absolute)")
    p.add_argument("--timeout", type=int, default=100,
                   help="the ETHERNET object's Timeout (late packets)")
    args = p.parse_args(argv)

    def make(sensor: tuple[str, int], bind: tuple[str, int]) -> object:
        from plugcell.devices.robot.rsi.config import CorrectionLimits, RsiConfig
        from plugcell.sim.controller.rsi_robot import RsiRobot
        from plugcell.sim.twin.dynamics import DynamicTwin
        from plugcell.sim.twin.scenario import TwinScenario

        big = (1e3,) * 6  # the controller's AXISCORR limits are the sensor's business here
        config = RsiConfig(robot_host=bind[0], listen_host=sensor[0], listen_port=sensor[1],
                           correction="joint", mode=args.mode, timeout_packets=args.timeout,
                           limits=CorrectionLimits(big, big, big))
        arm = DynamicTwin(TwinScenario(robot=args.robot, seed=args.seed,
                                       payload_kg=args.payload_kg))
        return RsiRobot(arm, config, bind=bind)

    def stats(robot: object) -> dict:
        st = robot.stats()  # type: ignore[attr-defined]
        return {"cycles": st.cycles, "answered": st.answered, "late": st.delay,
                "rtt_ns": list(robot.rtts)}  # type: ignore[attr-defined]

    return run_twin(args, make, f"RSI ({args.mode})", PREFIX, stats)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
