"""The cell controller service against real services in one event loop (thesis 7.6).

Discovery and subscription to all, wiring between other services at run time,
save/load and re-applying as services come back, tasks, program runs sequential
and concurrent, the monitor (who asked whom, queues from the journals) and the
controller's own commands.
"""

from __future__ import annotations

import asyncio
import json
import time
from collections.abc import Callable
from pathlib import Path

from cell_testlib import FakeRobot, SlowDevice, hosted, run

from plugcell.devices.camera import CameraService
from plugcell.devices.cell.service import CellController, cell_controller
from plugcell.devices.cell.tasks import check_task
from plugcell.devices.cell.wiring import load_wiring
from plugcell.devices.drill import DrillService
from plugcell.framework import Client, GenericDevice
from plugcell.sim.drivers.camera import SimulatedCamera
from plugcell.sim.drivers.drill import SimulatedDrill


async def eventually(predicate: Callable[[], bool], timeout: float = 8.0) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, "condition not reached in time"
        await asyncio.sleep(0.05)


def partners(c: CellController, name: str) -> set[str]:
    r = c.records.get(name)
    return set(r.partners) if r and r.alive else set()


def test_controller_discovers_wires_saves_loads_and_reapplies(cell: str, home: Path,
                                                              tmp_path: Path) -> None:
    async def body() -> None:
        camera = GenericDevice(CameraService(SimulatedCamera(time_scale=0.001)), cell=cell)
        tool = GenericDevice(DrillService(SimulatedDrill(time_scale=0.001)), cell=cell)
        robot = hosted(FakeRobot(), "ROBOT", cell=cell)
        for s in (camera, tool, robot):
            await s.start()
        ctl = cell_controller(cell=cell)
        await ctl.host.start()
        events = ctl.listen()
        try:
            await eventually(lambda: all(
                ctl.device_of(n) is not None for n in ("CAMERA", "TOOL", "ROBOT")))
            await eventually(
                lambda: {"CAMERA", "TOOL", "ROBOT"} <= set(ctl.host.participant.partners))
            assert ctl.records["CONTROLLER"].device is not None  # itself, as a service

            assert (await ctl.wire("ROBOT", "TOOL"))["ok"]
            assert (await ctl.wire("ROBOT", "CAMERA"))["ok"]
            assert partners(ctl, "ROBOT") == {"TOOL", "CAMERA"}
            assert set(robot.participant.partners) == {"TOOL", "CAMERA"}
            bad = await ctl.wire("ROBOT", "GHOST")
            assert not bad["ok"] and "GHOST" in bad["reason"]
            assert not (await ctl.wire("ROBOT", "ROBOT"))["ok"]
            assert not (await ctl.wire("CONTROLLER", "TOOL"))["ok"]

            doc = ctl.save(tmp_path / "cell.json")
            wires = {(w["service"], w["partner"]) for w in doc["wires"]}
            assert {("ROBOT", "TOOL"), ("ROBOT", "CAMERA")} <= wires
            assert ("ROBOT", "GHOST") in wires  # wanted, waiting for GHOST
            assert load_wiring(tmp_path / "cell.json")[1] == cell

            assert (await ctl.unwire("ROBOT", "CAMERA"))["ok"]
            assert partners(ctl, "ROBOT") == {"TOOL"}
            ctl.load(tmp_path / "cell.json")
            await eventually(lambda: "CAMERA" in robot.participant.partners)

            # the tool goes away and comes back: its wire is re-applied
            await tool.close()
            await eventually(lambda: not ctl.records["TOOL"].alive)
            assert "TOOL" not in robot.participant.partners
            tool = GenericDevice(DrillService(SimulatedDrill(time_scale=0.001)), cell=cell)
            await tool.start()
            await eventually(lambda: "TOOL" in robot.participant.partners)
            assert any("re-applied ROBOT → TOOL" in line["text"] for line in ctl.activity)
            kinds = set()
            while not events.empty():
                kinds.add(events.get_nowait()["type"])
            assert {"cell", "log"} <= kinds
        finally:
            await ctl.host.close()
            for s in (camera, tool, robot):
                await s.close()

    run(body(), 60.0)


