"""The twin's RSI side in a process of its own: ``plugcell twin rsi`` started and stopped.

The command (:mod:`plugcell.apps.commands.twin_robot`) stands where a KUKA controller
running plugcell's KRL program stands: the dynamic twin behind the RSI robot side
(:class:`~.rsi_robot.RsiRobot`).  :class:`RsiTwinProcess` runs it for tests and the demo:
start it, kill it (a pulled cable), start it again.
"""

from __future__ import annotations

import subprocess
import sys
import threading

__all__ = ["RsiTwinProcess"]

#: The first line the command prints when it streams.
BANNER = "twin rsi:"


class RsiTwinProcess:
    """``plugcell twin rsi`` in a process of its own: start, kill, start again.

    Parameters
    ----------
    sensor : str
        ``HOST:PORT`` where plugcell listens.
    *options : str
        More options of the command line (``--timeout``, ``--robot`` …).
    """

    def __init__(self, sensor: str, *options: str) -> None:
        host, _, port = sensor.rpartition(":")
        self.argv = [sys.executable, "-m", "plugcell", "twin", "rsi", "--ip", host,
                     "--port", port, *options]
        self.proc: subprocess.Popen[str] | None = None
        self.banner = ""

    def start(self, timeout: float = 30.0) -> RsiTwinProcess:
        """Start it and wait for its first line; RuntimeError with its output if it fails."""
        self.proc = subprocess.Popen(self.argv, stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE, text=True)
        got: list[str] = []
        reader = threading.Thread(target=lambda: got.append(self.proc.stdout.readline()),
                                  daemon=True)  # type: ignore[union-attr]
        reader.start()
        reader.join(timeout)
        if not got or not got[0].startswith(BANNER):
            self.kill()
            err = self.proc.stderr.read() if self.proc.stderr else ""
            raise RuntimeError(f"the twin's RSI side did not start: {got} {err}")
        self.banner = got[0].strip()
        return self

    def kill(self) -> None:
        """Kill it at once (a pulled cable, a controller gone)."""
        if self.proc is not None and self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(10)

    def __enter__(self) -> RsiTwinProcess:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.kill()
