"""The laser tracker service (Table 7-3) as a real OS process, shared by several robots.

Robots are clients here (each with its own name — the requester); their T-MACs are
published on the simulated world channel, at BASE·T·PROBE for each robot's own frames.
"""

from __future__ import annotations

import asyncio
import time

import numpy as np
import pytest
from metrology_testlib import pose, run, take_rows, unique_cell

from plugcell.apps.kinds import build
from plugcell.framework import Client, ProcessCall, ProcessStates
from plugcell.framework.bus import Bus
from plugcell.framework.keys import KeySpace
from plugcell.framework.transport import TransportConfig, open_session
from plugcell.io.units import pose_from_robot
from plugcell.sim.world import ReflectorPublisher

pytestmark = pytest.mark.timeout(90)

C, F, R = ProcessStates.Completed, ProcessStates.Failed, ProcessStates.Running

# Two robots in front of one tracker, each with its own BASE and PROBE (mm, deg, ZYZ).
BASE_A, PROBE_A = [2500.0, -800.0, -600.0, 30.0, 2.0, -20.0], [0.0, 0.0, 120.0, 0.0, 0.0, 0.0]
BASE_B, PROBE_B = [3200.0, 1500.0, -500.0, -60.0, 1.0, 45.0], [20.0, -10.0, 90.0, 90.0, 10.0, 0.0]
POSE_A = [1200.0, 100.0, 900.0, 10.0, 150.0, -20.0]
POSE_B = [1000.0, -300.0, 1100.0, -30.0, 130.0, 60.0]


def reflector(base, robot_pose, probe) -> np.ndarray:
    """Eq. (7.1): where the robot's T-MAC truly is, in the tracker frame."""
    return pose(base) @ pose(robot_pose) @ pose(probe)


def assert_pose(measured, expected, convention: str = "zyz") -> None:
    """Within the tracker's accuracy: 0.15 mm and 0.03° (thesis 8.2.1: 0.05 mm, 0.01°)."""
    M = pose_from_robot(measured, convention)
    E = pose_from_robot(expected, convention)
    assert np.linalg.norm(M[:3, 3] - E[:3, 3]) < 0.15e-3, (measured, expected)
    cos = np.clip((np.trace(M[:3, :3].T @ E[:3, :3]) - 1) / 2, -1, 1)
    assert np.rad2deg(np.arccos(cos)) < 0.03, (measured, expected)


async def ok(client: Client, command: str, option: str = "", data=None,
             service: str = "TRACKER") -> np.ndarray | None:
    call = await client.create_process(service, command, option, data, timeout=30)
    final = await call.result()
    assert final.state is C, f"{command}: {final.reason}"
    return None if final.data is None else ProcessCall.array(final)


async def setup_robot(client: Client, base, probe, robot_pose) -> None:
    await ok(client, "Set Base", "euler2tr", base)
    await ok(client, "Set Probe", "euler2tr", probe)
    await ok(client, "Move", "", robot_pose)


def both_tmacs(cell, world) -> None:
    """Robot A's and robot B's T-MACs published where their robots hold them (eq. 7.1)."""
    world(cell.name, "TMAC_A").publish(reflector(BASE_A, POSE_A, PROBE_A))
    world(cell.name, "TMAC_B").publish(reflector(BASE_B, POSE_B, PROBE_B))


async def comau_aimed_kuka_framed(comau: Client, kuka: Client) -> None:
    """Both see the tracker; the Kuka has given its BASE and PROBE (robot B's) but not
    moved the beam, the Comau is set up as robot A and holds the beam on its T-MAC."""
    assert await comau.wait_for("TRACKER") and await kuka.wait_for("TRACKER")
    await ok(kuka, "Set Base", "euler2tr", BASE_B)
    await ok(kuka, "Set Probe", "euler2tr", PROBE_B)
    await setup_robot(comau, BASE_A, PROBE_A, POSE_A)


async def move_and_measure(client: Client, robot_pose) -> tuple[np.ndarray, float]:
    """A robot's program (8.4.2): Move, then a Single Measurement; the pose and when it came."""
    await ok(client, "Move", "", robot_pose)
    return await ok(client, "Single Measurement", "tr2euler", 100), time.monotonic()


async def served_after_stop(holder: Client, stream: ProcessCall, waiting: asyncio.Task,
                            robot_pose) -> None:
    """``holder`` stops its ``stream``; only then is the robot ``waiting`` (queued behind
    it, :func:`move_and_measure`) served — with its own reflector, in its own frame."""
    stop = await holder.stop_process(stream)
    assert (await stop.result()).state is C
    stopped_at = time.monotonic()
    assert (await stream.result()).state is C
    measured, finished_at = await asyncio.wait_for(waiting, 20)
    assert_pose(measured, robot_pose)
    assert finished_at >= stopped_at - 0.05


