"""Child processes for the process-level tests: the real CLI run as ``python -m plugcell``.

Shared by the test folders (the root ``tests/conftest.py`` puts this folder on
``sys.path``): a :class:`Proc` collects stdout lines on a thread, waits for a line,
and is stopped or killed with its whole process group, so no test leaves a child
behind.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable


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


def plugcell_argv(*args: str) -> list[str]:
    """Command line of the real CLI: ``python -m plugcell …``."""
    return [sys.executable, "-m", "plugcell", *args]


class Proc:
    """A child process whose stdout lines are collected by a thread."""

    def __init__(self, argv: list[str], env: dict[str, str]) -> None:
        self.argv = argv
        self.popen = subprocess.Popen(
            argv,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=env,
            start_new_session=True,
        )
        self.lines: list[str] = []
        self._cond = threading.Condition()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.popen.stdout is not None
        for line in self.popen.stdout:
            with self._cond:
                self.lines.append(line.rstrip("\n"))
                self._cond.notify_all()
        with self._cond:
            self._cond.notify_all()

    def wait_line(self, predicate: Callable[[str], bool], timeout: float = 30.0) -> str:
        """The first stdout line satisfying ``predicate`` (AssertionError after timeout)."""
        deadline = time.monotonic() + timeout
        with self._cond:
            found = False
            while not found and time.monotonic() < deadline:  # poll(): exit without a notify
                found = self._cond.wait_for(
                    lambda: any(predicate(x) for x in self.lines) or self.popen.poll() is not None,
                    0.2,
                )
            for line in self.lines:
                if predicate(line):
                    return line
        err = (
            self.popen.stderr.read() if self.popen.poll() is not None and self.popen.stderr else ""
        )
        raise AssertionError(f"no such line from {self.argv} (found={found}): {self.lines} {err}")

    @property
    def pid(self) -> int:
        return self.popen.pid

    def kill9(self) -> None:
        os.killpg(self.popen.pid, signal.SIGKILL)
        self.popen.wait(10)

    def stop(self) -> None:
        if self.popen.poll() is None:
            os.killpg(self.popen.pid, signal.SIGTERM)
            try:
                self.popen.wait(15)
            except subprocess.TimeoutExpired:
                os.killpg(self.popen.pid, signal.SIGKILL)
                self.popen.wait(10)
        for stream in (self.popen.stdout, self.popen.stderr):
            if stream is not None:
                stream.close()
