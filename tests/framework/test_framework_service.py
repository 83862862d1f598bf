"""The generic service in one process: queue semantics, timeouts, bad input, partners, journal.

Services and clients here are real Zenoh participants (separate sessions on
loopback); the device is scripted so every step is under the test's control.
"""

from __future__ import annotations

import asyncio

import msgspec
import numpy as np
import pytest
from framework_testlib import cell_with, collect, run, scripted, states, unique_cell, until

from plugcell.framework import codec
from plugcell.framework import scheduler as scheduler_module
from plugcell.framework.journal import read_journal
from plugcell.framework.messages import (
    Acknowledgement,
    Command,
    Data,
    DataTypes,
    DeviceStates,
    Process,
    ProcessStates,
    Tag,
)
from plugcell.framework.participant import Participant, PartnerError

pytestmark = pytest.mark.timeout(60)

Q, R, C, F = (
    ProcessStates.Queued,
    ProcessStates.Running,
    ProcessStates.Completed,
    ProcessStates.Failed,
)


def test_create_acknowledge_update_complete(tmp_path):
    async def body():
        async with cell_with(tmp_path, "ROBOT") as (dev, robot):
            dev.interface.gates["g"] = asyncio.Event()
            work = await robot.create_process("DEV", "Work", "g")
            assert work.ack.state is Q and work.ack.instance == dev.participant.instance
            running = await anext(work)
            assert (running.state, running.seq) == (R, 1)
            dev.interface.gates["g"].set()
            assert [(u.state, u.seq) for u in await collect(work)] == [(C, 2)]
            # a process that ends within one event-loop turn: its data-less Running
            # update is journaled but superseded by the final one (seq 1 not sent)
            call = await robot.create_process("DEV", "Measure")
            updates = await collect(call)
            assert [(u.state, u.seq) for u in updates] == [(C, 2)]
            np.testing.assert_array_equal(call.array(updates[-1]), [1.0, 2.0, 3.0])
            assert dev.device.state is DeviceStates.Ready

    run(body())


def test_a_device_note_is_the_reason_of_the_completed_update(tmp_path):
    """GenericDevice.note: a warning on a process that succeeds reaches its sender as the
    Completed update's reason — and only that process's."""
    async def body():
        async with cell_with(tmp_path, "ROBOT") as (_dev, robot):
            noted = await collect(await robot.create_process("DEV", "Work", "note:mind it"))
            assert (noted[-1].state, noted[-1].reason) == (C, "mind it")
            plain = await collect(await robot.create_process("DEV", "Work", "x"))
            assert (plain[-1].state, plain[-1].reason) == (C, "")

    run(body())


def test_fifo_one_at_a_time_and_get_while_busy(tmp_path):
    async def body():
        async with cell_with(tmp_path, "A", "B") as (dev, a, b):
            dev.interface.gates["g"] = asyncio.Event()
            first = await a.create_process("DEV", "Work", "g")
            await dev.interface.started.wait()
            second = await b.create_process("DEV", "Work", "b")
            third = await a.create_process("DEV", "Work", "a2")
            assert second.ack.state is Q and third.ack.state is Q
            state, _ = await b.get("DEV")  # Get is served while a process runs
            assert state.device_info.state is DeviceStates.Busy
            assert dev.interface.log == ["Work:g"]
            dev.interface.gates["g"].set()
            for call in (first, second, third):
                assert (await call.result()).state is C
            assert dev.interface.log == ["Work:g", "Work:b", "Work:a2"]

    run(body())


def test_multiple_data_holds_the_device_until_the_same_senders_stop(tmp_path):
    async def body():
        async with cell_with(tmp_path, "A", "B") as (dev, a, b):
            stream = await a.create_process("DEV", "Stream")
            await dev.interface.started.wait()
            b_work = await b.create_process("DEV", "Work", "b")
            b_stop = await b.create_process("DEV", "Stop")  # not B's stream: must wait
            a_work = await a.create_process("DEV", "Work", "a")
            dev.interface.emit(1.0)
            dev.interface.emit(2.0)
            a_stop = await a.create_process("DEV", "Stop")
            assert (await a_stop.result()).state is C
            updates = await collect(stream)
            assert states(updates) == [R, R, R, C]
            assert [stream.array(u)[0] for u in updates[1:3]] == [1.0, 2.0]
            assert (await b_work.result()).state is C
            final = await b_stop.result()
            assert final.state is F and "no MultipleData process of B is running" in final.reason
            assert (await a_work.result()).state is C
            # B's Stop never dispatched
            assert dev.interface.log == ["Stream", "Stop", "Work:b", "Work:a"]

    run(body())


