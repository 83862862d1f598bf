"""The cell controller service (thesis 7.6, Figures 7-3, 7-9 … 7-12).

"The cell controller service is responsible for the overall management of services
in the work-cell."  Like every device it is hosted by a service (a
:class:`~plugcell.framework.service.GenericDevice`, :func:`cell_controller`): it has a
name in the cell, a command catalogue and a journal.  It

* **discovers** the services of the cell (liveliness) and **subscribes to all** of
  them, so it sees their state and connection changes; a service that leaves is
  kept, marked dead (Figure 7-9);
* **wires and unwires** partners between *other* services at run time
  (``ask_subscribe``: robot → tracker, robot → compute, Figure 7-3), **saves** the
  wiring of the cell to a file and **loads** it again, re-applying each wire as
  soon as both of its services are (back) in the cell (``cell/wiring.py``);
* **assigns tasks** — any command of any service with its option and input data,
  checked against the declaration (``cell/tasks.py``, Figure 7-10) — and
  **runs robot programs** on several robots sequentially or concurrently
  (``cell/runs.py``);
* **monitors** every process of the cell live: state, data, duration, who asked
  whom, and the queue of each shared device (``cell/monitor.py``, Figure 7-11);
* **feeds** its listeners (the web UI): the activity log and batched changes of the
  cell and of the processes (``cell/feed.py``).

Its own commands make all of that available to any participant (a script, a
robot program through its robot service, ``plugcell call CONTROLLER …``); the web
UI (``plugcell controller``) and ``plugcell cell`` use the same methods (on the
:class:`CellController`; its service is ``controller.host``).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import time
from collections import deque
from collections.abc import Iterable
from pathlib import Path
from typing import Any, ClassVar

from plugcell.devices.cell.directory import CellDirectory
from plugcell.devices.cell.feed import UiFeed
from plugcell.devices.cell.journal_tail import JournalTail
from plugcell.devices.cell.monitor import ProcessMonitor, data_view
from plugcell.devices.cell.robot_states import RobotStreams
from plugcell.devices.cell.runs import (
    MODES,
    ProgramRun,
    RunError,
    parse_runs,
    run_programs,
)
from plugcell.devices.cell.tasks import CheckedTask
from plugcell.devices.cell.wiring import (
    Wire,
    WiringError,
    WiringKeeper,
    load_wiring,
    parse_wiring,
    save_wiring,
)
from plugcell.framework.declaration import Declaration
from plugcell.framework.messages import (
    Command,
    CommandTypes,
    DataTypes,
    Device,
    Message,
    ProcessStates,
    ProcessUpdateNotification,
)
from plugcell.framework.participant import Partner, PartnerError
from plugcell.framework.process_call import ProcessCall
from plugcell.framework.service import DeviceError, GenericDevice

log = logging.getLogger("plugcell.devices.cell.service")

#: Seconds between two reads of the journals (queued processes).
JOURNAL_PERIOD = 0.5

__all__ = ["CellController", "cell_controller"]


class MonitoredProcesses:
    """The controller's participant side as its tasks and runs use it: every process it
    creates (tasks, fetches, the ACTIVATE of runs) is also put in its monitor."""

    def __init__(self, host: GenericDevice, monitor: ProcessMonitor, feed: UiFeed) -> None:
        self.host = host
        self.monitor = monitor
        self.feed = feed

    @property
    def partners(self) -> dict[str, Partner]:
        return self.host.participant.partners

    async def subscribe(self, partner: str, timeout: float = 5.0) -> Device:
        return await self.host.participant.subscribe(partner, timeout)

    async def create_process(
        self, partner: str, command: str, option: str = "", data: Any = None, **kwargs: Any
    ) -> ProcessCall:
        """:meth:`Participant.create_process`, monitored."""
        host = self.host
        call = await host.participant.create_process(partner, command, option, data, **kwargs)
        known = host.participant.partners.get(partner)
        declared = known.device.command(command) if known else None
        ack = call.ack
        record = self.monitor.created(
            partner, host.name, call.identifier, command=command, option=option,
            type=declared.type.value if declared else "",
            state=ack.state.value if ack else "Queued", reason=ack.reason if ack else "",
        )
        self.feed.process_changed(record.key)
        return call


class CellController:
    """The cell controller (module docstring): the device a
    :class:`~plugcell.framework.service.GenericDevice` hosts (:func:`cell_controller`)."""

    declaration = Declaration(
        kind="cell-controller",
        default_name="CONTROLLER",
        vendor="plugcell",
        info="Cell controller (thesis 7.6): discovery, wiring, tasks, program runs, monitor",
        commands=(
        Command(name="Wire", type=CommandTypes.NoData,
                input_data_type=DataTypes.String, input_data_size=(2,),
                info="make SERVICE subscribe to PARTNER: input [SERVICE, PARTNER]"),
        Command(name="Unwire", type=CommandTypes.NoData,
                input_data_type=DataTypes.String, input_data_size=(2,),
                info="make SERVICE drop PARTNER: input [SERVICE, PARTNER]"),
        Command(name="Save", type=CommandTypes.NoData,
                input_data_type=DataTypes.String, input_data_size=(1,),
                info="save the wiring of the cell to the file named by the input"),
        Command(name="Load", type=CommandTypes.NoData,
                input_data_type=DataTypes.String, input_data_size=(1,),
                info="load a wiring file; its wires are re-applied as services (re)appear"),
        Command(name="Run", type=CommandTypes.NoData,
                input_data_type=DataTypes.String, input_data_size=(-1,), timeout=86400.0,
                info="run robot programs, input ['ROBOT:PROGRAM', …]; option sequential "
                     "(default) | concurrent; completes when every program has ended"),
        Command(name="Cell", type=CommandTypes.SingleData,
                output_data_type=DataTypes.String, output_data_size=(1,),
                info="the services, their partners and the wanted wiring, as JSON"),
        Command(name="Processes", type=CommandTypes.SingleData,
                output_data_type=DataTypes.String, output_data_size=(1,),
                info="the monitored processes and the queues, as JSON"),
    ))
    params: ClassVar[dict[str, type]] = {"wiring": str, "journals": int}

    def __init__(
        self,
        *,
        wiring: str | Path | None = None,
        journals: bool | int = True,
        home: Path | None = None,
    ) -> None:
        self.keeper = WiringKeeper()
        self.monitor = ProcessMonitor()
        self._journals = (bool(journals), home)
        self.journal_tail: JournalTail | None = None
        self.runs: dict[str, ProgramRun] = {}
        self.tasks: dict[str, ProcessCall] = {}
        self._run_tasks: dict[str, asyncio.Task[Any]] = {}
        self.wiring_file = Path(wiring) if wiring else None
        self.service: GenericDevice | None = None
        self._background: set[asyncio.Task[Any]] = set()
        self._loops: list[asyncio.Task[Any]] = []

    def bind(self, service: GenericDevice) -> None:
        self.service = service
        journals, home = self._journals
        self.journal_tail = JournalTail(service.cell, home) if journals else None
        self.feed = UiFeed(service.name, cell=self.cell_json, processes=self._processes_event,
                           log=log)
        """What the web UI hears (cell/feed.py)."""
        self.robots = RobotStreams(self.feed)
        """The latest joint state and tracked move of each robot (robot_states.py)."""
        self.processes = MonitoredProcesses(service, self.monitor, self.feed)
        """Creates the controller's processes, each monitored."""
        self.directory = CellDirectory(service.participant, feed=self.feed, keeper=self.keeper,
                                       monitor=self.monitor, robots=self.robots,
                                       log=self._log, spawn=self._spawn)
        """The services and clients of the cell, and the wires asked for (directory.py)."""
        self.records = self.directory.records
        self.clients = self.directory.clients

    @property
    def host(self) -> GenericDevice:
        """The service hosting the controller (``start()``, ``close()``, its name, cell …)."""
        assert self.service is not None, "CellController used before a service hosts it"
        return self.service

    # -- life cycle ----------------------------------------------------------------------

    async def connect(self) -> None:
        """Once live in the cell: follow every process, joint state and tracked move, load
        the wiring, start discovery, refresh, the UI feed and the journal reader."""
        host, participant = self.host, self.host.participant
        assert participant.bus is not None
        host.own(participant.watch_processes(self._on_any_process))
        self.robots.watch(participant.bus, host.own)
        if self.wiring_file is not None:
            try:
                self.load(self.wiring_file)
            except WiringError as exc:
                self._log("error", str(exc))
        self._loops = [
            asyncio.create_task(self.directory.follow(participant.events()),
                                name=f"{host.name}-discovery"),
            asyncio.create_task(self.directory.refresh_loop(), name=f"{host.name}-refresh"),
            asyncio.create_task(self.feed.run(), name=f"{host.name}-flush"),
        ]
        if self.journal_tail is not None:
            self._loops.append(
                asyncio.create_task(self._journal_loop(), name=f"{host.name}-journal")
            )
        self.directory.seen()

    async def prepare_close(self) -> None:
        """Before the service closes: stop the loops, the runs and the tasks it follows."""
        for task in [*self._loops, *self._background]:
            task.cancel()
        for task in [*self._loops, *self._background]:
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await task
        self._loops.clear()
        self._background.clear()
        if self.journal_tail is not None:
            self.journal_tail.close()

    def _spawn(self, coro: Any) -> asyncio.Task[Any]:
        task = asyncio.get_running_loop().create_task(coro)
        self._background.add(task)
        task.add_done_callback(self._background.discard)
        return task

    # -- events to listeners (the web UI) ------------------------------------------------

    def listen(self, maxsize: int = 2000) -> asyncio.Queue[dict[str, Any]]:
        """A queue of events from now on (:meth:`UiFeed.listen`)."""
        return self.feed.listen(maxsize)

    def unlisten(self, queue: asyncio.Queue[dict[str, Any]]) -> None:
        self.feed.unlisten(queue)

    def emit(self, event: dict[str, Any]) -> None:
        """Send ``event`` to every listener now."""
        self.feed.emit(event)

    @property
    def activity(self) -> deque[dict[str, Any]]:
        """The last lines of the activity log."""
        return self.feed.activity

    def _log(self, level: str, text: str) -> None:
        """A line of the activity log (shown in the UI, logged)."""
        self.feed.log(level, text)

    def cell_json(self) -> dict[str, Any]:
        """Services (alive and dead), clients, and the wanted wiring with its status."""
        return {
            "cell": self.host.cell,
            "controller": self.host.name,
            "services": [r.to_json(self.host.name) for r in sorted(
                self.records.values(), key=lambda r: r.name)],
            "clients": sorted(self.clients),
            "wiring": self.keeper.status(self.directory.alive_set(), self.directory.partner_sets()),
            "wiringFile": str(self.wiring_file) if self.wiring_file else "",
        }

    def snapshot(self) -> dict[str, Any]:
        """Everything a new listener needs."""
        return {
            "type": "snapshot",
            **self.cell_json(),
            "processes": self.monitor.snapshot(),
            "queues": self.monitor.queues(),
            "runs": [r.to_json() for r in self.runs.values()],
            "log": list(self.activity),
            "journals": self.journal_tail is not None,
            **self.robots.snapshot(),
        }

    def _processes_event(self, keys: Iterable[tuple[str, str, int]]) -> dict[str, Any]:
        now = time.time_ns()
        records = [self.monitor.records[k] for k in keys if k in self.monitor.records]
        return {"processes": [r.to_json(now) for r in records], "queues": self.monitor.queues()}

    # -- discovery (Figure 7-9; cell/directory.py) -------------------------------------

    def on_partner_notification(self, partner: str, body: Message) -> None:
        """A partner's state changed (the service has recorded it): show it."""
        self.directory.partner_changed(partner)

    async def refresh(self) -> None:
        """Get every service (partners = the wiring), then re-apply missing wires."""
        await self.directory.refresh()

    # -- wiring (Figures 7-3, 7-9) -------------------------------------------------------

    async def wire(self, service: str, partner: str) -> dict[str, Any]:
        """Make ``service`` subscribe to ``partner``; the wire is kept (re-applied later)."""
        try:
            w = Wire(service, partner)
        except WiringError as exc:
            return {"ok": False, "reason": str(exc)}
        self.keeper.want(w)
        ok, reason = await self.directory.ask(w, True)
        if ok:
            self._log("info", f"wired {w}")
        else:
            self.keeper.failed(w, reason)
            self._log("error", f"cannot wire {w}: {reason}")
        self.feed.cell_changed()
        return {"ok": ok, "reason": reason}

    async def unwire(self, service: str, partner: str) -> dict[str, Any]:
        """Make ``service`` drop ``partner``; the wire is no longer wanted."""
        try:
            w = Wire(service, partner)
        except WiringError as exc:
            return {"ok": False, "reason": str(exc)}
        self.keeper.drop(w)
        ok, reason = await self.directory.ask(w, False)
        self._log("info" if ok else "error", f"unwired {w}" if ok else f"unwire {w}: {reason}")
        self.feed.cell_changed()
        return {"ok": ok, "reason": reason}

    def wiring_document(self) -> list[Wire]:
        """What :meth:`save` writes: the wires in place plus those wanted but waiting."""
        return sorted(set(self.directory.wiring_now()) | self.keeper.wanted)

    def save(self, path: Path) -> dict[str, Any]:
        """Save the wiring of the cell (WiringError if the file cannot be written)."""
        doc = save_wiring(self.wiring_document(), self.host.cell, Path(path))
        self.wiring_file = Path(path)
        self._log("info", f"saved {len(doc['wires'])} wires to {path}")
        self.feed.cell_changed()
        return doc

    def load(self, source: Path | dict[str, Any]) -> list[Wire]:
        """Load a wiring (file or document); its wires are applied now and kept."""
        if isinstance(source, dict):
            wires, cell = parse_wiring(source)
            where = "the document"
        else:
            wires, cell = load_wiring(Path(source))
            self.wiring_file = Path(source)
            where = str(source)
        for w in wires:
            self.keeper.want(w)
        if cell and cell != self.host.cell:
            self._log("warning", f"{where} was saved in cell {cell!r}; applying to "
                                 f"{self.host.cell!r}")
        self._log("info", f"loaded {len(wires)} wires from {where}")
        self.directory.refresh_now.set()
        self.feed.cell_changed()
        return wires

    # -- tasks (Figure 7-10) ---------------------------------------------------------------

    def device_of(self, name: str) -> Device | None:
        """The DeviceInfo of a live service, or None."""
        record = self.records.get(name)
        return record.device if record is not None and record.alive else None

    async def assign(self, task: CheckedTask) -> dict[str, Any]:
        """Create the process of ``task``; returns its acknowledgement (updates follow)."""
        call = await self.processes.create_process(
            task.service, task.command.name, task.option, task.data, timeout=task.timeout
        )
        ack = call.ack
        assert ack is not None
        task_id = f"{task.service}/{self.host.name}/{call.identifier}"
        refused = ack.state is ProcessStates.Failed
        self._log("error" if refused else "info",
                  f"task {task.service}.{task.command.name} "
                  + (f"refused: {ack.reason}" if refused else "queued"))
        if not refused:  # its updates may already be here (they travel with the ack)
            self.tasks[task_id] = call
            self._spawn(self._follow(task_id, call))
        return {"id": task_id, "state": ack.state.value, "reason": ack.reason,
                "identifier": str(call.identifier)}

    async def _follow(self, task_id: str, call: ProcessCall) -> None:
        try:
            async for update in call:
                record = self.monitor.updated(call.partner, update, source="controller")
                self.feed.process_changed(record.key)
                data, text = data_view(update.data)
                self.emit({"type": "task", "id": task_id, "state": update.state.value,
                           "reason": update.reason, "data": data, "dataText": text})
        finally:
            self.tasks.pop(task_id, None)

    async def fetch(self, partner: str, command: str, option: str = "", data: Any = None, *,
                    timeout: float = 10.0) -> tuple[ProcessUpdateNotification, Any]:
        """A process the controller needs the data of itself (the UI's residual view
        reads a compute service's matrix, the live wizards a robot's joints): created
        with ``data`` as its input, monitored like a task, awaited — each wait bounded
        by ``timeout`` — and returned as the final update with the last data any update
        carried, in full (a task's events carry only a summary of large data)."""
        call = await self.processes.create_process(partner, command, option, data, timeout=timeout)
        out = None
        async for update in call:
            record = self.monitor.updated(call.partner, update, source="controller")
            self.feed.process_changed(record.key)
            if update.data is not None:
                out = update.data
        assert call.final is not None
        return call.final, out

    async def stop_task(self, task_id: str) -> dict[str, Any]:
        """Send the StopData that ends a MultipleData task."""
        call = self.tasks.get(task_id)
        if call is None:
            return {"ok": False, "reason": f"no running task {task_id}"}
        try:
            stop = await self.host.participant.stop_process(call)
        except PartnerError as exc:
            return {"ok": False, "reason": str(exc)}
        final = await stop.result()
        return {"ok": final.state is ProcessStates.Completed, "reason": final.reason}

    # -- program runs ------------------------------------------------------------------

    def start_run(self, items: Any, mode: str = "sequential") -> ProgramRun:
        """Start running programs (RunError for a bad request); follow it in :attr:`runs`.

        ``items``: see :func:`~plugcell.devices.cell.runs.parse_runs` (robot,
        program and the program's ``name=value`` values)."""
        if mode not in MODES:
            raise RunError(f"mode must be one of {', '.join(MODES)}, not {mode!r}")
        run = ProgramRun(mode, parse_runs(items))
        self.runs[run.id] = run
        while len(self.runs) > 100:
            self.runs.pop(next(iter(self.runs)))
        text = ", ".join(f"{i.robot}:{i.program}" + (f" ({len(i.values)} values)" if i.values
                                                     else "") for i in run.items)
        self._log("info", f"{run.id} ({mode}): {text}")
        run_task = self._spawn(run_programs(self.processes, run, lambda: self._run_changed(run)))
        self._run_tasks[run.id] = run_task
        run_task.add_done_callback(lambda _: self._run_tasks.pop(run.id, None))
        run_task.add_done_callback(lambda _: self._log(
            "info" if run.state == "Completed" else "error", f"{run.id} {run.state.lower()}"))
        self._run_changed(run)
        return run

    async def wait_run(self, run: ProgramRun, timeout: float) -> bool:
        """Wait (at most ``timeout`` s) until ``run`` has ended; False if it still runs."""
        task = self._run_tasks.get(run.id)
        if task is not None:
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(asyncio.shield(task), timeout)
        return run.state != "Running"

    def _run_changed(self, run: ProgramRun) -> None:
        self.emit({"type": "run", "run": run.to_json()})

    # -- the monitor (Figure 7-11) -----------------------------------------------------

    def _on_any_process(self, service: str, update: ProcessUpdateNotification) -> None:
        record = self.monitor.updated(service, update)
        self.feed.process_changed(record.key)

    async def _journal_loop(self) -> None:
        assert self.journal_tail is not None
        while True:
            try:
                processes, updates = await asyncio.to_thread(self.journal_tail.poll)
            except Exception:
                log.exception("%s: reading the journals", self.host.name)
                processes, updates = [], []
            for record in self.monitor.from_journal(processes, updates):
                self.feed.process_changed(record.key)
            await asyncio.sleep(JOURNAL_PERIOD)

    # -- the controller's own commands -----------------------------------------------

    async def dispatch(self, command: Command, option: str, data: Any) -> str:
        """The controller as a service: Wire, Unwire, Save, Load, Run, Cell, Processes."""
        values = [str(v) for v in data.reshape(-1)] if data is not None else []
        match command.name:
            case "Wire" | "Unwire":
                act = self.wire if command.name == "Wire" else self.unwire
                result = await act(values[0], values[1])
                if not result["ok"]:
                    raise DeviceError(result["reason"])
            case "Save" | "Load":
                try:
                    if command.name == "Save":
                        self.save(Path(values[0]))
                    else:
                        self.load(Path(values[0]))
                except WiringError as exc:
                    raise DeviceError(str(exc)) from None
            case "Run":
                try:
                    run = self.start_run(values, option or "sequential")
                except RunError as exc:
                    raise DeviceError(str(exc)) from None
                task = self._run_tasks.get(run.id)
                if task is not None:
                    await asyncio.shield(task)
                if run.state != "Completed":
                    failed = [f"{i.robot}:{i.program}: {i.reason}" for i in run.items
                              if i.state not in ("Completed", "Skipped")]
                    raise DeviceError("; ".join(failed) or "run failed")
            case "Cell":
                self.host.data_feedback.post([json.dumps(self.cell_json())])
            case "Processes":
                self.host.data_feedback.post([json.dumps({
                    "processes": self.monitor.snapshot(), "queues": self.monitor.queues()})])
        return "OK"


def cell_controller(name: str | None = None, *, wiring: str | Path | None = None,
                    journals: bool | int = True, home: Path | None = None,
                    **options: Any) -> CellController:
    """A cell controller hosted by its service (``controller.host``; ``options``: the
    framework's keywords, ``cell``, ``transport``, ``journal`` …), not started."""
    controller = CellController(wiring=wiring, journals=journals, home=home)
    GenericDevice(controller, name, **options)
    return controller
