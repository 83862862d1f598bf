"""Helpers of the cell controller tests: a robot-like service, unique cells, child processes.

The child-process helpers are the framework tests' (``tests/framework/framework_testlib.py``).
"""

from __future__ import annotations

import asyncio
import sys
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "framework"))

from framework_testlib import Proc, plugcell_argv, run, unique_cell  # noqa: E402

from plugcell.framework import Command, CommandTypes, DataTypes, DeviceError, GenericDevice  # noqa: E402
from plugcell.framework.declaration import Declaration  # noqa: E402

PROGRAMS = HERE / "programs"

__all__ = ["PROGRAMS", "FakeRobot", "Proc", "SlowDevice", "plugcell_argv", "run", "unique_cell"]


def hosted(device: Any, name: str | None = None, **options: Any) -> GenericDevice:
    """A service hosting ``device`` (its test object is ``.interface``)."""
    return GenericDevice(device, name, **options)


class FakeRobot:
    """A robot service in miniature: ACTIVATE runs a 'program' that drives its partners.

    Programs: ``drill`` (TOOL Drill, then done), ``snap`` (CAMERA SnapShot), ``wait``
    (0.3 s), ``fail`` (fails with a reason).  Like plugcell's robot service, ACTIVATE
    completes when the program ends only with the option ``Wait``.
    """

    declaration = Declaration(kind="robot", vendor="tests", commands=(
        Command(name="ACTIVATE", type=CommandTypes.NoData, input_data_type=DataTypes.String,
                input_data_size=(-1,), timeout=30.0,
                info="run a program: [name]; option 'Wait': until it ends"),
        Command(name="ARM_POS", type=CommandTypes.SingleData, output_data_type=DataTypes.Double,
                output_data_size=(6,)),
    ))

    def __init__(self) -> None:
        self.ran: list[tuple[str, float, float]] = []
        self.service: GenericDevice | None = None

    def bind(self, service: GenericDevice) -> None:
        self.service = service

    async def dispatch(self, command: Command, option: str, data: Any) -> str:
        service = self.service
        assert service is not None
        if command.name == "ARM_POS":
            service.data_feedback.post([1000.0, 0.0, 800.0, 0.0, 90.0, 0.0])
            return "OK"
        program = str(data[0])
        loop = asyncio.get_running_loop()
        start = loop.time()
        if program == "drill":
            call = await service.participant.create_process("TOOL", "Drill", "Air", [550, 1100])
            final = await call.result()
            if final.state.value != "Completed":
                raise DeviceError(f"TOOL: {final.reason}")
        elif program == "snap":
            call = await service.participant.create_process("CAMERA", "SnapShot", "", 5)
            final = await call.result()
            if final.state.value != "Completed":
                raise DeviceError(f"CAMERA: {final.reason}")
        elif program == "wait":
            await asyncio.sleep(0.3)
        elif program == "fail":
            raise DeviceError("program fail: the program stopped with an error")
        else:
            raise DeviceError(f"no program {program!r}")
        self.ran.append((program, start, loop.time()))
        return "OK"


class SlowDevice:
    """A shared device whose ``Work`` takes ``seconds`` (to see its queue grow)."""

    declaration = Declaration(kind="slow", vendor="tests", commands=(
        Command(name="Work", type=CommandTypes.NoData, input_data_type=DataTypes.Double,
                input_data_size=(1,), timeout=10.0,
                info="work for DATA seconds (0: done at once, within the acknowledgement's turn)"),
    ))

    def bind(self, service: GenericDevice) -> None:
        """The device only answers its command feedback."""

    async def dispatch(self, command: Command, option: str, data: Any) -> str:
        if float(data[0]) > 0:
            await asyncio.sleep(float(data[0]))
        return "OK"
