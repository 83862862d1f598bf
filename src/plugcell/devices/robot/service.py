"""The robot service (thesis 7.2, Table 7-1): the robot's program drives the cell.

"The main responsibility of the Smart H4 robot service is activating robot
programs dispatched from the cell controller in the C3G controller.  When these
programs are being executed, they might send control commands to other
peripheral devices; in such cases, the robot service will setup the
communication channels between them."  (7.2)  The robot is not a dumb slave of a
PC program (4.1.3.2): the Control Logic lives in the robot program, and a new
application is a new program — no service code changes.

Commands (Table 7-1, plus the delegation of 8.3.2 and a status query):

==============  ==========  =====================  ==========================================
command         type        input → output         does
==============  ==========  =====================  ==========================================
ACTIVATE        NoData      String[*]              run a program: ``[name or path,
                                                   "var=value", …]``; option ``Wait``: until
                                                   its END (Failed with its error, or
                                                   why it stopped or deactivated itself)
DEACTIVATE      NoData      String[1]              stop the program (``""``: whichever runs)
ARM_POS         SingleData  → Double[6]            the controller's current position
ARM_JNTP        SingleData  → Double[*]            the joint readings (degrees)
JNTP_TO_POS     SingleData  Double[*] → Double[6]  the controller's forward kinematics
POS_TO_JNTP     SingleData  Double[6] → Double[*]  the controller's inverse kinematics
JointIncrement  SingleData  Double[12] → Double[*] δθ = J⁻¹Δx, target and measured (8.3.2)
PROGRAM_STATUS  SingleData  → String[*]            program, state, simulated s, message,
                                                   the last console lines
IDENTIFICATION  SingleData  → String[4]            manufacturer, model, serial number,
                                                   product code (the robot file's)
==============  ==========  =====================  ==========================================

A robot streamed over RSI or EGM also lets the robot drive while the PC corrects (issue
37's mode (b)): ``CORRECT``, ``CORRECT_SET``, ``CORRECT_END``, ``CORRECT_STATUS``
(:mod:`plugcell.devices.robot.corrections`), declared beside these and dispatched to it.

Positions are PDL's: mm and Comau ZYZ degrees.  The controller is reached over
the line protocol (:mod:`plugcell.devices.robot.bridge`): with ``sim`` the service
starts its own controller process with the
:class:`~plugcell.devices.robot.controller_process.ControllerLauncher` it is given
(``plugcell serve robot``: the simulated controller, :mod:`plugcell.sim.controller.launcher`),
otherwise it connects to ``line = HOST:PORT`` — a real controller speaking
docs/controller-protocol.md — or, with ``rsi = HOST:PORT`` / ``egm = HOST:PORT``, runs
the programs on the PC and streams each move to a KUKA robot over RSI or an ABB robot over
EGM (:mod:`plugcell.devices.robot.stream_controller`); either is a
:class:`~plugcell.devices.robot.link.RobotLink` chosen at construction.  The
program's ACTIVATE strings are handled by the
:class:`~plugcell.devices.robot.outbound.ExternalProcessHandler`.

``plugcell serve robot --name R1 --param sim=true [--param robot=smart_h4]
[--param payload_kg=36] [--param speed=100]``, or with the issue's flags
``python -m plugcell.devices.robot --name R1 --sim [--robot smart_h4]
[--payload-kg M] [--speed X] [--cell C]`` (``--line HOST:PORT`` for a real one).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from plugcell.devices.params import flag as _flag
from plugcell.devices.robot.bridge import (
    BridgeError,
    ControllerBridge,
    ControllerError,
    parse_address,
)
from plugcell.devices.robot.controller_process import (
    ControllerLauncher,
    ControllerProcess,
    ControllerStartError,
)
from plugcell.devices.robot.corrections import CORRECT_COMMANDS, PathCorrections
from plugcell.devices.robot.increment import joint_increment, pose_error_sizes
from plugcell.devices.robot.joint_state import (
    DEFAULT_RATE_HZ,
    JointStatePublisher,
    publish_joint_state,
)
from plugcell.devices.robot.link import RobotLink
from plugcell.devices.robot.outbound import ExternalProcessHandler
from plugcell.devices.robot.protocol import (
    ActivateLine,
    ArmJntp,
    ArmPos,
    Console,
    JntpToPos,
    PosToJntp,
    ProgramEnded,
    ProgramStarted,
    ProtocolError,
    Status,
    Stop,
    parse_fields,
    parse_numbers,
)
from plugcell.devices.robot.streamed import STREAM_PARAMS, streamed_link
from plugcell.framework.declaration import Declaration
from plugcell.framework.messages import Command, CommandTypes, ConnectionStates, DataTypes
from plugcell.framework.participant import PartnerError
from plugcell.framework.service import DeviceError, GenericDevice
from plugcell.kinematics import RobotDescription
from plugcell.pdl.predefined import EXT_DATA_MAX

__all__ = ["ProgramStatus", "RobotService"]

log = logging.getLogger("plugcell.devices.robot.service")

#: Console lines of the last program kept for PROGRAM_STATUS.
CONSOLE_LINES = 50
#: Longest wait for a program to load and start (real seconds).
RUN_TIMEOUT_S = 60.0
#: Pause between attempts to reach a controller whose connection dropped.
RECONNECT_S = 1.0
TEXT_MAX = 255

_D, _S = DataTypes.Double, DataTypes.String


@dataclass
class ProgramStatus:
    """The current or last program run, as the service saw it."""

    run: int = 0
    program: str = ""
    state: str = "NONE"
    sim_time: float = 0.0
    message: str = ""
    console: deque[str] = field(default_factory=lambda: deque(maxlen=CONSOLE_LINES))


class RobotService:
    """A robot: its controller's programs and arm, as a Plug-and-Produce device (which a
    :class:`~plugcell.framework.service.GenericDevice` hosts)."""

    declaration = Declaration(
        kind="robot",
        default_name="ROBOT",
        vendor="plugcell",
        info=("Robot service (thesis 7.2): runs robot programs on the controller and carries "
              "their ACTIVATE strings to the partners"),
        commands=(
        Command(name="ACTIVATE", type=CommandTypes.NoData, input_data_type=_S,
                input_data_size=(-1,), timeout=3600.0,
                info="run a robot program: [name or path, 'var=value', ...]; "
                     "option 'Wait': until it ends"),
        Command(name="DEACTIVATE", type=CommandTypes.NoData, input_data_type=_S,
                input_data_size=(1,), timeout=30.0,
                info="stop the robot program of that name ('' for any)"),
        Command(name="ARM_POS", type=CommandTypes.SingleData, output_data_type=_D,
                output_data_size=(6,), info="current position x, y, z mm, a, b, c deg (ZYZ)"),
        Command(name="ARM_JNTP", type=CommandTypes.SingleData, output_data_type=_D,
                output_data_size=(-1,), info="current joint angles, deg"),
        Command(name="JNTP_TO_POS", type=CommandTypes.SingleData, input_data_type=_D,
                input_data_size=(-1,), output_data_type=_D, output_data_size=(6,),
                info="nominal forward kinematics (the controller's)"),
        Command(name="POS_TO_JNTP", type=CommandTypes.SingleData, input_data_type=_D,
                input_data_size=(6,), output_data_type=_D, output_data_size=(-1,),
                timeout=30.0, info="nominal inverse kinematics (the controller's)"),
        Command(name="JointIncrement", type=CommandTypes.SingleData, input_data_type=_D,
                input_data_size=(12,), output_data_type=_D, output_data_size=(-1,),
                info="joint increment J^-1 dx from the target and the measured position "
                     "(8.3.2 CALC), deg; option 'errors': [|dp| mm, angle deg, increment...]"),
        Command(name="PROGRAM_STATUS", type=CommandTypes.SingleData, output_data_type=_S,
                output_data_size=(-1,),
                info="[program, state, simulated s, message, console lines...]"),
        Command(name="IDENTIFICATION", type=CommandTypes.SingleData, output_data_type=_S,
                output_data_size=(4,),
                info="[manufacturer, model, serial number, product code] of the robot "
                     "(its description file's [identification]; model: its name if none)"),
        *CORRECT_COMMANDS,
    ))
    params: ClassVar[dict[str, Any]] = {
        "sim": _flag,
        "line": str,
        "robot": str,
        "payload_kg": float,
        "speed": float,
        "seed": int,
        "library": str,
        "link_baud": float,
        "dynamics": _flag,
        "joint_rate": float,
        **STREAM_PARAMS,  # rsi=, egm= … (devices/robot/streamed.py)
    }

    def __init__(
        self,
        *,
        sim: bool = False,
        launcher: ControllerLauncher | None = None,
        line: str = "",
        robot: str = "smart_h4",
        payload_kg: float = 0.0,
        speed: float = 1.0,
        seed: int = 0,
        library: str = "",
        link_baud: float = 0.0,
        dynamics: bool = False,
        joint_rate: float = DEFAULT_RATE_HZ,
        connect_timeout: float = 30.0,
        **stream: Any,
    ) -> None:
        rsi, egm = stream.get("rsi", ""), stream.get("egm", "")
        if sum(map(bool, (sim, line, rsi, egm))) > 1:
            raise ValueError("give one of sim, line=HOST:PORT, rsi=HOST:PORT or "
                             "egm=HOST:PORT, not several")
        if not sim and not line and not rsi and not egm:
            raise ValueError("the robot service needs a controller: sim=true (a simulated one), "
                             "line=HOST:PORT, rsi=HOST:PORT (a KUKA robot over RSI) or "
                             "egm=HOST:PORT (an ABB robot over EGM)")
        if dynamics and not sim:
            raise ValueError("dynamics moves the simulated controller's twin in time: give "
                             "sim=true too")
        if not (speed > 0):
            raise ValueError(f"speed must be positive, not {speed}")
        if not (math.isfinite(payload_kg) and payload_kg >= 0):
            raise ValueError(f"payload_kg must be ≥ 0, not {payload_kg}")
        if not (link_baud >= 0):
            raise ValueError(f"link_baud must be 0 (no serial line) or positive, not {link_baud}")
        self.sim = sim
        self.launcher = launcher
        self.service: GenericDevice | None = None
        self.link_baud = link_baud
        self.dynamics = dynamics
        self.endpoint: tuple[str, int] | None = (parse_address(line or rsi or egm)
                                                 if line or rsi or egm else None)
        self.robot = robot
        self.payload_kg = payload_kg
        self.speed = speed
        self.seed = seed
        self.library = [Path(p) for p in library.split(",") if p.strip()] if library else []
        self.connect_timeout = connect_timeout
        # the link to the robot (plugcell.devices.robot.link): a controller that runs the
        # programs (line protocol), or the programs on the PC streaming over RSI or EGM
        streamed = streamed_link(self, robot=robot, library=self.library,
                                 name=self.declaration.name(), **stream)
        self.streamed = streamed
        self.bridge: RobotLink = streamed or ControllerBridge(self)
        self.corrections = PathCorrections(streamed, robot)  # mode (b): CORRECT …
        if sim and launcher is None:
            raise ValueError("sim=true needs a controller launcher (plugcell serve robot gives "
                             "the simulated controller)")
        self.outbound = ExternalProcessHandler(self)
        self.sim_process: ControllerProcess | None = None
        self.program = ProgramStatus()
        self._run_waiters: dict[int, asyncio.Future[ProgramEnded]] = {}
        self._reconnect: asyncio.Task[None] | None = None
        self.robot_description: RobotDescription | None = None
        self.joint_rate = joint_rate
        self.joint_state: JointStatePublisher | None = None

    def bind(self, service: GenericDevice) -> None:
        self.service = service
        if self.streamed is not None:  # the UI's device panel shows its link
            self.streamed.name = service.name
            service.device.info = (f"{service.declaration.info} Robot link: "
                                   f"{self.streamed.describe()}.")

    @property
    def host(self) -> GenericDevice:
        """The service hosting this robot."""
        assert self.service is not None, "RobotService used before a service hosts it"
        return self.service

    @property
    def name(self) -> str:
        """The service's name."""
        return self.host.name

    # ------------------------------------------------------------------ connection
    async def connect(self) -> None:
        """Start the robot's own controller (``sim``) and connect to the controller."""
        host = self.host
        try:
            if self.sim:
                assert self.launcher is not None
                self.sim_process = self.launcher(
                    name=host.name, cell=host.cell, robot=self.robot,
                    payload_kg=self.payload_kg, speed=self.speed, seed=self.seed,
                    library=self.library, transport=host.participant.transport,
                    link_baud=self.link_baud, dynamics=self.dynamics,
                )
                self.endpoint = await self.sim_process.start(self.connect_timeout)
            assert self.endpoint is not None
            await self._connect_bridge()
        except (BridgeError, ControllerStartError) as exc:
            raise PartnerError(f"{host.name}: {exc}") from None
        self.outbound.start()
        self.joint_state = publish_joint_state(self, self.joint_rate)
        host.connection_state.post(ConnectionStates.Online)

    async def _connect_bridge(self, timeout: float | None = None) -> None:
        assert self.endpoint is not None
        hello = await self.bridge.connect(*self.endpoint, timeout or self.connect_timeout)
        robot = hello.fields.get("robot", "")
        if self.sim_process is not None:
            # our own simulated controller: it loaded the robot we gave it (a name or a
            # description file, e.g. an imported URDF) and says only the robot's name
            robot = self.robot
        self.robot_description = None
        if robot:
            from plugcell.io.robots import load_robot

            try:
                self.robot_description = load_robot(robot)
            except Exception as exc:  # a real controller may name a robot we do not know
                log.warning("%s: robot %r of the controller is unknown here: %s",
                            self.name, robot, exc)

    async def disconnect(self) -> None:
        """Stop forwarding, close the link, stop the simulated controller."""
        reconnect, self._reconnect = self._reconnect, None
        if reconnect is not None:
            reconnect.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await reconnect
        if self.joint_state is not None:
            await self.joint_state.close()
        await self.outbound.close()
        await self.bridge.close()
        self._fail_waiters("the robot service is shutting down")
        if self.sim_process is not None:
            await self.sim_process.stop()
        self.host.connection_state.post(ConnectionStates.Offline)

    async def _reconnect_loop(self) -> None:
        """Reach the controller again after a dropped connection (until shutdown)."""
        while not self.host.closing:
            await asyncio.sleep(RECONNECT_S)
            if self.sim_process is not None and not self.sim_process.alive:
                log.error("%s: the simulated controller has exited", self.name)
                return
            try:
                await self._connect_bridge(5.0)
            except BridgeError as exc:
                log.info("%s: controller still unreachable: %s", self.name, exc)
                continue
            log.warning("%s: reconnected to the controller at %s", self.name,
                        self.bridge.address)
            self.host.connection_state.post(ConnectionStates.Online)
            return

    def capacities(self) -> tuple[int, int]:
        """How many values ext_cmd_data and characters ext_cmd_text hold (from HELLO)."""
        def number(key: str, default: int) -> int:
            text = self.bridge.field(key)
            return int(text) if text.isdigit() else default

        return number("data", EXT_DATA_MAX), number("text", TEXT_MAX)

    # ------------------------------------------------------------------ the controller speaks
    def on_activate(self, line: ActivateLine) -> None:
        log.info("%s: %s", self.name, line.activate)
        self.outbound.submit(line.activate)

    def on_garbled(self, line: str, reason: str) -> None:
        log.warning("%s: garbled line from the controller %r: %s", self.name, line[:200], reason)
        self.outbound.submit_garbled(reason)

    def on_started(self, event: ProgramStarted) -> None:
        self.program = ProgramStatus(event.run, event.program, "RUNNING")
        self.outbound.started(event.run)

    def on_console(self, event: Console) -> None:
        if event.run == self.program.run:
            self.program.console.append(event.text)
        log.info("%s: %s> %s", self.name, self.program.program, event.text)

    def on_ended(self, event: ProgramEnded) -> None:
        if event.run == self.program.run:
            p = self.program
            p.state, p.sim_time, p.message = event.state, event.sim_time, event.message
        log.info("%s: program %s %s after %.3f simulated s%s", self.name, event.program,
                 event.state, event.sim_time, f": {event.message}" if event.message else "")
        self.outbound.ended(event.run)
        waiter = self._run_waiters.pop(event.run, None)
        if waiter is not None and not waiter.done():
            waiter.set_result(event)

    def on_lost(self, reason: str) -> None:
        log.warning("%s: %s", self.name, reason)
        self.outbound.lost()
        if self.program.state == "RUNNING":
            self.program.state, self.program.message = "STOPPED", reason
        self._fail_waiters(reason)
        if not self.host.closing:
            self.host.connection_state.post(ConnectionStates.Error)
            if self._reconnect is None or self._reconnect.done():
                self._reconnect = asyncio.get_running_loop().create_task(self._reconnect_loop())

    def _fail_waiters(self, reason: str) -> None:
        for waiter in self._run_waiters.values():
            if not waiter.done():
                waiter.set_exception(BridgeError(reason))
        self._run_waiters.clear()

    # ------------------------------------------------------------------ Table 7-1
    async def dispatch(self, command: Command, option: str, data: Any) -> str:
        """CommandDispatcher: the commands of Table 7-1 (see :meth:`perform`)."""
        output = await self.perform(command, option, data)
        if output is not None:
            self.host.data_feedback.post(output)
        return "OK"

    async def perform(self, command: Command, option: str, data: Any) -> Any:
        """Carry out one command; its output (None for NoData).  DeviceError says why not.

        Shared by the service interface and the programs' own requests
        (``ACTIVATE ROBOT #JointIncrement##…``).
        """
        if not self.bridge.connected:
            raise DeviceError(f"controller not connected ({self.bridge.lost_reason})")
        b = self.bridge
        try:
            match command.name:
                case "ACTIVATE":
                    return await self._activate(option, data)
                case "DEACTIVATE":
                    name = str(data.reshape(-1)[0]).strip() if data is not None else ""
                    await b.request(Stop(b.new_id(), name), timeout=command.timeout - 1)
                    return None
                case "ARM_POS":
                    return _numbers(await b.request(ArmPos(b.new_id())), 6)
                case "ARM_JNTP":
                    return _numbers(await b.request(ArmJntp(b.new_id())))
                case "JNTP_TO_POS":
                    values = tuple(float(v) for v in np.asarray(data).reshape(-1))
                    return _numbers(await b.request(JntpToPos(b.new_id(), values)), 6)
                case "POS_TO_JNTP":
                    values = tuple(float(v) for v in np.asarray(data).reshape(-1))
                    text = await b.request(PosToJntp(b.new_id(), values),
                                           timeout=command.timeout - 1)
                    return _numbers(text)
                case "JointIncrement":
                    return await self._joint_increment(option, data)
                case "PROGRAM_STATUS":
                    return await self._program_status()
                case "IDENTIFICATION":
                    return self._identification()
                case name if name.startswith("CORRECT"):
                    return await self.corrections.perform(command, option, data)
        except ControllerError as exc:
            raise DeviceError(str(exc)) from None
        except BridgeError as exc:
            raise DeviceError(str(exc)) from None
        raise DeviceError(f"{command.name} is not implemented")  # pragma: no cover

    def _identification(self) -> list[str]:
        """[manufacturer, model, serial number, product code] of the robot file."""
        from plugcell.io.robots import robot_identification

        desc = self.robot_description
        if desc is None:
            raise DeviceError("the controller's robot is unknown here (no description)")
        try:
            ident = robot_identification(self.robot if self.sim_process is not None
                                         else desc.name)
        except Exception:  # an imported URDF, a robot file of the controller's only
            ident = {}
        return [ident.get("manufacturer", ""), ident.get("model", "") or desc.name,
                ident.get("serial_number", ""), ident.get("product_code", "")]

    async def _activate(self, option: str, data: Any) -> None:
        if option not in ("", "Wait"):
            raise DeviceError(f"unknown option {option!r}: '' (start the program) or 'Wait' "
                              "(until it ends)")
        items = [str(s) for s in np.asarray(data, dtype=object).reshape(-1)]
        if not items or not items[0].strip():
            raise DeviceError("no program given")
        values: dict[str, str] = {}
        for item in items[1:]:
            key, sep, text = item.partition("=")
            if not sep or not key.strip():
                raise DeviceError(f"bad variable preset {item!r}: expected name=value")
            values[key.strip()] = text.strip()
        run = self.bridge.new_id()
        waiter: asyncio.Future[ProgramEnded] = asyncio.get_running_loop().create_future()
        self._run_waiters[run] = waiter
        try:
            await self.bridge.run(run, items[0].strip(), values, timeout=RUN_TIMEOUT_S)
            if option != "Wait":
                return None
            ended = await waiter
        finally:
            if self._run_waiters.get(run) is waiter:
                del self._run_waiters[run]
        return _outcome(ended)

    async def _joint_increment(self, option: str, data: Any) -> np.ndarray:
        """δθ; with option ``errors``: [‖Δp‖ mm, ∠ΔR °, δθ…] (SENSOR_COM's test, 8.3.2)."""
        mode = option.strip().lower()
        if mode not in ("", "errors"):
            raise DeviceError(f"unknown option {option!r} ('' or 'errors')")
        if self.robot_description is None:
            robot = self.bridge.field("robot") or "?"
            raise DeviceError(f"the controller's robot {robot!r} has no description here: "
                              "the joint increment needs its kinematics")
        values = [float(v) for v in np.asarray(data).reshape(-1)]
        joints = _numbers(await self.bridge.request(ArmJntp(self.bridge.new_id())))
        try:
            dq = joint_increment(self.robot_description, joints, values[:6], values[6:])
        except ValueError as exc:
            raise DeviceError(str(exc)) from None
        if mode == "errors":
            return np.concatenate([pose_error_sizes(values[:6], values[6:]), dq])
        return dq

    async def _program_status(self) -> list[str]:
        p = self.program
        sim_time = p.sim_time
        if p.state == "RUNNING":
            text = await self.bridge.request(Status(self.bridge.new_id()))
            with contextlib.suppress(ProtocolError, ValueError):
                fields = parse_fields([w for w in text.split(" ") if w])
                if fields.get("run") == str(p.run):
                    sim_time = float(fields.get("sim", "0"))
        return [p.program, p.state, f"{sim_time:.3f}", p.message, *p.console]


def _numbers(text: str, count: int | None = None) -> np.ndarray:
    try:
        return np.asarray(parse_numbers(text, count, "controller answer"), dtype=float)
    except ProtocolError as exc:
        raise DeviceError(f"bad answer from the controller: {exc}") from None


def _outcome(ended: ProgramEnded) -> None:
    """Completed (None) only for a program that ran to its END; DeviceError says why not.

    A program's own ``DEACTIVATE`` ends it before its END — PDL programs give up that
    way (the shipped ones after a failed step, the reason on the console), so it is a
    failure: ``program CALIBRATION deactivated itself: calibration: Move failed: …
    (DEACTIVATE at …/calibration.pdl:35:5)``.
    """
    match ended.state:
        case "FINISHED":
            return None
        case "DEACTIVATED":
            raise DeviceError(f"program {ended.program} deactivated itself: "
                              f"{ended.message or 'DEACTIVATE before its END'}")
    raise DeviceError(f"program {ended.program} {ended.state.lower()}: {ended.message}")
