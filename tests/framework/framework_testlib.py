"""Helpers of the framework tests: unique cells, a scripted device, child processes."""

from __future__ import annotations

import asyncio
import os
import signal
import subprocess
import sys
import threading
import time
import uuid
from collections.abc import Coroutine
from typing import Any

import numpy as np

from plugcell.framework import Command, CommandTypes, DataTypes, DeviceError, GenericDevice


def unique_cell(prefix: str = "t") -> str:
    """A fresh cell name: tests never see each other (nor anything else on the host)."""
    return f"{prefix}{uuid.uuid4().hex[:12]}"


def run(coro: Coroutine[Any, Any, Any], timeout: float = 45.0) -> Any:
    """Run an async test body with a hard timeout."""
    return asyncio.run(asyncio.wait_for(coro, timeout))


class ScriptedDevice(GenericDevice):
    """A device whose every step the test controls (for the queue semantics).

    ``Work`` (NoData): logs its option, then waits for ``gates[option]`` if set.
    ``Measure`` (SingleData): returns ``[1, 2, 3]``.  ``Stream`` (MultipleData):
    posts one value per ``emit()``.  ``Stop`` (StopData).  ``Slow`` never answers
    (timeout 0.3 s).  ``Hold`` is a MultipleData with a 0.5 s timeout.
    ``Flaky`` (SingleData) returns the wrong shape.  ``Fail`` answers "E42".
    """

    kind = "scripted"
    vendor = "tests"
    commands = (
        Command(name="Work", type=CommandTypes.NoData, timeout=20.0),
        Command(
            name="Measure",
            type=CommandTypes.SingleData,
            output_data_type=DataTypes.Double,
            output_data_size=(3,),
        ),
        Command(
            name="Stream",
            type=CommandTypes.MultipleData,
            output_data_type=DataTypes.Double,
            output_data_size=(1,),
            timeout=30.0,
        ),
        Command(
            name="Hold",
            type=CommandTypes.MultipleData,
            output_data_type=DataTypes.Double,
            output_data_size=(1,),
            timeout=0.5,
        ),
        Command(name="Stop", type=CommandTypes.StopData),
        Command(name="Slow", type=CommandTypes.NoData, timeout=0.3),
        Command(
            name="Flaky",
            type=CommandTypes.SingleData,
            output_data_type=DataTypes.Double,
            output_data_size=(3,),
        ),
        Command(name="Fail", type=CommandTypes.NoData),
        Command(
            name="Set",
            type=CommandTypes.NoData,
            input_data_type=DataTypes.Integer,
            input_data_size=(2,),
        ),
    )

    def __init__(self, name: str | None = "DEV", **kwargs: Any) -> None:
        super().__init__(name, **kwargs)
        self.log: list[str] = []
        self.gates: dict[str, asyncio.Event] = {}
        self.streaming = False
        self.started = asyncio.Event()

    def emit(self, value: float) -> None:
        self.data_feedback.post(np.array([value]))

    async def dispatch(self, command: Command, option: str, data: Any) -> str | None:
        self.log.append(f"{command.name}:{option}" if option else command.name)
        match command.name:
            case "Work":
                self.started.set()
                gate = self.gates.get(option)
                if gate is not None:
                    await gate.wait()
            case "Measure":
                self.data_feedback.post([1.0, 2.0, 3.0])
            case "Stream" | "Hold":
                self.streaming = True
                self.started.set()
            case "Stop":
                self.streaming = False
            case "Slow":
                await asyncio.Event().wait()
            case "Flaky":
                self.data_feedback.post([1.0, 2.0])
            case "Fail":
                return "E42"
            case "Set":
                if int(data[0]) < 0:
                    raise DeviceError("negative values are not allowed")
        return "OK"


# -- OS processes ------------------------------------------------------------------------


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

    def wait_line(self, predicate: Any, timeout: float = 20.0) -> str:
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
