"""The robot service's link to a robot streamed from the PC: the program runs on the PC.

:class:`StreamController` is a :class:`~plugcell.devices.robot.link.RobotLink` that is the
controller itself, in the service's process: it runs the robot programs with the
language runtime (:class:`~plugcell.devices.robot.runner.ProgramRunner`), plans and checks
every move on the PC (:class:`~plugcell.devices.robot.planned_motion.PlannedMotion`) and
streams it to the robot as whole joint commands through a vendor's real-time link
(:class:`~plugcell.devices.robot.stream.drive.StreamDrive`) — issue 37's mode *the PC
drives*: the controller's program only starts the interface where the robot stands and
follows.  The link's cycle loop runs in a child process of its own
(:class:`~plugcell.devices.robot.stream.process.LinkProcess`), so that nothing the service
does delays an answer.  One controller, one vendor's link each (:mod:`.streamed` makes it from the
service's options): KUKA RSI's absolute joint corrections (``AKorr``), joint feedback
``AIPos``; ABB EGM's joint targets (``EGMRunJoint``), joint feedback ``feedBack.joints``.

It answers the service's requests as a line-protocol controller would (the same
messages, the same replies, ``ERR`` reasons as :class:`ControllerError`; the shared part
is :mod:`plugcell.devices.robot.requests`), so the robot service, its commands and the
programs behave as with the simulated controller.  The program's time is real time: a
move lasts its trajectory's duration.

*Connected* means the robot is streaming: :meth:`StreamController.connect` binds the link
(once) and waits for the controller's packets; when the stream stops — the controller
silent for one controller timeout, its limit of missed cycles, a refused correction — the
running program stops and the service hears ``on_lost`` with the link's reason; its
reconnection loop then calls :meth:`~StreamController.connect` again, which returns as
soon as the controller streams again.
"""

from __future__ import annotations

import asyncio
import contextlib
import hashlib
import itertools
import logging
import math
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from plugcell.devices.robot.bridge import BridgeError, BridgeHandler, ControllerError
from plugcell.devices.robot.calibration_file import read_calibration
from plugcell.devices.robot.move_learning import MoveLearning
from plugcell.devices.robot.planned_motion import PlannedMotion
from plugcell.devices.robot.protocol import (
    VERSION,
    ActivateLine,
    Console,
    Hello,
    Message,
    Move,
    ProgramEnded,
    ProgramStarted,
    ProtocolError,
    Request,
    Stop,
    Value,
    decode,
    format_number,
)
from plugcell.devices.robot.requests import Staged, answer, check_line, deliver, status_text
from plugcell.devices.robot.runner import TEXT_MAX, ProgramRunner, RunError
from plugcell.devices.robot.stream.correcting import Corrector
from plugcell.devices.robot.stream.drive import StreamDrive, drive_refusal
from plugcell.devices.robot.stream.limits import CorrectionLimits
from plugcell.devices.robot.stream.process import BUSY, CorrectorClient, LinkProcess, link_class
from plugcell.devices.robot.stream.realtime import RealTime
from plugcell.devices.robot.tracked_moves import tracked_moves_for
from plugcell.kinematics import RobotDescription
from plugcell.motion import CartesianLimits, JointLimits
from plugcell.pdl import MotionError, SimClock
from plugcell.pdl.predefined import EXT_DATA_MAX
from plugcell.pdl.values import Position

__all__ = ["StreamController", "StreamedMotion", "planner_limits", "robot_endpoint",
           "streaming_limits"]

log = logging.getLogger("plugcell.devices.robot.stream_controller")

