"""Service processes of a cell on this machine: start, wait until serving, stop.

What ``plugcell serve KIND`` is to one service, :class:`CellProcesses` is to a cell:
every device its own OS process (``python -m plugcell serve …``), in one cell and one
``PLUGCELL_HOME``, stopped together (SIGTERM to each process group, SIGKILL after a
bound).  Used by ``plugcell demo``.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

__all__ = ["CellProcesses", "ServiceStartError"]

READY = "serving in cell"


class ServiceStartError(RuntimeError):
    """A service process exited or did not serve in time; the message has its stderr."""


class _Service:
    def __init__(self, name: str, argv: list[str], env: dict[str, str],
                 ready: str = READY) -> None:
        self.name = name
        self.marker = ready
        self.popen = subprocess.Popen(argv, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                      stderr=subprocess.PIPE, text=True, env=env,
                                      start_new_session=True)
        self.ready = threading.Event()
        self.errors: list[str] = []
        self.output: list[str] = []  # the last lines it printed
        self.reader = threading.Thread(target=self._read_stdout, daemon=True)
        self.reader.start()
        threading.Thread(target=self._read_stderr, daemon=True).start()

    def _read_stdout(self) -> None:
        assert self.popen.stdout is not None
        for line in self.popen.stdout:
            self.output = [*self.output[-30:], line.rstrip()]
            if self.marker in line:
                self.ready.set()

    def _read_stderr(self) -> None:
        assert self.popen.stderr is not None
        for line in self.popen.stderr:
            self.errors = [*self.errors[-30:], line.rstrip()]

    def stop(self, timeout: float = 10.0) -> None:
        self.terminate()
        self.reap(timeout)

    def terminate(self) -> None:
        """SIGTERM its process group (:meth:`reap` waits for it)."""
        if self.popen.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(self.popen.pid, signal.SIGTERM)

    def reap(self, timeout: float = 10.0) -> None:
        """Wait ``timeout`` s for it to end (then SIGKILL); nothing of its group is left."""
        if self.popen.poll() is None:
            try:
                self.popen.wait(timeout)
            except subprocess.TimeoutExpired:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(self.popen.pid, signal.SIGKILL)
                self.popen.wait(timeout)
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(self.popen.pid, signal.SIGKILL)  # nothing of its group is left


class CellProcesses:
    """The service processes of one cell; a context manager that stops them all."""

    def __init__(self, cell: str, home: Path) -> None:
        self.cell = cell
        self.home = Path(home)
        self.env = {**os.environ, "PLUGCELL_HOME": str(self.home), "PYTHONUNBUFFERED": "1"}
        self.services: list[_Service] = []

    def serve(self, kind: str, name: str, **params: object) -> None:
        """Start ``plugcell serve KIND --name NAME --param k=v …`` (not waited for)."""
        argv = [sys.executable, "-m", "plugcell", "serve", kind, "--cell", self.cell,
                "--name", name]
        for key, value in params.items():
            argv += ["--param", f"{key}={value}"]
        self.services.append(_Service(name, argv, self.env))

    def run(self, name: str, args: list[str], ready: str) -> None:
        """Start ``plugcell ARGS…`` (a simulated device that is no service, e.g. the twin's
        RSI side), ready when it prints ``ready`` (not waited for)."""
        self.services.append(_Service(name, [sys.executable, "-m", "plugcell", *args],
                                      self.env, ready))

    def wait_ready(self, timeout: float = 60.0) -> None:
        """Until every service serves; ServiceStartError with the reason otherwise."""
        deadline = time.monotonic() + timeout
        for service in self.services:
            while not service.ready.wait(0.1):
                if service.popen.poll() is not None:
                    raise ServiceStartError(f"{service.name} exited with code "
                                            f"{service.popen.returncode}: "
                                            + "\n".join(service.errors[-10:]))
                if time.monotonic() > deadline:
                    raise ServiceStartError(f"{service.name} did not serve within {timeout:g} s")

    def stop_all(self) -> None:
        """SIGTERM every process (the last started first), then wait for each: they
        shut down side by side."""
        for service in reversed(self.services):
            service.terminate()
        for service in reversed(self.services):
            service.reap()

    def stop(self, name: str) -> list[str]:
        """Stop one process; the last lines it printed."""
        for service in self.services:
            if service.name == name:
                service.stop()
                service.reader.join(5.0)  # its last lines
                return list(service.output)
        raise KeyError(name)

    def __enter__(self) -> CellProcesses:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop_all()
