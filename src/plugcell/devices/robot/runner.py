"""Running robot programs on the PC or in the simulated controller (thesis 4.1.3.2, 7.2).

:class:`ProgramRunner` is a controller's program side, apart from any socket and any
arm: it runs on whatever :class:`~plugcell.pdl.interfaces.Motion` it is given — the
simulated controller's twin (:class:`plugcell.sim.controller.arm.TwinArm`) or a robot
moved from the PC through planned trajectories
(:class:`plugcell.devices.robot.planned_motion.PlannedMotion`), so the same program runs
unchanged on both.  It finds a program (by name in the program library, or by path), loads it with
the language runtime (errors carry file and line), presets its variables, runs
it in a thread on the controller's :class:`SimClock`, and hands the robot
service's answers to it — the handshake of 4.1.3.2 (``RESULT`` →
``Execution.post_result``: the data variables, ``ext_cmd_message``,
``ext_cmd_result`` and last ``ext_cmd_finished``), stream frames and stream
ends.  Events (started, console lines, ended) go to the ``events`` callback.
One program at a time, as on a controller with one arm.
"""

from __future__ import annotations

import logging
import re
import threading
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from plugcell.devices.robot.protocol import (
    Console,
    Message,
    ProgramEnded,
    ProgramStarted,
    ResultData,
)
from plugcell.devices.robot.value_text import value_from_text
from plugcell.pdl import (
    BUILTIN_LIBRARY,
    Execution,
    ExecutionState,
    Location,
    Motion,
    Program,
    ProgramError,
    SimClock,
)
from plugcell.pdl.conversion import data_updates
from plugcell.pdl.interfaces import Channel
from plugcell.pdl.predefined import EXT_DATA_MAX

__all__ = ["TEXT_MAX", "ProgramRunner", "RunError", "RunInfo", "is_program_name",
           "resolve_program"]

log = logging.getLogger("plugcell.devices.robot.runner")

#: Capacity of ext_cmd_message and ext_cmd_text (STRING[255]).
TEXT_MAX = 255
#: How long STOP waits for a program to end (real seconds).
STOP_WAIT_S = 10.0
_PROGRAM_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]{0,63}\Z")


class RunError(RuntimeError):
    """A program that cannot be started; the message says why (with file and line)."""


@dataclass
class RunInfo:
    """The current or last run."""

    run: int
    program: str
    execution: Execution
    state: str = "RUNNING"
    message: str = ""
    ended: threading.Event = field(default_factory=threading.Event)
    """Set once the ENDED event has been emitted."""
    said: list[str] = field(default_factory=list)
    """The program's last non-blank console line (at most one item): why a program that
    deactivated itself did so — the shipped programs write it before their DEACTIVATE."""


def is_program_name(ref: str) -> bool:
    """True for a program's name in the library (``calibration``), False for a path."""
    return bool(_PROGRAM_NAME.match(ref.strip()))


def resolve_program(ref: str, library: Sequence[Path] = ()) -> Path:
    """The file of ``ref``: a name in the program library, or a path."""
    ref = ref.strip()
    if not ref:
        raise RunError("no program given")
    if not is_program_name(ref):
        path = Path(ref).expanduser()
        if not path.is_file():
            raise RunError(_missing_file(ref, path))
        return path
    dirs = [*library, BUILTIN_LIBRARY]
    for folder in dirs:
        for name in dict.fromkeys((ref, ref.lower(), ref.upper())):
            candidate = Path(folder) / f"{name}.pdl"
            if candidate.is_file():
                return candidate
    looked = ", ".join(str(d) for d in dirs)
    raise RunError(f"no program {ref!r} in the program library (looked in {looked})")


def _failed_answer(execution: Execution) -> str:
    """``ext_cmd_message`` if the program's last request failed (``ext_cmd_result`` FALSE)."""
    try:
        ok = execution.get_variable("ext_cmd_result")
        message = execution.get_variable("ext_cmd_message")
    except KeyError:  # pragma: no cover - predefined in every program
        return ""
    return str(message) if ok is False and message else ""


