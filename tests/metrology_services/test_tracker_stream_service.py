"""Stream Measurement (issue 38): the tracker's real-time output straight to the requester."""

from __future__ import annotations

import asyncio
import contextlib

import numpy as np
import pytest
from metrology_testlib import pose, run, unique_cell

from plugcell.apps.kinds import build
from plugcell.devices.tracker.service import STREAM_COLUMNS
from plugcell.framework import Client, ProcessCall, ProcessStates
from plugcell.framework.bus import Bus
from plugcell.framework.keys import KeySpace
from plugcell.sim.world import ReflectorPublisher

pytestmark = [pytest.mark.timeout(90), pytest.mark.slow]

C, F = ProcessStates.Completed, ProcessStates.Failed
BASE, PROBE = [2500.0, -800.0, -600.0, 30.0, 2.0, -20.0], [0.0, 0.0, 120.0, 0.0, 0.0, 0.0]
POSE = [1200.0, 100.0, 900.0, 10.0, 150.0, -20.0]
COL = {name: i for i, name in enumerate(STREAM_COLUMNS)}


async def _ok(client, command, option="", data=None):
    final = await (await client.create_process("TRACKER", command, option, data,
                                               timeout=30)).result()
    assert final.state is C, f"{command}: {final.reason}"
    return final


async def _rows(call, seconds):
    """The rows of a stream's data updates for ``seconds``."""
    out = []

    async def collect():
        async for update in call:
            if update.data is not None:
                out.append(ProcessCall.array(update))

    with pytest.raises(TimeoutError):
        await asyncio.wait_for(collect(), seconds)
    return out


@contextlib.asynccontextmanager
async def _tracker_in(cell, world_session):
    """The tracker service started in ``cell``, the T-MAC published at BASE·POSE·PROBE
    (eq. 7.1); both closed after."""
    tracker = build("tracker", None, {"seed": 5}, cell=cell, journal=False)
    tmac = ReflectorPublisher(Bus(world_session, KeySpace(cell)), "TMAC", "tmac")
    tmac.publish(pose(BASE) @ pose(POSE) @ pose(PROBE))
    await tracker.start()
    try:
        yield tracker
    finally:
        tmac.close()
        await tracker.close()


async def _aimed(robot):
    """The robot's BASE and PROBE given, the beam moved to its T-MAC at POSE."""
    assert await robot.wait_for("TRACKER")
    await _ok(robot, "Set Base", "euler2tr", BASE)
    await _ok(robot, "Set Probe", "euler2tr", PROBE)
    await _ok(robot, "Move", "", POSE)


def test_a_1khz_stream_in_batches_with_each_samples_own_times(world_session):
    cell = unique_cell()

    async def body():
        async with _tracker_in(cell, world_session), Client("ROBOT", cell=cell) as robot:
            await _aimed(robot)
            call = await robot.create_process("TRACKER", "Stream Measurement", "tr2euler",
                                              [1000, 8])
            messages = await _rows(call, 1.0)
            await _ok(robot, "Stop Measurement")
            assert (await call.result()).state is C
        assert messages and all(m.shape == (8, len(STREAM_COLUMNS)) for m in messages)
        rows = np.vstack(messages)
        assert len(rows) > 400  # most of a second at 1 kHz, on a loaded 2-core machine too
        np.testing.assert_array_equal(np.diff(rows[:, COL["seq"]]), 1)  # none lost
        # tracker clock: 1 ms apart (its 20 ppm drift), monotonic; PC arrival monotonic
        np.testing.assert_allclose(np.diff(rows[:, COL["tracker_time_s"]]), 1e-3 * (1 + 20e-6),
                                   rtol=1e-6)
        assert np.all(np.diff(rows[:, COL["pc_time_s"]]) >= 0)
        assert np.all(rows[:, COL["status"]] == 0) and np.all(rows[:, COL["six_dof"]] == 1)
        xyz = rows[:, COL["x"]: COL["z"] + 1]
        assert np.abs(xyz.mean(axis=0) - POSE[:3]).max() < 0.1  # mm, robot frame (eq. 7.2)
        assert np.abs(np.median(rows[:, COL["a"]: COL["c"] + 1], axis=0) - POSE[3:]).max() < 0.05

    run(body())


def test_a_line_of_sight_break_is_flagged_and_the_stream_recovers(world_session):
    cell = unique_cell()

    async def body():
        async with _tracker_in(cell, world_session) as tracker:
            tracker.interface.driver.blocked = lambda t: 0.2 <= t < 0.4
            async with Client("ROBOT", cell=cell) as robot:
                await _aimed(robot)
                call = await robot.create_process("TRACKER", "Stream Measurement", "tr2euler",
                                                  [500, 10])
                rows = np.vstack(await _rows(call, 1.5))
                await _ok(robot, "Stop Measurement")
        status = rows[:, COL["status"]]
        t = rows[:, COL["tracker_time_s"]] - rows[0, COL["tracker_time_s"]]
        broken = t[status == 1]  # line of sight
        assert broken.min() == pytest.approx(0.2, abs=0.01)
        assert broken.max() == pytest.approx(0.7, abs=0.01)  # + 0.3 s re-acquisition
        assert np.all(np.isnan(rows[status == 1, COL["x"]]))
        assert np.all(status[t > 0.71] == 0)

    run(body())


def test_bad_requests_are_refused_and_a_vanished_subscriber_frees_the_tracker(world_session):
    cell = unique_cell()

    async def body():
        async with _tracker_in(cell, world_session) as tracker:
            async with Client("ROBOT", cell=cell) as robot:
                assert await robot.wait_for("TRACKER")
                target = pose(BASE) @ pose(POSE) @ pose(PROBE)
                await _ok(robot, "Move", "", [*(target[:3, 3] * 1e3), 0, 0, 0])
                for data, reason in (
                        ([2000, 8], "rate 2000 Hz outside 1…1000 Hz (the tracker's output rate)"),
                        ([0, 8], "rate 0 Hz outside 1…1000 Hz"),
                        ([1000, 0], "0 samples per message outside 1…100"),
                        ([1000, 8, 1], "input: size [3] does not match the declared [2]")):
                    final = await (await robot.create_process(
                        "TRACKER", "Stream Measurement", "", data)).result()
                    assert final.state is F and reason in final.reason, final.reason
            gone = Client("GONE", cell=cell)
            await gone.start()
            assert await gone.wait_for("TRACKER")
            await _ok(gone, "Move", "", [*(target[:3, 3] * 1e3), 0, 0, 0])
            call = await gone.create_process("TRACKER", "Stream Measurement", "", [1000, 10])
            await _rows(call, 0.3)
            await gone.close()  # without Stop Measurement
            async with Client("OTHER", cell=cell) as other:
                assert await other.wait_for("TRACKER")
                await _ok(other, "Move", "", [*(target[:3, 3] * 1e3), 0, 0, 0])
                await _ok(other, "Single Measurement", "", 10)  # the tracker was freed
                stream = tracker.interface._stream
                assert stream is None or stream.done()

    run(body())
