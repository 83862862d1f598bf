"""The event loop every plugcell process runs on: uvloop where it exists, else asyncio's.

A message crossing a service costs a few wake-ups of its event loop (a Zenoh
callback posting to the :class:`~plugcell.framework.port.Port`, the process
handler, the receiver); uvloop (libuv) makes each of them cheaper than the
pure-Python selector loop — about a fifth of the CreateProcess→ProcessUpdate
latency of ``plugcell bench transport`` on the development machine.  Code written
for asyncio runs unchanged on either; ``PLUGCELL_UVLOOP=0`` chooses asyncio's loop.
"""

from __future__ import annotations

import asyncio
import os
from collections.abc import Coroutine
from typing import Any, TypeVar

T = TypeVar("T")


def _uvloop() -> Any:
    if os.environ.get("PLUGCELL_UVLOOP", "1") in ("0", "false", "no"):
        return None
    try:
        import uvloop
    except ImportError:  # not on this platform (Windows): asyncio's loop
        return None
    return uvloop


def run(main: Coroutine[Any, Any, T]) -> T:
    """``asyncio.run(main)`` on the plugcell event loop."""
    uvloop = _uvloop()
    if uvloop is None:
        return asyncio.run(main)
    with asyncio.Runner(loop_factory=uvloop.new_event_loop) as runner:
        return runner.run(main)


def new_event_loop() -> asyncio.AbstractEventLoop:
    """A new plugcell event loop (for a loop run in a thread of its own)."""
    uvloop = _uvloop()
    return uvloop.new_event_loop() if uvloop is not None else asyncio.new_event_loop()


def name() -> str:
    """``"uvloop"`` or ``"asyncio"``: the loop :func:`run` uses."""
    return "uvloop" if _uvloop() is not None else "asyncio"
