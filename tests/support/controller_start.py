"""Starting a streamed robot service and its controller in the order a user keeps."""

from __future__ import annotations

import asyncio
from typing import Any


async def start_with_controller(service: Any, controller: Any) -> None:
    """Start ``service`` and, once its link listens, the controller (``controller.start``,
    blocking, run in a thread) — the order a user keeps: ``serve robot`` first, and the
    robot's program (RSI_ON, EGMRunJoint) after the service said it listens.  Started
    together, a loaded machine let the service's cell join (Zenoh, the duplicate-name
    query) outlast the controller's own timeout counted from its first packet (the
    twin's EGM \\CommTimeout of 4 s), and the stream was over before the link listened.
    """
    starting = asyncio.create_task(service.start())
    listening = asyncio.create_task(service.interface.bridge.listening.wait())
    done, _ = await asyncio.wait({starting, listening}, return_when=asyncio.FIRST_COMPLETED)
    if starting in done:  # failed (or finished) before its link listened
        listening.cancel()
        await starting
        return
    await asyncio.to_thread(controller.start)
    await starting
