"""The twin's RSI side in a process of its own: ``plugcell twin rsi`` started and stopped.

The command (:mod:`plugcell.apps.commands.twin_robot`) stands where a KUKA controller
running plugcell's KRL program stands: the dynamic twin behind the RSI robot side
(:class:`~.rsi_robot.RsiRobot`).  :class:`RsiTwinProcess` runs it for tests, benchmarks
and the demo: start it, kill it (a pulled cable), start it again.
"""

from __future__ import annotations

from plugcell.sim.controller.twin_process import TwinProcess

__all__ = ["BANNER", "RsiTwinProcess"]

#: The first line the command prints when it streams.
BANNER = "twin rsi:"


class RsiTwinProcess(TwinProcess):
    """``plugcell twin rsi`` in a process of its own: ``RsiTwinProcess(sensor, *options)``.

    Parameters
    ----------
    sensor : str
        ``HOST:PORT`` where plugcell listens.
    *options : str
        More options of the command line (``--timeout``, ``--robot``, ``--stats`` …).
    """

    def __init__(self, sensor: str, *options: str) -> None:
        super().__init__("rsi", sensor, *options)
