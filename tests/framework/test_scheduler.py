"""The process scheduler on its own (framework/scheduler.py, thesis 5.2.3.4–5.2.3.5).

No Zenoh, no journal, no service: a :class:`ProcessScheduler` is given four recording
seams, and each test drives it the way a service's admission and a device would —
``post`` an admitted process, the device's ``dispatch`` answers or feeds ``on_data`` /
``on_cmd`` — then reads what went to the seams.
"""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable
from typing import Any

import numpy as np
import pytest

from plugcell.framework import scheduler as scheduler_module
from plugcell.framework.data import from_data
from plugcell.framework.messages import (
    Command,
    CommandTypes,
    DataTypes,
    Device,
    Process,
    ProcessStates,
    ProcessUpdateNotification,
    Tag,
)
from plugcell.framework.processqueue import Entry
from plugcell.framework.scheduler import DeviceError, ProcessScheduler

MOVE = Command(name="Move", type=CommandTypes.NoData, timeout=1.0)
SLOW = Command(name="Slow", type=CommandTypes.NoData, timeout=0.05)
SHOT = Command(name="Shot", type=CommandTypes.SingleData,
               output_data_type=DataTypes.Double, output_data_size=(3,))
STREAM = Command(name="Stream", type=CommandTypes.MultipleData,
                 output_data_type=DataTypes.Double, output_data_size=(2,), timeout=5.0)
STOP = Command(name="StopStream", type=CommandTypes.StopData)
DEVICE = Device(name="DEV", commands=(MOVE, SLOW, SHOT, STREAM, STOP))


class Recorder:
    """The four seams of a scheduler, recording what they are told."""

    def __init__(self) -> None:
        self.updates: list[tuple[str, int, ProcessStates, str, Any]] = []
        self.busy: list[bool] = []
        self.heartbeats: list[tuple[str, int, ProcessUpdateNotification]] = []
        self.dispatched: list[tuple[str, str, Any]] = []
        self.device: Callable[[Command, str, Any], Awaitable[str | None]] | None = None
        self.scheduler = ProcessScheduler(
            "DEV", DEVICE, dispatch=self._dispatch, update=self._update,
            busy=self.busy.append, heartbeat=self._heartbeat)

    async def _dispatch(self, command: Command, option: str, data: Any) -> str | None:
        self.dispatched.append((command.name, option, data))
        assert self.device is not None
        return await self.device(command, option, data)

    def _update(self, entry: Entry, state: ProcessStates, reason: str, data: Any) -> None:
        entry.seq += 1
        self.updates.append((entry.sender, entry.identifier, state, reason, data))

    def _heartbeat(self, entry: Entry, update: ProcessUpdateNotification) -> None:
        self.heartbeats.append((entry.sender, entry.identifier, update))

    def states(self, sender: str, identifier: int) -> list[ProcessStates]:
        return [u[2] for u in self.updates if u[:2] == (sender, identifier)]

    def final(self, sender: str, identifier: int) -> tuple[ProcessStates, str, Any]:
        last = [u for u in self.updates if u[:2] == (sender, identifier)][-1]
        return last[2], last[3], last[4]


def entry(command: Command, sender: str = "A", identifier: int = 1,
          instance: str = "i1", data: Any = None) -> Entry:
    process = Process(command=command, tag=Tag(sender=sender, recipient="DEV"),
                      identifier=identifier)
    return Entry(process=process, command=command, instance=instance, input=data)


async def settle(rec: Recorder, sender: str, identifier: int, timeout: float = 3.0) -> None:
    """Wait until ``sender``'s process ``identifier`` has its final update."""
    async with asyncio.timeout(timeout):
        while rec.scheduler.knows(sender, identifier) or not rec.states(sender, identifier):
            await asyncio.sleep(0.002)


def run(test: Callable[[Recorder], Awaitable[None]]) -> None:
    async def main() -> None:
        rec = Recorder()
        rec.scheduler.start()
        try:
            await test(rec)
        finally:
            rec.scheduler.shut("test over")
            await rec.scheduler.stop()

    asyncio.run(main())


def test_a_nodata_process_runs_then_completes_and_frees_the_device() -> None:
    async def body(rec: Recorder) -> None:
        async def device(command: Command, option: str, data: Any) -> str:
            return "OK"
        rec.device = device
        rec.scheduler.post(entry(MOVE))
        assert rec.scheduler.knows("A", 1)
        await settle(rec, "A", 1)
        assert rec.states("A", 1) == [ProcessStates.Running, ProcessStates.Completed]
        assert rec.busy == [True, False]
        assert not rec.scheduler.knows("A", 1)
    run(body)


def test_the_command_feedback_decides_when_dispatch_returns_none() -> None:
    async def body(rec: Recorder) -> None:
        async def device(command: Command, option: str, data: Any) -> None:
            codes = {1: "OK", 2: "JAMMED"}
            identifier = len(rec.dispatched)
            asyncio.get_running_loop().call_later(0.01, rec.scheduler.on_cmd, codes[identifier])
            return None
        rec.device = device
        rec.scheduler.post(entry(MOVE, identifier=1))
        rec.scheduler.post(entry(MOVE, identifier=2))
        await settle(rec, "A", 2)
        assert rec.final("A", 1)[:2] == (ProcessStates.Completed, "")
        state, reason, _ = rec.final("A", 2)
        assert state is ProcessStates.Failed
        assert reason == "Move: device feedback 'JAMMED' (success code 'OK')"
    run(body)


