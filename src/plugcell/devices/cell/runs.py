"""Running robot programs on the cell's robots, one after another or together (thesis 7.6).

"Although it is possible to create the tasks to all of the services to which the
cell controller has subscribed, the main purpose is assigning and activating a
robot program in the robot service.  If the work cell contains several robots,
the operator can also specify the synchronization between them: whether they will
run sequentially or concurrently to each other."

A program is activated with the robot service's ``ACTIVATE`` command (Table 7-1,
input ``name: String``); the process ends when the program ends, so a *run* is a
list of ``(robot, program)`` items whose ACTIVATE processes are created one after
another (``sequential``: the next starts when the previous one Completed, and a
failure stops the rest) or all at once (``concurrent``).  An item may carry the
program's *values* (``"name=value"`` strings, docs/robot-programs.md): they follow the
program name in the ACTIVATE data.  When a program has ended, the robot's
``PROGRAM_STATUS`` (if it has one) tells how: ``FINISHED`` (Completed), or — Failed —
``DEACTIVATED`` by its own checks, ``FAILED``, ``STOPPED``, with the simulated time, the
message and the last console lines.  The program library
is listed from the files shipped with plugcell.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import logging
import re
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from plugcell.framework.data import from_data
from plugcell.framework.messages import Command, Device, ProcessStates

if TYPE_CHECKING:
    from plugcell.framework.participant import Participant

log = logging.getLogger("plugcell.devices.cell.service")

MODES = ("sequential", "concurrent")
ACTIVATE = "ACTIVATE"
STATUS = "PROGRAM_STATUS"
#: Most items of one run.
MAX_ITEMS = 64
#: Most values of one program, and the longest (characters of ``name=value``).
MAX_VALUES = 64
MAX_VALUE_CHARS = 65_536
#: Seconds the program status may take to come after a program ended; console lines kept.
STATUS_TIMEOUT = 10.0
CONSOLE_LINES = 6
_PROGRAM_LINE = re.compile(r"^\s*PROGRAM\s+([A-Za-z_]\w*)", re.IGNORECASE | re.MULTILINE)
_VALUE = re.compile(r"^\s*([A-Za-z_]\w*)\s*=(.*)$", re.DOTALL)
_ids = itertools.count(1)

__all__ = [
    "MODES",
    "ProgramRun",
    "RunError",
    "RunItem",
    "activate_command",
    "list_programs",
    "parse_run_items",
    "parse_runs",
    "program_library",
    "run_programs",
]


class RunError(ValueError):
    """A run that cannot be started; the message says why."""


@dataclass
class RunItem:
    """One program on one robot."""

    robot: str
    program: str
    values: list[str] = field(default_factory=list)
    state: str = "Waiting"
    reason: str = ""
    identifier: int = 0
    started_ns: int = 0
    ended_ns: int = 0
    #: How the program ended, by the robot's PROGRAM_STATUS ("" if not known):
    #: FINISHED, DEACTIVATED, …; its simulated seconds, message, last console lines.
    program_state: str = ""
    sim_s: float | None = None
    message: str = ""
    console: list[str] = field(default_factory=list)

    def to_json(self) -> dict[str, Any]:
        return {
            "robot": self.robot, "program": self.program, "values": len(self.values),
            "state": self.state, "reason": self.reason, "identifier": str(self.identifier),
            "startedNs": self.started_ns, "endedNs": self.ended_ns,
            "programState": self.program_state, "simS": self.sim_s, "message": self.message,
            "console": self.console,
        }


@dataclass
class ProgramRun:
    """A set of programs run sequentially or concurrently."""

    mode: str
    items: list[RunItem]
    id: str = field(default_factory=lambda: f"run-{next(_ids)}")
    state: str = "Running"
    started_ns: int = field(default_factory=time.time_ns)
    ended_ns: int = 0

    def to_json(self) -> dict[str, Any]:
        return {
            "id": self.id, "mode": self.mode, "state": self.state,
            "startedNs": self.started_ns, "endedNs": self.ended_ns,
            "items": [i.to_json() for i in self.items],
        }


def parse_run_items(items: Any) -> list[tuple[str, str]]:
    """``[["R1", "prog"], …]``, ``[{"robot": …, "program": …}]`` or ``["R1:prog", …]``."""
    if not isinstance(items, list) or not items:
        raise RunError("give at least one robot and program")
    if len(items) > MAX_ITEMS:
        raise RunError(f"at most {MAX_ITEMS} programs in one run")
    out = []
    for i, item in enumerate(items, 1):
        if isinstance(item, dict):
            robot, program = item.get("robot"), item.get("program")
        elif isinstance(item, list | tuple) and len(item) == 2:
            robot, program = item
        elif isinstance(item, str) and ":" in item:
            robot, _, program = item.partition(":")
        else:
            raise RunError(f"item {i}: expected ROBOT:PROGRAM")
        if not isinstance(robot, str) or not robot.strip():
            raise RunError(f"item {i}: no robot")
        if not isinstance(program, str) or not program.strip():
            raise RunError(f"item {i}: no program")
        out.append((robot.strip(), program.strip()))
    return out


def _values(value: Any, where: str) -> list[str]:
    """A program's values: ``["name=value", …]`` or ``{"name": value, …}`` (text/numbers)."""
    if value is None:
        return []
    if isinstance(value, dict):
        pairs = []
        for k, v in value.items():
            if isinstance(v, bool) or not isinstance(v, str | int | float):
                raise RunError(f"{where}: value {k!r} must be a text or a number")
            pairs.append(f"{k}={v}")
        value = pairs
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise RunError(f"{where}: values are 'name=value' texts")
    if len(value) > MAX_VALUES:
        raise RunError(f"{where}: at most {MAX_VALUES} values")
    out = []
    for j, text in enumerate(value, 1):
        match = _VALUE.match(text)
        if match is None:
            raise RunError(f"{where}: value {j} {text[:40]!r}: expected name=value")
        if len(text) > MAX_VALUE_CHARS:
            raise RunError(f"{where}: value {match.group(1)} is longer than "
                           f"{MAX_VALUE_CHARS} characters")
        if any(ord(c) < 32 for c in text):
            raise RunError(f"{where}: value {match.group(1)} holds a line break or another "
                           "control character")
        out.append(f"{match.group(1)}={match.group(2).strip()}")
    return out


