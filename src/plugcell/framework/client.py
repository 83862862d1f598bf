"""The client API: async (:class:`Client`) and blocking (:class:`BlockingClient`).

Async::

    async with Client(cell="lab") as client:
        call = await client.create_process("CAMERA", "SnapShot", "", 500)
        print(call.ack)                       # Acknowledgement (Queued or Failed + reason)
        async for update in call:             # ProcessUpdates until Completed/Failed
            print(update.state, call.array(update))

Blocking (scripts, notebooks, tests) — the same calls, run in a private event loop
thread::

    with BlockingClient(cell="lab") as client:
        call = client.create_process("TOOL", "Drill", "Air", [550, 1100])
        for update in call:
            print(update.state)
"""

from __future__ import annotations

import asyncio
import threading
from collections.abc import Coroutine, Iterator
from typing import Any, TypeVar

from plugcell.framework import eventloop
from plugcell.framework.keys import DEFAULT_CELL
from plugcell.framework.messages import (
    Acknowledgement,
    Device,
    GenericDeviceState,
    ProcessUpdateNotification,
    SubscribeResponse,
)
from plugcell.framework.participant import Participant
from plugcell.framework.process_call import ProcessCall
from plugcell.framework.transport import TransportConfig

T = TypeVar("T")

#: The async client is a participant without an inbound side.
Client = Participant

_MARGIN = 5.0


class BlockingProcessCall:
    """A :class:`ProcessCall` seen from blocking code: ``ack``, iteration, ``result()``."""

    def __init__(self, client: BlockingClient, call: ProcessCall) -> None:
        self._client = client
        self.call = call

    @property
    def ack(self) -> Acknowledgement:
        assert self.call.ack is not None
        return self.call.ack

    @property
    def identifier(self) -> int:
        return self.call.identifier

    @property
    def final(self) -> ProcessUpdateNotification | None:
        return self.call.final

    def __iter__(self) -> Iterator[ProcessUpdateNotification]:
        while True:
            try:
                yield self._client._run(self.call.__anext__(), self.call.timeout)
            except StopAsyncIteration:
                return

    def result(self) -> ProcessUpdateNotification:
        """Wait for and return the final update."""
        for _ in self:
            pass
        assert self.call.final is not None
        return self.call.final

    array = staticmethod(ProcessCall.array)


class BlockingClient:
    """A :class:`Client` driven from blocking code (its event loop runs in a thread)."""

    def __init__(
        self,
        name: str | None = None,
        *,
        cell: str = DEFAULT_CELL,
        transport: TransportConfig | None = None,
    ) -> None:
        self._loop = eventloop.new_event_loop()
        self._thread = threading.Thread(
            target=self._loop.run_forever, name="plugcell-client", daemon=True
        )
        self._thread.start()
        self.participant = Participant(name, cell=cell, transport=transport)
        try:
            self._run(self.participant.start(), 30.0)
        except BaseException:
            self._stop_loop()
            raise

    def _run(self, coro: Coroutine[Any, Any, T], timeout: float) -> T:
        future = asyncio.run_coroutine_threadsafe(coro, self._loop)
        return future.result(timeout + _MARGIN)

    @property
    def name(self) -> str:
        return self.participant.name

    def services(self) -> list[str]:
        """Names of the live services (from presence)."""
        return self.participant.services()

    def wait_for(self, name: str, timeout: float = 10.0) -> bool:
        return self._run(self.participant.wait_for(name, timeout), timeout)

    def wait_gone(self, name: str, timeout: float = 10.0) -> bool:
        return self._run(self.participant.wait_gone(name, timeout), timeout)

    def get(self, name: str, timeout: float = 5.0) -> GenericDeviceState:
        return self._run(self.participant.get(name, timeout), timeout)[0]

    def list_services(self, timeout: float = 3.0) -> list[GenericDeviceState]:
        return self._run(self.participant.list_services(timeout), timeout)

    def subscribe(self, partner: str, timeout: float = 5.0) -> Device:
        return self._run(self.participant.subscribe(partner, timeout), timeout)

    def unsubscribe(self, partner: str) -> bool:
        return self._run(self.participant.unsubscribe(partner), 5.0)

    def ask_subscribe(
        self, service: str, partner: str, subscribe: bool = True, timeout: float = 10.0
    ) -> SubscribeResponse:
        return self._run(
            self.participant.ask_subscribe(service, partner, subscribe, timeout), timeout
        )

    def create_process(
        self,
        partner: str,
        command: str,
        option: str = "",
        data: Any = None,
        *,
        timeout: float = 10.0,
        check: bool = True,
    ) -> BlockingProcessCall:
        """``CreateProcess`` at ``partner``: returns once acknowledged (see :class:`Client`)."""
        call = self._run(
            self.participant.create_process(
                partner, command, option, data, timeout=timeout, check=check
            ),
            2 * timeout,
        )
        return BlockingProcessCall(self, call)

    def stop_process(
        self, call: BlockingProcessCall, command: str | None = None
    ) -> BlockingProcessCall:
        """Send the StopData command ending a MultipleData process."""
        stop = self._run(self.participant.stop_process(call.call, command), 2 * call.call.timeout)
        return BlockingProcessCall(self, stop)

    def close(self) -> None:
        """Close the participant and stop the loop thread."""
        if self._loop.is_closed():
            return
        try:
            self._run(self.participant.close(), 10.0)
        finally:
            self._stop_loop()

    def _stop_loop(self) -> None:
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(timeout=10.0)
        if not self._thread.is_alive():
            self._loop.close()

    def __enter__(self) -> BlockingClient:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
