"""Running a program: :class:`Execution` holds the mutable state of one run.

A :class:`~.program.Program` is immutable and can be run any number of times; each
run is an ``Execution`` with its own variables, call stack, current line and
simulated time.  The execution talks to the world only through the
:class:`~.interfaces.Motion`, :class:`~.interfaces.Channel` and
:class:`~.interfaces.Clock` it is given.

Threads: :meth:`Execution.run` (or :meth:`Execution.start` for a background
thread) executes the program; any other thread may call :meth:`Execution.post` /
:meth:`Execution.set_variable` (service answers, applied between statements),
:meth:`Execution.stop` (the program ends at the next statement, or at once from
a WAIT, DELAY or move), and read :attr:`Execution.location`, :attr:`Execution.state`
or :meth:`Execution.get_variable`.
"""

from __future__ import annotations

import enum
import logging
import math
import sys
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from plugcell.pdl import nodes as n
from plugcell.pdl import predefined
from plugcell.pdl.conversion import (
    ConversionError,
    data_updates,
    to_language,
    to_python,
)
from plugcell.pdl.errors import (
    ChannelError,
    ExecutionError,
    IndexOutOfBoundsError,
    Location,
    MotionFailedError,
    ProgramError,
    StackOverflowError,
    UninitializedError,
    ValueConversionError,
    WaitTimeoutError,
)
from plugcell.pdl.formatting import format_value
from plugcell.pdl.inbox import Inbox
from plugcell.pdl.interfaces import Channel, Clock, Motion, SimClock
from plugcell.pdl.operators import apply_binary, apply_unary
from plugcell.pdl.printer import format_expr
from plugcell.pdl.program import Program
from plugcell.pdl.scope import EXTERNAL_STORE, ModuleScope, VarInfo
from plugcell.pdl.types import (
    JOINTPOS,
    REAL,
    ArrayType,
    LangType,
    StringType,
)
from plugcell.pdl.values import (
    UNINIT,
    ArrayValue,
    JointPos,
    Position,
    Vector,
    copy_value,
)

__all__ = ["Execution", "ExecutionResult", "ExecutionState"]

log = logging.getLogger(__name__)

#: Smallest real-time pause of a WAIT poll (keeps speed=inf from spinning).
MIN_REAL_POLL_S = 0.0002
#: Python frames one routine call of the program takes (measured: 9).
_FRAMES_PER_CALL = 10


def _stack_depth() -> int:
    frame, depth = sys._getframe(), 0
    while frame is not None:
        depth, frame = depth + 1, frame.f_back
    return depth


class ExecutionState(enum.Enum):
    READY = "ready"
    RUNNING = "running"
    FINISHED = "finished"  # reached END, or DEACTIVATE
    FAILED = "failed"  # a ProgramError ended it (see ``error``)
    STOPPED = "stopped"  # Execution.stop()


@dataclass(frozen=True, slots=True)
class ExecutionResult:
    """How a run ended."""

    state: ExecutionState
    error: ProgramError | None
    sim_time: float  # simulated seconds the run took
    real_time: float  # wall-clock seconds
    location: Location | None  # last statement executed
    deactivated: bool = False

    @property
    def ok(self) -> bool:
        """Finished normally (END or DEACTIVATE)."""
        return self.state is ExecutionState.FINISHED

    def raise_for_error(self) -> ExecutionResult:
        """Raise the error that ended the run, if any; else return self."""
        if self.error is not None:
            raise self.error
        return self


class _Stopped(Exception):  # noqa: N818 - control flow, not an error
    pass


class _Deactivate(Exception):  # noqa: N818 - control flow, not an error
    pass


class _ReturnSignal(Exception):  # noqa: N818 - control flow, not an error
    def __init__(self, value: Any) -> None:
        self.value = value


