"""``plugcell cell``: the cell controller's functions from the terminal (thesis 7.6).

::

    plugcell cell ls [--json] [--commands]         services, state, partners (the wiring)
                                                   (also as ``plugcell services``)
    plugcell cell wire A B | unwire A B            A subscribes to / drops partner B
                                                   (also as ``plugcell wire``/``unwire``)
    plugcell cell save FILE                        the wiring of the cell to a file
    plugcell cell load FILE [--wait S] [--keep]    re-apply a saved wiring (and keep it)
    plugcell cell run ROBOT PROGRAM [ROBOT PROGRAM …] [--concurrent] [--value [ROBOT:]N=V …]
    plugcell cell monitor [--json] [--duration S] [--count N] [--service NAME]
    plugcell cell serve [--port 8765] [--wiring FILE] …   the cell controller and its web UI

``plugcell services`` is ``plugcell cell ls`` (:mod:`plugcell.apps.commands.services`);
``plugcell controller`` the deprecated name of ``plugcell cell serve``.
The same functions as the web UI (``plugcell cell serve``), scriptable: ``--json``
output, exit code 0 on success, 1 when a wire, program or process failed, 2 for
bad usage.  ``--via CONTROLLER`` sends wire/unwire/load/run to a running cell
controller service instead, which then keeps the wiring and shows the run.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import signal
import sys
import time
from pathlib import Path
from typing import Any

from plugcell.apps.cli import CommandError
from plugcell.apps.commands.cellargs import add_cell_args, cell_of, transport_of
from plugcell.framework import eventloop

#: The kind a cell controller announces, and its name before issue #33.
CELL_CONTROLLER_KINDS = ("cell-controller", "controller")


def _emit(obj: dict[str, Any]) -> None:
    sys.stdout.write(json.dumps(obj) + "\n")
    sys.stdout.flush()


def configure(p: argparse.ArgumentParser) -> None:
    """Add the ``cell`` options to its parser (declared in :mod:`plugcell.apps.cli`)."""
    p.description = (
        "The cell controller from the terminal: list the services, wire and "
        "unwire partners, save and load the wiring, run robot programs, monitor processes."
    )
    sub = p.add_subparsers(dest="cell_command", metavar="ACTION", required=True)

    ls = sub.add_parser("ls", help="the services of the cell and their partners")
    add_ls_options(ls, options=False)

    for name, subscribe in (("wire", True), ("unwire", False)):
        add_wire_options(
            sub.add_parser(name, help=f"service A {'subscribes to' if subscribe else 'drops'} B"),
            subscribe=subscribe, options=False)

    save = sub.add_parser("save", help="save the wiring of the cell to FILE")
    save.add_argument("file", type=Path)
    save.add_argument("--settle", type=float, default=0.3, help="discovery time, s")
    save.add_argument("--json", action="store_true", help="print the document")
    save.set_defaults(func=run_save)

    load = sub.add_parser("load", help="apply the wiring saved in FILE")
    load.add_argument("file", type=Path)
    load.add_argument("--wait", type=float, default=5.0,
                      help="seconds to wait for absent services (default 5)")
    load.add_argument("--keep", action="store_true",
                      help="stay and re-apply the wiring as services (re)appear, until Ctrl-C")
    load.add_argument("--duration", type=float, help="with --keep: stop after S seconds")
    load.add_argument("--json", action="store_true", help="JSON lines")
    load.add_argument("--via", metavar="CONTROLLER", help="ask this cell controller service")
    load.set_defaults(func=run_load)

    run = sub.add_parser("run", help="run robot programs: ROBOT PROGRAM [ROBOT PROGRAM …]")
    run.add_argument("pairs", nargs="+", metavar="ROBOT PROGRAM")
    mode = run.add_mutually_exclusive_group()
    mode.add_argument("--concurrent", action="store_true", help="all robots at once")
    mode.add_argument("--sequential", action="store_true", help="one after another (default)")
    run.add_argument("--value", action="append", default=[], metavar="[ROBOT:]NAME=VALUE",
                     help="a program value (repeatable; docs/robot-programs.md), e.g. "
                          "--value pnt0001=1500,0,1300,0,90,0; ROBOT: when several robots run")
    run.add_argument("--via", metavar="CONTROLLER", help="ask this cell controller service")
    run.set_defaults(func=run_run)

    mon = sub.add_parser("monitor", help="every process of the cell, live")
    mon.add_argument("--json", action="store_true", help="JSON lines")
    mon.add_argument("--duration", type=float, help="stop after S seconds")
    mon.add_argument("--count", type=int, help="stop after N processes ended")
    mon.add_argument("--service", help="only processes sent by or to this service")
    mon.add_argument("--no-journals", action="store_true",
                     help="do not read the journals (queued processes are then not shown)")
    mon.set_defaults(func=run_monitor)

    for s in (ls, *[sub.choices[n] for n in ("wire", "unwire")], save, load, run, mon):
        _add_common_options(s)

    from plugcell.apps.commands.controller import add_serve_options

    add_serve_options(sub.add_parser("serve", help="run the cell controller service and its web "
                                                 "UI (docs/cell-controller.md)"))


def _add_common_options(p: argparse.ArgumentParser) -> None:
    """The cell options and ``--timeout`` of every action (and of their aliases)."""
    add_cell_args(p)
    p.add_argument("--timeout", type=float, default=10.0,
                   help="seconds to wait for a service or an answer (default 10)")


async def _participant(args: argparse.Namespace, prefix: str) -> Any:
    from plugcell.framework.participant import Participant, default_client_name

    client = Participant(default_client_name(prefix), cell=cell_of(args),
                         transport=transport_of(args))
    await client.start()
    return client


# -- ls ------------------------------------------------------------------------------------


def add_ls_options(p: argparse.ArgumentParser, *, options: bool = True) -> None:
    """The options of ``cell ls`` and of its alias ``plugcell services`` (``options``: also
    the cell and ``--timeout`` options, which :func:`configure` adds to all its actions)."""
    p.description = (
        "Discover the services of the cell (liveliness + Get) and print their DeviceInfo: "
        "kind, state, connection, partners (the wiring); --commands: each command catalogue. "
        "Exit code 0 (also for an empty cell), 2 for bad usage.")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.add_argument("--commands", action="store_true",
                   help="list each service's description and command catalogue")
    p.add_argument("--settle", type=float, default=0.3, help="discovery time, s (default 0.3)")
    if options:
        _add_common_options(p)
    p.set_defaults(func=run_ls)


def run_ls(args: argparse.Namespace) -> int:
    """One JSON shape (``{"cell", "services", "wires"}``) and one exit-code rule for
    ``cell ls`` and ``services``."""
    from plugcell.devices.cell.tasks import describe_command

    states = eventloop.run(_states(args, args.settle))
    wires = _wires(states)
    if args.json:
        print(json.dumps({
            "cell": args.cell,
            "services": [{
                "name": s.device_info.name, "kind": s.device_info.kind,
                "state": s.device_info.state.value,
                "connection": s.device_info.connection.value,
                "info": s.device_info.info,
                "partners": sorted(p.name for p in s.partners),
                "commands": [describe_command(c) for c in s.device_info.commands],
            } for s in states],
            "wires": [w.to_json() for w in wires],
        }, indent=2))
        return 0
    if not states:
        print(f"no services in cell {args.cell!r}")
        return 0
    width = max(len("SERVICE"), *(len(s.device_info.name) for s in states))
    kinds = max(10, *(len(s.device_info.kind) for s in states))
    print(f"{'SERVICE':<{width}}  {'KIND':<{kinds}} {'STATE':<6} {'CONNECTION':<10} PARTNERS")
    for s in states:
        d = s.device_info
        partners = ", ".join(sorted(p.name for p in s.partners)) or "-"
        print(f"{d.name:<{width}}  {d.kind or '?':<{kinds}} {d.state.value:<6} "
              f"{d.connection.value:<10} {partners}")
        if args.commands:
            from plugcell.framework.data import describe

            if d.info:
                print(f"{'':<{width}}    {d.info}")
            for c in d.commands:
                print(f"{'':<{width}}    {c.name:<24} {c.type.value:<13} "
                      f"in: {describe(c.input_data_type, c.input_data_size):<16} "
                      f"out: {describe(c.output_data_type, c.output_data_size)}")
    print(f"wires: {', '.join(str(w) for w in wires) or 'none'}")
    return 0


async def _states(args: argparse.Namespace, settle: float) -> list[Any]:
    client = await _participant(args, "cell")
    try:
        await asyncio.sleep(settle)
        return await client.list_services(min(args.timeout, 3.0))
    finally:
        await client.close()


def _wires(states: list[Any]) -> list[Any]:
    """The wires between services; a cell controller's own subscriptions left out (its kind
    ``cell-controller``, or ``controller`` as a cell controller before issue #33 says)."""
    from plugcell.devices.cell.wiring import wires_in_place

    return wires_in_place({s.device_info.name: [p.name for p in s.partners] for s in states
                           if s.device_info.kind not in CELL_CONTROLLER_KINDS})


