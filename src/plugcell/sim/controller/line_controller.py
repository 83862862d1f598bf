"""The simulated robot controller: it speaks the line protocol to the robot service.

Its program (a separate OS process, as a real controller is) is
``python -m plugcell.sim.controller --robot smart_h4 --port P --cell C --name N
[--payload-kg M] [--speed X] [--seed S]`` (:mod:`plugcell.apps.commands.sim_controller`;
the old ``python -m plugcell.sim.controller.controller`` still runs it).

It stands where the thesis's Comau C3G stood (7.2): it owns the arm — a
:class:`~plugcell.sim.twin.robot.RobotTwin` driven through
:class:`~plugcell.sim.controller.arm.TwinArm`, which teleports, or with ``--dynamics``
the dynamic twin driven through :class:`~plugcell.sim.controller.arm.DynamicArm`, whose
moves take their time and whose T-MAC is published as it moves — runs robot programs with the
language runtime on a :class:`SimClock` with a speed factor (reporting simulated
time), publishes its T-MAC's true pose to the sim-only world after every move,
and talks to the robot service over TCP with the protocol of
docs/controller-protocol.md.  A real controller with socket messaging can take
its place: the service cannot tell the difference.

One service connection at a time (a second one is refused with ``ERR 0``).  A
dropped connection stops the running program safely (at its next statement, at
once if it is waiting or moving) and stops a MOVE; the controller then waits for
the service to connect again.  It exits on SIGTERM/SIGINT, or when its parent
process is gone (``--parent-watch``, set by the robot service that started it).
"""

from __future__ import annotations

import contextlib
import logging
import math
import socket
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path

from plugcell.devices.robot.framing import FramingError, LineBuffer, frame_line
from plugcell.devices.robot.protocol import (
    VERSION,
    Console,
    Hello,
    Message,
    Move,
    ProgramEnded,
    ProgramStarted,
    ProtocolError,
    Reply,
    Request,
    Result,
    ResultData,
    Run,
    Stop,
    StreamEnd,
    Value,
    decode,
    encode,
    format_number,
)
from plugcell.devices.robot.requests import Staged, answer, check_line, deliver, status_text
from plugcell.devices.robot.runner import TEXT_MAX, ProgramRunner, RunError
from plugcell.devices.robot.serial_line import SerialLine
from plugcell.pdl import MotionError, SimClock
from plugcell.pdl.predefined import EXT_DATA_MAX
from plugcell.pdl.values import Position
from plugcell.sim.controller.arm import DynamicArm, TwinArm

__all__ = ["SimController"]

log = logging.getLogger("plugcell.sim.controller")

LOST = "connection to the robot service lost"
#: How long a new connection waits for the previous one to finish closing.
HANDOVER_S = 1.0


class Link:
    """One service connection: thread-safe line writer."""

    def __init__(self, sock: socket.socket) -> None:
        self.sock = sock
        self._lock = threading.Lock()
        self.closed = False

    def send_line(self, line: str) -> None:
        data = frame_line(line)
        with self._lock:
            if self.closed:
                raise ConnectionError(LOST)
            try:
                self.sock.sendall(data)
            except OSError as exc:
                self.closed = True
                raise ConnectionError(f"{LOST}: {exc}") from None

    def send(self, message: Message) -> None:
        self.send_line(encode(message))

    def close(self) -> None:
        with self._lock:
            self.closed = True
        with contextlib.suppress(OSError):
            self.sock.shutdown(socket.SHUT_RDWR)
        with contextlib.suppress(OSError):
            self.sock.close()


