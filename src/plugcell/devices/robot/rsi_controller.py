"""The robot service's link to a KUKA robot over RSI: the program runs on the PC.

:class:`RsiController` is a :class:`~plugcell.devices.robot.link.RobotLink` that is the
controller itself, in the service's process: it runs the robot programs with the
language runtime (:class:`~plugcell.devices.robot.runner.ProgramRunner`), plans and checks
every move on the PC (:class:`~plugcell.devices.robot.planned_motion.PlannedMotion`) and
streams it to the robot as absolute joint corrections through an
:class:`~plugcell.devices.robot.rsi.link.RsiLink`
(:class:`~plugcell.devices.robot.rsi.drive.RsiDrive`) — issue 37's mode *the PC drives*:
the controller's KRL program only starts RSI where the robot stands and follows
(``plugcell rsi files --mode absolute``).  Joint feedback (ARM_JNTP, ARM_POS and every
move's start) is the RSI packets' ``AIPos``.

It answers the service's requests as a line-protocol controller would (the same
messages, the same replies, ``ERR`` reasons as :class:`ControllerError`), so the robot
service, its commands and the programs behave as with the simulated controller.  The
program's time is real time: a move lasts its trajectory's duration.

*Connected* means the robot is streaming: :meth:`connect` binds the link (once) and waits
for the controller's packets; when the stream stops — the controller silent for one
controller timeout, ``Timeout`` missed cycles, a refused correction — the running program
stops and the service hears ``on_lost`` with the link's reason; its reconnection loop
then calls :meth:`connect` again, which returns as soon as the controller streams again.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import itertools
import logging
import math
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

from plugcell.devices.robot.bridge import (
    BridgeError,
    BridgeHandler,
    ControllerError,
    parse_address,
)
from plugcell.devices.robot.planned_motion import PlannedMotion
from plugcell.devices.robot.protocol import (
    VERSION,
    ActivateLine,
    ArmJntp,
    ArmPos,
    Console,
    Hello,
    JntpToPos,
    Message,
    Move,
    Ping,
    PosToJntp,
    ProgramEnded,
    ProgramStarted,
    ProtocolError,
    Request,
    Result,
    ResultData,
    Status,
    Stop,
    StreamEnd,
    Value,
    decode,
    format_number,
    format_numbers,
)
from plugcell.devices.robot.rsi.config import CorrectionLimits, RsiConfig
from plugcell.devices.robot.rsi.drive import RsiDrive
from plugcell.devices.robot.rsi.link import RsiLink
from plugcell.devices.robot.runner import TEXT_MAX, ProgramRunner, RunError
from plugcell.devices.robot.tracked_moves import tracked_moves_for
from plugcell.io.robots import load_robot
from plugcell.kinematics import RobotDescription
from plugcell.motion import CartesianLimits, JointLimits
from plugcell.pdl import MotionError, SimClock
from plugcell.pdl.predefined import EXT_DATA_MAX
from plugcell.pdl.values import JointPos, Position

__all__ = ["RsiController", "StreamedMotion", "rsi_controller", "streaming_limits"]

log = logging.getLogger("plugcell.devices.robot.rsi_controller")

#: How often the stream's state is looked at (s).
WATCH_S = 0.05
#: Margin of the RSI link's speed limit over the planner's joint speed limit: the planner
#: keeps every move within the joint limits, the link refuses what would exceed them by more.
SPEED_MARGIN = 1.5


def streaming_limits(joint: JointLimits, cycle_s: float) -> CorrectionLimits:
    """The RSI link's limits when the PC streams whole moves (policy ``"refuse"``).

    ``max_speed_i = 1.5 · v_i`` and ``max_step_i = 1.5 · v_i · T``: a planned move never
    reaches them, a correction that would is refused and fails the stream.  The total
    offset is a full turn per axis (the joint limits are checked when the move is planned).

    Parameters
    ----------
    joint : JointLimits
        The planner's joint limits (rad/s …), six axes.
    cycle_s : float
        The controller's cycle ``T`` (s).

    Returns
    -------
    CorrectionLimits
        In SI (rad, rad/s).
    """
    v = [float(x) * SPEED_MARGIN for x in joint.velocity]
    return CorrectionLimits(tuple(x * cycle_s for x in v), (2 * math.pi,) * 6,
                            tuple(v), "refuse")


class StreamedMotion(PlannedMotion):
    """PlannedMotion on a drive that moves in real time: when ``follow`` returns, the move's
    time has passed; the clock is advanced by it and the interpreter is told ``None`` (it
    must not wait a second time)."""

    def __init__(self, *args: object, clock: SimClock, **kwargs: object) -> None:
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]
        self.clock = clock

    def _run(self, move: object) -> float:
        duration = super()._run(move)  # type: ignore[arg-type]
        self.clock.advance(duration)
        return None  # type: ignore[return-value]


class _Channel:
    """``WRITE pc_client``: the program's line goes to the service (in its event loop)."""

    def __init__(self, controller: RsiController) -> None:
        self.controller = controller

    def write(self, line: str) -> None:
        if "\n" in line or "\r" in line:
            raise ValueError("a pc_client line cannot contain a line break")
        c = self.controller
        if not c.connected:
            raise ConnectionError(f"no connection to the robot service ({c.lost_reason})")
        c.in_loop(c.program_line, line)


