"""A small sensor service for the robot tests: all four command types with data a
robot program can hold (served as ``plugcell serve robot_devices:ProbeService``)."""

from __future__ import annotations

import asyncio
import contextlib
from typing import Any

import numpy as np

from plugcell.framework import Command, CommandTypes, DataTypes, DeviceError, GenericDevice
from plugcell.framework.declaration import Declaration


class ProbeService:
    """``Measure`` (SingleData → Double[3]), ``Track`` (MultipleData: rate Hz → Double[3]
    frames), ``StopTrack`` (StopData), ``Name`` (SingleData → String[1]), ``Zero`` (NoData,
    option ``X``/``Y``/``Z``)."""

    declaration = Declaration(kind="probe", default_name="PROBE", vendor="tests", commands=(
        Command(name="Measure", type=CommandTypes.SingleData,
                output_data_type=DataTypes.Double, output_data_size=(3,)),
        Command(name="Track", type=CommandTypes.MultipleData, input_data_type=DataTypes.Integer,
                input_data_size=(1,), output_data_type=DataTypes.Double, output_data_size=(3,),
                timeout=60.0),
        Command(name="StopTrack", type=CommandTypes.StopData),
        Command(name="Name", type=CommandTypes.SingleData, output_data_type=DataTypes.String,
                output_data_size=(1,)),
        Command(name="Zero", type=CommandTypes.NoData),
    ))

    def __init__(self) -> None:
        self.count = 0
        self._track: asyncio.Task[None] | None = None
        self.service: GenericDevice | None = None

    def bind(self, service: GenericDevice) -> None:
        self.service = service

    async def dispatch(self, command: Command, option: str, data: Any) -> str:
        assert self.service is not None
        match command.name:
            case "Measure":
                self.count += 1
                self.service.data_feedback.post(np.array([1.5, -2.0, 10.0 * self.count]))
            case "Track":
                rate = int(data[0])
                if not 1 <= rate <= 1000:
                    raise DeviceError(f"rate {rate} Hz outside 1…1000 Hz")
                self._track = asyncio.create_task(self._stream(1.0 / rate))
            case "StopTrack":
                track, self._track = self._track, None
                if track is not None:
                    track.cancel()
                    with contextlib.suppress(asyncio.CancelledError):
                        await track
            case "Name":
                self.service.data_feedback.post(["probe #7"])
            case "Zero":
                if option not in ("X", "Y", "Z"):
                    raise DeviceError(f"unknown axis {option!r}")
                self.count = 0
        return "OK"

    async def _stream(self, period: float) -> None:
        assert self.service is not None
        k = 0
        while True:
            k += 1
            self.service.data_feedback.post(np.array([float(k), 2.0 * k, 3.0 * k]))
            await asyncio.sleep(period)
