"""A service's outbox: what one event-loop turn tells senders, durable first, then batched.

Acknowledgements of CreateProcess and ProcessUpdates collect during a turn of the
service's event loop; :meth:`Outbox.flush` (scheduled once per turn, or at once for a
final update) commits the journal — every accepted process and every update is durable
before anyone can see it — then sends them: the updates for one sender in one sample
(a :class:`~plugcell.framework.messages.ProcessUpdateBatch` when there are several, up to
:data:`BATCH_BYTES` of data each, its acknowledgements first; docs/protocol.md,
"Batches").  A data-less Running update whose process ends within the same flush is
journaled but not sent (its ``seq`` is skipped): the final update supersedes it.

The outbox knows no Zenoh key and no session: the service gives it four seams —
``commit()`` (the journal), ``reply(query, body)`` (an acknowledgement answering a
query), ``publish(sender, body)`` (one sample on the sender's process key) and
``is_open()`` (the session still serves).
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable
from typing import Any

from plugcell.framework.messages import (
    Acknowledgement,
    Message,
    ProcessStates,
    ProcessUpdateBatch,
    ProcessUpdateNotification,
)
from plugcell.framework.processqueue import Entry

log = logging.getLogger("plugcell.framework.outbox")

#: Largest data (bytes) one :class:`ProcessUpdateBatch` carries; a frame larger than
#: this travels alone.  1 MiB lets a burst of 64 KiB – 0.3 MB frames share a sample
#: (64 KiB was the limit before: each 64 KiB frame then paid a put, a hop and a decode
#: of its own — docs/results/framework-performance.md, "Batches of large frames").
BATCH_BYTES = 1024 * 1024


class Outbox:
    """Acknowledgements and updates of one event-loop turn (module docstring).

    Parameters
    ----------
    owner : str
        The service's name (for the log).
    commit : callable
        ``commit()``: makes everything journaled so far durable.
    reply : callable
        ``reply(query, body)``: answers a CreateProcess that came as a query.
    publish : callable
        ``publish(sender, body)``: one sample for ``sender`` on its process key.
    is_open : callable
        ``is_open()``: whether the session can still send.
    """

    def __init__(self, owner: str, *, commit: Callable[[], None],
                 reply: Callable[[Any, Message], None],
                 publish: Callable[[str, Message], None],
                 is_open: Callable[[], bool]) -> None:
        self.owner = owner
        self._commit = commit
        self._reply = reply
        self._publish = publish
        self._is_open = is_open
        self._acks: list[tuple[Any, Acknowledgement]] = []
        self._updates: list[tuple[Entry, ProcessUpdateNotification]] = []
        self._scheduled = False
        self.loop: asyncio.AbstractEventLoop | None = None
        """The service's event loop (set when it starts): where :meth:`flush_soon` runs."""

    def __bool__(self) -> bool:
        """Whether anything waits to be sent."""
        return bool(self._acks or self._updates)

    def acknowledge(self, answer: Any, ack: Acknowledgement) -> None:
        """Acknowledge a CreateProcess at the next flush (``answer``: its query, or the
        name of the sender that published it)."""
        self._acks.append((answer, ack))
        self.flush_soon()

    def update(self, entry: Entry, update: ProcessUpdateNotification) -> None:
        """Send ``update`` of ``entry``'s process: at once when final, else this turn."""
        self._updates.append((entry, update))
        if update.state.final:
            self.flush()
        else:
            self.flush_soon()

    def flush_soon(self) -> None:
        """Flush once, at the end of this turn of the event loop."""
        if not self._scheduled and self.loop is not None:
            self._scheduled = True
            self.loop.call_soon(self.flush)

    def flush(self) -> None:
        """Commit the journal, then acknowledge and publish what it now holds."""
        self._scheduled = False
        if not self:
            return
        try:
            self._commit()
        except Exception:  # a full disk must not silence the service
            log.exception("%s: journal commit failed", self.owner)
        acks, self._acks = self._acks, []
        to_senders: dict[str, list[Acknowledgement]] = {}
        for answer, ack in acks:
            if isinstance(answer, str):
                to_senders.setdefault(answer, []).append(ack)
            else:
                self._reply(answer, ack)
        updates, self._updates = self._updates, []
        if not self._is_open():
            return
        ended = {id(entry) for entry, update in updates if update.state.final}
        batch: list[ProcessUpdateNotification] = []
        sender, size = "", 0
        for entry, update in updates:
            if (update.state is ProcessStates.Running and update.data is None
                    and id(entry) in ended):
                continue
            nbytes = len(update.data.buffer) if update.data is not None else 0
            if batch and (entry.sender != sender or size + nbytes > BATCH_BYTES):
                self._send(sender, to_senders.pop(sender, []), batch)
                batch, size = [], 0
            batch.append(update)
            sender, size = entry.sender, size + nbytes
        if batch:
            self._send(sender, to_senders.pop(sender, []), batch)
        for sender, acknowledgements in to_senders.items():
            self._send(sender, acknowledgements, [])

    def _send(self, sender: str, acks: list[Acknowledgement],
              updates: list[ProcessUpdateNotification]) -> None:
        """Acknowledgements, then updates, for ``sender`` in one sample."""
        body: Message
        if len(acks) + len(updates) == 1:
            body = acks[0] if acks else updates[0]
        else:
            body = ProcessUpdateBatch(acks=acks, updates=updates)
        self._publish(sender, body)