def parse_runs(items: Any) -> list[RunItem]:
    """The items of a run with their values: ``[{"robot", "program", "values"}, …]``,
    ``[["R1", "prog"], …]``, or texts ``["R1:prog", "name=value", …, "R2:prog", …]``
    where each ``name=value`` belongs to the program before it (RunError if bad)."""
    if isinstance(items, list) and all(isinstance(i, str) for i in items):
        grouped: list[Any] = []
        for text in items:
            if _VALUE.match(text):
                if not grouped:
                    raise RunError(f"value {text[:40]!r} before any ROBOT:PROGRAM")
                grouped[-1]["values"].append(text)
            else:
                grouped.append({"text": text, "values": []})
        pairs = parse_run_items([g["text"] for g in grouped])
        return [RunItem(r, p, _values(g["values"], f"item {i}"))
                for i, ((r, p), g) in enumerate(zip(pairs, grouped, strict=True), 1)]
    pairs = parse_run_items(items)
    out = []
    for i, ((robot, program), item) in enumerate(zip(pairs, items, strict=True), 1):
        values = item.get("values") if isinstance(item, dict) else None
        out.append(RunItem(robot, program, _values(values, f"item {i}")))
    return out


def activate_command(device: Device) -> Command:
    """The robot service's ACTIVATE command (RunError if ``device`` has none)."""
    for command in device.commands:
        if command.name.upper() == ACTIVATE:
            return command
    raise RunError(f"{device.name} is not a robot service: it has no {ACTIVATE} command")


def activate_input(command: Command, program: str, values: list[str] | None = None
                   ) -> tuple[str, Any]:
    """Option and data that name ``program`` (and give its ``values``) for this ACTIVATE
    declaration (RunError if the declaration has no room for the values).

    plugcell's robot service completes ACTIVATE when the program *starts* unless the
    option is ``Wait`` (then when it ends): a run needs the end, so ``Wait`` is
    asked for whenever the command's description offers it.
    """
    option = "Wait" if "'wait'" in command.info.lower() else ""
    size = command.input_data_size
    if values and not (command.takes_input and len(size) == 1
                       and (size[0] < 0 or size[0] > len(values))):
        raise RunError(f"{command.name} of this robot takes no program values")
    if not command.takes_input:
        return program, None
    if size == ():
        return option, program
    return option, [program, *(values or [])]


def program_library() -> Path:
    """The folder of the robot programs shipped with plugcell."""
    from plugcell.pdl.library import BUILTIN_LIBRARY

    return BUILTIN_LIBRARY