def test_a_process_queued_behind_a_long_hold_outwaits_its_timeout(tmp_path, monkeypatch):
    """While it waits in the queue the service's Queued heartbeat keeps it alive: the
    requester's timeout bounds silence, not the queue (a robot waiting for the tracker
    behind another robot's Continuous Measurement, 8.4.3)."""
    monkeypatch.setattr(scheduler_module, "QUEUED_HEARTBEAT_S", 0.1)

    async def body():
        async with cell_with(tmp_path, "A", "B") as (dev, a, b):
            stream = await a.create_process("DEV", "Stream")
            await dev.interface.started.wait()
            queued = await b.create_process("DEV", "Work", "b", timeout=0.5)
            await asyncio.sleep(1.5)  # three times B's timeout
            assert not queued.done
            assert (await (await a.create_process("DEV", "Stop")).result()).state is C
            seen = states(await collect(queued))
            assert seen[-1] is C and Q not in seen  # heartbeats are not passed on as updates
            assert (await stream.result()).state is C
            rows = [r for r in read_journal([dev.journal.path]) if r["command"] == "Work"]
            assert [u["state"] for u in rows[0]["updates"]] == ["Running", "Completed"]

    run(body())


def test_a_process_sent_while_the_device_connects_outwaits_its_timeout(tmp_path, monkeypatch):
    """The service is live (its door open) before its device is connected — a robot
    service waiting for the controller's stream: a process sent meanwhile waits in the
    queue and its sender hears the Queued heartbeat, instead of timing out in silence
    ("no update from ROBOT within 10 s" when the EGM twin started slowly, issue-free
    defect of docs/robot-service.md's EGM example under load)."""
    monkeypatch.setattr(scheduler_module, "QUEUED_HEARTBEAT_S", 0.1)
    connected = asyncio.Event()

    async def body():
        cell = unique_cell()
        dev = scripted(cell=cell, journal=tmp_path / "journal")

        async def connect():
            await connected.wait()

        dev.interface.connect = connect
        starting = asyncio.create_task(dev.start())
        client = Participant("A", cell=cell)
        await client.start()
        try:
            assert await client.wait_for("DEV", 10)
            call = await client.create_process("DEV", "Work", "w", timeout=0.5)
            assert call.ack.state is Q
            updates = asyncio.create_task(collect(call))  # the sender waits for updates
            await asyncio.sleep(1.5)  # three times the sender's timeout, still connecting
            assert not updates.done() and dev.interface.log == []
            connected.set()
            await starting
            assert states(await updates)[-1] is C and dev.interface.log == ["Work:w"]
        finally:
            connected.set()
            await client.close()
            await dev.close()

    run(body())


def test_stop_data_with_nothing_running_fails(tmp_path):
    async def body():
        async with cell_with(tmp_path, "A") as (dev, a):
            final = await (await a.create_process("DEV", "Stop")).result()
            assert final.state is F
            assert final.reason == "Stop: no MultipleData process of A is running"
            assert dev.interface.log == []

    run(body())


def test_lost_sender_frees_the_device(tmp_path):
    async def body():
        async with cell_with(tmp_path, "A", "B") as (dev, a, b):
            stream = await a.create_process("DEV", "Stream")
            await dev.interface.started.wait()
            queued = await b.create_process("DEV", "Work", "b")
            await a.close()  # A's liveliness token disappears
            assert (await queued.result()).state is C
            # the service stopped the stream
            assert dev.interface.log == ["Stream", "Stop", "Work:b"]
            rows = {r["command"]: r for r in read_journal([dev.journal.path])}
            assert rows["Stream"]["state"] == "Failed"
            assert "sender A lost" in rows["Stream"]["reason"]
            assert stream.final is not None  # A's own view ended when it closed

    run(body())


def test_every_wait_has_a_timeout(tmp_path):
    async def body():
        async with cell_with(tmp_path, "A") as (dev, a):
            slow = await (await a.create_process("DEV", "Slow")).result()
            assert slow.state is F
            assert "no command feedback from the device within 0.3 s" in slow.reason
            hold = await (await a.create_process("DEV", "Hold")).result()
            assert hold.state is F and "held the device longer than its timeout" in hold.reason
            assert (await (await a.create_process("DEV", "Measure")).result()).state is C
            # the requester's own timeout: a Work that never finishes
            dev.interface.gates["never"] = asyncio.Event()
            call = await a.create_process("DEV", "Work", "never", timeout=0.3)
            final = await call.result()
            assert final.state is F and final.seq == 0
            assert "no update from DEV within 0.3 s" in final.reason
            dev.interface.gates["never"].set()

    run(body())


