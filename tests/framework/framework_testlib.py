"""Helpers of the framework tests: unique cells, a scripted device, child processes."""

from __future__ import annotations

import asyncio
import contextlib
import time
import uuid
from collections.abc import AsyncIterator, Coroutine
from pathlib import Path
from typing import Any

import numpy as np
from childproc import Proc, plugcell_argv  # noqa: F401  (re-exported for the tests)

from plugcell.framework import Command, CommandTypes, DataTypes, DeviceError, GenericDevice
from plugcell.framework.declaration import Declaration
from plugcell.framework.messages import ProcessStates
from plugcell.framework.participant import Participant


def unique_cell(prefix: str = "t") -> str:
    """A fresh cell name: tests never see each other (nor anything else on the host)."""
    return f"{prefix}{uuid.uuid4().hex[:12]}"


def run(coro: Coroutine[Any, Any, Any], timeout: float = 45.0) -> Any:
    """Run an async test body with a hard timeout."""
    return asyncio.run(asyncio.wait_for(coro, timeout))


class ScriptedDevice:
    """A device whose every step the test controls (for the queue semantics).

    ``Work`` (NoData): logs its option, then waits for ``gates[option]`` if set; an
    option ``note:TEXT`` notes TEXT on the process (:meth:`GenericDevice.note`);
    hosted by :func:`scripted`.
    ``Measure`` (SingleData): returns ``[1, 2, 3]``.  ``Stream`` (MultipleData):
    posts one value per ``emit()``.  ``Stop`` (StopData).  ``Slow`` never answers
    (timeout 0.3 s).  ``Hold`` is a MultipleData with a 0.5 s timeout.
    ``Flaky`` (SingleData) returns the wrong shape.  ``Fail`` answers "E42".
    """

    declaration = Declaration(kind="scripted", vendor="tests", commands=(
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
    ))

    def __init__(self) -> None:
        self.service: GenericDevice | None = None
        self.log: list[str] = []
        self.gates: dict[str, asyncio.Event] = {}
        self.streaming = False
        self.started = asyncio.Event()

    def bind(self, service: GenericDevice) -> None:
        self.service = service

    def emit(self, value: float) -> None:
        self.service.data_feedback.post(np.array([value]))

    async def dispatch(self, command: Command, option: str, data: Any) -> str | None:
        self.log.append(f"{command.name}:{option}" if option else command.name)
        match command.name:
            case "Work":
                if option.startswith("note:"):
                    self.service.note(option.removeprefix("note:"))
                self.started.set()
                gate = self.gates.get(option)
                if gate is not None:
                    await gate.wait()
            case "Measure":
                self.service.data_feedback.post([1.0, 2.0, 3.0])
            case "Stream" | "Hold":
                self.streaming = True
                self.started.set()
            case "Stop":
                self.streaming = False
            case "Slow":
                await asyncio.Event().wait()
            case "Flaky":
                self.service.data_feedback.post([1.0, 2.0])
            case "Fail":
                return "E42"
            case "Set":
                if int(data[0]) < 0:
                    raise DeviceError("negative values are not allowed")
        return "OK"


def scripted(name: str | None = "DEV", **kwargs: Any) -> GenericDevice:
    """A service hosting a :class:`ScriptedDevice` (``.interface``)."""
    return GenericDevice(ScriptedDevice(), name, **kwargs)


# -- one cell in this process (async tests) ---------------------------------------------


async def until(predicate: Any, timeout: float = 10.0) -> None:
    """Wait (bounded) for a condition that another task or process makes true."""
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, "condition not reached in time"
        await asyncio.sleep(0.01)


@contextlib.asynccontextmanager
async def cell_with(tmp_path: Path, *clients: str, **device_kwargs: Any) -> AsyncIterator[Any]:
    """A ScriptedDevice "DEV" and the named clients, all in a fresh cell."""
    cell = unique_cell()
    dev = scripted(cell=cell, journal=tmp_path / "journal", **device_kwargs)
    await dev.start()
    parts = [Participant(name, cell=cell) for name in clients]
    try:
        for p in parts:
            await p.start()
            assert await p.wait_for("DEV", 10)
        yield dev, *parts
    finally:
        for p in parts:
            await p.close()
        await dev.close()


def states(updates: Any) -> list[ProcessStates]:
    return [u.state for u in updates]


async def collect(call: Any) -> list[Any]:
    return [u async for u in call]



# -- OS processes ------------------------------------------------------------------------