# -- wire / unwire ---------------------------------------------------------------------------


def add_wire_options(p: argparse.ArgumentParser, *, subscribe: bool, options: bool = True) -> None:
    """The options of ``cell wire``/``cell unwire`` and of their aliases ``plugcell
    wire``/``plugcell unwire`` (``options``: also the cell and ``--timeout`` options, which
    :func:`configure` adds to all its actions at once)."""
    p.description = (
        "Service A subscribes to partner B at run time (Get B's DeviceInfo, add it to A's "
        "Partners)." if subscribe else "Service A drops partner B from its Partners at run "
        "time.") + " Exit code 0 when done, 1 when the service refused, 2 for bad usage."
    p.add_argument("service", metavar="A")
    p.add_argument("partner", metavar="B")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.add_argument("--via", metavar="CONTROLLER", help="ask this cell controller service")
    if options:
        add_cell_args(p)
        p.add_argument("--timeout", type=float, default=10.0,
                       help="seconds to wait for A and B to be in the cell, and for the answer "
                            "(default 10)")
    p.set_defaults(func=run_wire, subscribe=subscribe)


def run_wire(args: argparse.Namespace) -> int:
    """One JSON shape (``{"ok", "service", "partner", "reason"}``) and one exit-code rule
    (1 when the wire failed) for ``cell wire`` and ``wire``, ``cell unwire`` and ``unwire``."""
    ok, reason = eventloop.run(_wire(args))
    if args.json:
        print(json.dumps({"ok": ok, "service": args.service, "partner": args.partner,
                          "reason": reason}))
    elif ok:
        verb = "subscribed to" if args.subscribe else "dropped"
        print(f"{args.service} {verb} {args.partner}")
    else:
        print(f"plugcell: error: {reason}", file=sys.stderr)
    return 0 if ok else 1