def test_set_base_probe_move_and_measurements_in_the_robot_frame(cell, world):
    tmac = world(cell.name, "TMAC_A")
    tmac.publish(reflector(BASE_A, POSE_A, PROBE_A))

    async def body():
        async with Client("ROBOT_A", cell=cell.name) as robot:
            assert await robot.wait_for("TRACKER")
            await setup_robot(robot, BASE_A, PROBE_A, POSE_A)
            # Single Measurement: eq. 7.2 in the robot frame, in each of Table 7-3's options
            assert_pose(await ok(robot, "Single Measurement", "tr2euler", 1000), POSE_A)
            assert_pose(await ok(robot, "Single Measurement", "", 50), POSE_A)  # its convention
            rpy = await ok(robot, "Single Measurement", "tr2rpy", 1000)
            np.testing.assert_allclose(pose_from_robot(rpy, "rpy"), pose(POSE_A), atol=2e-4)
            prj = await ok(robot, "Single Measurement", "tr2prj", 1000)
            np.testing.assert_allclose(pose_from_robot(prj, "prj"), pose(POSE_A), atol=2e-4)
            # the robot moves; the locked beam follows its T-MAC (no Move needed)
            moved = [*POSE_A[:2], POSE_A[2] - 150.0, *POSE_A[3:]]
            tmac.publish(reflector(BASE_A, moved, PROBE_A))
            assert_pose(await ok(robot, "Single Measurement", "tr2euler", 1000), moved)
            # Continuous Measurement: a stream until Stop Measurement releases the tracker
            stream = await robot.create_process("TRACKER", "Continuous Measurement", "tr2euler",
                                                20, timeout=30)
            samples = await take_rows(stream, 3)
            stop = await robot.stop_process(stream)
            assert (await stop.result()).state is C
            assert (await stream.result()).state is C
            for s in samples:
                assert_pose(s, moved)

    run(body())


def test_two_robots_with_their_own_base_and_probe_get_their_own_measurements(cell, world):
    both_tmacs(cell, world)

    async def body():
        async with Client("KUKA_A", cell=cell.name) as a, Client("COMAU_B", cell=cell.name) as b:
            assert await a.wait_for("TRACKER") and await b.wait_for("TRACKER")
            await setup_robot(a, BASE_A, PROBE_A, POSE_A)
            await setup_robot(b, BASE_B, PROBE_B, POSE_B)  # the beam goes to B's T-MAC
            assert_pose(await ok(b, "Single Measurement", "tr2euler", 200), POSE_B)
            await ok(a, "Move", "", POSE_A)  # every robot moves the beam before measuring
            assert_pose(await ok(a, "Single Measurement", "tr2euler", 200), POSE_A)
            await ok(b, "Move", "", POSE_B)
            assert_pose(await ok(b, "Single Measurement", "tr2euler", 200), POSE_B)
            # the same raw measurement, in A's frame, is not B's pose: frames are per robot
            await ok(a, "Move", "", POSE_A)
            assert not np.allclose(await ok(a, "Single Measurement", "tr2euler", 50), POSE_B,
                                   atol=1.0)

    run(body())


def test_a_robot_whose_beam_another_robot_took_is_measured_not_the_other(cell, world):
    """The beam is locked for the last Move's requester.  A measurement by another
    robot aims the beam back where that robot's own last Move put it, so it measures
    its own reflector — never the other robot's — and two robots taking turns cannot
    starve each other by stealing the beam (7.4, 8.4.3)."""
    both_tmacs(cell, world)

    async def body():
        async with Client("KUKA_A", cell=cell.name) as a, Client("COMAU_B", cell=cell.name) as b, \
                Client("NEWCOMER", cell=cell.name) as c:
            assert await a.wait_for("TRACKER") and await b.wait_for("TRACKER")
            await setup_robot(a, BASE_A, PROBE_A, POSE_A)
            await setup_robot(b, BASE_B, PROBE_B, POSE_B)  # B took the beam
            assert_pose(await ok(a, "Single Measurement", "tr2euler", 50), POSE_A)
            assert_pose(await ok(b, "Single Measurement", "tr2euler", 50), POSE_B)
            stream = await a.create_process("TRACKER", "Continuous Measurement", "tr2euler",
                                            20, timeout=30)
            first = await anext(aiter(stream))
            while first.data is None:
                first = await anext(aiter(stream))
            assert_pose(ProcessCall.array(first), POSE_A)
            await ok(a, "Stop Measurement")
            # a requester that never moved the beam is not given someone else's reflector
            final = await (await c.create_process("TRACKER", "Single Measurement", "tr2euler",
                                                  50, timeout=30)).result()
            assert final.state is F
            assert final.reason == ("Single Measurement: the beam is pointed for KUKA_A; "
                                    "send Move first")

    run(body())


