"""A CCR-style Port: a FIFO message queue any thread may post to (thesis appendix E.1).

Zenoh calls its callbacks on its own threads and forbids calling Zenoh or
blocking inside them, so every callback of plugcell does exactly one thing:
``port.post(item)``.  One asyncio task of the owning participant receives the
items in order.  The lock only guards the deque append/pop; it is never held
across a wait.  The event loop is woken once per burst, not once per message,
which is what keeps high notification rates cheap.
"""

from __future__ import annotations

import asyncio
import contextlib
import threading
from collections import deque
from typing import Generic, TypeVar

T = TypeVar("T")


class Port(Generic[T]):
    """FIFO queue: ``post`` from any thread, ``receive``/``receive_all`` in the loop."""

    def __init__(self, loop: asyncio.AbstractEventLoop) -> None:
        self._loop = loop
        self._items: deque[T] = deque()
        self._lock = threading.Lock()
        self._waiter: asyncio.Future[None] | None = None
        self._closed = False

    def post(self, item: T) -> None:
        """Enqueue ``item``; safe from any thread, never blocks."""
        with self._lock:
            if self._closed:
                return
            self._items.append(item)
            waiter, self._waiter = self._waiter, None
        if waiter is not None:
            with contextlib.suppress(RuntimeError):  # loop closed under a late callback
                self._loop.call_soon_threadsafe(_wake, waiter)

    def close(self) -> None:
        """Drop pending items, refuse new ones and release a waiting receiver."""
        with self._lock:
            self._closed = True
            self._items.clear()
            waiter, self._waiter = self._waiter, None
        if waiter is not None and not waiter.done():
            waiter.set_result(None)

    @property
    def closed(self) -> bool:
        return self._closed

    def __len__(self) -> int:
        return len(self._items)

    async def receive_all(self) -> list[T]:
        """Everything posted so far (at least one item), in order; ``[]`` once closed."""
        while True:
            with self._lock:
                if self._items:
                    items = list(self._items)
                    self._items.clear()
                    return items
                if self._closed:
                    return []
                waiter = self._loop.create_future()
                self._waiter = waiter
            await waiter


def _wake(waiter: asyncio.Future[None]) -> None:
    if not waiter.done():
        waiter.set_result(None)