def test_no_command_feedback_within_the_timeout_fails_the_process() -> None:
    async def body(rec: Recorder) -> None:
        async def device(command: Command, option: str, data: Any) -> None:
            return None
        rec.device = device
        rec.scheduler.post(entry(SLOW))
        await settle(rec, "A", 1)
        assert rec.final("A", 1)[:2] == (
            ProcessStates.Failed, "Slow: no command feedback from the device within 0.05 s")
        rec.scheduler.on_cmd("OK")  # late feedback: nobody waits for it any more
        assert rec.scheduler.stray_feedback == 1
    run(body)


@pytest.mark.parametrize(("raised", "reason"), [
    (DeviceError("arm is in E-stop"), "Move: arm is in E-stop"),
    (ZeroDivisionError("boom"), "Move: device interface error: ZeroDivisionError('boom')"),
])
def test_device_errors_fail_the_process_and_the_next_one_still_runs(
        raised: Exception, reason: str) -> None:
    async def body(rec: Recorder) -> None:
        async def device(command: Command, option: str, data: Any) -> str:
            if len(rec.dispatched) == 1:
                raise raised
            return "OK"
        rec.device = device
        rec.scheduler.post(entry(MOVE, identifier=1))
        rec.scheduler.post(entry(MOVE, identifier=2))
        await settle(rec, "A", 2)
        assert rec.final("A", 1)[:2] == (ProcessStates.Failed, reason)
        assert rec.final("A", 2)[0] is ProcessStates.Completed
    run(body)


def test_single_data_completes_with_the_first_value_checked_against_the_catalogue() -> None:
    async def body(rec: Recorder) -> None:
        values = {1: [1.0, 2.0, 3.0], 2: None, 3: [1.0, 2.0]}

        async def device(command: Command, option: str, data: Any) -> str:
            value = values[len(rec.dispatched)]
            if value is not None:
                rec.scheduler.on_data(value)
            return "OK"
        rec.device = device
        for identifier in (1, 2, 3):
            rec.scheduler.post(entry(SHOT, identifier=identifier))
        await settle(rec, "A", 3)
        state, _, data = rec.final("A", 1)
        assert state is ProcessStates.Completed
        np.testing.assert_array_equal(from_data(data), [1.0, 2.0, 3.0])
        assert rec.final("A", 2)[:2] == (
            ProcessStates.Failed, "Shot: the device reported success but no data")
        state, reason, _ = rec.final("A", 3)
        assert state is ProcessStates.Failed
        assert reason.startswith("device produced invalid data: ")
    run(body)


def test_notes_become_the_reason_of_the_completed_update() -> None:
    async def body(rec: Recorder) -> None:
        async def device(command: Command, option: str, data: Any) -> str:
            rec.scheduler.note("target 1 outside the region")
            rec.scheduler.note("")
            rec.scheduler.note("target 2 outside the region")
            return "OK"
        rec.device = device
        rec.scheduler.post(entry(MOVE))
        await settle(rec, "A", 1)
        assert rec.final("A", 1)[:2] == (
            ProcessStates.Completed, "target 1 outside the region; target 2 outside the region")
    run(body)


def test_a_stream_holds_the_device_until_its_senders_stop() -> None:
    async def body(rec: Recorder) -> None:
        async def device(command: Command, option: str, data: Any) -> str:
            if command.name == "Stream":
                for k in range(3):
                    rec.scheduler.on_data([float(k), 0.0])
            return "OK"
        rec.device = device
        rec.scheduler.post(entry(STREAM, sender="A", identifier=1))
        rec.scheduler.post(entry(MOVE, sender="B", identifier=1))
        await asyncio.sleep(0.05)
        # B waits behind A's hold: the device is A's until A's StopData
        assert rec.states("B", 1) == []
        assert rec.states("A", 1) == [ProcessStates.Running] * 4
        rec.scheduler.post(entry(STOP, sender="A", identifier=2))
        await settle(rec, "B", 1)
        assert rec.final("A", 2)[0] is ProcessStates.Completed
        assert rec.final("A", 1)[:2] == (ProcessStates.Completed, "")
        assert rec.states("B", 1) == [ProcessStates.Running, ProcessStates.Completed]
        assert [name for name, _, _ in rec.dispatched] == ["Stream", "StopStream", "Move"]
        frames = [from_data(u[4]) for u in rec.updates if u[:2] == ("A", 1) and u[4] is not None]
        assert [f[0] for f in frames] == [0.0, 1.0, 2.0]
    run(body)


def test_a_stop_without_a_stream_fails() -> None:
    async def body(rec: Recorder) -> None:
        rec.scheduler.post(entry(STOP))
        await settle(rec, "A", 1)
        assert rec.final("A", 1)[:2] == (
            ProcessStates.Failed, "StopStream: no MultipleData process of A is running")
        assert rec.dispatched == []
    run(body)


