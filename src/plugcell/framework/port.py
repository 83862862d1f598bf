"""A CCR-style Port: a FIFO message queue any thread may post to (thesis appendix E.1).

Zenoh calls its callbacks on its own threads and forbids calling Zenoh or
blocking inside them, so every callback of plugcell does exactly one thing:
``port.post(item)``.  The owning participant's event loop hands the items, in
order, to one receiver.  The lock only guards the deque; it is never held across
a wait.  The loop is woken once per burst, not once per message — the receiver
runs directly in that wake-up (no task switch in between), which is what keeps
both the latency of one message and the cost of high notification rates low.
"""

from __future__ import annotations

import asyncio
import contextlib
import threading
from collections import deque
from collections.abc import Callable
from typing import Generic, TypeVar

T = TypeVar("T")


class Port(Generic[T]):
    """FIFO queue: ``post`` from any thread; ``receiver(items)`` runs in the loop."""

    def __init__(
        self, loop: asyncio.AbstractEventLoop, receiver: Callable[[list[T]], None]
    ) -> None:
        self._loop = loop
        self._receiver = receiver
        self._items: deque[T] = deque()
        self._lock = threading.Lock()
        self._scheduled = False
        self._closed = False

    def post(self, item: T) -> None:
        """Enqueue ``item``; safe from any thread, never blocks."""
        with self._lock:
            if self._closed:
                return
            self._items.append(item)
            if self._scheduled:
                return
            self._scheduled = True
        with contextlib.suppress(RuntimeError):  # loop closed under a late callback
            self._loop.call_soon_threadsafe(self._drain)

    def _drain(self) -> None:
        with self._lock:
            items = list(self._items)
            self._items.clear()
            self._scheduled = False
        if items:
            self._receiver(items)

    def close(self) -> None:
        """Drop pending items and refuse new ones."""
        with self._lock:
            self._closed = True
            self._items.clear()

    @property
    def closed(self) -> bool:
        return self._closed

    def __len__(self) -> int:
        return len(self._items)
