"""Starting and stopping the simulated controller process of a ``--sim`` robot service.

``plugcell serve robot --sim`` runs two OS processes, as a real cell would have a
PC and a robot controller: the service, and
``python -m plugcell.sim.controller`` listening on a free loopback port
that it prints on its first line.  The controller watches its parent and exits
when the service is gone; the service stops it on shutdown (SIGTERM, then SIGKILL).
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import os
import re
import sys
from pathlib import Path

from plugcell.devices.robot.controller_process import ControllerStartError
from plugcell.framework.transport import TransportConfig

__all__ = ["SimControllerError", "SimControllerProcess"]

_LISTENING = re.compile(r"listening on (\S+):(\d+)\s*$")


class SimControllerError(ControllerStartError):
    """The simulated controller could not be started."""


class SimControllerProcess:
    """One simulated controller child process (a
    :class:`~plugcell.devices.robot.controller_process.ControllerProcess`; the class is the
    :class:`~plugcell.devices.robot.controller_process.ControllerLauncher` that
    ``plugcell serve robot`` gives the robot service)."""

    def __init__(
        self,
        *,
        name: str,
        cell: str,
        robot: str = "smart_h4",
        payload_kg: float = 0.0,
        speed: float = 1.0,
        seed: int = 0,
        library: list[Path] | None = None,
        transport: TransportConfig | None = None,
        log_level: str = "WARNING",
        link_baud: float = 0.0,
        dynamics: bool = False,
    ) -> None:
        self.argv = [
            sys.executable, "-m", "plugcell.sim.controller",
            "--robot", robot, "--port", "0", "--cell", cell, "--name", name,
            "--payload-kg", repr(float(payload_kg)),
            "--speed", "inf" if math.isinf(speed) else repr(float(speed)),
            "--seed", str(int(seed)), "--parent-watch", "--log-level", log_level,
            "--link-baud", repr(float(link_baud)),
        ] + (["--dynamics"] if dynamics else [])
        for folder in library or []:
            self.argv += ["--library", str(folder)]
        self.env = dict(os.environ)
        if transport is not None:
            if transport.connect:
                self.env["PLUGCELL_CONNECT"] = ",".join(transport.connect)
            if not transport.multicast:
                self.env["PLUGCELL_MULTICAST"] = "0"
        self.process: asyncio.subprocess.Process | None = None
        self._drain: asyncio.Task[None] | None = None

    async def start(self, timeout: float = 30.0) -> tuple[str, int]:
        """Start it; (host, port) it listens on.  SimControllerError if it does not come up."""
        self.process = await asyncio.create_subprocess_exec(
            *self.argv, stdin=asyncio.subprocess.DEVNULL, stdout=asyncio.subprocess.PIPE,
            env=self.env,
        )
        assert self.process.stdout is not None
        try:
            async with asyncio.timeout(timeout):
                while True:
                    raw = await self.process.stdout.readline()
                    if not raw:
                        code = await self.process.wait()
                        raise SimControllerError(
                            f"the simulated controller exited with code {code} before "
                            "listening (see its error above)")
                    match = _LISTENING.search(raw.decode("utf-8", "replace"))
                    if match:
                        break
        except TimeoutError:
            await self.stop()
            raise SimControllerError(
                f"the simulated controller did not listen within {timeout:g} s") from None
        except BaseException:
            await self.stop()
            raise
        self._drain = asyncio.create_task(self._drain_stdout())
        return match.group(1), int(match.group(2))

    async def _drain_stdout(self) -> None:
        assert self.process is not None and self.process.stdout is not None
        with contextlib.suppress(Exception):
            while await self.process.stdout.readline():
                pass

    @property
    def alive(self) -> bool:
        return self.process is not None and self.process.returncode is None

    async def stop(self, timeout: float = 5.0) -> None:
        """SIGTERM, then SIGKILL after ``timeout`` seconds."""
        process, self.process = self.process, None
        if process is None:
            return
        if process.returncode is None:
            with contextlib.suppress(ProcessLookupError):
                process.terminate()
            try:
                async with asyncio.timeout(timeout):
                    await process.wait()
            except TimeoutError:
                with contextlib.suppress(ProcessLookupError):
                    process.kill()
                await process.wait()
        if self._drain is not None:
            self._drain.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._drain
