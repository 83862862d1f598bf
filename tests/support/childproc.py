"""Child processes for the process-level tests: the real CLI run as ``python -m plugcell``.

Shared by the test folders (the root ``tests/conftest.py`` puts this folder on
``sys.path``): a :class:`Proc` collects stdout lines on a thread, waits for a line,
and is stopped or killed with its whole process group, so no test leaves a child
behind; a :class:`Launcher` starts them with one home and stops them all,
:class:`CellProcesses` the services of one cell; :func:`until` and :func:`wait_until`
poll for what another process or thread makes true.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import IO


def until(predicate: Callable[[], object], timeout: float = 15.0,
          what: str = "condition") -> object:
    """Poll (bounded) for a condition another process makes true; its value."""
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value:
            return value
        assert time.monotonic() < deadline, f"{what} not reached within {timeout:g} s"
        time.sleep(0.02)


def wait_until(predicate: Callable[[], object], timeout: float = 2.0) -> bool:
    """Whether ``predicate()`` holds within ``timeout`` s, polled every 2 ms (a link's
    cycle is 4 ms): for ``assert wait_until(…)`` and ``assert not wait_until(…)``."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return True
        time.sleep(0.002)
    return bool(predicate())


def plugcell_argv(*args: str) -> list[str]:
    """Command line of the real CLI: ``python -m plugcell …``."""
    return [sys.executable, "-m", "plugcell", *args]


class Proc:
    """A child process (its own process group) whose stdout lines, and stderr lines in
    ``errors``, threads collect."""

    def __init__(self, argv: list[str], env: dict[str, str]) -> None:
        self.argv = argv
        self.popen = subprocess.Popen(
            argv, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
            text=True, env=env, start_new_session=True,
        )
        self.lines: list[str] = []
        self.errors: list[str] = []
        self._cond = threading.Condition()
        for stream, sink in ((self.popen.stdout, self.lines), (self.popen.stderr, self.errors)):
            threading.Thread(target=self._read, args=(stream, sink), daemon=True).start()

    def _read(self, stream: IO[str], sink: list[str]) -> None:
        for line in stream:
            with self._cond:
                sink.append(line.rstrip("\n"))
                self._cond.notify_all()
        with self._cond:
            self._cond.notify_all()

    def wait_line(self, predicate: Callable[[str], bool], timeout: float = 30.0) -> str:
        """The first stdout line satisfying ``predicate`` (AssertionError after ``timeout``,
        or when the process has ended without it)."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while True:
                for line in self.lines:
                    if predicate(line):
                        return line
                left = deadline - time.monotonic()
                if left <= 0 or self.popen.poll() is not None:
                    break
                self._cond.wait(min(left, 0.2))
        raise AssertionError(f"no such line from {self.argv}: {self.lines} {self.errors[-20:]}")

    def wait_serving(self, timeout: float = 30.0) -> Proc:
        """Wait until the service says it serves (``plugcell serve``'s line); itself."""
        self.wait_line(lambda line: "serving in cell" in line, timeout)
        return self

    @property
    def pid(self) -> int:
        return self.popen.pid

    def kill9(self) -> None:
        """SIGKILL the whole process group (e.g. a service and its simulated controller)."""
        if self.popen.poll() is None:
            os.killpg(self.popen.pid, signal.SIGKILL)
        self.popen.wait(10)

    def stop(self) -> None:
        """SIGTERM the group, SIGKILL after 15 s; every wait bounded."""
        self.reap(self.terminate())

    def terminate(self) -> bool:
        """SIGTERM the group if its leader still runs; whether it did (for :meth:`reap`)."""
        if self.popen.poll() is not None:
            return False
        os.killpg(self.popen.pid, signal.SIGTERM)
        return True

    def reap(self, terminated: bool) -> None:
        """After :meth:`terminate`: wait for the leader it sent SIGTERM (SIGKILL the group
        after 15 s); where the leader had already gone, SIGKILL what is left of its
        group."""
        if terminated:
            try:
                self.popen.wait(15)
            except subprocess.TimeoutExpired:
                os.killpg(self.popen.pid, signal.SIGKILL)
                self.popen.wait(10)
        else:  # the leader is gone: make sure nothing of its group is left
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(self.popen.pid, signal.SIGKILL)


def group_alive(pgid: int) -> bool:
    """Whether any process of process group ``pgid`` still exists."""
    try:
        os.killpg(pgid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # pragma: no cover
        return True
    return True


class Launcher:
    """Child processes started with one ``PLUGCELL_HOME``; :meth:`stop` stops them all.

    Parameters
    ----------
    home : str or Path
        The services' home (keys, journals, programs).
    env : dict, optional
        More environment of every child.
    """

    def __init__(self, home: str | os.PathLike[str], env: dict[str, str] | None = None) -> None:
        self.env = {**os.environ, "PLUGCELL_HOME": str(home), "PYTHONUNBUFFERED": "1",
                    **(env or {})}
        self.started: list[Proc] = []

    def start(self, argv: list[str], env: dict[str, str] | None = None) -> Proc:
        """Start ``argv`` (``env``: this child's own additions)."""
        proc = Proc(argv, {**self.env, **(env or {})})
        self.started.append(proc)
        return proc

    def serve(self, kind: str, cell: str, *extra: str, name: str | None = None,
              env: dict[str, str] | None = None, wait: bool = True) -> Proc:
        """``plugcell serve KIND --cell CELL …`` (``--name NAME``), waited for until it
        serves unless ``wait`` is False (then :meth:`Proc.wait_serving`: services that do
        not need each other start side by side)."""
        argv = plugcell_argv("serve", kind, "--cell", cell, *extra)
        if name:
            argv += ["--name", name]
        proc = self.start(argv, env)
        return proc.wait_serving() if wait else proc

    def stop(self) -> None:
        """Stop every child started (its whole process group): all are sent SIGTERM first,
        then each is waited for, so that they shut down side by side."""
        terminated = [proc.terminate() for proc in self.started]
        for proc, sent in zip(self.started, terminated, strict=True):
            proc.reap(sent)


class CellProcesses:
    """The services of one cell run as OS processes, through a :class:`Launcher`
    (``stop()`` ends them all).

    Parameters
    ----------
    name : str
        The cell.
    home : str or Path
        Its services' home.
    """

    def __init__(self, name: str, home: str | os.PathLike[str]) -> None:
        self.name = name
        self.home = Path(home)
        self.launcher = Launcher(home)

    def start(self, *args: str) -> Proc:
        """Start ``plugcell ARGS…``."""
        return self.launcher.start(plugcell_argv(*args))

    def serve(self, kind: str, *extra: str) -> Proc:
        """``plugcell serve KIND`` in this cell, waited for until it serves."""
        return self.launcher.serve(kind, self.name, *extra)

    def cli(self, *args: str, timeout: float = 30.0) -> Proc:
        """Run a ``plugcell`` command in this cell to its end (bounded)."""
        proc = self.start(*args, "--cell", self.name)
        proc.popen.wait(timeout)
        return proc

    def stop(self) -> None:
        """Stop every child started."""
        self.launcher.stop()
