"""The publisher of the transport benchmark (thesis 5.3.1, Figure 5-16).

A service built on the same template as every other: ``Echo`` (SingleData)
returns its input in the ProcessUpdate — the latency test; ``Push``
(MultipleData) pushes N ProcessUpdates carrying an array of the given shape as
fast as possible — the throughput test; ``StopPush`` (StopData) ends it.
"""

from __future__ import annotations

import asyncio
from typing import Any

import numpy as np

from plugcell.framework.declaration import Declaration
from plugcell.framework.messages import Command, CommandTypes, DataTypes
from plugcell.framework.service import DeviceError, GenericDevice

#: Frames pushed per event-loop turn (then the loop serves everything else).
BURST = 64


class BenchService:
    """Publisher for ``plugcell bench transport`` (also servable: ``plugcell serve bench``);
    a :class:`~plugcell.framework.service.GenericDevice` hosts it (:func:`bench_service`)."""

    declaration = Declaration(
        kind="bench",
        default_name="PUBLISHER",
        vendor="plugcell",
        info="transport benchmark publisher (thesis 5.3)",
        commands=(
        Command(
            name="Echo",
            type=CommandTypes.SingleData,
            input_data_type=DataTypes.Byte,
            input_data_size=(),
            output_data_type=DataTypes.Byte,
            output_data_size=(),
            info="return the input data",
        ),
        Command(
            name="Push",
            type=CommandTypes.MultipleData,
            input_data_type=DataTypes.Integer,
            input_data_size=(-1,),
            output_data_type=DataTypes.Byte,
            output_data_size=(),
            timeout=3600.0,
            info="input [count, *shape]: push count arrays of that shape",
        ),
        Command(name="StopPush", type=CommandTypes.StopData),
    ))

    def __init__(self) -> None:
        self.service: GenericDevice | None = None
        self._pusher: asyncio.Task[None] | None = None

    def bind(self, service: GenericDevice) -> None:
        self.service = service

    async def dispatch(self, command: Command, option: str, data: Any) -> str:
        assert self.service is not None
        match command.name:
            case "Echo":
                self.service.data_feedback.post(data)
            case "Push":
                if data is None or len(data) < 2 or int(data[0]) < 0:
                    raise DeviceError("Push needs [count, *shape] with count >= 0")
                frame = np.full(tuple(int(d) for d in data[1:]), 7, np.uint8)
                frame.flags.writeable = False  # never changes: streamed without a copy
                self._pusher = asyncio.create_task(self._push(int(data[0]), frame))
            case "StopPush":
                if self._pusher is not None:
                    self._pusher.cancel()
        return "OK"

    async def _push(self, count: int, frame: np.ndarray) -> None:
        assert self.service is not None
        post = self.service.data_feedback.post
        for i in range(count):
            post(frame)
            if i % BURST == BURST - 1:
                await asyncio.sleep(0)


def bench_service(name: str | None = None, **options: Any) -> GenericDevice:
    """A service hosting a :class:`BenchService` (``options``: the framework's keywords,
    ``cell``, ``transport``, ``journal`` …)."""
    return GenericDevice(BenchService(), name, **options)