async def _wire(args: argparse.Namespace) -> tuple[bool, str]:
    client = await _participant(args, "cell")
    try:
        if args.via:
            command = "Wire" if args.subscribe else "Unwire"
            return await _via(client, args, command, "", [args.service, args.partner])
        # both may still be starting (a robot service starts its controller first): wait
        # for them as `plugcell call` waits for its service (`serve … &` then `wire`); a
        # partner to drop may have left the cell
        await client.wait_for(args.service, args.timeout)
        if args.subscribe and not await client.wait_for(args.partner, args.timeout):
            return False, (f"unknown device {args.partner!r}: no such service in cell "
                           f"{cell_of(args)!r} (waited {args.timeout:g} s)")
        response = await client.ask_subscribe(args.service, args.partner, args.subscribe,
                                              args.timeout)
        return response.ok, response.reason
    finally:
        await client.close()


async def _via(client: Any, args: argparse.Namespace, command: str, option: str,
               data: Any, timeout: float | None = None) -> tuple[bool, str]:
    if not await client.wait_for(args.via, min(args.timeout, 5.0)):
        return False, f"no cell controller {args.via!r} in cell {args.cell!r}"
    call = await client.create_process(args.via, command, option, data,
                                       timeout=timeout or args.timeout)
    final = await call.result()
    return final.state.value == "Completed", final.reason


# -- save / load -----------------------------------------------------------------------------


def run_save(args: argparse.Namespace) -> int:
    from plugcell.devices.cell.wiring import WiringError, save_wiring

    states = eventloop.run(_states(args, args.settle))
    try:
        doc = save_wiring(_wires(states), cell_of(args), args.file)
    except WiringError as exc:
        raise CommandError(str(exc)) from None
    if args.json:
        print(json.dumps(doc, indent=2))
    else:
        print(f"saved {len(doc['wires'])} wires of cell {args.cell!r} to {args.file}")
    return 0


def run_load(args: argparse.Namespace) -> int:
    from plugcell.devices.cell.wiring import WiringError, load_wiring

    try:
        wires, _ = load_wiring(args.file)
    except WiringError as exc:
        raise CommandError(str(exc)) from None
    return eventloop.run(_load(args, wires))