def _missing_file(ref: str, path: Path) -> str:
    """Why ``ref`` is no program file, saying where the controller looked."""
    where = path.absolute()
    if path.is_absolute():
        what = "no such file" if not path.exists() else "not a file"
        return f"no such program file: {ref} ({what})"
    return (f"no such program file: {ref} (looked for {where}: a relative path is taken from "
            f"the robot controller's folder {Path.cwd()}, not the caller's; give an absolute "
            "path, or put the program in the program library (library=DIR) and give its name)")


def _deactivated(said: Sequence[str], answer: str, where: Location | None) -> str:
    """Why a program ended before its END, and where: ENDED's text for ``DEACTIVATED``.

    A program's own ``DEACTIVATE`` is how PDL programs give up — the shipped ones after a
    failed step, the reason written to the console first; the thesis's EXAMPLE after a
    failed answer, silently.  So the text is what the program said last, else the failed
    answer it got last, then the statement's place: ``calibration: Move failed: TRACKER
    Move: beam not locked (DEACTIVATE at …/calibration.pdl:35:5)``, ``after the failed
    answer 'TOOL Drill: the drill broke' (DEACTIVATE at …/example.pdl:42:5)``.
    """
    place = f"DEACTIVATE at {where}" if where is not None else "DEACTIVATE"
    if said:
        return f"{said[-1]} ({place})"
    if answer:
        return f"after the failed answer {answer!r} ({place})"
    return place


def _clip(text: str) -> str:
    return text if len(text) <= TEXT_MAX else text[: TEXT_MAX - 1] + "…"


