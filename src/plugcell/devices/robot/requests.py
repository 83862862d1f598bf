"""A controller's answers to the robot service, whoever runs the programs.

What every controller that runs robot programs with a
:class:`~plugcell.devices.robot.runner.ProgramRunner` does with the line protocol's
messages (docs/controller-protocol.md) the same way — the simulated controller
(:mod:`plugcell.sim.controller.line_controller`, over TCP) and the programs on the PC
streaming to a real robot (:mod:`plugcell.devices.robot.stream_controller`, in the
service's process):

* :func:`answer` — the requests answered at once from the arm's model: ``PING``,
  ``STATUS``, ``ARM_POS``, ``ARM_JNTP``, ``POS_TO_JNTP``, ``JNTP_TO_POS``;
* :func:`status_text` — the ``STATUS`` reply's ``key=value`` words;
* :func:`deliver` — the service's answers to the running program (``DATA``/``TEXT``,
  ``FRAME``, ``RESULT``, ``END``) handed to the runner;
* :class:`Staged` — the ``VALUE`` presets of a ``RUN``, bounded;
* :func:`check_line` — a ``WRITE pc_client`` line that can be sent as one line.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from plugcell.devices.robot.protocol import (
    ArmJntp,
    ArmPos,
    JntpToPos,
    Message,
    Ping,
    PosToJntp,
    Request,
    Result,
    ResultData,
    Status,
    StreamEnd,
    format_number,
    format_numbers,
)
from plugcell.devices.robot.runner import ProgramRunner
from plugcell.pdl import Motion, SimClock
from plugcell.pdl.values import JointPos, Position

__all__ = ["Staged", "answer", "check_line", "deliver", "status_text"]

#: Staged VALUE lines: at most this many RUN ids and values per id.
MAX_STAGED_RUNS = 8
MAX_VALUES_PER_RUN = 1000


def answer(arm: Motion, req: Request, status: Callable[[], str]) -> str:
    """The text of the ``OK`` to a request answered from the arm's model.

    Parameters
    ----------
    arm : Motion
        The controller's arm (its readings and nominal kinematics; mm, degrees).
    req : Request
        ``PING``, ``STATUS``, ``ARM_POS``, ``ARM_JNTP``, ``POS_TO_JNTP`` or ``JNTP_TO_POS``.
    status : callable
        The ``STATUS`` text (:func:`status_text` with the controller's state).

    Returns
    -------
    str
        The reply's text.

    Raises
    ------
    MotionError, ValueError
        The arm refused (unreachable pose, no feedback …) or a request of another kind.
    """
    if isinstance(req, Ping):
        return ""
    if isinstance(req, Status):
        return status()
    if isinstance(req, ArmPos):
        return format_numbers(arm.arm_pos().as_tuple())
    if isinstance(req, ArmJntp):
        return format_numbers(arm.arm_jntp().joints)
    if isinstance(req, PosToJntp):
        return format_numbers(arm.pos_to_jntp(Position(*req.values)).joints)
    if isinstance(req, JntpToPos):
        return format_numbers(arm.jntp_to_pos(JointPos(req.values)).as_tuple())
    raise ValueError(f"unsupported request {type(req).__name__}")


def status_text(runner: ProgramRunner, clock: SimClock, moving: bool = False) -> str:
    """``state=… run=… program=… sim=… line=… [last_run=… last_program=… last_state=…]
    clock=…``: the ``STATUS`` reply (spaces in values written as ``_``).

    Parameters
    ----------
    runner : ProgramRunner
        The controller's programs.
    clock : SimClock
        The controller's clock (``clock``: its time, s).
    moving : bool
        A ``MOVE`` request runs (state ``MOVING`` when no program does).

    Returns
    -------
    str
        The words.
    """
    cur = runner.current
    fields = {"state": "IDLE", "run": "0", "program": "", "sim": "0", "line": ""}
    if cur is not None:
        loc = cur.execution.location
        fields.update(state="RUNNING", run=str(cur.run), program=cur.program,
                      sim=format_number(round(cur.execution.sim_time, 6)),
                      line=f"{Path(loc.file).name}:{loc.line}" if loc else "")
    elif moving:
        fields["state"] = "MOVING"
    last = runner.last
    if last is not None:
        fields.update(last_run=str(last.run), last_program=last.program, last_state=last.state)
    fields["clock"] = format_number(round(clock.now(), 6))
    return " ".join(f"{k}={v.replace(' ', '_')}" for k, v in fields.items())


def deliver(runner: ProgramRunner, message: Message) -> bool:
    """Hand the service's answer ``message`` to the running program.

    Returns
    -------
    bool
        Whether ``message`` was an answer (``DATA``/``TEXT``/``FRAME``, ``RESULT``,
        ``END``); other messages are the caller's.
    """
    if isinstance(message, ResultData):
        (runner.frame if message.frame else runner.stage_data)(message)
    elif isinstance(message, Result):
        runner.result(message.ok, message.message)
    elif isinstance(message, StreamEnd):
        runner.stream_end(message.ok, message.message)
    else:
        return False
    return True


class Staged:
    """The ``VALUE`` presets of the ``RUN`` of each id, until that ``RUN`` takes them;
    at most :data:`MAX_STAGED_RUNS` ids (the oldest dropped) and
    :data:`MAX_VALUES_PER_RUN` values each."""

    def __init__(self) -> None:
        self._runs: dict[int, dict[str, str]] = {}

    def add(self, run_id: int, name: str, text: str) -> None:
        """Keep ``name = text`` for the run ``run_id``."""
        staged = self._runs.setdefault(run_id, {})
        if len(self._runs) > MAX_STAGED_RUNS:
            self._runs.pop(next(iter(self._runs)))
        if len(staged) < MAX_VALUES_PER_RUN:
            staged[name] = text

    def take(self, run_id: int) -> dict[str, str]:
        """The presets of ``run_id`` (and forget them)."""
        return self._runs.pop(run_id, {})


def check_line(line: str) -> str:
    """``line`` if it can go to the service as one ``WRITE pc_client`` line.

    Raises
    ------
    ValueError
        It holds a line break.
    """
    if "\n" in line or "\r" in line:
        raise ValueError("a pc_client line cannot contain a line break")
    return line