def test_tasks_runs_and_the_monitor(cell: str, home: Path) -> None:
    async def body() -> None:
        tool = GenericDevice(DrillService(SimulatedDrill(time_scale=0.001)), cell=cell)
        camera = GenericDevice(CameraService(SimulatedCamera(time_scale=0.001)), cell=cell)
        slow = hosted(SlowDevice(), "SLOW", cell=cell)
        r1, r2 = hosted(FakeRobot(), "R1", cell=cell), hosted(FakeRobot(), "R2", cell=cell)
        services = [tool, camera, slow, r1, r2]
        for s in services:
            await s.start()
        ctl = cell_controller(cell=cell)
        await ctl.host.start()
        try:
            await eventually(lambda: all(ctl.device_of(s.name) for s in services))
            for robot in ("R1", "R2"):
                for partner in ("TOOL", "CAMERA"):
                    assert (await ctl.wire(robot, partner))["ok"]

            # a task: any command of any service, with its option and data
            events = ctl.listen()
            ack = await ctl.assign(check_task(ctl.device_of("TOOL"), "TOOL", "Drill", "Air",
                                              [550, 1100]))
            assert ack["state"] == "Queued"
            key = ("TOOL", "CONTROLLER", int(ack["identifier"]))
            await eventually(lambda: ctl.monitor.records[key].state == "Completed")
            # its listeners hear it end, even when the end came with the acknowledgement
            instant = await ctl.assign(check_task(ctl.device_of("SLOW"), "SLOW", "Work", "",
                                                  [0.0]))
            task_states: list[str] = []

            def drained() -> bool:
                while not events.empty():
                    e = events.get_nowait()
                    if e["type"] == "task" and e["id"].endswith("/" + instant["identifier"]):
                        task_states.append(e["state"])
                return "Completed" in task_states

            await eventually(drained)
            ctl.unlisten(events)
            refused = await ctl.assign(check_task(ctl.device_of("TOOL"), "TOOL", "Drill", "Oil",
                                                  [550, 1100]))
            fkey = ("TOOL", "CONTROLLER", int(refused["identifier"]))
            await eventually(lambda: ctl.monitor.records[fkey].state == "Failed")
            assert "unknown option 'Oil'" in ctl.monitor.records[fkey].reason

            # programs: sequential, then concurrent, then a failure stops a sequence
            run1 = ctl.start_run([["R1", "drill"], ["R2", "snap"]], "sequential")
            await eventually(lambda: run1.state != "Running")
            assert run1.state == "Completed", run1.to_json()

            def seen() -> set[tuple[str, str, str, str]]:
                return {(r.sender, r.recipient, r.command, r.state)
                        for r in ctl.monitor.records.values()}

            await eventually(lambda: {  # who asked whom; command names from the journals
                ("R1", "TOOL", "Drill", "Completed"), ("R2", "CAMERA", "SnapShot", "Completed"),
                ("CONTROLLER", "R1", "ACTIVATE", "Completed")} <= seen(), 3.0)

            seq = ctl.start_run(["R1:wait", "R2:wait"], "sequential")
            await eventually(lambda: seq.state != "Running")
            (_, s1, e1), (_, s2, e2) = r1.interface.ran[-1], r2.interface.ran[-1]
            assert s2 >= e1  # one after the other
            con = ctl.start_run(["R1:wait", "R2:wait"], "concurrent")
            await eventually(lambda: con.state != "Running")
            (_, s1, e1), (_, s2, e2) = r1.interface.ran[-1], r2.interface.ran[-1]
            assert con.state == "Completed" and s2 < e1 and s1 < e2  # together

            bad = ctl.start_run(["R1:fail", "R2:wait"], "sequential")
            await eventually(lambda: bad.state != "Running")
            assert bad.state == "Failed"
            assert "program fail" in bad.items[0].reason
            assert bad.items[1].state == "Skipped"
            ghost = ctl.start_run(["GHOST:x"], "concurrent")
            await eventually(lambda: ghost.state != "Running")
            assert ghost.items[0].state == "Failed" and "GHOST" in ghost.items[0].reason
            notrobot = ctl.start_run(["TOOL:x"], "concurrent")
            await eventually(lambda: notrobot.state != "Running")
            assert "has no ACTIVATE command" in notrobot.items[0].reason

            # a shared device used by someone else: its queue, read from its journal
            async with Client("OTHER", cell=cell) as other:
                calls = [await other.create_process("SLOW", "Work", "", 0.4) for _ in range(3)]
                await eventually(lambda: ctl.monitor.queues().get("SLOW", {}).get("length", 0)
                                 >= 1, 3.0)
                q = ctl.monitor.queues()["SLOW"]
                assert q["running"][0]["sender"] == "OTHER"
                assert q["queued"][0]["command"] == "Work"
                for call in calls:
                    assert (await call.result()).state.value == "Completed"
            await eventually(lambda: "SLOW" not in ctl.monitor.queues())

            # the controller is a service: its own commands
            async with Client(cell=cell) as client:
                final = await (await client.create_process("CONTROLLER", "Cell")).result()
                cell_json = json.loads(_text(final))
                assert {"R1", "R2", "TOOL"} <= {s["name"] for s in cell_json["services"]}
                final = await (await client.create_process(
                    "CONTROLLER", "Unwire", "", ["R2", "CAMERA"])).result()
                assert final.state.value == "Completed"
                assert "CAMERA" not in r2.participant.partners
                final = await (await client.create_process(
                    "CONTROLLER", "Run", "concurrent", ["R1:wait", "R2:fail"],
                    timeout=20)).result()
                assert final.state.value == "Failed" and "R2:fail" in final.reason
        finally:
            await ctl.host.close()
            for s in services:
                await s.close()

    run(body(), 80.0)


def _text(update: object) -> str:
    from plugcell.framework.data import from_data

    return str(from_data(update.data)[0])  # type: ignore[attr-defined]