def test_device_failures_end_failed_with_reason(tmp_path):
    async def body():
        async with cell_with(tmp_path, "A") as (_, a):
            fail = await (await a.create_process("DEV", "Fail")).result()
            assert fail.reason == "Fail: device feedback 'E42' (success code 'OK')"
            flaky = await (await a.create_process("DEV", "Flaky")).result()
            assert "device produced invalid data" in flaky.reason
            assert "size [2] does not match the declared [3]" in flaky.reason
            neg = await (await a.create_process("DEV", "Set", data=[-1, 0])).result()
            assert neg.state is F and neg.reason == "Set: negative values are not allowed"
            ok = await (await a.create_process("DEV", "Set", data=[1, 2])).result()
            assert ok.state is C

    run(body())


async def _raw_create(client: Participant, payload: bytes) -> Acknowledgement:
    """Send raw bytes as a CreateProcess and decode the acknowledgement."""

    def ask():
        return [
            r for r in client.session.get(client.keys.create("DEV"), payload=payload, timeout=5)
        ]

    replies = await asyncio.to_thread(ask)
    assert len(replies) == 1 and replies[0].ok is not None
    body = codec.decode(replies[0].ok.payload.to_bytes()).body
    assert isinstance(body, Acknowledgement)
    return body


def test_bad_input_fails_with_a_precise_reason_and_the_service_keeps_serving(tmp_path):
    async def body():
        async with cell_with(tmp_path, "A", max_payload=20_000) as (dev, a):

            async def reason_of(command, data=None, **kw):
                call = await a.create_process("DEV", command, data=data, check=False, **kw)
                assert call.ack.state is F
                return call.ack.reason

            assert "unknown command 'Nope' for DEV" in await reason_of("Nope")
            assert (
                await reason_of("Set", Data(DataTypes.Double, (2,), b"\0" * 16))
                == "Set input: type Double does not match the declared Integer"
            )
            assert (
                await reason_of("Set", Data(DataTypes.Integer, (3,), b"\0" * 12))
                == "Set input: size [3] does not match the declared [2]"
            )
            assert (
                await reason_of("Set", Data(DataTypes.Integer, (2,), b"\0" * 7))
                == "Set input: buffer of 7 bytes does not match Integer[2] (8 bytes)"
            )
            assert await reason_of("Set") == "Set input: Integer[2] expected, got no data"
            assert "exceeds the limit of 20000 bytes" in await reason_of(
                "Set", Data(DataTypes.Byte, (30_000,), b"\0" * 30_000)
            )
            # checked on the client too, with the same words
            local = await a.create_process("DEV", "Set", data=[1.5, 2])
            assert local.final.reason == "Set input: Integer expected, got float64 values"
            unknown = await a.create_process("NOBODY", "Work")
            assert "unknown device 'NOBODY'" in unknown.final.reason

            good = codec.encode(
                "A",
                a.instance,
                Process(command=Command(name="Measure"), tag=Tag("A", "DEV"), identifier=424242),
            )
            assert (await _raw_create(a, b"\xc1\xc1")).reason.startswith("malformed message")
            assert (await _raw_create(a, good[:-3])).state is F
            assert "invalid message" in (await _raw_create(a, b"\x93\x01\x02\x03")).reason
            wrong = codec.encode(
                "A",
                a.instance,
                Process(command=Command(name="Measure"), tag=Tag("A", "OTHER"), identifier=7),
            )
            assert "addressed to OTHER" in (await _raw_create(a, wrong)).reason
            forged = codec.encode(
                "A",
                a.instance,
                Process(command=Command(name="Measure"), tag=Tag("B", "DEV"), identifier=8),
            )
            assert "differs from the envelope sender" in (await _raw_create(a, forged)).reason
            assert (await _raw_create(a, good)).state is Q
            dup = await _raw_create(a, good)
            assert dup.state is F and "424242" in dup.reason
            not_a_process = codec.encode("A", a.instance, Acknowledgement(identifier=1, state=Q))
            assert "expected a Process" in (await _raw_create(a, not_a_process)).reason

            final = await (await a.create_process("DEV", "Measure")).result()
            assert final.state is C  # still serving
            rejected = [r for r in read_journal([dev.journal.path]) if r.get("rejected")]
            assert len(rejected) >= 6

    run(body())


