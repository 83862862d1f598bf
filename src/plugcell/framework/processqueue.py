"""The process queue of a service (thesis 4.1.4, 5.2.3.4–5.2.3.5, Figures 4-6 and 5-13).

A FIFO task queue instead of locks: one process runs at a time.  While a
MultipleData process holds the device, the only process that may run next is the
StopData of the *same sender*; every other process stays queued in its order
(the thesis re-posts them to the port; keeping them in place is the same order
without the busy loop).  Nothing is ever dropped by the scheduler — processes
leave the queue only to run, or when their sender is gone or the service shuts
down, and then they end Failed with the reason.

Used from the service's event loop only; waiting never holds anything.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import time
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

from plugcell.framework.messages import Command, CommandTypes, Process


@dataclass(eq=False)
class Entry:
    """A process accepted by a service, with what the service knows about it."""

    process: Process
    command: Command
    """The recipient's own catalogue entry for ``process.command.name``."""
    instance: str = ""
    """The sender's incarnation (its Zenoh id), from the envelope."""
    received_ns: int = field(default_factory=time.time_ns)
    input: Any = None
    """The checked input data as a numpy array (None for no data)."""
    seq: int = 0
    """Number of ProcessUpdates sent so far."""
    abort_reason: str = ""
    """Set while running to ask the ProcessHandler to stop this process."""

    @functools.cached_property
    def sender(self) -> str:
        return self.process.tag.sender

    @functools.cached_property
    def identifier(self) -> int:
        return self.process.identifier

    @property
    def type(self) -> CommandTypes:
        return self.command.type


class ProcessQueue:
    """FIFO of :class:`Entry` with the re-scheduling rule of 5.2.3.5."""

    def __init__(self) -> None:
        self._items: deque[Entry] = deque()
        self._changed = asyncio.Event()

    def __len__(self) -> int:
        return len(self._items)

    def __iter__(self) -> Iterator[Entry]:
        return iter(list(self._items))

    def post(self, entry: Entry) -> None:
        """Append a process (``ProcessQueue.Post`` of the CreateProcessHandler)."""
        self._items.append(entry)
        self._changed.set()

    def poke(self) -> None:
        """Wake whoever waits, e.g. because a running process must be aborted."""
        self._changed.set()

    def take_next(self) -> Entry | None:
        """The oldest process when the device is free, or None if the queue is empty."""
        return self._items.popleft() if self._items else None

    def take_stop_for(self, sender: str) -> Entry | None:
        """While ``sender``'s MultipleData process runs: its first StopData, others keep order."""
        for entry in self._items:
            if entry.type is CommandTypes.StopData and entry.sender == sender:
                self._items.remove(entry)
                return entry
        return None

    def remove_if(self, predicate: Callable[[Entry], bool]) -> list[Entry]:
        """Take out every queued process matching ``predicate`` (kept order for the rest)."""
        gone = [e for e in self._items if predicate(e)]
        if gone:
            self._items = deque(e for e in self._items if not predicate(e))
            self._changed.set()
        return gone

    async def wait(self, timeout: float | None) -> None:
        """Return when the queue changed or was poked, or after ``timeout`` seconds."""
        self._changed.clear()
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(self._changed.wait(), timeout)