class RsiController:
    """The programs on the PC, the moves over RSI (module docstring).

    Parameters
    ----------
    handler : BridgeHandler
        The robot service: told of program events, ACTIVATE strings and a lost stream.
    config : RsiConfig
        The stream (joint corrections, absolute mode).
    description : RobotDescription
        The robot (the controller's nominal model).
    robot : str
        Its name or description file, as the HELLO's ``robot``.
    joint_limits : JointLimits
        The planner's joint limits.
    cartesian_limits : CartesianLimits
        The planner's TCP limits of linear moves.
    library : sequence of Path
        Folders of robot programs.
    name : str
        The service's name (HELLO ``name``).
    """

    def __init__(self, handler: BridgeHandler, config: RsiConfig, description: RobotDescription,
                 robot: str, joint_limits: JointLimits, cartesian_limits: CartesianLimits,
                 library: Sequence[Path] = (), name: str = "ROBOT") -> None:
        if description.n_readings != 6:
            raise ValueError(f"RSI streams six axes; {description.name} has "
                             f"{description.n_readings}")
        self.handler = handler
        self.config = config
        self.description = description
        self.robot = robot
        self.name = name
        self.address = f"{config.listen_host}:{config.listen_port}"
        self.link = RsiLink(config)
        self.drive = RsiDrive(self.link)
        self.clock = SimClock(speed=1.0)
        self.motion = StreamedMotion(description, self.drive, joint_limits, cartesian_limits,
                                     clock=self.clock)
        self.motion.move_tracked = tracked_moves_for(self)  # type: ignore[attr-defined]
        self.runner = ProgramRunner(self.motion, self.clock, _Channel(self), self._event,
                                    library)
        self.hello: Hello | None = None
        self._started = False
        self._connected = False
        self._lost_reason = "not connected"
        self._ids = itertools.count(1)
        self._staged: dict[int, dict[str, str]] = {}
        self._loop: asyncio.AbstractEventLoop | None = None
        self._watch: asyncio.Task[None] | None = None

    # ------------------------------------------------------------------ RobotLink
    @property
    def connected(self) -> bool:
        return self._connected

    @property
    def lost_reason(self) -> str:
        return self._lost_reason

    def field(self, key: str, default: str = "") -> str:
        return self.hello.fields.get(key, default) if self.hello else default

    def new_id(self) -> int:
        return next(self._ids)

    async def connect(self, host: str, port: int, timeout: float = 10.0) -> Hello:
        """Listen (once) and wait for the controller's stream; BridgeError if none comes."""
        self._loop = asyncio.get_running_loop()
        if not self._started:
            try:
                host, port = self.link.start()
            except OSError as exc:
                raise BridgeError(str(exc)) from None
            self._started = True
            self.address = f"{host}:{port}"

        def ready(link: RsiLink) -> bool:
            return link.streaming and link.failure is None and link.latest is not None

        if not await asyncio.to_thread(self.link.wait, ready, timeout):
            why = f" (last: {self.link.failure})" if self.link.failure is not None else ""
            raise BridgeError(f"no RSI stream from the controller at {self.config.robot_host} "
                              f"to {self.address} within {timeout:g} s{why}")
        self.hello = Hello(VERSION, {
            "robot": self.robot, "axes": "6", "data": str(EXT_DATA_MAX), "text": str(TEXT_MAX),
            "name": self.name, "rsi": self.address, "mode": "pc-drives"})
        self._connected, self._lost_reason = True, ""
        self._watch = asyncio.create_task(self._watch_stream(), name="rsi-watch")
        return self.hello

    async def close(self) -> None:
        """Stop the running program and the link (the service is shutting down)."""
        self._connected, self._lost_reason = False, "connection to the robot closed"
        watch, self._watch = self._watch, None
        if watch is not None and watch is not asyncio.current_task():
            watch.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await watch
        await asyncio.to_thread(self._stop_program, "the robot service is shutting down")
        await asyncio.to_thread(self.link.close)

    async def send(self, *messages: Message) -> None:
        """The program's answers, in order (as a controller reads them)."""
        if not self._connected:
            raise BridgeError(self._lost_reason)
        for m in messages:
            if isinstance(m, ResultData):
                (self.runner.frame if m.frame else self.runner.stage_data)(m)
            elif isinstance(m, Result):
                self.runner.result(m.ok, m.message)
            elif isinstance(m, StreamEnd):
                self.runner.stream_end(m.ok, m.message)
            elif isinstance(m, Value):
                self._staged.setdefault(m.id, {})[m.name] = m.text

    async def request(self, request: Request, *, before: tuple[Message, ...] = (),
                      timeout: float | None = None) -> str:
        """The answer to ``request``; ControllerError with the reason if refused."""
        await self.send(*before)
        try:
            return await asyncio.to_thread(self._answer, request)
        except (MotionError, RunError, ValueError) as exc:
            raise ControllerError(str(exc) or type(exc).__name__) from None

    async def run(self, run_id: int, program: str, values: Mapping[str, str] | None = None,
                  timeout: float | None = None) -> str:
        """Start ``program`` as run ``run_id``; its name (ControllerError: why not)."""
        if not self._connected:
            raise BridgeError(self._lost_reason)
        presets = {**self._staged.pop(run_id, {}), **(values or {})}
        try:
            info = await asyncio.to_thread(self.runner.start, run_id, program, presets)
        except RunError as exc:
            raise ControllerError(str(exc)) from None
        return info.program

    # ------------------------------------------------------------------ requests
    def _answer(self, req: Request) -> str:
        m = self.motion
        if isinstance(req, Ping):
            return ""
        if isinstance(req, Status):
            return self._status()
        if isinstance(req, ArmPos):
            return format_numbers(m.arm_pos().as_tuple())
        if isinstance(req, ArmJntp):
            return format_numbers(m.arm_jntp().joints)
        if isinstance(req, PosToJntp):
            return format_numbers(m.pos_to_jntp(Position(*req.values)).joints)
        if isinstance(req, JntpToPos):
            return format_numbers(m.jntp_to_pos(JointPos(req.values)).as_tuple())
        if isinstance(req, Stop):
            return self.runner.stop("stopped by the robot service", req.program).state
        if isinstance(req, Move):
            busy = self.runner.busy_reason()
            if busy:
                raise RunError(busy)
            t0 = self.clock.now()
            if req.kind == "TO":
                m.move_to(Position(*req.values))
            else:
                m.move_joints(req.values)
            return format_number(self.clock.now() - t0)
        raise ValueError(f"unsupported request {type(req).__name__}")

    def _status(self) -> str:
        cur = self.runner.current
        fields = {"state": "IDLE", "run": "0", "program": "", "sim": "0"}
        if cur is not None:
            fields.update(state="RUNNING", run=str(cur.run), program=cur.program,
                          sim=format_number(round(cur.execution.sim_time, 6)))
        fields["clock"] = format_number(round(self.clock.now(), 6))
        return " ".join(f"{k}={v.replace(' ', '_')}" for k, v in fields.items())

    # ------------------------------------------------------------------ the stream
    async def _watch_stream(self) -> None:
        link = self.link
        while self._connected:
            await asyncio.sleep(WATCH_S)
            if link.streaming and link.failure is None:
                continue
            reason = str(link.failure) if link.failure is not None else "RSI stream stopped"
            self._connected, self._lost_reason = False, reason
            await asyncio.to_thread(self._stop_program, reason)
            self.handler.on_lost(reason)
            return

    def _stop_program(self, reason: str) -> None:
        if self.runner.current is not None:
            with contextlib.suppress(RunError):
                self.runner.stop(reason)

    # ------------------------------------------------------------------ events
    def in_loop(self, call: Callable[..., None], *args: object) -> None:
        """Run ``call(*args)`` in the service's event loop (from any thread), in order."""
        loop = self._loop
        if loop is not None and not loop.is_closed():
            with contextlib.suppress(RuntimeError):  # the loop is shutting down
                loop.call_soon_threadsafe(call, *args)

    def _event(self, message: Message) -> None:
        self.in_loop(self._dispatch, message)

    def _dispatch(self, message: Message) -> None:
        h = self.handler
        if isinstance(message, ProgramStarted):
            h.on_started(message)
        elif isinstance(message, ProgramEnded):
            h.on_ended(message)
        elif isinstance(message, Console):
            h.on_console(message)

    def program_line(self, line: str) -> None:
        """A ``WRITE pc_client`` line of the program: an ACTIVATE string, or garbled."""
        try:
            message = decode(line, "controller")
        except ProtocolError as exc:
            self.handler.on_garbled(line, str(exc))
            return
        if isinstance(message, ActivateLine):
            self.handler.on_activate(message)
        else:
            self.handler.on_garbled(line, "a program line that is not an ACTIVATE string")