def test_requester_of_a_service_that_shuts_down_gets_failed(tmp_path):
    async def body():
        async with cell_with(tmp_path, "A") as (dev, a):
            stream = await a.create_process("DEV", "Stream")
            await dev.interface.started.wait()
            await dev.close()
            final = await stream.result()
            assert final.state is F
            assert "DEV" in final.reason and ("shut" in final.reason or "lost" in final.reason)
            assert "DEV" not in a.partners

    run(body())


def test_partners_wire_unwire_and_resubscribe_after_restart(tmp_path):
    async def body():
        cell = unique_cell()
        dev = scripted(cell=cell, journal=tmp_path / "j1")
        robot = scripted("ROBOT", cell=cell, journal=tmp_path / "j2")
        ctl = Participant("CONTROLLER", cell=cell)
        await dev.start()
        await robot.start()
        await ctl.start()
        try:
            assert await ctl.wait_for("DEV") and await ctl.wait_for("ROBOT")
            response = await ctl.ask_subscribe("ROBOT", "DEV")
            assert response.ok and response.partner.name == "DEV"
            assert [c.name for c in response.partner.commands][:2] == ["Work", "Measure"]
            state, _ = await ctl.get("ROBOT")
            assert [p.name for p in state.partners] == ["DEV"]
            # the service uses its partner like any client (5.2.3.6)
            final = await (await robot.participant.create_process("DEV", "Measure")).result()
            assert final.state is C
            self_wire = await ctl.ask_subscribe("ROBOT", "ROBOT")
            assert not self_wire.ok and "itself" in self_wire.reason
            missing = await ctl.ask_subscribe("ROBOT", "NOBODY")
            assert not missing.ok and "unknown device 'NOBODY'" in missing.reason

            await dev.close()  # partner shuts down: removed from ROBOT's Partners
            await until(lambda: "DEV" not in robot.participant.partners)
            dev2 = scripted(cell=cell, journal=tmp_path / "j1")
            await dev2.start()
            try:
                assert await ctl.wait_for("DEV")
                again = await ctl.ask_subscribe("ROBOT", "DEV")
                assert again.ok
                assert robot.participant.partners["DEV"].instance == dev2.participant.instance
                gone = await ctl.ask_subscribe("ROBOT", "DEV", subscribe=False)
                assert gone.ok and "DEV" not in robot.participant.partners
            finally:
                await dev2.close()
        finally:
            await ctl.close()
            await robot.close()
            await dev.close()

    run(body())


def test_a_service_holds_its_participant_and_the_old_process_calls_warn(tmp_path):
    """Composition (issue #33): the host is no Participant; its participant (role
    "service") sends its processes; ``service.create_process``/``stop_process``, which a
    device's code may still call, forward to it with a DeprecationWarning."""
    async def body():
        cell = unique_cell()
        dev = scripted(cell=cell, journal=False)
        robot = scripted("ROBOT", cell=cell, journal=False)
        assert not isinstance(robot, Participant) and robot.participant.role == "service"
        await dev.start()
        await robot.start()
        try:
            assert await robot.participant.wait_for("DEV", 10)
            with pytest.warns(DeprecationWarning, match=r"service\.participant\.create_process"):
                call = await robot.create_process("DEV", "Stream")
            assert call.ack is not None and call.ack.state is Q
            with pytest.warns(DeprecationWarning, match=r"service\.participant\.stop_process"):
                stop = await robot.stop_process(call)
            assert (await stop.result()).state is C
            assert (await call.result()).state is C
            assert dev.participant.is_alive("ROBOT")  # presence seen by the host's participant
        finally:
            await robot.close()
            await dev.close()

    run(body())


def test_presence_events_and_cells_are_isolated(tmp_path):
    async def body():
        async with cell_with(tmp_path, "A") as (_, a):
            other = Participant("SPY", cell=unique_cell())
            await other.start()
            try:
                assert "DEV" in a.services()
                assert other.services() == []
                assert await other.list_services(1.0) == []
                blind = await other.create_process("DEV", "Measure", timeout=2)
                assert blind.final.state is F and "unknown device 'DEV'" in blind.final.reason
            finally:
                await other.close()
            events = a.events()
            watcher = asyncio.create_task(anext(events))
            await asyncio.sleep(0)
            late = Participant("LATE", cell=a.keys.cell)
            await late.start()
            event = await asyncio.wait_for(watcher, 10)
            assert (event.kind, event.presence.name) == ("join", "LATE")
            await late.close()
            await until(lambda: not a.is_alive("LATE", "client"))
            await events.aclose()

    run(body())


