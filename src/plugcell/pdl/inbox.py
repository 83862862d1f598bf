"""The thread-safe mailbox through which services set program variables.

Other threads :meth:`put` batches of already-converted values; the interpreter
thread :meth:`drain`\\ s them between statements (and while it WAITs), so a batch
(e.g. ``ext_cmd_result`` then ``ext_cmd_finished``) is applied atomically and in
order, never in the middle of a statement.
"""

from __future__ import annotations

import threading
from collections import deque
from typing import Any

__all__ = ["Inbox"]


class Inbox:
    """Batches of ``(variable info, value)`` pairs, with a change counter to wait on."""

    def __init__(self) -> None:
        self._cond = threading.Condition()
        self._batches: deque[list[tuple[Any, Any]]] = deque()
        self._version = 0

    def put(self, batch: list[tuple[Any, Any]]) -> None:
        """Queue one batch and wake the interpreter."""
        with self._cond:
            self._batches.append(batch)
            self._version += 1
            self._cond.notify_all()

    def drain(self) -> list[list[tuple[Any, Any]]]:
        """Take every queued batch, oldest first."""
        with self._cond:
            out = list(self._batches)
            self._batches.clear()
            return out

    @property
    def version(self) -> int:
        """Increases with every :meth:`put` and :meth:`wake`."""
        with self._cond:
            return self._version

    def pending(self) -> bool:
        """Whether batches are waiting (cheap, lock-free peek)."""
        return bool(self._batches)

    def wait_change(self, seen: int, timeout: float) -> bool:
        """Block up to ``timeout`` real seconds until :attr:`version` differs from ``seen``."""
        with self._cond:
            return self._cond.wait_for(lambda: self._version != seen, timeout=max(0.0, timeout))

    def wake(self) -> None:
        """Wake a waiting interpreter (used by ``stop``)."""
        with self._cond:
            self._version += 1
            self._cond.notify_all()