class _Frame:
    """One activation: a routine call (or the main body)."""

    __slots__ = ("infos", "loc", "name", "scope", "values")

    def __init__(
        self, scope: ModuleScope, name: str, infos: dict[str, VarInfo], loc: Location | None
    ) -> None:
        self.scope = scope
        self.name = name
        self.infos = infos
        self.values: dict[str, Any] = {}
        self.loc = loc


def _initial(t: LangType) -> Any:
    return ArrayValue.empty(t) if isinstance(t, ArrayType) else UNINIT


class Execution:
    """One run of a :class:`~.program.Program`.

    ``values`` presets global variables before the run (the equivalent of PDL's
    ``.var`` file: taught positions…), converted like service data.
    ``wait_budget_s`` bounds the *real* time any one WAIT may take (tests);
    ``statement_budget`` bounds the number of statements executed.
    """

    def __init__(
        self,
        program: Program,
        *,
        motion: Motion | None = None,
        channel: Channel | None = None,
        clock: Clock | None = None,
        values: Mapping[str, Any] | None = None,
        console: Callable[[str], None] | None = None,
        wait_budget_s: float | None = None,
        statement_budget: int | None = None,
        poll_interval_s: float = 0.05,
        max_call_depth: int = 64,
    ) -> None:
        self.program = program
        self.motion = motion  # type: ignore[assignment]
        self.channel = channel
        self.clock: Clock = clock if clock is not None else SimClock()
        self.wait_budget_s = wait_budget_s
        self.statement_budget = statement_budget
        self.poll_interval_s = poll_interval_s
        self.max_call_depth = max_call_depth
        self.console: list[str] = []
        self._console_cb = console
        self._inbox = Inbox()
        self._stop_event = threading.Event()
        self._done = threading.Event()
        self._run_lock = threading.Lock()
        self._state = ExecutionState.READY
        self._result: ExecutionResult | None = None
        self._stop_reason = ""
        self._loc: Location | None = None
        self._frames: list[_Frame] = []
        self._traps: set[int] = set()
        self._statements = 0
        self._start_sim = self.clock.now()
        self._stores: dict[str, dict[str, Any]] = {EXTERNAL_STORE: {}}
        for k, (t, v) in (*predefined.EXTERNALS.items(), *predefined.SYSTEM_VARIABLES.items()):
            self._stores[EXTERNAL_STORE][k] = _initial(t) if v is None else v
        for scope in program.scopes.values():
            store = self._stores.setdefault(scope.key, {})
            for info in scope.globals.values():
                if info.store == scope.key:
                    store[n.key(info.name)] = _initial(info.type)
        self._routine_infos: dict[int, dict[str, VarInfo]] = {}
        if values:
            for name, value in values.items():
                info, v = self._preset(name, value)
                self._stores[info.store][n.key(info.name)] = v
        self._stmt_dispatch: dict[type, Callable[[Any, _Frame], None]] = {
            n.Assign: self._exec_assign,
            n.CallStmt: self._exec_call,
            n.If: self._exec_if,
            n.For: self._exec_for,
            n.While: self._exec_while,
            n.Repeat: self._exec_repeat,
            n.Select: self._exec_select,
            n.Wait: self._exec_wait,
            n.Delay: self._exec_delay,
            n.Move: self._exec_move,
            n.MoveRelative: self._exec_move_relative,
            n.Write: self._exec_write,
            n.Return: self._exec_return,
            n.Deactivate: self._exec_deactivate,
        }
        self._expr_dispatch: dict[type, Callable[[Any, _Frame], Any]] = {
            n.IntLit: lambda e, f: e.value,
            n.RealLit: lambda e, f: e.value,
            n.StrLit: lambda e, f: e.value,
            n.BoolLit: lambda e, f: e.value,
            n.Name: self._eval_name,
            n.Index: self._eval_index,
            n.Field: self._eval_field,
            n.Call: self._eval_call,
            n.Unary: lambda e, f: apply_unary(e.op, self._eval(e.operand, f), e.loc),
            n.Binary: lambda e, f: apply_binary(
                e.op, self._eval(e.left, f), self._eval(e.right, f), e.loc
            ),
        }

    # ================================================================= public API
    @property
    def state(self) -> ExecutionState:
        return self._state

    @property
    def result(self) -> ExecutionResult | None:
        """Set once the run has ended."""
        return self._result

    @property
    def error(self) -> ProgramError | None:
        return self._result.error if self._result else None

    @property
    def location(self) -> Location | None:
        """The statement being executed (or last executed)."""
        return self._loc

    @property
    def sim_time(self) -> float:
        """Simulated seconds since the execution was created."""
        return self.clock.now() - self._start_sim

    @property
    def call_stack(self) -> tuple[tuple[str, Location | None], ...]:
        """``(routine, call site)`` from the main program inwards."""
        return tuple((f.name, f.loc) for f in list(self._frames))

    def run(self) -> ExecutionResult:
        """Execute the program to its end in the calling thread; never raises a
        :class:`~.errors.ProgramError` (it is in the result).  Runs once."""
        with self._run_lock:
            if self._state is not ExecutionState.READY:
                raise RuntimeError("an Execution runs once; make a new one to run again")
            self._state = ExecutionState.RUNNING
        needed = self.max_call_depth * _FRAMES_PER_CALL + _stack_depth() + 200
        if sys.getrecursionlimit() < needed:  # only for a max_call_depth above the default
            sys.setrecursionlimit(needed)
        real0 = time.monotonic()
        error: ProgramError | None = None
        deactivated = False
        main = self.program.scopes[self.program.main_key]
        try:
            frame = _Frame(main, self.program.name, {}, None)
            self._frames.append(frame)
            self._exec_block(self.program.module.body or (), frame)
            state = ExecutionState.FINISHED
        except _Deactivate:
            state, deactivated = ExecutionState.FINISHED, True
        except _Stopped:
            state = ExecutionState.STOPPED
        except _ReturnSignal:  # pragma: no cover - the checker forbids it
            state = ExecutionState.FINISHED
        except ProgramError as exc:
            state, error = ExecutionState.FAILED, exc
        except RecursionError:
            state = ExecutionState.FAILED
            error = StackOverflowError.at(self._loc, "routine calls nested too deeply")
        except Exception as exc:  # an implementation bug must not kill the controller
            log.exception("internal error running %s", self.program.name)
            state = ExecutionState.FAILED
            error = ExecutionError.at(self._loc, f"internal error: {exc!r}")
        self._result = ExecutionResult(
            state, error, self.sim_time, time.monotonic() - real0, self._loc, deactivated
        )
        self._state = state
        self._done.set()
        return self._result

    def start(self) -> threading.Thread:
        """Run in a daemon thread; returns it (see :meth:`join`)."""
        thread = threading.Thread(target=self.run, name=f"pdl-{self.program.name}", daemon=True)
        thread.start()
        return thread

    def join(self, timeout: float | None = None) -> ExecutionResult | None:
        """Wait for the end of the run; the result, or ``None`` on timeout."""
        self._done.wait(timeout)
        return self._result

    def stop(self, reason: str = "stopped") -> None:
        """Ask the program to end safely (at the next statement, or now if it is
        waiting, delaying or moving).  Thread-safe; idempotent."""
        self._stop_reason = reason
        self._stop_event.set()
        self._inbox.wake()

    def post(self, updates: Mapping[str, Any]) -> None:
        """Set program variables from another thread (a service's answer).

        All values are converted now to the declared types — a value that does not
        fit raises :class:`~.errors.ValueConversionError` here and nothing is set —
        and applied together, in order, between two statements.  Settable: the
        service variables (``ext_cmd_finished``, ``ext_cmd_result``,
        ``ext_cmd_message``) and the program's global variables.
        """
        batch = [self._convert(name, value) for name, value in updates.items()]
        self._inbox.put(batch)

    def post_result(self, ok: bool, data: Any = None, message: str = "") -> None:
        """Answer the program's pending command the thesis way (4.1.3.2, 5.2.3.6).

        In one batch, in this order: the data, ``ext_cmd_message := message``,
        ``ext_cmd_result := ok`` and last ``ext_cmd_finished := TRUE``.  Data is
        ``None`` (no data: ``ext_cmd_count = 0``), a string (→ ``ext_cmd_text``), or
        numbers / a numeric array of any shape (booleans as 0/1): flattened row-major
        into ``ext_cmd_data[1..ext_cmd_count]``, with ``ext_cmd_rows`` the first
        dimension and ``ext_cmd_cols`` the product of the others (a 4×4 pose:
        1 row of 16; 24 poses: 24 rows of 16).  Data that does not fit raises
        :class:`~.errors.ValueConversionError` and nothing is set.
        """
        updates = dict(data_updates(data, self.program.file))
        updates.update(
            {"ext_cmd_message": message, "ext_cmd_result": bool(ok), "ext_cmd_finished": True}
        )
        self.post(updates)

    def set_variable(self, name: str, value: Any) -> None:
        """``post({name: value})``."""
        self.post({name: value})

    def get_variable(self, name: str) -> Any:
        """A global, service or system variable as plain Python (arrays as lists,
        uninitialized as ``None``).  Safe from any thread between statements."""
        main = self.program.scopes[self.program.main_key]
        sym = main.resolve(n.key(name))
        if sym is None or sym.kind != "var" or sym.var is None:
            raise KeyError(f"{self.program.name} has no variable {name}")
        return to_python(copy_value(self._stores[sym.var.store][n.key(sym.var.name)]))

    # ================================================================= BuiltinContext
    def trap(self, code: int, on: bool) -> None:
        if on:
            self._traps.add(code)
        else:
            self._traps.discard(code)

    # ================================================================= variables
    def _preset(self, name: str, value: Any) -> tuple[VarInfo, Any]:
        """A preset value (the variable file): an array may be given its first rows
        only — PDL's variable files hold partly initialised arrays; the rest stays
        uninitialised."""
        info, t = self._convert(name, None, any_global=True, check_only=True)
        short = (isinstance(t, ArrayType) and t.dims[0] is not None
                 and isinstance(value, list | tuple) and 0 < len(value) < t.dims[0])
        if not short:
            return self._convert(name, value, any_global=True)
        part_type = ArrayType(t.element, (len(value), *t.dims[1:]))
        try:
            part = to_language(value, part_type)
        except ConversionError as exc:
            raise ValueConversionError.at(
                info.loc, f"cannot set {info.name} ({info.type}): {exc}") from None
        full = ArrayValue.empty(t)
        full.data[: len(part.data)] = part.data
        return info, full

    def _convert(self, name: str, value: Any, any_global: bool = False,
                 check_only: bool = False) -> tuple[VarInfo, Any]:
        try:
            info = self.program.variable(name)
        except KeyError as exc:
            raise ValueConversionError(self.program.file, 0, str(exc.args[0])) from None
        if check_only:
            return info, info.type
        try:
            return info, to_language(value, info.type)
        except ConversionError as exc:
            raise ValueConversionError.at(
                info.loc, f"cannot set {info.name} ({info.type}): {exc}"
            ) from None

    def _apply_inbox(self) -> None:
        for batch in self._inbox.drain():
            for info, value in batch:
                self._stores[info.store][n.key(info.name)] = copy_value(value)

    def _storage(self, info: VarInfo, frame: _Frame) -> dict[str, Any]:
        return frame.values if info.store == "local" else self._stores[info.store]

    def _read_var(self, info: VarInfo, frame: _Frame, loc: Location) -> Any:
        value = self._storage(info, frame)[n.key(info.name)]
        if value is UNINIT:
            raise UninitializedError.at(loc, f"{info.name} is uninitialized")
        return value

    def _coerce(self, value: Any, t: LangType) -> Any:
        """Value semantics of assignment: INTEGER → REAL, strings cut to length, copies."""
        if t == REAL and isinstance(value, int) and not isinstance(value, bool):
            return float(value)
        if isinstance(t, StringType) and isinstance(value, str):
            return value if t.length is None else value[: t.length]
        if isinstance(value, ArrayValue):
            out = value.copy()
            el = t.element if isinstance(t, ArrayType) else None
            if el == REAL:
                out.data = [float(x) if isinstance(x, int) else x for x in out.data]
            elif isinstance(el, StringType) and el.length is not None:
                out.data = [x[: el.length] if isinstance(x, str) else x for x in out.data]
            if isinstance(t, ArrayType) and all(d is not None for d in t.dims):
                out.type = t
            return out
        return value

    # ================================================================= statements
    def _boundary(self, stmt: n.Stmt) -> None:
        self._loc = stmt.loc
        if self._stop_event.is_set():
            raise _Stopped
        if self._inbox.pending():
            self._apply_inbox()
        self._statements += 1
        if self.statement_budget is not None and self._statements > self.statement_budget:
            err = ExecutionError.at(
                stmt.loc, f"statement budget of {self.statement_budget} exceeded"
            )
            err.trappable = False  # type: ignore[attr-defined]
            raise err

    def _exec_block(self, stmts: tuple[n.Stmt, ...], frame: _Frame) -> None:
        for s in stmts:
            self._boundary(s)
            try:
                self._stmt_dispatch[type(s)](s, frame)
            except ExecutionError as err:
                if not self._trapped(err):
                    raise
                store = self._stores[EXTERNAL_STORE]
                store["$ERROR"] = err.code
                store["$ERROR_MSG"] = str(err)[:255]

    def _trapped(self, err: ExecutionError) -> bool:
        if not getattr(err, "trappable", True):
            return False
        return err.code in self._traps or predefined.ERR_ANY in self._traps

    def _exec_assign(self, s: n.Assign, frame: _Frame) -> None:
        self._assign(s.target, self._eval(s.value, frame), frame)

    def _assign(self, target: n.Expr, value: Any, frame: _Frame) -> None:
        if isinstance(target, n.Name):
            sym = frame.scope.resolve(n.key(target.name), frame.infos)
            assert sym is not None and sym.var is not None
            info = sym.var
            self._storage(info, frame)[n.key(info.name)] = self._coerce(value, info.type)
        elif isinstance(target, n.Index):
            base = self._eval(target.base, frame)
            idx = [self._eval(i, frame) for i in target.indices]
            if isinstance(base, ArrayValue):
                off = self._offset(base, idx, target)
                base.data[off] = self._coerce(value, base.type.element)
            else:  # JOINTPOS
                j = self._joint_index(base, idx[0], target)
                joints = list(base.joints)
                joints[j] = float(value)
                self._assign(target.base, JointPos(tuple(joints)), frame)
        elif isinstance(target, n.Field):
            base = self._eval(target.base, frame)
            new = base.with_field(target.name, value if target.name == "CNFG" else float(value))
            self._assign(target.base, new, frame)
        else:  # pragma: no cover - the checker forbids it
            raise ExecutionError.at(target.loc, "not assignable")

    def _exec_call(self, s: n.CallStmt, frame: _Frame) -> None:
        self._call(s.name, s.args, s.loc, frame, statement=True)

    def _exec_if(self, s: n.If, frame: _Frame) -> None:
        if self._eval(s.cond, frame):
            self._exec_block(s.then, frame)
        elif s.orelse is not None:
            self._exec_block(s.orelse, frame)

    def _exec_for(self, s: n.For, frame: _Frame) -> None:
        start = self._eval(s.start, frame)
        stop = self._eval(s.stop, frame)
        step = self._eval(s.step, frame) if s.step is not None else 1
        if step <= 0:
            raise ExecutionError.at(
                s.loc, f"FOR STEP must be positive, not {step} (count down with DOWNTO)"
            )
        var = n.Name(s.var, s.loc)
        i = start
        while (i >= stop) if s.downto else (i <= stop):
            self._assign(var, i, frame)
            self._exec_block(s.body, frame)
            i = i - step if s.downto else i + step

    def _exec_while(self, s: n.While, frame: _Frame) -> None:
        while self._eval(s.cond, frame):
            self._exec_block(s.body, frame)
            self._boundary_loop(s)

    def _boundary_loop(self, s: n.Stmt) -> None:
        """An empty loop body still reaches a statement boundary."""
        self._boundary(s)

    def _exec_repeat(self, s: n.Repeat, frame: _Frame) -> None:
        while True:
            self._exec_block(s.body, frame)
            self._boundary_loop(s)
            if self._eval(s.cond, frame):
                return

    def _exec_select(self, s: n.Select, frame: _Frame) -> None:
        subject = self._eval(s.subject, frame)
        for case in s.cases:
            if any(self._eval(v, frame) == subject for v in case.values):
                self._exec_block(case.body, frame)
                return
        if s.orelse is not None:
            self._exec_block(s.orelse, frame)

    def _exec_wait(self, s: n.Wait, frame: _Frame) -> None:
        timeout_s = None
        if s.timeout is not None:
            timeout_s = max(0.0, float(self._eval(s.timeout, frame)) / 1000.0)
        speed = self.clock.speed
        t0 = self.clock.now()
        real0 = time.monotonic()
        while True:
            self._apply_inbox()
            if self._stop_event.is_set():
                raise _Stopped
            if self._eval(s.cond, frame):
                return
            waited = self.clock.now() - t0
            if timeout_s is not None and waited >= timeout_s - 1e-12:
                raise WaitTimeoutError.at(
                    s.loc,
                    f"WAIT FOR {format_expr(s.cond)} timed out after {timeout_s * 1000:g} ms",
                )
            if self.wait_budget_s is not None and time.monotonic() - real0 > self.wait_budget_s:
                err = WaitTimeoutError.at(
                    s.loc,
                    f"WAIT FOR {format_expr(s.cond)} still false after the real-time budget "
                    f"of {self.wait_budget_s:g} s",
                )
                err.trappable = False  # type: ignore[attr-defined]
                raise err
            step = self.poll_interval_s
            if timeout_s is not None:
                step = min(step, timeout_s - waited)
            real_step = max(step / speed if math.isfinite(speed) else 0.0, MIN_REAL_POLL_S)
            seen = self._inbox.version
            r0 = time.monotonic()
            self._inbox.wait_change(seen, real_step)
            # simulated time runs `speed` times faster than the real time that passed
            advance = (time.monotonic() - r0) * speed if math.isfinite(speed) else step
            if timeout_s is not None:
                advance = min(advance, timeout_s - waited)
            self.clock.advance(advance)

    def _sleep(self, seconds: float) -> None:
        """Let ``seconds`` of simulated time pass (``seconds / speed`` real)."""
        if seconds <= 0:
            return
        speed = self.clock.speed
        if math.isfinite(speed):
            real = seconds / speed
            r0 = time.monotonic()
            if self._stop_event.wait(real):
                self.clock.advance(min(seconds, (time.monotonic() - r0) * speed))
                raise _Stopped
        elif self._stop_event.is_set():
            raise _Stopped
        self.clock.advance(seconds)

    def _exec_delay(self, s: n.Delay, frame: _Frame) -> None:
        ms = float(self._eval(s.duration, frame))
        if ms < 0:
            raise ExecutionError.at(s.loc, f"DELAY of a negative time ({ms:g} ms)")
        self._sleep(ms / 1000.0)

    def _motion(self, loc: Location) -> Motion:
        if self.motion is None:
            raise MotionFailedError.at(loc, "no arm is attached to this controller")
        return self.motion

    def _move(self, what: str, loc: Location, thunk: Callable[[], float | None]) -> None:
        try:
            duration = thunk()
        except ProgramError:
            raise
        except Exception as exc:
            raise MotionFailedError.at(loc, f"{what} failed: {exc}") from exc
        if duration is not None:
            duration = float(duration)
            if not math.isfinite(duration) or duration < 0:
                raise MotionFailedError.at(loc, f"{what}: the arm reported a duration {duration}")
            self._sleep(duration)

    def _exec_move(self, s: n.Move, frame: _Frame) -> None:
        target = self._eval(s.target, frame)
        motion = self._motion(s.loc)
        text = f"MOVE {'' if s.kind == 'TO' else s.kind + ' '}TO {format_expr(s.target)}"
        if s.tracking is not None:
            self._move_tracked(f"{text} WITH TRACKING {s.tracking}", s, target, motion)
        elif isinstance(target, JointPos):
            self._move(text, s.loc, lambda: motion.move_joints(list(target.joints)))
        elif s.kind == "JOINT":
            self._move(
                text,
                s.loc,
                lambda: motion.move_joints(
                    list(to_language(motion.pos_to_jntp(target), JOINTPOS).joints)
                ),
            )
        else:
            self._move(text, s.loc, lambda: motion.move_to(target, linear=s.kind == "LINEAR"))

    def _move_tracked(self, text: str, s: n.Move, target: Position, motion: Motion) -> None:
        """``MOVE LINEAR TO p WITH TRACKING T``: the arm's ``move_tracked(pose, tracker)``
        (:class:`~.interfaces.TrackedMotion`) — an arm moved over a streaming link."""
        tracked = getattr(motion, "move_tracked", None)
        if tracked is None:
            raise MotionFailedError.at(
                s.loc, f"{text}: tracking needs a streaming link (--rsi/--egm): this "
                "controller runs its moves by itself, no correction reaches them while they run")
        self._move(text, s.loc, lambda: tracked(target, s.tracking))

    def _exec_move_relative(self, s: n.MoveRelative, frame: _Frame) -> None:
        v: Vector = self._eval(s.vector, frame)
        motion = self._motion(s.loc)
        text = f"MOVE RELATIVE {format_expr(s.vector)} IN {s.frame}"
        self._move(text, s.loc, lambda: motion.move_relative((v.x, v.y, v.z), s.frame))

    def _exec_write(self, s: n.Write, frame: _Frame) -> None:
        lines: list[str] = []
        parts: list[str] = []
        for item in s.items:
            value = self._eval(item.expr, frame)
            if value is predefined.NEWLINE_VALUE:
                lines.append("".join(parts))
                parts = []
                continue
            width = self._eval(item.width, frame) if item.width is not None else None
            prec = self._eval(item.precision, frame) if item.precision is not None else None
            parts.append(format_value(value, width, prec))
        if parts or not lines:
            lines.append("".join(parts))
        lun = n.key(s.lun)
        if lun == "PC_CLIENT":
            if self.channel is None:
                raise ChannelError.at(s.loc, "WRITE pc_client: no PC connection")
            for line in lines:
                try:
                    self.channel.write(line)
                except Exception as exc:
                    raise ChannelError.at(s.loc, f"WRITE pc_client failed: {exc}") from exc
        elif lun != "LUN_NULL":
            for line in lines:
                self.console.append(line)
                if self._console_cb is not None:
                    self._console_cb(line)

    def _exec_return(self, s: n.Return, frame: _Frame) -> None:
        raise _ReturnSignal(self._eval(s.value, frame) if s.value is not None else None)

    def _exec_deactivate(self, s: n.Deactivate, frame: _Frame) -> None:
        raise _Deactivate

    # ================================================================= expressions
    def _eval(self, e: n.Expr, frame: _Frame) -> Any:
        return self._expr_dispatch[type(e)](e, frame)

    def _eval_name(self, e: n.Name, frame: _Frame) -> Any:
        sym = frame.scope.resolve(n.key(e.name), frame.infos)
        assert sym is not None
        if sym.kind == "var":
            assert sym.var is not None
            return self._read_var(sym.var, frame, e.loc)
        if sym.kind == "const":
            assert sym.const is not None
            return sym.const.value
        return self._call(e.name, (), e.loc, frame, statement=False)

    def _offset(self, arr: ArrayValue, idx: list[int], e: n.Index) -> int:
        off = arr.offset(idx)
        if off is None:
            bounds = ", ".join(f"1..{d}" for d in arr.dims)
            given = ", ".join(str(i) for i in idx)
            raise IndexOutOfBoundsError.at(
                e.loc, f"index [{given}] outside {format_expr(e.base)}[{bounds}]"
            )
        return off

    def _joint_index(self, jnt: JointPos, i: int, e: n.Index) -> int:
        if not 1 <= i <= len(jnt.joints):
            raise IndexOutOfBoundsError.at(
                e.loc, f"axis {i} outside {format_expr(e.base)}[1..{len(jnt.joints)}]"
            )
        return i - 1

    def _eval_index(self, e: n.Index, frame: _Frame) -> Any:
        base = self._eval(e.base, frame)
        idx = [self._eval(i, frame) for i in e.indices]
        if isinstance(base, ArrayValue):
            value = base.data[self._offset(base, idx, e)]
            if value is UNINIT:
                raise UninitializedError.at(e.loc, f"{format_expr(e)} is uninitialized")
            return value
        return base.joints[self._joint_index(base, idx[0], e)]

    def _eval_field(self, e: n.Field, frame: _Frame) -> Any:
        base: Position | Vector = self._eval(e.base, frame)
        return base.get(e.name)

    def _eval_call(self, e: n.Call, frame: _Frame) -> Any:
        return self._call(e.name, e.args, e.loc, frame, statement=False)

    def _call(
        self, name: str, args: tuple[n.Expr, ...], loc: Location, frame: _Frame, statement: bool
    ) -> Any:
        sym = frame.scope.resolve_call(n.key(name), statement)
        assert sym is not None
        if sym.kind == "routine":
            assert sym.routine is not None
            values = [copy_value(self._eval(a, frame)) for a in args]
            scope = self.program.scopes[sym.routine.module]
            return self._invoke(scope, sym.routine.routine, values, loc)
        b = sym.builtin
        assert b is not None
        values = [
            None if b.arg_spec(i).output else self._eval(a, frame) for i, a in enumerate(args)
        ]
        out = b.impl(self, values, loc)
        if sym.kind == "function":
            return out
        outputs = [a for i, a in enumerate(args) if b.arg_spec(i).output]
        for target, value in zip(outputs, out, strict=True):
            self._assign(target, value, frame)
        return None

    def _invoke(self, scope: ModuleScope, r: n.Routine, args: list[Any], loc: Location) -> Any:
        if len(self._frames) > self.max_call_depth:
            raise StackOverflowError.at(
                loc, f"more than {self.max_call_depth} nested routine calls (runaway recursion?)"
            )
        infos = self._routine_infos.get(id(r))
        if infos is None:
            infos = {}
            for p in r.params:
                infos[n.key(p.name)] = VarInfo(p.name, p.type, p.loc, "local")
            for d in r.locals:
                for x in d.names:
                    infos[n.key(x)] = VarInfo(x, d.type, d.loc, "local")
            self._routine_infos[id(r)] = infos
        frame = _Frame(scope, r.name, infos, loc)
        for p, value in zip(r.params, args, strict=True):
            frame.values[n.key(p.name)] = self._coerce(value, p.type)
        for d in r.locals:
            for x in d.names:
                frame.values[n.key(x)] = _initial(d.type)
        caller_loc = self._loc
        self._frames.append(frame)
        try:
            self._exec_block(r.body, frame)
        except _ReturnSignal as ret:
            self._loc = caller_loc
            if r.return_type is None:
                return None
            return self._coerce(ret.value, r.return_type)
        finally:
            self._frames.pop()
        if r.return_type is None:
            self._loc = caller_loc
        else:
            raise ExecutionError.at(
                self._loc or loc, f"routine {r.name} ended without RETURN of {r.return_type}"
            )
        return None