def test_a_reflector_that_vanishes_ends_the_lock_with_its_name(cell, world):
    """The T-MAC's robot is switched off (its world publisher gone): the tracker says
    which reflector it lost, not that another one 'jumped' (it measures nothing else)."""
    tmac_a = world(cell.name, "TMAC_A")
    tmac_a.publish(reflector(BASE_A, POSE_A, PROBE_A))
    world(cell.name, "TMAC_B").publish(reflector(BASE_B, POSE_B, PROBE_B))

    async def body():
        async with Client("VANISH", cell=cell.name) as a:
            assert await a.wait_for("TRACKER")
            await setup_robot(a, BASE_A, PROBE_A, POSE_A)
            assert_pose(await ok(a, "Single Measurement", "tr2euler", 50), POSE_A)
            tmac_a.close()
            for _ in range(2):  # and it stays lost until the next Move
                final = await (await a.create_process("TRACKER", "Single Measurement",
                                                      "tr2euler", 50, timeout=30)).result()
                assert final.state is F
                assert "the reflector TMAC_A the beam was locked on is gone; send Move again" \
                    in final.reason
            again = world(cell.name, "TMAC_A")
            again.publish(reflector(BASE_A, POSE_A, PROBE_A))
            await ok(a, "Move", "", POSE_A)
            assert_pose(await ok(a, "Single Measurement", "tr2euler", 50), POSE_A)

    run(body())


def test_the_second_robot_waits_for_the_first_robots_stop_measurement(cell, world):
    both_tmacs(cell, world)

    async def body():
        async with Client("COMAU", cell=cell.name) as comau, \
                Client("KUKA", cell=cell.name) as kuka:
            await comau_aimed_kuka_framed(comau, kuka)
            stream = await comau.create_process("TRACKER", "Continuous Measurement", "", 50,
                                                timeout=30)
            first = await anext(aiter(stream))  # Running: the Comau holds the tracker
            assert first.state is R
            waiting = asyncio.create_task(move_and_measure(kuka, POSE_B))
            frames = 0
            async for update in stream:  # the Comau corrects its position meanwhile (8.3.2)
                frames += update.data is not None
                if frames == 8:
                    break
            assert not waiting.done()  # queued behind the Comau's stream (8.4.3)
            await served_after_stop(comau, stream, waiting, POSE_B)

    run(body())


def test_a_tracked_path_holds_the_tracker_the_other_robot_is_served_after(cell, world):
    """Issue 38: a Stream Measurement (a tracked path) holds the shared tracker until its
    Stop Measurement, as Continuous Measurement does (8.4.3); the other robot's Move and
    measurement wait in the queue and are served after, each in its own frame."""
    both_tmacs(cell, world)

    async def body():
        async with Client("COMAU", cell=cell.name) as comau, \
                Client("KUKA", cell=cell.name) as kuka:
            await comau_aimed_kuka_framed(comau, kuka)
            stream = await comau.create_process("TRACKER", "Stream Measurement", "tr2euler",
                                                [1000, 10], timeout=30)
            rows = []
            updates = aiter(stream)
            while not rows:  # Running with data: the Comau's tracked path holds the tracker
                update = await anext(updates)
                assert update.state is R
                if update.data is not None:
                    rows.append(ProcessCall.array(update))

            waiting = asyncio.create_task(move_and_measure(kuka, POSE_B))
            await take_rows(updates, 20, rows)  # the path goes on, its samples keep coming
            assert not waiting.done()  # queued behind the stream
            await served_after_stop(comau, stream, waiting, POSE_B)
        samples = np.vstack(rows)
        assert samples.shape == (200, 11)
        np.testing.assert_array_equal(np.diff(samples[:, -1]), 1)  # seq: no sample lost
        assert np.abs(np.median(samples[:, 2:5], axis=0) - POSE_A[:3]).max() < 0.15

    run(body())


def test_a_robot_that_dies_holding_the_tracker_does_not_block_the_other(cell, world):
    both_tmacs(cell, world)

    async def prepare():
        async with Client("HOLDER", cell=cell.name) as holder:
            assert await holder.wait_for("TRACKER")
            await setup_robot(holder, BASE_A, PROBE_A, POSE_A)  # frames stay with the name

    run(prepare())
    holder = cell.start("call", "TRACKER", "Continuous Measurement", "--data", "50",
                        "--name", "HOLDER", "--cell", cell.name, "--timeout", "60")
    holder.wait_line(lambda line: '"seq": 3' in line)  # streaming: it holds the tracker

    async def body():
        async with Client("SURVIVOR", cell=cell.name) as survivor:
            assert await survivor.wait_for("TRACKER")
            base = await survivor.create_process("TRACKER", "Set Base", "euler2tr", BASE_B,
                                                 timeout=30)
            assert base.ack.state is ProcessStates.Queued
            await asyncio.sleep(0.3)
            assert not base.done  # held by the stream of HOLDER
            holder.kill9()  # dies without Stop Measurement
            assert (await base.result()).state is C
            await ok(survivor, "Set Probe", "euler2tr", PROBE_B)
            await ok(survivor, "Move", "", POSE_B)
            assert_pose(await ok(survivor, "Single Measurement", "tr2euler", 100), POSE_B)

    run(body(), timeout=60)