#: How often the stream's state is looked at (s).
WATCH_S = 0.05
#: Margin of the link's speed limit over the planner's joint speed limit: the planner
#: keeps every move within the joint limits, the link refuses what would exceed them by more.
SPEED_MARGIN = 1.5
def streaming_limits(joint: JointLimits, cycle_s: float) -> CorrectionLimits:
    """The link's limits when the PC streams whole moves (policy ``"refuse"``).

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


def planner_limits(joint_speed_deg_s: float, tcp_speed_mm_s: float
                   ) -> tuple[JointLimits, CartesianLimits]:
    """The planner's limits from the service's options.

    Parameters
    ----------
    joint_speed_deg_s : float
        Every joint's speed limit (°/s); acceleration 3× and jerk 30× it per second.
    tcp_speed_mm_s : float
        The TCP's speed limit of linear moves (mm/s); acceleration 5× and jerk 50× it;
        the orientation's 30 °/s, 120 °/s², 1200 °/s³.

    Returns
    -------
    tuple of (JointLimits, CartesianLimits)
        In SI.

    Raises
    ------
    ValueError
        A limit that is not a positive number.
    """
    for what, v in (("joint_speed", joint_speed_deg_s), ("tcp_speed", tcp_speed_mm_s)):
        if not (math.isfinite(v) and v > 0):
            raise ValueError(f"{what} must be a positive number, not {v}")
    v = math.radians(joint_speed_deg_s)
    joint = JointLimits.uniform(6, v, 3 * v, 30 * v)
    s = tcp_speed_mm_s / 1000.0
    cart = CartesianLimits(s, 5 * s, 50 * s, math.radians(30), math.radians(120),
                           math.radians(1200))
    return joint, cart


def robot_endpoint(option: str, listen_host: str, robot_address: str) -> tuple[str, int | None]:
    """The controller's host and (fixed source) port from ``HOST`` or ``HOST:PORT``.

    Parameters
    ----------
    option : str
        The service's option of the stream (``"rsi"``, ``"egm"``), for messages.
    listen_host : str
        Where plugcell listens: the controller's host when ``robot_address`` is empty.
    robot_address : str
        ``HOST`` or ``HOST:PORT``; empty: the listen host, unless that is a wildcard.

    Returns
    -------
    tuple of (str, int or None)
        Host, and port (``None``: any).

    Raises
    ------
    ValueError
        A bad address, or a wildcard listen address without the controller's.
    """
    if not robot_address:
        if listen_host in ("0.0.0.0", "::"):
            raise ValueError(f"{option}={listen_host}:… listens on every address: give the "
                             f"controller's address with {option}_robot=HOST[:PORT]")
        return listen_host, None
    rhost, sep, rport = robot_address.strip().rpartition(":")
    if not sep:
        rhost, rport = rport, ""
    if rport and not (rport.isdigit() and 0 < int(rport) < 65536):
        raise ValueError(f"bad {option.upper()} robot address {robot_address!r}: expected "
                         "HOST or HOST:PORT")
    return rhost.strip("[]"), int(rport) if rport else None


class StreamedMotion(PlannedMotion):
    """PlannedMotion on a drive that moves in real time: when ``follow`` returns, the move's
    time has passed; the clock is advanced by it and the interpreter is told ``None`` (it
    must not wait a second time).  ``refusal``: why the stream cannot carry the PC's moves
    (:func:`~plugcell.devices.robot.stream.drive.drive_refusal`; ``""``: it can), said
    before a move is planned."""

    def __init__(self, *args: object, clock: SimClock, refusal: str = "",
                 **kwargs: object) -> None:
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]
        self.clock = clock
        self.refusal = refusal

    def _run(self, move: object) -> float:
        if self.refusal:
            raise MotionError(self.refusal)
        duration = super()._run(move)  # type: ignore[arg-type]
        self.clock.advance(duration)
        return None  # type: ignore[return-value]


class _Channel:
    """``WRITE pc_client``: the program's line goes to the service (in its event loop)."""

    def __init__(self, controller: StreamController) -> None:
        self.controller = controller

    def write(self, line: str) -> None:
        c = self.controller
        check_line(line)
        if not c.connected:
            raise ConnectionError(f"no connection to the robot service ({c.lost_reason})")
        c.in_loop(c.program_line, line)