def list_programs(folders: list[Path] | None = None) -> list[dict[str, Any]]:
    """The programs of the library: name, file, first comment lines; libraries marked."""
    out = []
    for folder in [*(folders or []), program_library()]:
        if not folder.is_dir():
            continue
        for path in sorted(folder.glob("*.pdl")):
            try:
                text = path.read_text(encoding="utf-8")
            except (OSError, UnicodeDecodeError):
                continue
            match = _PROGRAM_LINE.search(text)
            about = []
            for line in text.splitlines():
                if not line.startswith("--"):
                    break
                about.append(line[2:].strip())
            out.append({
                "name": path.stem,
                "program": match.group(1) if match else "",
                "library": match is None,
                "path": str(path),
                "about": " ".join(about)[:600],
                "lines": text.count("\n") + 1,
            })
    return out


async def _run_item(
    participant: Participant, item: RunItem, changed: Callable[[], None]
) -> bool:
    item.state = "Starting"
    item.started_ns = time.time_ns()
    changed()
    try:
        partner = participant.partners.get(item.robot)
        if partner is None:
            await participant.subscribe(item.robot, 5.0)
            partner = participant.partners[item.robot]
        command = activate_command(partner.device)
        option, data = activate_input(command, item.program, item.values)
    except Exception as exc:  # PartnerError, RunError: the item fails with the reason
        item.state, item.reason, item.ended_ns = "Failed", str(exc), time.time_ns()
        changed()
        return False
    call = await participant.create_process(
        item.robot, command.name, option, data, timeout=max(command.timeout, 5.0)
    )
    item.identifier = call.identifier
    item.state = "Queued" if call.final is None else call.final.state.value
    changed()
    async for update in call:
        if update.state is ProcessStates.Running and item.state != "Running":
            item.state = "Running"
            changed()
    final = call.final
    assert final is not None
    if option == "Wait" and final.state in (ProcessStates.Completed, ProcessStates.Failed):
        await _program_status(participant, item, partner.device, final.state, final.reason)
    item.state, item.reason, item.ended_ns = final.state.value, final.reason, time.time_ns()
    changed()
    return final.state is ProcessStates.Completed


async def _program_status(participant: Participant, item: RunItem, device: Device,
                          state: ProcessStates, reason: str) -> None:
    """How the program ended, by the robot's PROGRAM_STATUS (nothing if it has none):
    ``[program, state, simulated s, message, console lines…]``.

    After a Failed ACTIVATE the status is this run's only if the failure's ``reason``
    quotes its message (a program that failed, stopped or deactivated itself); a program
    that could not start leaves the status of an earlier run, which is not shown.
    """
    if device.command(STATUS) is None:
        return
    try:
        call = await participant.create_process(item.robot, STATUS, timeout=STATUS_TIMEOUT)
        data = None
        async for update in call:
            if update.data is not None:
                data = update.data
    except Exception as exc:  # a robot gone meanwhile: the run's state says enough
        log.debug("%s %s: %s", item.robot, STATUS, exc)
        return
    if call.final is None or call.final.state is not ProcessStates.Completed or data is None:
        return
    fields = [str(v) for v in from_data(data).reshape(-1)]
    if len(fields) < 2 or fields[0].lower() not in (item.program.lower(),
                                                     Path(item.program).stem.lower()):
        return  # another program's status (one started meanwhile)
    message = fields[3] if len(fields) > 3 else ""
    if state is ProcessStates.Failed and (not message or message not in reason):
        return  # an earlier run's status: this one did not start
    item.program_state = fields[1]
    with contextlib.suppress(ValueError, IndexError):
        item.sim_s = float(fields[2])
    item.message = message
    item.console = [f for f in fields[4:] if f.strip()][-CONSOLE_LINES:]


async def run_programs(
    participant: Participant, run: ProgramRun, changed: Callable[[], None]
) -> ProgramRun:
    """Run ``run``'s items as its mode says; ``changed()`` after every state change."""
    if run.mode == "concurrent":
        results = await asyncio.gather(
            *(_run_item(participant, item, changed) for item in run.items)
        )
        ok = all(results)
    else:
        ok = True
        for item in run.items:
            if not ok:
                item.state, item.reason = "Skipped", "an earlier program failed"
                continue
            ok = await _run_item(participant, item, changed)
        changed()
    run.state = "Completed" if ok else "Failed"
    run.ended_ns = time.time_ns()
    changed()
    return run