class SimController:
    """The controller: arm, clock, programs, and the service connection."""

    def __init__(
        self,
        arm: TwinArm | DynamicArm,
        *,
        speed: float = 1.0,
        clock: SimClock | None = None,
        name: str = "ROBOT",
        library: Sequence[Path] = (),
        extra_hello: dict[str, str] | None = None,
        link_baud: float = 0.0,
    ) -> None:
        self.arm = arm
        #: the robot ↔ PC serial line in simulated time (None: a network link, free)
        self.serial = SerialLine(link_baud) if link_baud > 0 else None
        self.clock = clock if clock is not None else SimClock(speed=speed)
        self.name = name
        self.extra_hello = dict(extra_hello or {})
        self.runner = ProgramRunner(arm, self.clock, _ProgramChannel(self), self._event, library)
        self._link: Link | None = None
        self._link_lock = threading.Lock()
        self._staged = Staged()
        self._move_lock = threading.Lock()
        self._moving = False
        self._move_stop = threading.Event()
        self._shutdown = threading.Event()
        self._idle = threading.Event()
        self._idle.set()
        self.connections = 0

    # ------------------------------------------------------------------ links
    @property
    def link(self) -> Link | None:
        with self._link_lock:
            return self._link

    def _event(self, message: Message) -> None:
        if self.serial is not None:
            if isinstance(message, ProgramStarted):
                self.serial.reset()
            elif isinstance(message, ProgramEnded):  # the run's line usage, on its console
                self._event(Console(message.run, str(self.serial.usage())))
        link = self.link
        if link is not None:
            with contextlib.suppress(ConnectionError):
                link.send(message)

    def carry(self, line: str, outbound: bool) -> None:
        """A program's line crossed the serial line: its time passes on the clock."""
        if self.serial is not None:
            self.clock.advance(self.serial.carry(line, outbound))

    def hello(self) -> Hello:
        fields = {
            "robot": self.arm.description.name,
            "axes": str(self.arm.axes),
            "data": str(EXT_DATA_MAX),
            "text": str(TEXT_MAX),
            "speed": format_number(self.clock.speed) if math.isfinite(self.clock.speed) else "inf",
            "name": self.name,
            "sim": "1",
        }
        if self.serial is not None:
            fields["baud"] = format_number(self.serial.baud)
        fields.update(self.extra_hello)
        return Hello(VERSION, fields)

    # ------------------------------------------------------------------ serving
    def serve(self, listener: socket.socket) -> None:
        """Accept service connections until :meth:`shutdown` (one at a time)."""
        listener.settimeout(0.2)
        while not self._shutdown.is_set():
            try:
                sock, _ = listener.accept()
            except TimeoutError:
                continue
            except OSError:
                if self._shutdown.is_set():
                    break
                raise
            sock.settimeout(None)
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            # a service reconnecting at once may find its old link still closing
            self._idle.wait(HANDOVER_S)
            with self._link_lock:
                busy = self._link is not None
                if not busy:
                    self._link = Link(sock)
                    self._idle.clear()
                    link = self._link
            if busy:
                with contextlib.suppress(OSError):
                    sock.sendall(frame_line(encode(Reply(0, False, "controller busy: another "
                                                                   "service is connected"))))
                with contextlib.suppress(OSError):
                    sock.close()
                continue
            self.connections += 1
            threading.Thread(target=self._serve_link, args=(link,), name="service-link",
                             daemon=True).start()

    def shutdown(self) -> None:
        """Stop serving: stop the program and any move, close the connection."""
        self._shutdown.set()
        self._lost("controller shutting down")

    def _serve_link(self, link: Link) -> None:
        buffer = LineBuffer()
        try:
            link.send(self.hello())
            while True:
                chunk = link.sock.recv(65536)
                if not chunk:
                    break
                for item in buffer.feed(chunk):
                    if isinstance(item, FramingError):
                        link.send(Reply(0, False, f"garbled line: {item.reason}"))
                    else:
                        self._handle_line(link, item)
        except (OSError, ConnectionError):
            pass
        finally:
            link.close()
            self._lost(LOST)  # the program stops before another service may connect
            with self._link_lock:
                if self._link is link:
                    self._link = None
            self._idle.set()

    def _lost(self, reason: str) -> None:
        """The service is gone: a running program stops safely, a move stops."""
        self._move_stop.set()
        self._halt()
        if self.runner.current is not None:
            with contextlib.suppress(RunError):
                self.runner.stop(reason)
        link = self.link
        if link is not None and self._shutdown.is_set():
            link.close()

    # ------------------------------------------------------------------ messages
    def _handle_line(self, link: Link, line: str) -> None:
        try:
            message = decode(line, "service")
        except ProtocolError as exc:
            ident = _leading_id(line)
            link.send(Reply(ident, False, f"garbled line: {exc}"))
            return
        if isinstance(message, ResultData | Result | StreamEnd):
            self.carry(line, outbound=False)
        if not deliver(self.runner, message) and isinstance(message, Request):
            self._request(link, message)

    def _request(self, link: Link, req: Request) -> None:
        if isinstance(req, Value):
            self._staged.add(req.id, req.name, req.text)
            return
        if isinstance(req, Run):
            values = self._staged.take(req.id)
            self._in_thread(link, req.id, lambda: self._run(req, values))
            return
        if isinstance(req, Stop):
            self._in_thread(link, req.id, lambda: self._stop(req))
            return
        if isinstance(req, Move):
            self._in_thread(link, req.id, lambda: self._move(req))
            return
        try:
            text = self._answer(req)
        except (MotionError, RunError, ValueError) as exc:
            link.send(Reply(req.id, False, str(exc) or type(exc).__name__))
        except Exception as exc:  # never let one request kill the link
            log.exception("request %s failed", req)
            link.send(Reply(req.id, False, f"internal error: {exc!r}"))
        else:
            link.send(Reply(req.id, True, text))

    def _in_thread(self, link: Link, ident: int, work: Callable[[], str]) -> None:
        def run() -> None:
            try:
                reply = Reply(ident, True, work())
            except (MotionError, RunError, ValueError) as exc:
                reply = Reply(ident, False, str(exc) or type(exc).__name__)
            except Exception as exc:
                log.exception("request %d failed", ident)
                reply = Reply(ident, False, f"internal error: {exc!r}")
            with contextlib.suppress(ConnectionError):
                link.send(reply)

        threading.Thread(target=run, name=f"request-{ident}", daemon=True).start()

    def _answer(self, req: Request) -> str:
        return answer(self.arm, req, self.status)

    def status(self) -> str:
        """``state=… run=… program=… sim=… line=… clock=…`` of the status reply."""
        return status_text(self.runner, self.clock, self._moving)

    def _run(self, req: Run, values: dict[str, str]) -> str:
        with self._move_lock:  # the arm has one owner: a program or a MOVE
            if self._moving:
                raise RunError("the arm is moving (MOVE in progress)")
            info = self.runner.start(req.id, req.program, values)
        return info.program

    def _halt(self) -> None:
        """An arm that moves in time stops its move now."""
        if isinstance(self.arm, DynamicArm):
            self.arm.halt()

    def _stop(self, req: Stop) -> str:
        if self.runner.current is None and self._moving:
            self._move_stop.set()
            self._halt()
            return "MOVE stopped"
        info = self.runner.stop("stopped by the robot service", req.program)
        return info.state

    def _move(self, req: Move) -> str:
        with self._move_lock:
            busy = self.runner.busy_reason()
            if busy:
                raise RunError(busy)
            if self._moving:
                raise RunError("the arm is already moving")
            self._moving = True
            self._move_stop.clear()
        try:
            t0 = self.clock.now()
            if req.kind == "TO":
                duration = self.arm.move_to(Position(*req.values))
            else:
                duration = self.arm.move_joints(req.values)
            if duration is None:  # the arm moved in time: the clock has advanced
                return format_number(self.clock.now() - t0)
            speed = self.clock.speed
            real = duration / speed if math.isfinite(speed) else 0.0
            t0 = time.monotonic()
            if real > 0 and self._move_stop.wait(real):
                self.clock.advance(min(duration, (time.monotonic() - t0) * speed))
                raise RunError("MOVE stopped before the arm settled")
            self.clock.advance(duration)
            return format_number(duration)
        finally:
            self._moving = False


class _ProgramChannel:
    """``WRITE pc_client``: the program's lines go to the service verbatim."""

    def __init__(self, controller: SimController) -> None:
        self.controller = controller

    def write(self, line: str) -> None:
        check_line(line)
        link = self.controller.link
        if link is None:
            raise ConnectionError("no connection to the robot service")
        self.controller.carry(line, outbound=True)
        link.send_line(line)


def _leading_id(line: str) -> int:
    words = line.split(" ", 2)
    if len(words) > 1 and words[1].isdigit() and 1 <= int(words[1]) < 2**31:
        return int(words[1])
    return 0
