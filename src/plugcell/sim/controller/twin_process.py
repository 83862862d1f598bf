"""The twin as a robot controller streaming to plugcell, in a process of its own.

``plugcell twin rsi`` (a KUKA controller streaming RSI) and ``plugcell twin egm`` (an ABB
controller's EGM loop) are commands (:mod:`plugcell.apps.commands.twin_robot`);
:class:`TwinProcess` runs one of them for tests, benchmarks and the demo: start it, kill
it (a pulled cable), start it again (:class:`~.rsi_twin.RsiTwinProcess`,
:class:`~.egm_twin.EgmTwinProcess`).
"""

from __future__ import annotations

import subprocess
import sys
import threading

__all__ = ["TwinProcess"]


class TwinProcess:
    """``plugcell twin WHAT`` in a process of its own: start, kill, start again.

    Parameters
    ----------
    what : str
        The robot side: ``"rsi"`` or ``"egm"``; its first line starts ``twin WHAT:``.
    sensor : str
        ``HOST:PORT`` where plugcell listens (the command's ``--ip`` and ``--port``).
    *options : str
        More options of the command line (``--timeout``, ``--robot``, ``--stats`` …).
    """

    def __init__(self, what: str, sensor: str, *options: str) -> None:
        host, _, port = sensor.rpartition(":")
        self.argv = [sys.executable, "-m", "plugcell", "twin", what, "--ip", host,
                     "--port", port, *options]
        self.prefix = f"twin {what}:"
        self.proc: subprocess.Popen[str] | None = None
        self.banner = ""

    def start(self, timeout: float = 30.0) -> TwinProcess:
        """Start it and wait for its first line; RuntimeError with its output if it fails."""
        self.proc = subprocess.Popen(self.argv, stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE, text=True)
        got: list[str] = []
        reader = threading.Thread(target=lambda: got.append(self.proc.stdout.readline()),
                                  daemon=True)  # type: ignore[union-attr]
        reader.start()
        reader.join(timeout)
        if not got or not got[0].startswith(self.prefix):
            self.kill()
            err = self.proc.stderr.read() if self.proc.stderr else ""
            raise RuntimeError(f"the twin's robot side ({' '.join(self.argv[2:])}) did not "
                               f"start: {got} {err}")
        self.banner = got[0].strip()
        return self

    def kill(self) -> None:
        """Kill it at once (a pulled cable, a controller gone)."""
        if self.proc is not None and self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(10)

    def __enter__(self) -> TwinProcess:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.kill()