class StreamController:
    """The programs on the PC, the moves streamed to the robot (module docstring).

    Parameters
    ----------
    handler : BridgeHandler
        The robot service: told of program events, ACTIVATE strings and a lost stream.
    config : RsiConfig or EgmConfig
        The stream; its ``joint_targets`` must hold (RSI: absolute joint corrections;
        EGM: joint mode).
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
    process : bool
        Run the link's cycle loop in a child process
        (:class:`~plugcell.devices.robot.stream.process.LinkProcess`, the default), or in
        a thread of this process (measurements: ``benchmarks/rsi_latency.py
        --in-service``).
    correct_max : tuple of (float, float)
        The largest correction of mode (b) (``CORRECT``, :attr:`corrector`), mm and
        degrees per axis.
    calibration : str
        The robot's calibration (a PARAMS.json of ``plugcell calibrate``, of this robot):
        the tracked moves' model (:mod:`~plugcell.devices.robot.tracked_moves`); empty:
        the nominal model.
    realtime : RealTime, optional
        The link's scheduling (:mod:`~plugcell.devices.robot.stream.realtime`): its
        thread's priority, its CPUs, its memory locked.
    learned_dir : str
        Where the tracked moves' learned corrections are (:mod:`.move_learning`: each
        tracked move of a program learns across the program's runs); empty: none learns.
    learning_law : {"p", "inverse"}
        The law a new learned correction starts with (:class:`~.move_learning.MoveLearning`).

    Raises
    ------
    ValueError
        Not six axes, or a calibration that cannot be read or is of another robot.
    """

    def __init__(self, handler: BridgeHandler, config: Any, description: RobotDescription,
                 robot: str, joint_limits: JointLimits, cartesian_limits: CartesianLimits,
                 library: Sequence[Path] = (), name: str = "ROBOT",
                 process: bool = True, correct_max: tuple[float, float] = (5.0, 1.0),
                 calibration: str = "", realtime: RealTime | None = None,
                 learned_dir: str = "", learning_law: str = "p") -> None:
        self.vendor = config.vendor
        if description.n_readings != 6:
            raise ValueError(f"{self.vendor} streams six axes; {description.name} has "
                             f"{description.n_readings}")
        self.handler = handler
        self.config = config
        self.description = description
        self.robot = robot
        self.name = name
        self.address = f"{config.listen_host}:{config.listen_port}"
        self.correct_max = correct_max
        self.calibration = read_calibration(calibration, description.name) \
            if calibration else None
        self.calibration_name = Path(calibration).name if calibration else ""
        self.move_learning = MoveLearning(
            learned_dir, description.name,
            f"sha256:{hashlib.sha256(Path(calibration).read_bytes()).hexdigest()}"
            if calibration else "nominal",
            getattr(self.calibration, "residual_model", None) is not None, law=learning_law
        ) if learned_dir else None
        self.corrector: Corrector | CorrectorClient
        if process:
            self.link = self.drive = LinkProcess(config, realtime=realtime)
            self.corrector = self.link.corrector
        else:
            self.link = link_class(self.vendor)(config, realtime=realtime)
            self.drive = StreamDrive(self.link, feedback_only=True)
            self.corrector = Corrector(self.link)
        #: Set once the link listens for the controller's stream (a controller started
        #: before then may give up: its own timeout runs from its first packet)
        self.listening = asyncio.Event()
        self.clock = SimClock(speed=1.0)
        self.motion = StreamedMotion(description, self.drive, joint_limits, cartesian_limits,
                                     clock=self.clock, refusal=drive_refusal(config))
        self.motion.move_tracked = tracked_moves_for(self)  # type: ignore[attr-defined]
        self.runner = ProgramRunner(self.motion, self.clock, _Channel(self), self._event,
                                    library)
        self.hello: Hello | None = None
        self._started = False
        self._closing = False  # close() ends a wait for the stream
        self._connected = False
        self._lost_reason = "not connected"
        self._ids = itertools.count(1)
        self._staged = Staged()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._watch: asyncio.Task[None] | None = None

    def describe(self) -> str:
        """The link in a sentence (the service's info in the UI's device panel)."""
        name = {"RSI": "KUKA RSI", "EGM": "ABB EGM"}.get(self.vendor, self.vendor)
        port = f":{self.config.robot_port}" if self.config.robot_port else ""
        where = (f"{name}, listening on {self.address} for the controller at "
                 f"{self.config.robot_host}{port}; ")
        if not self.config.joint_targets:
            return where + (f"the robot drives, the PC corrects (CORRECT: corrections on "
                            f"the controller's own path every {self.config.cycle_s * 1000:g} "
                            f"ms)")
        return where + (f"the PC drives (the program runs on the PC, every move streamed as "
                        f"joint commands every {self.config.cycle_s * 1000:g} ms), or the "
                        f"robot drives and the PC corrects (CORRECT)")

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
        if not self._started or not getattr(self.link, "alive", True):  # or it crashed
            try:
                host, port = await asyncio.to_thread(self.link.start)
            except OSError as exc:
                raise BridgeError(str(exc)) from None
            self._started = True
            self.address = f"{host}:{port}"
            self.listening.set()

        def ready(link: Any) -> bool:
            return self._closing or (link.streaming and link.failure is None
                                     and link.latest is not None)

        streams = await asyncio.to_thread(self.link.wait, ready, timeout)
        if self._closing:
            raise BridgeError("the robot service is shutting down")
        if not streams:
            why = f" (last: {self.link.failure})" if self.link.failure is not None else ""
            raise BridgeError(f"no {self.vendor} stream from the controller at "
                              f"{self.config.robot_host} to {self.address} within "
                              f"{timeout:g} s{why}")
        self.hello = Hello(VERSION, {
            "robot": self.robot, "axes": "6", "data": str(EXT_DATA_MAX), "text": str(TEXT_MAX),
            "name": self.name, self.vendor.lower(): self.address,
            "mode": "pc-drives" if self.config.joint_targets else "robot-drives"})
        self._connected, self._lost_reason = True, ""
        self._watch = asyncio.create_task(self._watch_stream(),
                                          name=f"{self.vendor.lower()}-watch")
        return self.hello

    async def close(self) -> None:
        """Stop the running program and the link (the service is shutting down)."""
        self._closing = True
        self._connected, self._lost_reason = False, "connection to the robot closed"
        watch, self._watch = self._watch, None
        if watch is not None and watch is not asyncio.current_task():
            watch.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await watch
        await asyncio.to_thread(self._stop_program, "the robot service is shutting down")
        await asyncio.to_thread(self.link.close)  # ends a correction (CORRECT) still running
        if isinstance(self.corrector, Corrector):  # its thread, when the link is in ours
            await asyncio.to_thread(self.corrector.close)

    async def send(self, *messages: Message) -> None:
        """The program's answers, in order (as a controller reads them)."""
        if not self._connected:
            raise BridgeError(self._lost_reason)
        for m in messages:
            if not deliver(self.runner, m) and isinstance(m, Value):
                self._staged.add(m.id, m.name, m.text)

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
        presets = {**self._staged.take(run_id), **(values or {})}
        if await asyncio.to_thread(lambda: self.corrector.active):
            raise ControllerError(BUSY)
        try:
            info = await asyncio.to_thread(self.runner.start, run_id, program, presets)
        except RunError as exc:
            raise ControllerError(str(exc)) from None
        return info.program

    # ------------------------------------------------------------------ requests
    def _answer(self, req: Request) -> str:
        if isinstance(req, Stop):
            return self.runner.stop("stopped by the robot service", req.program).state
        if isinstance(req, Move):
            busy = self.runner.busy_reason() or (BUSY if self.corrector.active else "")
            if busy:
                raise RunError(busy)
            t0 = self.clock.now()
            if req.kind == "TO":
                self.motion.move_to(Position(*req.values))
            else:
                self.motion.move_joints(req.values)
            return format_number(self.clock.now() - t0)
        return answer(self.motion, req, lambda: status_text(self.runner, self.clock))

    # ------------------------------------------------------------------ the stream
    async def _watch_stream(self) -> None:
        link = self.link
        while self._connected:
            await asyncio.sleep(WATCH_S)
            if link.streaming and link.failure is None:
                continue
            reason = (str(link.failure) if link.failure is not None
                      else f"{self.vendor} stream stopped")
            self._connected, self._lost_reason = False, reason
            await asyncio.to_thread(self._stop_program, reason)
            self.handler.on_lost(reason)
            return

    def _stop_program(self, reason: str) -> None:
        if self.runner.current is not None:
            with contextlib.suppress(RunError):
                self.runner.stop(reason)

    # ------------------------------------------------------------------ events
    @property
    def event_loop(self) -> asyncio.AbstractEventLoop | None:
        """The service's event loop, once connected (``None`` before)."""
        return self._loop

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

    def say(self, line: str) -> None:
        """A line for the running program's console (from any thread; none: dropped)."""
        current = self.runner.current
        if current is not None:
            self._event(Console(current.run, line))

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