async def _load(args: argparse.Namespace, wires: list[Any]) -> int:
    from plugcell.devices.cell.wiring import WiringKeeper

    client = await _participant(args, "cell")
    try:
        if args.via:
            ok, reason = await _via(client, args, "Load", "", [str(args.file.resolve())])
            _report_load(args, None, ok, reason)
            return 0 if ok else 1
        keeper = WiringKeeper(set(wires))
        deadline = time.monotonic() + args.wait
        done: dict[Any, tuple[bool, str]] = {}
        while True:
            await _apply(client, keeper, done, args)
            pending = [w for w in wires if not done.get(w, (False, ""))[0]]
            if not pending or time.monotonic() >= deadline:
                break
            await asyncio.sleep(0.2)
        for w in wires:
            ok, reason = done.get(w, (False, ""))
            if not ok and not reason:
                absent = [n for n in (w.service, w.partner) if not client.is_alive(n)]
                reason = f"{', '.join(absent) or 'service'} not in the cell"
            _report_load(args, w, ok, reason)
        failed = sum(not done.get(w, (False, ""))[0] for w in wires)
        if args.keep:
            await _keep(client, keeper, args)
        return 1 if failed else 0
    finally:
        await client.close()


async def _apply(client: Any, keeper: Any, done: dict[Any, tuple[bool, str]],
                 args: argparse.Namespace) -> list[Any]:
    alive = set(client.services())
    partners: dict[str, set[str]] = {}
    for name in alive:
        with contextlib.suppress(Exception):
            state, _ = await client.get(name, min(args.timeout, 2.0))
            partners[name] = {p.name for p in state.partners}
    alive &= set(partners)

    async def ask(wire: Any) -> tuple[bool, str]:
        response = await client.ask_subscribe(wire.service, wire.partner, True, args.timeout)
        return response.ok, response.reason

    applied = []
    for w, ok, reason in await keeper.reapply(alive, partners, ask):
        done[w] = (ok, reason)
        if ok:
            applied.append(w)
    for w in keeper.wanted:
        if w.partner in partners.get(w.service, set()) and w not in done:
            done[w] = (True, "")
    return applied


def _report_load(args: argparse.Namespace, wire: Any, ok: bool, reason: str) -> None:
    if args.json:
        _emit({"event": "wire", **(wire.to_json() if wire else {}), "ok": ok, "reason": reason})
    elif wire is None:
        print("loaded" if ok else f"load failed: {reason}")
    else:
        print(f"{wire}: {'in place' if ok else 'FAILED ' + reason}")


async def _keep(client: Any, keeper: Any, args: argparse.Namespace) -> None:
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    end = time.monotonic() + args.duration if args.duration else None
    while not stop.is_set() and (end is None or time.monotonic() < end):
        done: dict[Any, tuple[bool, str]] = {}
        for w in await _apply(client, keeper, done, args):
            _report_load(args, w, True, "re-applied")
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(stop.wait(), 0.5)


# -- run ------------------------------------------------------------------------------------


def run_run(args: argparse.Namespace) -> int:
    if len(args.pairs) % 2:
        raise CommandError("give ROBOT PROGRAM pairs, e.g. cell run R1 example R2 example")
    pairs = [(r, program_ref(p)) for r, p in zip(args.pairs[::2], args.pairs[1::2],
                                                  strict=True)]
    mode = "concurrent" if args.concurrent else "sequential"
    args.values_of = _values_of(args.value, [r for r, _ in pairs])
    return eventloop.run(_run(args, pairs, mode))


def program_ref(program: str) -> str:
    """PROGRAM as the robot is to find it: a name of the program library unchanged; a
    relative path to a file in this folder made absolute — the robot service (and its
    controller) may run in another folder, where the relative path would not be found;
    anything else unchanged (the controller's error says where it looked)."""
    from plugcell.devices.robot.runner import is_program_name

    if is_program_name(program):
        return program
    path = Path(program).expanduser()
    if not path.is_absolute() and path.is_file():
        return str(path.resolve())
    return program