def test_presence_streams_stop_collecting_when_dropped_left_or_closed(tmp_path):
    """A stream of events() that its owner drops (never iterated, or left by break)
    stops collecting at once; aclose ends even an iteration that waits."""

    async def body():
        async with cell_with(tmp_path, "A") as (_, a):
            kept, dropped = a.events(), a.events()
            del dropped  # never iterated: no longer collecting
            assert len(a._watchers) == 1

            async def first_event():
                async for event in a.events():
                    return event  # leaves the loop: the stream is dropped

            leaver = asyncio.create_task(first_event())
            waiting = a.events()
            pending = asyncio.create_task(anext(waiting))
            await asyncio.sleep(0)
            assert len(a._watchers) == 3
            late = Participant("LATE", cell=a.keys.cell)
            await late.start()
            try:
                event = await asyncio.wait_for(anext(kept), 10)
                assert (event.kind, event.presence.name) == ("join", "LATE")
                assert (await asyncio.wait_for(pending, 10)).presence.name == "LATE"
                assert (await asyncio.wait_for(leaver, 10)).presence.name == "LATE"
                assert len(a._watchers) == 2  # kept and waiting
                closing = asyncio.create_task(anext(waiting))
                await asyncio.sleep(0)
                await waiting.aclose()
                with pytest.raises(StopAsyncIteration):
                    await asyncio.wait_for(closing, 5)
                await late.close()
                await until(lambda: len(kept) >= 1)  # LATE's leave
                assert len(waiting) == 0  # closed: collects nothing
            finally:
                await late.close()

    run(body())


def test_journal_records_processes_and_updates(tmp_path):
    async def body():
        async with cell_with(tmp_path, "A") as (dev, a):
            await (await a.create_process("DEV", "Measure")).result()
            await (await a.create_process("DEV", "Fail")).result()
            await a.create_process("DEV", "Nope", check=False)
            rows = read_journal([dev.journal.path])
            by_command = {r["command"]: r for r in rows}
            measure = by_command["Measure"]
            assert (measure["sender"], measure["recipient"], measure["state"]) == (
                "A",
                "DEV",
                "Completed",
            )
            assert measure["command_type"] == "SingleData"
            assert measure["acked_ns"] >= measure["received_ns"]
            assert measure["finished_ns"] >= measure["acked_ns"]
            assert [(u["seq"], u["state"]) for u in measure["updates"]] == [
                (1, "Running"),
                (2, "Completed"),
            ]
            assert measure["updates"][1]["data"] == "Double[3] [1.0, 2.0, 3.0]"
            assert by_command["Fail"]["state"] == "Failed"
            assert "E42" in by_command["Fail"]["reason"]
            assert by_command["Nope"]["state"] == "Failed"
            assert msgspec.json.encode(rows)  # exportable as JSON

    run(body())


def test_a_second_service_of_one_name_on_this_host_is_refused_by_the_journal(tmp_path):
    """Even where presence cannot tell (here: another cell), a service whose journal
    another process holds does not start, and the first keeps serving."""

    async def body():
        first = scripted(cell=unique_cell(), journal=tmp_path)
        await first.start()
        try:
            second = scripted(cell=unique_cell(), journal=tmp_path)
            with pytest.raises(PartnerError, match="already running on this host"):
                await second.start()
            client = Participant("A", cell=first.cell)
            await client.start()
            try:
                done = await (await client.create_process("DEV", "Measure")).result()
                assert done.state is C
            finally:
                await client.close()
        finally:
            await first.close()

    run(body())


def test_two_services_with_one_name_leave_exactly_one(tmp_path):
    async def body():
        cell = unique_cell()
        one = scripted(cell=cell, journal=tmp_path / "j1")
        two = scripted(cell=cell, journal=tmp_path / "j2")
        results = await asyncio.gather(one.start(), two.start(), return_exceptions=True)
        try:
            refused = [r for r in results if isinstance(r, Exception)]
            if not refused:  # both started before seeing each other: the younger withdraws
                done, _ = await asyncio.wait(
                    {
                        asyncio.create_task(one.stopped.wait()),
                        asyncio.create_task(two.stopped.wait()),
                    },
                    timeout=10,
                    return_when=asyncio.FIRST_COMPLETED,
                )
                assert done
            survivors = [s for s in (one, two) if not s._closing]
            assert len(survivors) == 1
            loser = two if survivors[0] is one else one
            assert "already running" in (loser.conflict or str(refused[0]))
        finally:
            await one.close()
            await two.close()

    run(body())
