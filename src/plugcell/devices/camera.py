"""The camera service: the CameraService design template of thesis 5.2.3.

Commands (5.1.1.1, 5.2.3.3, Figure 5-3): ``Connect``/``Disconnect`` (NoData),
``SnapShot`` (SingleData: exposure time in ms → a 480×640 8-bit image),
``MovieShot`` (MultipleData: frame rate in frames/s → a stream of images) and
``StopMovie`` (StopData).  The device interface layer (Figure 5-10) is
:meth:`CameraService.dispatch`; the camera itself is behind :class:`CameraDriver`
(``plugcell serve camera`` gives it the simulated one,
:class:`plugcell.sim.drivers.camera.SimulatedCamera`; a real camera's SDK is another
class with these methods).

The thesis listing declares the image as ``{640, 480}`` (width, height); by F.5
(d) a matrix size is rows first, so the catalogue says ``(480, 640)``.
"""

from __future__ import annotations

import asyncio
import contextlib
from typing import Protocol, runtime_checkable

import numpy as np

from plugcell.framework.declaration import Declaration
from plugcell.framework.messages import Command, CommandTypes, ConnectionStates, DataTypes
from plugcell.framework.service import DeviceError, GenericDevice

WIDTH, HEIGHT = 640, 480
MAX_FPS = 80
#: The exposure times a camera takes (ms).
EXPOSURE_MS = (1, 10_000)

S = "S"  # the success code of the thesis's camera API
IMAGE = (HEIGHT, WIDTH)


class CameraError(RuntimeError):
    """The camera refused a request (its reason is the message)."""


@runtime_checkable
class CameraDriver(Protocol):
    """The seam between :class:`CameraService` and a camera (its SDK, or a model).

    ``time_scale`` scales the driver's waits (1 for a real camera; the simulated one
    runs faster for tests), ``connected`` says whether it is online.
    """

    time_scale: float
    connected: bool

    async def connect(self) -> None:
        """Open the link to the camera."""

    async def disconnect(self) -> None:
        """Close it."""

    async def grab(self, exposure_ms: int) -> np.ndarray:
        """Expose for ``exposure_ms`` and return the image, ``uint8`` of shape
        (:data:`HEIGHT`, :data:`WIDTH`); :class:`CameraError` if the camera refuses."""
        ...


class CameraService:
    """A 640×480 grayscale camera behind a :class:`CameraDriver` (the device a
    :class:`~plugcell.framework.service.GenericDevice` hosts)."""

    declaration = Declaration(
        kind="camera",
        vendor="plugcell (simulated)",
        info="Specs: 640x480, 8bit Grayscale, Framerate: 80fps",
        commands=(
        Command(
            name="Connect",
            type=CommandTypes.NoData,
            success_code=S,
            info="connect to the camera controller",
        ),
        Command(
            name="Disconnect",
            type=CommandTypes.NoData,
            success_code=S,
            info="disconnect from the camera controller",
        ),
        Command(
            name="SnapShot",
            type=CommandTypes.SingleData,
            success_code=S,
            input_data_type=DataTypes.Integer,
            input_data_size=(1,),
            output_data_type=DataTypes.Byte,
            output_data_size=IMAGE,
            timeout=15.0,
            info="one image; input: exposure time in ms",
        ),
        Command(
            name="MovieShot",
            type=CommandTypes.MultipleData,
            success_code=S,
            input_data_type=DataTypes.Integer,
            input_data_size=(1,),
            output_data_type=DataTypes.Byte,
            output_data_size=IMAGE,
            timeout=600.0,
            info="a stream of images until StopMovie; input: frame rate in frames/s",
        ),
        Command(
            name="StopMovie", type=CommandTypes.StopData, success_code=S, info="stop the movie"
        ),
    ))

    def __init__(self, driver: CameraDriver) -> None:
        self.camera = driver
        self.service: GenericDevice | None = None
        self._movie: asyncio.Task[None] | None = None

    def bind(self, service: GenericDevice) -> None:
        self.service = service

    async def connect(self) -> None:
        await self.camera.connect()
        if self.service is not None:
            self.service.connection_state.post(ConnectionStates.Online)

    async def disconnect(self) -> None:
        await self._stop_movie()
        await self.camera.disconnect()
        if self.service is not None:
            self.service.connection_state.post(ConnectionStates.Offline)

    async def dispatch(self, command: Command, option: str, data: np.ndarray | None) -> str:
        """CommandDispatcher of the camera interface."""
        try:
            match command.name:
                case "Connect":
                    await self.connect()
                case "Disconnect":
                    await self.disconnect()
                case "SnapShot":
                    assert data is not None and self.service is not None
                    self.service.data_feedback.post(await self.camera.grab(int(data[0])))
                case "MovieShot":
                    assert data is not None
                    self._start_movie(int(data[0]))
                case "StopMovie":
                    await self._stop_movie()
        except CameraError as exc:
            raise DeviceError(str(exc)) from exc
        return S

    def _start_movie(self, fps: int) -> None:
        if not self.camera.connected:
            raise CameraError("camera offline: send Connect first")
        if not 1 <= fps <= MAX_FPS:
            raise CameraError(f"frame rate {fps} outside 1…{MAX_FPS} frames/s")
        self._movie = asyncio.create_task(self._film(fps))

    async def _film(self, fps: int) -> None:
        """The FeedbackReceiver of a movie: one DataFeedback per frame."""
        assert self.service is not None
        period = 1.0 / fps
        loop = asyncio.get_running_loop()
        next_frame = loop.time()
        while True:
            self.service.data_feedback.post(await self.camera.grab(1))
            next_frame += period
            await asyncio.sleep(max(0.0, next_frame - loop.time()) * self.camera.time_scale)

    async def _stop_movie(self) -> None:
        movie, self._movie = self._movie, None
        if movie is not None:
            movie.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await movie