def rsi_controller(handler: BridgeHandler, *, listen: str, robot_address: str, robot: str,
                   timeout_packets: int = 100, joint_speed_deg_s: float = 20.0,
                   tcp_speed_mm_s: float = 100.0, library: Sequence[Path] = (),
                   name: str = "ROBOT") -> RsiController:
    """An :class:`RsiController` from the robot service's options.

    Parameters
    ----------
    handler : BridgeHandler
        The robot service.
    listen : str
        ``HOST:PORT`` where plugcell receives the robot's packets (the ethernet
        configuration's ``IP_NUMBER`` and ``PORT``).
    robot_address : str
        The controller's ``HOST`` or ``HOST:PORT`` (packets from elsewhere are dropped);
        empty: the listen host, unless that is a wildcard.
    robot : str
        The robot: a shipped name or a description file.
    timeout_packets : int
        The ETHERNET object's ``Timeout`` (late cycles before the controller breaks off).
    joint_speed_deg_s : float
        Every joint's speed limit (°/s); acceleration 3× and jerk 30× it per second.
    tcp_speed_mm_s : float
        The TCP's speed limit of linear moves (mm/s); acceleration 5× and jerk 50× it.
    library : sequence of Path
        Folders of robot programs.
    name : str
        The service's name.

    Returns
    -------
    RsiController
        Not yet connected.

    Raises
    ------
    ValueError
        A bad address, limit or robot, with the reason.
    """
    host, port = parse_address(listen)
    if robot_address:
        rhost, sep, rport = robot_address.strip().rpartition(":")
        if not sep:
            rhost, rport = rport, ""
        if rport and not (rport.isdigit() and 0 < int(rport) < 65536):
            raise ValueError(f"bad RSI robot address {robot_address!r}: expected HOST or "
                             "HOST:PORT")
        robot_port = int(rport) if rport else None
    elif host in ("0.0.0.0", "::"):
        raise ValueError(f"rsi={listen} listens on every address: give the controller's "
                         "address with rsi_robot=HOST[:PORT]")
    else:
        rhost, robot_port = host, None
    for what, v in (("joint_speed", joint_speed_deg_s), ("tcp_speed", tcp_speed_mm_s)):
        if not (math.isfinite(v) and v > 0):
            raise ValueError(f"{what} must be a positive number, not {v}")
    v = math.radians(joint_speed_deg_s)
    joint = JointLimits.uniform(6, v, 3 * v, 30 * v)
    s = tcp_speed_mm_s / 1000.0
    cart = CartesianLimits(s, 5 * s, 50 * s, math.radians(30), math.radians(120),
                           math.radians(1200))
    base = RsiConfig(robot_host=rhost.strip("[]"), listen_host=host, listen_port=port,
                     robot_port=robot_port, correction="joint", mode="absolute",
                     timeout_packets=timeout_packets)
    config = dataclasses.replace(base, limits=streaming_limits(joint, base.cycle_s))
    return RsiController(handler, config, load_robot(robot), robot, joint, cart, library, name)