def test_a_lost_sender_loses_its_queue_and_its_hold_and_the_stream_is_stopped() -> None:
    async def body(rec: Recorder) -> None:
        async def device(command: Command, option: str, data: Any) -> str:
            return "OK"
        rec.device = device
        rec.scheduler.post(entry(STREAM, sender="A", identifier=1, instance="i1"))
        rec.scheduler.post(entry(MOVE, sender="A", identifier=2, instance="i1"))
        rec.scheduler.post(entry(MOVE, sender="A", identifier=3, instance="i2"))
        await asyncio.sleep(0.02)
        rec.scheduler.sender_lost("A", "i1")
        await settle(rec, "A", 3)
        assert rec.final("A", 2)[:2] == (
            ProcessStates.Failed, "sender A lost (liveliness) before the process started")
        assert rec.final("A", 1)[:2] == (
            ProcessStates.Failed, "sender A lost (liveliness token withdrawn)")
        # the stream was stopped with the catalogue's StopData; the new incarnation's runs
        assert [name for name, _, _ in rec.dispatched] == ["Stream", "StopStream", "Move"]
        assert rec.final("A", 3)[0] is ProcessStates.Completed
    run(body)


def test_a_hold_ends_failed_after_the_commands_timeout() -> None:
    short = Command(name="Stream", type=CommandTypes.MultipleData,
                    output_data_type=DataTypes.Double, output_data_size=(2,), timeout=0.05)

    async def body(rec: Recorder) -> None:
        async def device(command: Command, option: str, data: Any) -> str:
            return "OK"
        rec.device = device
        rec.scheduler.post(entry(short))
        await settle(rec, "A", 1)
        assert rec.final("A", 1)[:2] == (
            ProcessStates.Failed, "Stream: held the device longer than its timeout of 0.05 s")
        assert [name for name, _, _ in rec.dispatched] == ["Stream", "StopStream"]
    run(body)


def test_waiting_senders_hear_a_queued_heartbeat(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(scheduler_module, "QUEUED_HEARTBEAT_S", 0.02)

    async def body(rec: Recorder) -> None:
        async def device(command: Command, option: str, data: Any) -> str:
            return "OK"
        rec.device = device
        rec.scheduler.post(entry(STREAM, sender="A", identifier=1))
        rec.scheduler.post(entry(MOVE, sender="B", identifier=7))
        async with asyncio.timeout(3.0):
            while len(rec.heartbeats) < 3:
                await asyncio.sleep(0.005)
        assert {(s, i) for s, i, _ in rec.heartbeats} == {("B", 7)}
        seqs = [u.seq for _, _, u in rec.heartbeats]
        assert seqs == sorted(seqs) and len(set(seqs)) == len(seqs)
        assert all(u.state is ProcessStates.Queued and u.identifier == 7
                   for _, _, u in rec.heartbeats)
        assert rec.states("B", 1) == []  # heartbeats are not updates (not journalled)
    run(body)


def test_invalid_stream_data_aborts_the_stream() -> None:
    async def body(rec: Recorder) -> None:
        async def device(command: Command, option: str, data: Any) -> str:
            if command.name == "Stream":
                rec.scheduler.on_data([1.0, 2.0, 3.0])  # the catalogue says (2,)
            return "OK"
        rec.device = device
        rec.scheduler.post(entry(STREAM))
        await settle(rec, "A", 1)
        state, reason, _ = rec.final("A", 1)
        assert state is ProcessStates.Failed
        assert reason.startswith("device produced invalid data: ")
        assert [name for name, _, _ in rec.dispatched] == ["Stream", "StopStream"]
    run(body)


def test_feedback_when_nothing_expects_it_is_counted_not_lost_silently() -> None:
    async def body(rec: Recorder) -> None:
        rec.scheduler.on_data([1.0, 2.0])
        rec.scheduler.on_cmd("OK")
        assert rec.scheduler.stray_feedback == 2
        assert rec.updates == []
    run(body)


def test_shut_fails_what_waits_and_stop_ends_the_handler() -> None:
    async def main() -> None:
        rec = Recorder()
        gate = asyncio.Event()

        async def device(command: Command, option: str, data: Any) -> str:
            await gate.wait()
            return "OK"
        rec.device = device
        rec.scheduler.start()
        rec.scheduler.post(entry(MOVE, identifier=1))
        rec.scheduler.post(entry(MOVE, identifier=2))
        await asyncio.sleep(0.02)
        rec.scheduler.shut("service shutting down")
        assert rec.final("A", 2)[:2] == (ProcessStates.Failed, "service shutting down")
        gate.set()
        await rec.scheduler.stop()
        assert rec.final("A", 1)[0] is ProcessStates.Completed  # the running one ends
        assert rec.scheduler.known == {}
        rec.scheduler.post(entry(MOVE, identifier=3))
        await asyncio.sleep(0.02)
        assert rec.states("A", 3) == []  # nothing runs after shut
    asyncio.run(main())
