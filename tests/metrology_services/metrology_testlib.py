"""Helpers of the metrology-service tests: cells, child processes, the simulated world."""

from __future__ import annotations

import asyncio
import os
import signal
import subprocess
import sys
import threading
import time
import uuid
from collections.abc import Callable, Coroutine
from typing import Any

import numpy as np

from plugcell.services.tracker_frames import matrix_from_vector


def unique_cell(prefix: str = "m") -> str:
    """A fresh cell name: tests never see each other (nor anything else on the host)."""
    return f"{prefix}{uuid.uuid4().hex[:12]}"


def run(coro: Coroutine[Any, Any, Any], timeout: float = 45.0) -> Any:
    """Run an async test body with a hard timeout."""
    return asyncio.run(asyncio.wait_for(coro, timeout))


def until(predicate: Callable[[], bool], timeout: float = 15.0) -> None:
    """Poll (bounded) for a condition another process makes true."""
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, "condition not reached in time"
        time.sleep(0.02)


def pose(v: list[float]) -> np.ndarray:
    """A 6-vector (mm, deg, Euler ZYZ) as a 4×4 matrix in metres."""
    return matrix_from_vector(v, "euler")


def plugcell_argv(*args: str) -> list[str]:
    return [sys.executable, "-m", "plugcell", *args]


class Proc:
    """A child process whose stdout lines are collected by a thread."""

    def __init__(self, argv: list[str], env: dict[str, str]) -> None:
        self.argv = argv
        self.popen = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                      text=True, env=env, start_new_session=True)
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
            while time.monotonic() < deadline:
                for line in self.lines:
                    if predicate(line):
                        return line
                if self.popen.poll() is not None:
                    break
                self._cond.wait(0.2)
        err = self.popen.stderr.read() if self.popen.poll() is not None and self.popen.stderr \
            else ""
        raise AssertionError(f"no such line from {self.argv}: {self.lines} {err}")

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