def test_beam_not_locked_fails_with_the_reason_and_the_service_carries_on(world_session):
    """A fresh tracker (in this process): never pointed, nothing to capture, lost mid-stream."""
    cell = unique_cell()

    async def body():
        tracker = build("tracker", None, {"seed": 3}, cell=cell, journal=False)
        await tracker.start()
        session = open_session(TransportConfig.from_env())
        tmac = ReflectorPublisher(Bus(session, KeySpace(cell)), "TMAC", "tmac")
        tmac.publish(reflector(BASE_A, POSE_A, PROBE_A))
        try:
            async with Client("ROBOT", cell=cell) as robot:
                assert await robot.wait_for("TRACKER")

                async def failed(command, option="", data=None) -> str:
                    call = await robot.create_process("TRACKER", command, option, data)
                    final = await call.result()
                    assert final.state is F
                    return final.reason

                reason = await failed("Single Measurement", "tr2euler", 1000)
                assert reason == ("Single Measurement: beam not locked: the beam has not been "
                                  "pointed at a reflector; send Move first")
                await ok(robot, "Set Base", "euler2tr", BASE_A)
                await ok(robot, "Set Probe", "euler2tr", PROBE_A)
                wrong = [POSE_A[0] + 60.0, *POSE_A[1:]]  # 60 mm off: beyond the 10 mm radius
                reason = await failed("Move", "", wrong)
                assert reason.startswith("Move: beam not locked: no reflector within the 10.0 mm "
                                         "capture radius of the beam (nearest: TMAC, ")
                assert "check BASE, PROBE and the robot pose given to Move" in reason
                assert "capture" in reason and "point_at" not in reason
                off = [POSE_A[0] + 4.0, *POSE_A[1:]]  # 4 mm off: the ADM finds it (8.4.3)
                await ok(robot, "Move", "", off)
                assert_pose(await ok(robot, "Single Measurement", "tr2euler", 100), POSE_A)
                # the reflector disappears while streaming: the stream ends with the reason
                stream = await robot.create_process("TRACKER", "Continuous Measurement", "", 20)
                async for update in stream:
                    if update.data is not None:
                        break
                tmac.close()
                final = await asyncio.wait_for(stream.result(), 10)
                assert final.state is F and "beam not locked" in final.reason
                assert "the reflector TMAC the beam was locked on is gone" in final.reason
                reason = await failed("Single Measurement", "", 0)
                assert reason == "Single Measurement: duration 0 ms outside 1…60000 ms"
                reason = await failed("Set Base", "quaternion2tr", BASE_A)
                assert "unknown option 'quaternion2tr'" in reason
                # nothing in the cell to lock on: the reason says what is missing (issue 39)
                reason = await failed("Move", "", POSE_A)
                assert reason == ("Move: beam not locked: no reflector in the cell to lock on — "
                                  "the simulated reflectors are the simulated robots' T-MACs: "
                                  "start a robot in this cell first (plugcell serve robot "
                                  "--param sim=true)")
                # still serving: a new reflector, Move, measure
                again = ReflectorPublisher(Bus(session, KeySpace(cell)), "TMAC2", "smr")
                again.publish(reflector(BASE_A, POSE_A, PROBE_A))
                # its queryable reaches the tracker's session asynchronously, as every
                # Zenoh declaration does: Move until the tracker finds it (bounded)
                deadline = time.monotonic() + 10
                while True:
                    call = await robot.create_process("TRACKER", "Move", "", POSE_A, timeout=30)
                    final = await call.result()
                    if (final.state is C or "no reflector in the cell" not in final.reason
                            or time.monotonic() > deadline):
                        break
                    await asyncio.sleep(0.05)
                assert final.state is C, f"Move: {final.reason}"
                smr = await ok(robot, "Single Measurement", "tr2euler", 100)
                # an SMR gives a position only (rotation identity in the tracker frame)
                expected = pose(BASE_A) @ pose(POSE_A) @ pose(PROBE_A)
                got = pose(BASE_A) @ pose_from_robot(smr, "zyz") @ pose(PROBE_A)
                np.testing.assert_allclose(got[:3, 3], expected[:3, 3], atol=1.5e-4)
                again.close()
                status = tracker.interface.status()
                assert status is not None and status.busy_s > 0
        finally:
            await tracker.close()
            session.close()

    run(body())