def _values_of(values: list[str], robots: list[str]) -> dict[str, list[str]]:
    """``--value [ROBOT:]NAME=VALUE`` → each robot's ``name=value`` texts."""
    out: dict[str, list[str]] = {r: [] for r in robots}
    for text in values:
        head, sep, rest = text.partition(":")
        robot, item = (head, rest) if sep and head in out and "=" not in head else ("", text)
        if "=" not in item or not item.partition("=")[0].strip():
            raise CommandError(f"--value {text!r}: expected [ROBOT:]NAME=VALUE")
        if not robot:
            if len(out) > 1:
                raise CommandError(f"--value {text!r}: several robots run; say which "
                                   f"(ROBOT:NAME=VALUE, ROBOT one of {', '.join(out)})")
            robot = robots[0]
        out[robot].append(item)
    return out


async def _run(args: argparse.Namespace, pairs: list[tuple[str, str]], mode: str) -> int:
    from plugcell.devices.cell.runs import ProgramRun, RunItem, run_programs

    client = await _participant(args, "run")
    try:
        if args.via:
            items = [x for r, p in pairs for x in (f"{r}:{p}", *args.values_of[r])]
            ok, reason = await _via(client, args, "Run", mode, items, timeout=86400.0)
            _emit({"event": "run", "mode": mode, "state": "Completed" if ok else "Failed",
                   "reason": reason})
            return 0 if ok else 1
        for robot, _ in pairs:
            await client.wait_for(robot, min(args.timeout, 5.0))
        run = ProgramRun(mode, [RunItem(r, p, args.values_of[r]) for r, p in pairs])
        last: list[str] = []

        def changed() -> None:
            for i, item in enumerate(run.items):
                line = json.dumps({"event": "program", **item.to_json()})
                if i >= len(last):
                    last.append("")
                if line != last[i]:
                    last[i] = line
                    sys.stdout.write(line + "\n")
            sys.stdout.flush()

        await run_programs(client, run, changed)
        _emit({"event": "run", "mode": mode, "state": run.state,
               "seconds": round((run.ended_ns - run.started_ns) / 1e9, 3)})
        return 0 if run.state == "Completed" else 1
    finally:
        await client.close()


# -- monitor --------------------------------------------------------------------------------


def run_monitor(args: argparse.Namespace) -> int:
    eventloop.run(_monitor(args))
    return 0


def _monitoring(args: argparse.Namespace) -> None:
    """Say that the monitor is watching: every process that ends from now on is shown
    (what ended before is history, read but not printed)."""
    if args.json:
        _emit({"event": "monitoring", "cell": cell_of(args)})
    else:
        print(f"monitoring cell {cell_of(args)!r} (Ctrl-C to stop)", flush=True)


async def _monitor(args: argparse.Namespace) -> None:
    from plugcell.devices.cell.journal_tail import JournalTail
    from plugcell.devices.cell.monitor import MonitorFeed, ProcessMonitor

    client = await _participant(args, "monitor")
    monitor = ProcessMonitor()
    stop = asyncio.Event()
    tail = None if args.no_journals else JournalTail(cell_of(args))
    # without the journals no row will name the command: nothing to wait for
    feed = MonitorFeed(service=args.service, hold_s=0.0 if tail is None else 1.0)

    def show(record: Any) -> None:
        if not feed.offer(record):
            return
        if args.json:
            _emit({"event": "process", **record.to_json()})
        else:
            t = time.strftime("%H:%M:%S", time.localtime())
            duration = record.duration()
            extra = f" {duration:.3f}s" if record.final and duration is not None else ""
            reason = f"  {record.reason}" if record.reason else ""
            data = f"  {record.data_text}" if record.data_text else ""
            print(f"{t} {record.sender:>14} → {record.recipient:<12} {record.command:<22} "
                  f"{record.state:<9}{extra}{data}{reason}", flush=True)
        if args.count is not None and feed.ended >= args.count:
            stop.set()

    subscriber = client.watch_processes(
        lambda service, update: show(monitor.updated(service, update)))
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    end = time.monotonic() + args.duration if args.duration else None
    first = True
    try:
        while not stop.is_set() and (end is None or time.monotonic() < end):
            if tail is not None:
                processes, updates = await asyncio.to_thread(tail.poll)
                for record in monitor.from_journal(processes, updates):
                    if not first:
                        show(record)
                if first:  # history: read, not printed
                    feed.history(monitor.records.values())
            if first:
                _monitoring(args)
                first = False
            for key in feed.held():
                if key in monitor.records:
                    show(monitor.records[key])
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(stop.wait(), 0.25)
    finally:
        subscriber.undeclare()
        if tail is not None:
            tail.close()
        await client.close()
