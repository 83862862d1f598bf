"""The robot service's tracker feed of a tracked move (issue 38): ``Stream Measurement``
opened by the robot's own participant, its samples straight to the correction loop as
TCP poses in the robot's frame on the robot's clock; the stream holds the shared tracker
until the move ends, and another robot's request is served after."""

from __future__ import annotations

import asyncio
import time

import numpy as np
import pytest
from metrology_testlib import pose, run, unique_cell

from plugcell.apps.kinds import build
from plugcell.devices.robot.tracked_moves import ServiceTrackerFeed
from plugcell.framework import Client, ProcessStates
from plugcell.framework.bus import Bus
from plugcell.framework.keys import KeySpace
from plugcell.sim.world import ReflectorPublisher

pytestmark = [pytest.mark.timeout(90), pytest.mark.slow]

BASE, PROBE = [2500.0, -800.0, -600.0, 30.0, 2.0, -20.0], [0.0, 0.0, 120.0, 0.0, 0.0, 0.0]
POSE = [1200.0, 100.0, 900.0, 10.0, 150.0, -20.0]
TOOL = np.eye(4)
TOOL[:3, 3] = [0.0, 0.0, 0.2]  # the TCP 200 mm along the flange's z


async def _ok(client, command, option="", data=None):
    final = await (await client.create_process("TRACKER", command, option, data,
                                               timeout=30)).result()
    assert final.state is ProcessStates.Completed, f"{command}: {final.reason}"
    return final


def test_the_feed_gives_tcp_poses_on_the_robots_clock_and_holds_the_tracker(world_session):
    cell = unique_cell()

    async def body():
        tracker = build("tracker", None, {"seed": 5}, cell=cell, journal=False)
        tmac = ReflectorPublisher(Bus(world_session, KeySpace(cell)), "TMAC", "tmac")
        tmac.publish(pose(BASE) @ pose(POSE) @ pose(PROBE))
        await tracker.start()
        try:
            async with Client("ROBOT", cell=cell) as robot, Client("KUKA", cell=cell) as kuka:
                assert await robot.wait_for("TRACKER") and await kuka.wait_for("TRACKER")
                for command, data in (("Set Base", BASE), ("Set Probe", PROBE)):
                    await _ok(robot, command, "euler2tr", data)
                await _ok(robot, "Move", "", POSE)
                feed = ServiceTrackerFeed(robot, asyncio.get_running_loop(), "TRACKER", TOOL)
                t0 = time.monotonic() - 7.0  # the robot's clock: its own zero, 7 s ago
                await asyncio.to_thread(feed.start)  # the stream opens at 7 s or later
                other = asyncio.create_task(_ok(kuka, "Set Base", "euler2tr", BASE))
                samples = []
                for _ in range(100):  # robot cycles
                    await asyncio.sleep(0.004)
                    t_robot = time.monotonic() - t0
                    samples += feed.poll(t_robot, time.time())
                assert not other.done()  # the tracked move holds the tracker
                await asyncio.to_thread(feed.stop)
                # the samples that arrived after the last cycle (every one has: the
                # stream has ended), seen by a cycle after it
                rest = feed.poll(time.monotonic() - t0, time.time())
                await other  # served after the move
        finally:
            tmac.close()
            await tracker.close()
        assert len(samples) > 100 and all(s.ok and s.six_dof for s in samples + rest)
        want = (pose(POSE) @ TOOL)[:3, 3]
        got = np.array([s.pose[:3, 3] for s in samples])
        assert np.abs(np.median(got, axis=0) - want).max() < 0.1e-3  # the TCP, F0 (m)
        t = np.array([s.time_s for s in samples + rest])
        assert np.all(np.diff(t) > 0)  # in order, also across the cycles
        # acquisition times on the robot's clock: after the stream was asked for, before
        # the cycle that saw them (whatever the latency of a loaded machine), 1 ms apart
        # as the tracker took them at 1 kHz
        assert t[0] > 7.0 - 0.005 and t[len(samples) - 1] <= t_robot
        assert np.median(np.diff(t)) == pytest.approx(1e-3, rel=0.1)

    run(body())
