"""A simulated 8-bit grayscale camera controller, 640×480, up to 80 frames/s.

Stands in for the Cognex camera of the thesis's CameraService template (5.2.3.3:
"Specs: 640x480, 8bit Grayscale, Framerate: 80fps").  Images are deterministic:
a gradient with a bright disc that moves one step per frame, brightness
proportional to the exposure time, so tests can check what they receive.
"""

from __future__ import annotations

import asyncio
from typing import ClassVar

import numpy as np

from plugcell.devices.camera import EXPOSURE_MS, HEIGHT, WIDTH, CameraError


class SimulatedCamera:
    """The camera controller: connect, grab a frame with an exposure time (a
    :class:`~plugcell.devices.camera.CameraDriver`)."""

    params: ClassVar[dict[str, type]] = {"time_scale": float}
    """What ``plugcell serve camera --param K=V`` sets."""

    def __init__(self, time_scale: float = 1.0, shape: tuple[int, int] = (HEIGHT, WIDTH)) -> None:
        self.time_scale = time_scale
        self.shape = shape
        self.connected = False
        self.frames = 0
        rows, cols = np.mgrid[0 : shape[0], 0 : shape[1]]
        self._rows, self._cols = rows, cols
        self._base = (cols * 200 // max(shape[1] - 1, 1)).astype(np.float32)

    async def connect(self) -> None:
        await asyncio.sleep(0)
        self.connected = True

    async def disconnect(self) -> None:
        await asyncio.sleep(0)
        self.connected = False

    def image(self, exposure_ms: int) -> np.ndarray:
        """The frame the sensor sees after ``exposure_ms`` (no waiting)."""
        cy = (self.frames * 7) % self.shape[0]
        cx = (self.frames * 11) % self.shape[1]
        disc = ((self._rows - cy) ** 2 + (self._cols - cx) ** 2) < 40**2
        gain = min(exposure_ms / 10.0, 1.0)
        img = self._base * gain + disc * 55.0
        self.frames += 1
        return np.clip(img, 0, 255).astype(np.uint8)

    async def grab(self, exposure_ms: int) -> np.ndarray:
        """Expose for ``exposure_ms`` (scaled by ``time_scale``) and return the image."""
        if not self.connected:
            raise CameraError("camera offline: send Connect first")
        lo, hi = EXPOSURE_MS
        if not lo <= exposure_ms <= hi:
            raise CameraError(f"exposure {exposure_ms} ms outside {lo}…{hi} ms")
        await asyncio.sleep(exposure_ms / 1000.0 * self.time_scale)
        return self.image(exposure_ms)