class ProgramRunner:
    """Loads, runs and answers the programs of one controller."""

    def __init__(
        self,
        motion: Motion,
        clock: SimClock,
        channel: Channel,
        events: Callable[[Message], None],
        library: Sequence[Path] = (),
    ) -> None:
        self.motion = motion
        self.clock = clock
        self.channel = channel
        self.events = events
        self.library = [Path(p) for p in library]
        self._lock = threading.Lock()
        self._current: RunInfo | None = None
        self.last: RunInfo | None = None
        self._data: ResultData | None = None

    # ------------------------------------------------------------------ state
    @property
    def current(self) -> RunInfo | None:
        """The running program, if any."""
        with self._lock:
            return self._current

    def busy_reason(self) -> str:
        """Why the arm is not free ("" if no program runs)."""
        cur = self.current
        return f"the arm is in use by program {cur.program} (run {cur.run})" if cur else ""

    # ------------------------------------------------------------------ run / stop
    def start(self, run: int, ref: str, values: Mapping[str, str] | None = None) -> RunInfo:
        """Load ``ref``, preset ``values`` (name → text) and start it as run ``run``.

        Raises :class:`RunError` with the reason (a load error reads
        ``file:line:column: message``).  The ``STARTED`` event is emitted before
        the program's first statement runs.
        """
        with self._lock:
            if self._current is not None:
                cur = self._current
                raise RunError(f"program {cur.program} is already running (run {cur.run})")
        path = resolve_program(ref, self.library)
        try:
            program = Program.load(path, library_path=self.library)
        except ProgramError as exc:
            raise RunError(str(exc)) from None
        except OSError as exc:
            raise RunError(f"cannot read {path}: {exc.strerror or exc}") from None
        said: list[str] = []  # the last console line, kept for a DEACTIVATE's message

        def console(line: str) -> None:
            if line.strip():
                said[:] = [line.strip()]
            self.events(Console(run, line))

        presets: dict[str, Any] = {}
        for name, text in (values or {}).items():
            try:
                info = program.variable(name)
            except KeyError as exc:
                raise RunError(f"VALUE {name}: {exc.args[0]}") from None
            try:
                presets[name] = value_from_text(text, info.type)
            except ValueError as exc:
                raise RunError(f"VALUE {name} ({info.type}): {exc}") from None
        try:
            execution = Execution(
                program,
                motion=self.motion,
                channel=self.channel,
                clock=self.clock,
                values=presets,
                console=console,
            )
        except ProgramError as exc:
            raise RunError(str(exc)) from None
        info = RunInfo(run, program.name, execution, said=said)
        with self._lock:
            if self._current is not None:  # raced with another start
                raise RunError(f"program {self._current.program} is already running")
            self._current = info
            self._data = None
        self.events(ProgramStarted(run, program.name))
        execution.start()
        threading.Thread(target=self._watch, args=(info,), name=f"watch-{run}",
                         daemon=True).start()
        return info

    def _watch(self, info: RunInfo) -> None:
        result = info.execution.join()
        assert result is not None
        if result.state is ExecutionState.FINISHED and result.deactivated:
            info.state = "DEACTIVATED"
            info.message = _deactivated(info.said, _failed_answer(info.execution),
                                        result.location)
        elif result.state is ExecutionState.FINISHED:
            info.state = "FINISHED"
        elif result.state is ExecutionState.FAILED:
            info.state, info.message = "FAILED", str(result.error or "failed")
        else:
            info.state = "STOPPED"
            info.message = info.message or "stopped"
        with self._lock:
            if self._current is info:
                self._current = None
            self.last = info
        try:
            self.events(ProgramEnded(info.run, info.program, info.state, result.sim_time,
                                     result.real_time, info.message))
        finally:
            info.ended.set()

    def stop(self, reason: str, program: str = "", wait_s: float = STOP_WAIT_S) -> RunInfo:
        """Stop the running program safely (if it is ``program``); wait until it ended."""
        info = self.current
        if info is None:
            raise RunError("no program is running")
        if program and program.upper() != info.program.upper():
            raise RunError(f"program {program} is not running (running: {info.program})")
        info.message = reason
        info.execution.stop(reason)
        if not info.ended.wait(wait_s):
            raise RunError(f"program {info.program} did not stop within {wait_s:g} s")
        return info

    # ------------------------------------------------------------------ service answers
    def stage_data(self, data: ResultData) -> None:
        """``DATA``/``TEXT``: keep it for the next RESULT."""
        self._data = data

    def result(self, ok: bool, message: str) -> bool:
        """``RESULT``: the handshake (one batch).  False if no program waits for it."""
        data, self._data = self._data, None
        info = self.current
        if info is None:
            log.info("RESULT %s with no program running: ignored", ok)
            return False
        try:
            info.execution.post_result(ok, _payload(data), _clip(message))
        except ProgramError as exc:
            info.execution.post_result(False, None, _clip(f"the answer's data did not fit: {exc}"))
        return True

    def frame(self, data: ResultData) -> bool:
        """``FRAME``/``FRAMETEXT``: set the data variables now, without the handshake."""
        info = self.current
        if info is None:
            return False
        try:
            info.execution.post(dict(data_updates(_payload(data), info.execution.program.file)))
        except ProgramError as exc:
            log.warning("stream frame not delivered: %s", exc)
            return False
        return True

    def stream_end(self, ok: bool, message: str) -> bool:
        """``STREAMEND``: FALSE sets ext_cmd_result := FALSE and ext_cmd_message."""
        info = self.current
        if info is None or ok:
            return info is not None
        info.execution.post({"ext_cmd_result": False, "ext_cmd_message": _clip(message)})
        return True


def _payload(data: ResultData | None) -> Any:
    """A DATA/TEXT message as what ``post_result`` takes (None, a str or an array)."""
    if data is None:
        return None
    if data.text is not None:
        return data.text
    if data.rows * data.cols == 0:
        return None
    if data.rows * data.cols > EXT_DATA_MAX:
        return np.zeros(data.rows * data.cols)  # post_result explains that it does not fit
    return np.asarray(data.values, dtype=float).reshape(data.rows, data.cols)
