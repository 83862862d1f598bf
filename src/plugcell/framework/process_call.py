"""A process as its sender sees it: the acknowledgement and the stream of ProcessUpdates.

This is the requester half of 5.2.3.6 (the ``ExternalProcessHandler`` of Figure
5-14): after ``CreateProcess`` the sender receives ``ProcessUpdate`` notifications
until the process is Completed or Failed.  Every wait is bounded: if no update
arrives within ``timeout`` seconds, or the recipient dies or shuts down, the
stream ends with a *local* Failed update (``seq == 0``) whose ``reason`` says why.
"""

from __future__ import annotations

import asyncio
from collections import deque
from typing import TYPE_CHECKING, Any

from plugcell.framework.data import from_data
from plugcell.framework.messages import (
    Acknowledgement,
    ProcessStates,
    ProcessUpdateNotification,
    Tag,
)

if TYPE_CHECKING:
    import numpy as np


class ProcessCall:
    """Acknowledgement + async iterator of the updates of one process."""

    def __init__(
        self,
        sender: str,
        partner: str,
        command: str,
        identifier: int,
        timeout: float,
        loop: asyncio.AbstractEventLoop,
    ) -> None:
        self.partner = partner
        self.command = command
        self.identifier = identifier
        self.timeout = timeout
        self.tag = Tag(sender, partner)
        self.ack: Acknowledgement | None = None
        self._synthetic_ack = False
        self.instance = ""
        """The recipient incarnation that acknowledged the process."""
        self.final: ProcessUpdateNotification | None = None
        self.sent_ns = 0
        self._loop = loop
        self._acked: asyncio.Future[Acknowledgement] = loop.create_future()
        self._ack_waiters: list[asyncio.Future[None]] = []
        self._updates: deque[ProcessUpdateNotification] = deque()
        self._waiter: asyncio.Future[None] | None = None
        self._delivered_final = False
        self._last_seq = 0
        self._heard = 0.0
        """Loop time of the last sign of life of the process (an update or a heartbeat)."""

    def __repr__(self) -> str:
        state = (
            self.final.state.value if self.final else (self.ack.state.value if self.ack else "?")
        )
        return f"<ProcessCall {self.partner}.{self.command} #{self.identifier} {state}>"

    # -- fed by the participant (event-loop thread) -------------------------------------

    def acknowledge(self, ack: Acknowledgement, instance: str) -> None:
        """The recipient's acknowledgement arrived (from its incarnation ``instance``)."""
        if self._acked.done():
            # the real acknowledgement after an update overtook it: keep the real one
            if self._synthetic_ack and ack.state is not ProcessStates.Failed:
                self.ack = ack
                self._synthetic_ack = False
            self.instance = self.instance or instance or ack.instance
            return
        self.ack = ack
        self.instance = instance or ack.instance
        self._acked.set_result(ack)
        for waiter in self._ack_waiters:
            _wake(waiter)
        if ack.state is ProcessStates.Failed:
            self._push(self._local(ack.reason or "rejected"))

    def receive(self, update: ProcessUpdateNotification, instance: str = "") -> None:
        """A ProcessUpdate of the recipient arrived (a Queued one is a heartbeat; one that
        overtook the acknowledgement acknowledges Queued)."""
        if self.final is not None or update.seq <= self._last_seq:
            return
        self._last_seq = update.seq
        if update.state is ProcessStates.Queued:  # still waiting in the queue: heartbeat
            self._heard = self._loop.time()
            if not self._acked.done():
                self.acknowledge(Acknowledgement(identifier=self.identifier,
                                             state=ProcessStates.Queued, instance=instance),
                             instance)
                self._synthetic_ack = True
            waiter = self._waiter
            if waiter is not None and not waiter.done():
                waiter.set_result(None)  # re-arm the inactivity timer
            return
        if not self._acked.done():  # the update overtook the acknowledgement
            self.acknowledge(
                Acknowledgement(
                    identifier=self.identifier, state=ProcessStates.Queued, instance=instance
                ),
                instance,
            )
            self._synthetic_ack = True
        self._push(update)

    def fail(self, reason: str) -> None:
        """End the process locally (recipient lost, shut down, timed out …): a Failed
        acknowledgement if none came yet, else a local Failed update (``seq == 0``)."""
        if self.final is not None:
            return
        if not self._acked.done():
            self.acknowledge(
                Acknowledgement(
                    identifier=self.identifier, state=ProcessStates.Failed, reason=reason
                ),
                "",
            )
            return
        self._push(self._local(reason))

    def _local(self, reason: str) -> ProcessUpdateNotification:
        return ProcessUpdateNotification(
            tag=self.tag,
            identifier=self.identifier,
            state=ProcessStates.Failed,
            reason=reason,
            seq=0,
        )

    def _push(self, update: ProcessUpdateNotification) -> None:
        if self.final is not None:
            return
        if update.state.final:
            self.final = update
        self._updates.append(update)
        waiter, self._waiter = self._waiter, None
        if waiter is not None and not waiter.done():
            waiter.set_result(None)

    # -- public ------------------------------------------------------------------------

    @property
    def done(self) -> bool:
        """Whether the final update has arrived."""
        return self.final is not None

    async def acknowledged(self) -> Acknowledgement:
        """The acknowledgement (waits at most ``timeout``; a timeout acknowledges Failed)."""
        if not self._acked.done():
            waiter = self._loop.create_future()
            self._ack_waiters.append(waiter)
            handle = self._loop.call_later(self.timeout, _wake, waiter)
            try:
                await waiter  # woken by _on_ack itself: no extra turn of the loop
            finally:
                handle.cancel()
                self._ack_waiters.remove(waiter)
            if not self._acked.done():
                self.fail(f"no acknowledgement from {self.partner} within {self.timeout:g} s")
        return self._acked.result()

    def __aiter__(self) -> ProcessCall:
        return self

    async def __anext__(self) -> ProcessUpdateNotification:
        if self._delivered_final and not self._updates:
            raise StopAsyncIteration
        self._heard = self._loop.time()
        while not self._updates:
            left = self._heard + self.timeout - self._loop.time()
            if left <= 0:
                self.fail(f"no update from {self.partner} within {self.timeout:g} s")
                break
            waiter = self._waiter = self._loop.create_future()
            handle = self._loop.call_later(left, _wake, waiter)
            try:
                await waiter
            finally:
                handle.cancel()
                self._waiter = None
        update = self._updates.popleft()
        if update.state.final:
            self._delivered_final = True
        return update

    async def result(self) -> ProcessUpdateNotification:
        """Wait for the final update (Completed or Failed) and return it."""
        async for _ in self:
            pass
        assert self.final is not None
        return self.final

    @staticmethod
    def array(update: ProcessUpdateNotification) -> np.ndarray | Any:
        """The data of an update as an n-D numpy array (None if it carries none): for
        numbers a read-only view into the bytes of the sample it came in (no copy)."""
        return from_data(update.data)


def _wake(waiter: asyncio.Future[None]) -> None:
    if not waiter.done():
        waiter.set_result(None)
