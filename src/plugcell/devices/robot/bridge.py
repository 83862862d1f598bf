"""The robot service's end of the controller link (docs/controller-protocol.md).

In the thesis the robot service reached the C3G controller over RS-232 (7.2); here
it is one TCP connection to the controller, simulated or real, carrying the line
protocol.  :class:`ControllerBridge` is an asyncio client that

* connects and reads the controller's ``HELLO`` (who it is, the robot, the
  capacity of the program's data variables);
* sends requests with an identifier and waits — bounded — for the matching
  ``OK``/``ERR`` (:meth:`request`, :meth:`run`): :class:`ControllerError` carries
  the controller's reason (e.g. a program's ``file:line:column: message``);
* sends the handshake and data to the running program (:meth:`send`);
* hands what the controller sends on its own — the program's ACTIVATE strings,
  garbled lines, program events — to a :class:`BridgeHandler`, in order, in the
  event loop;
* notices a dropped connection at once: every pending request fails with
  :class:`BridgeError` and the handler's ``on_lost`` is called.

It knows nothing of services or Zenoh: it is the protocol seen from the PC side.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import logging
from collections.abc import Mapping
from typing import Protocol

from plugcell.devices.robot.framing import FramingError, LineBuffer, frame_line
from plugcell.devices.robot.protocol import (
    MAX_ID,
    VERSION,
    ActivateLine,
    Console,
    Hello,
    Message,
    ProgramEnded,
    ProgramStarted,
    ProtocolError,
    Reply,
    Request,
    Run,
    Value,
    decode,
    encode,
)

__all__ = ["BridgeError", "BridgeHandler", "ControllerBridge", "ControllerError", "parse_address"]

log = logging.getLogger("plugcell.devices.robot.bridge")

LOST = "connection to the controller lost"


class BridgeError(ConnectionError):
    """No connection, a dropped one, or no answer in time; the text says which."""


class ControllerError(RuntimeError):
    """The controller refused a request (``ERR``); the text is its reason."""


class BridgeHandler(Protocol):
    """What the controller sends unasked (called in the event loop, in order)."""

    def on_activate(self, line: ActivateLine) -> None: ...

    def on_garbled(self, line: str, reason: str) -> None: ...

    def on_started(self, event: ProgramStarted) -> None: ...

    def on_ended(self, event: ProgramEnded) -> None: ...

    def on_console(self, event: Console) -> None: ...

    def on_lost(self, reason: str) -> None: ...


def parse_address(text: str) -> tuple[str, int]:
    """``HOST:PORT`` → (host, port); ValueError with the reason."""
    host, sep, port = text.strip().rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise ValueError(f"bad controller address {text!r}: expected HOST:PORT")
    return host.strip("[]"), int(port)


class ControllerBridge:
    """One connection to a robot controller."""

    def __init__(self, handler: BridgeHandler, *, request_timeout: float = 30.0) -> None:
        self.handler = handler
        self.request_timeout = request_timeout
        self.hello: Hello | None = None
        self.address = ""
        self._reader: asyncio.StreamReader | None = None
        self._writer: asyncio.StreamWriter | None = None
        self._read_task: asyncio.Task[None] | None = None
        self._pending: dict[int, asyncio.Future[Reply]] = {}
        self._ids = itertools.count(1)
        self._lost_reason = "not connected"
        self._hello_waiter: asyncio.Future[Hello] | None = None

    @property
    def connected(self) -> bool:
        return self._writer is not None and not self._writer.is_closing()

    @property
    def lost_reason(self) -> str:
        """Why there is no connection (if there is none)."""
        return self._lost_reason

    def field(self, key: str, default: str = "") -> str:
        """A field of the controller's HELLO."""
        return self.hello.fields.get(key, default) if self.hello else default

    # ------------------------------------------------------------------ connection
    async def connect(self, host: str, port: int, timeout: float = 10.0) -> Hello:
        """Connect and read the HELLO; BridgeError with the reason otherwise."""
        self.address = f"{host}:{port}"
        try:
            async with asyncio.timeout(timeout):
                reader, writer = await asyncio.open_connection(host, port)
        except (OSError, TimeoutError) as exc:
            raise BridgeError(f"cannot connect to the controller at {self.address}: "
                              f"{exc or 'timed out'}") from None
        self._reader, self._writer = reader, writer
        loop = asyncio.get_running_loop()
        self._hello_waiter = loop.create_future()
        self._read_task = asyncio.create_task(self._read_loop(), name="controller-link")
        try:
            async with asyncio.timeout(timeout):
                hello = await asyncio.shield(self._hello_waiter)
        except TimeoutError:
            await self.close()
            raise BridgeError(f"no HELLO from the controller at {self.address} "
                              f"within {timeout:g} s") from None
        except BridgeError:
            await self.close()
            raise
        if hello.version != VERSION:
            await self.close()
            raise BridgeError(f"the controller at {self.address} speaks protocol version "
                              f"{hello.version}; this service speaks {VERSION}")
        self.hello = hello
        self._lost_reason = ""
        return hello

    async def close(self) -> None:
        """Close the connection (pending requests fail); the handler is not told."""
        writer, self._writer = self._writer, None
        if writer is not None:
            writer.close()
            with contextlib.suppress(Exception):
                async with asyncio.timeout(2.0):
                    await writer.wait_closed()
        task, self._read_task = self._read_task, None
        if task is not None and task is not asyncio.current_task():
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await task
        self._fail_pending("connection to the controller closed")

    def _fail_pending(self, reason: str) -> None:
        self._lost_reason = reason
        for future in self._pending.values():
            if not future.done():
                future.set_exception(BridgeError(reason))
        self._pending.clear()
        waiter = self._hello_waiter
        if waiter is not None and not waiter.done():
            waiter.set_exception(BridgeError(reason))

    # ------------------------------------------------------------------ reading
    async def _read_loop(self) -> None:
        assert self._reader is not None
        buffer = LineBuffer()
        reason = LOST
        try:
            while True:
                chunk = await self._reader.read(65536)
                if not chunk:
                    break
                for item in buffer.feed(chunk):
                    self._dispatch(item)
        except asyncio.CancelledError:
            raise
        except OSError as exc:
            reason = f"{LOST}: {exc}"
        writer, self._writer = self._writer, None
        if writer is not None:
            writer.close()
        self._fail_pending(reason)
        established, self.hello = self.hello is not None, None
        if established:  # during connect, the caller hears it from connect()
            self.handler.on_lost(reason)

    def _dispatch(self, item: str | FramingError) -> None:
        if isinstance(item, FramingError):
            self.handler.on_garbled("", item.reason)
            return
        try:
            message = decode(item, "controller")
        except ProtocolError as exc:
            self.handler.on_garbled(item, str(exc))
            return
        if isinstance(message, Hello):
            waiter = self._hello_waiter
            if waiter is not None and not waiter.done():
                waiter.set_result(message)
            else:
                self.handler.on_garbled(item, "HELLO after the start of the session")
        elif isinstance(message, Reply):
            self._on_reply(message)
        elif isinstance(message, ActivateLine):
            self.handler.on_activate(message)
        elif isinstance(message, ProgramStarted):
            self.handler.on_started(message)
        elif isinstance(message, ProgramEnded):
            self.handler.on_ended(message)
        elif isinstance(message, Console):
            self.handler.on_console(message)

    def _on_reply(self, reply: Reply) -> None:
        if reply.id == 0:
            log.warning("controller at %s: %s", self.address, reply.text)
            waiter = self._hello_waiter
            if waiter is not None and not waiter.done():  # refused before HELLO (busy)
                waiter.set_exception(BridgeError(f"the controller refused: {reply.text}"))
            return
        future = self._pending.pop(reply.id, None)
        if future is None:
            log.warning("controller at %s: reply to unknown request %d", self.address, reply.id)
        elif not future.done():
            future.set_result(reply)

    # ------------------------------------------------------------------ writing
    async def send(self, *messages: Message) -> None:
        """Send messages in order (BridgeError if not connected)."""
        writer = self._writer
        if writer is None or writer.is_closing():
            raise BridgeError(self._lost_reason or LOST)
        try:
            for message in messages:
                writer.write(frame_line(encode(message)))
            await writer.drain()
        except (OSError, RuntimeError) as exc:
            raise BridgeError(f"{LOST}: {exc}") from None

    def new_id(self) -> int:
        """A fresh request identifier."""
        ident = next(self._ids)
        if ident > MAX_ID:  # pragma: no cover - 2**31 requests
            self._ids = itertools.count(2)
            ident = 1
        return ident

    async def request(self, request: Request, *, before: tuple[Message, ...] = (),
                      timeout: float | None = None) -> str:
        """Send ``before`` then ``request``; the text of its ``OK``.

        ControllerError for ``ERR`` (its reason), BridgeError if the connection is
        lost or no answer arrives within ``timeout`` (default ``request_timeout``).
        """
        loop = asyncio.get_running_loop()
        future: asyncio.Future[Reply] = loop.create_future()
        self._pending[request.id] = future
        limit = self.request_timeout if timeout is None else timeout
        try:
            await self.send(*before, request)
            async with asyncio.timeout(limit):
                reply = await future
        except TimeoutError:
            raise BridgeError(f"no answer from the controller to {type(request).__name__.upper()} "
                              f"within {limit:g} s") from None
        finally:
            self._pending.pop(request.id, None)
        if not reply.ok:
            raise ControllerError(reply.text)
        return reply.text

    async def run(self, run_id: int, program: str, values: Mapping[str, str] | None = None,
                  timeout: float | None = None) -> str:
        """``VALUE``… ``RUN``: start ``program`` as run ``run_id`` (from :meth:`new_id`);
        returns the PROGRAM's name."""
        before = tuple(Value(run_id, name, text) for name, text in (values or {}).items())
        return await self.request(Run(run_id, program), before=before, timeout=timeout)
