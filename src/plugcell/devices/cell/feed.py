"""What the cell controller's listeners (the web UI) hear: its feed.

The cell controller (``controller.py``) changes its picture of the cell many times a
second — a service joins, a wire is applied, a process streams frames.  A listener
wants each change once and at a pace a browser can draw, so the feed

* keeps the **activity log** (the last :data:`LOG_LINES` lines, each also logged) and
  sends each line at once;
* collects **dirty marks** — "the cell changed" and "this process changed" — and every
  :data:`FLUSH_PERIOD` seconds sends one ``cell`` event and one ``processes`` event for
  all of them (a process that changed 50 times in a period is sent once);
* gives each listener its own bounded queue; one that falls behind is emptied and told
  ``{"type": "resync"}`` (it should ask for a new snapshot), so a slow browser never
  holds the controller back.

It knows nothing of Zenoh or of the services: what a ``cell`` or a ``processes`` event
holds is asked of its ``cell`` and ``processes`` seams when it is flushed.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections import deque
from collections.abc import Callable, Iterable
from typing import Any

#: Seconds between two batches of changes to listeners.
FLUSH_PERIOD = 0.1
#: Lines of the activity log kept.
LOG_LINES = 300

Event = dict[str, Any]
ProcessKey = tuple[str, str, int]
"""A monitored process: (recipient, sender, identifier)."""


class UiFeed:
    """Events to listeners, the activity log and batched change marks (module doc).

    Parameters
    ----------
    name
        The controller's name (in log lines).
    cell
        Returns the body of a ``cell`` event (services, clients, wiring).
    processes
        Given the changed process keys, returns the body of a ``processes`` event.
    log
        Where activity lines are logged too.
    """

    def __init__(
        self,
        name: str,
        *,
        cell: Callable[[], dict[str, Any]],
        processes: Callable[[Iterable[ProcessKey]], dict[str, Any]],
        log: logging.Logger,
    ) -> None:
        self.name = name
        self._cell = cell
        self._processes = processes
        self._log = log
        self.activity: deque[dict[str, Any]] = deque(maxlen=LOG_LINES)
        """The last lines of the activity log, oldest first."""
        self._listeners: set[asyncio.Queue[Event]] = set()
        self._changed: set[ProcessKey] = set()
        self._cell_changed = False
        self._pending = asyncio.Event()

    # -- listeners ---------------------------------------------------------------------

    def listen(self, maxsize: int = 2000) -> asyncio.Queue[Event]:
        """A queue of events from now on (``{"type": …}``); :meth:`unlisten` when done.

        If a listener falls behind, its queue is emptied and it gets one
        ``{"type": "resync"}``: it should ask for a new snapshot.
        """
        queue: asyncio.Queue[Event] = asyncio.Queue(maxsize)
        self._listeners.add(queue)
        return queue

    def unlisten(self, queue: asyncio.Queue[Event]) -> None:
        """Stop sending to ``queue``."""
        self._listeners.discard(queue)

    def emit(self, event: Event) -> None:
        """Send ``event`` to every listener now."""
        for queue in list(self._listeners):
            try:
                queue.put_nowait(event)
            except asyncio.QueueFull:
                while not queue.empty():
                    queue.get_nowait()
                queue.put_nowait({"type": "resync"})

    # -- the activity log and the change marks -------------------------------------------

    def log(self, level: str, text: str) -> None:
        """A line of the activity log (``level``: info | warning | error), logged and sent."""
        line = {"t": time.time_ns(), "level": level, "text": text}
        self.activity.append(line)
        getattr(self._log, "warning" if level == "error" else "info")("%s: %s", self.name, text)
        self.emit({"type": "log", "line": line})

    def cell_changed(self) -> None:
        """The services, clients or wiring changed: a ``cell`` event at the next flush."""
        self._cell_changed = True
        self._pending.set()

    def process_changed(self, key: ProcessKey) -> None:
        """A monitored process changed: it is in the next ``processes`` event."""
        self._changed.add(key)
        self._pending.set()

    def flush(self) -> None:
        """Send what changed since the last flush (at most one event of each type)."""
        if self._cell_changed:
            self._cell_changed = False
            self.emit({"type": "cell", **self._cell()})
        if self._changed:
            keys, self._changed = self._changed, set()
            self.emit({"type": "processes", **self._processes(keys)})

    async def run(self) -> None:
        """Flush :data:`FLUSH_PERIOD` seconds after the first change since the last flush,
        until cancelled (an idle cell does not wake the loop)."""
        while True:
            await self._pending.wait()
            await asyncio.sleep(FLUSH_PERIOD)
            self._pending.clear()
            self.flush()


__all__ = ["FLUSH_PERIOD", "LOG_LINES", "UiFeed"]
