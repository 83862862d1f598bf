"""Data goes where it is needed (thesis 9.3): output routed service to service.

The robot program only orchestrates: the tracker appends its measurements straight
into the robot's workspace of the compute service, and the compute service sets the
robot's BASE in the tracker — each forwarded process on behalf of the robot.
"""

from __future__ import annotations

import numpy as np
import pytest
from metrology_testlib import pose, run, take_rows

from plugcell.framework import Client, ProcessCall, ProcessStates

pytestmark = pytest.mark.timeout(90)

C, F = ProcessStates.Completed, ProcessStates.Failed
BASE = [2800.0, 600.0, -400.0, 15.0, 3.0, -10.0]
PROBE = [0.0, 30.0, 110.0, 0.0, 5.0, 0.0]
ROBOT_POSE = [1300.0, -200.0, 1000.0, 0.0, 140.0, 30.0]
TO_MT = "tr2euler; to=COMPUTE:Set Matrix:mT:append"


async def final_of(client: Client, service: str, command: str, option: str = "", data=None):
    return await (await client.create_process(service, command, option, data,
                                              timeout=30)).result()


async def ok(client: Client, service: str, command: str, option: str = "", data=None):
    final = await final_of(client, service, command, option, data)
    assert final.state is C, f"{command}: {final.reason}"
    return None if final.data is None else ProcessCall.array(final)


def test_single_and_continuous_measurements_are_appended_into_the_robots_mT(cell, world):
    world(cell.name, "TMAC_R").publish(pose(BASE) @ pose(ROBOT_POSE) @ pose(PROBE))

    async def body():
        async with Client("ROUTED", cell=cell.name) as robot, \
                Client("OTHER", cell=cell.name) as other:
            assert await robot.wait_for("TRACKER") and await robot.wait_for("COMPUTE")
            await ok(robot, "TRACKER", "Set Base", "euler2tr", BASE)
            await ok(robot, "TRACKER", "Set Probe", "euler2tr", PROBE)
            await ok(robot, "TRACKER", "Move", "", ROBOT_POSE)
            seen = [await ok(robot, "TRACKER", "Single Measurement", TO_MT, 1000)
                    for _ in range(3)]
            # the rows are in the robot's own workspace the moment the measurement completes
            mT = await ok(robot, "COMPUTE", "Get Matrix", "mT")
            np.testing.assert_array_equal(mT, np.stack(seen))
            assert (await final_of(other, "COMPUTE", "Get Matrix", "mT")).state is F  # not OTHER's

            stream = await robot.create_process(
                "TRACKER", "Continuous Measurement", "tr2euler; to=COMPUTE:Set Matrix:mC:append",
                20, timeout=30)
            streamed = await take_rows(stream, 5)
            stop = await robot.stop_process(stream)
            assert (await stop.result()).state is C
            async for update in stream:  # whatever came before the stop
                if update.data is not None:
                    streamed.append(ProcessCall.array(update))
            assert (await stream.result()).state is C
            # Stop Measurement completes once every routed value has arrived
            np.testing.assert_array_equal(await ok(robot, "COMPUTE", "Get Matrix", "mC"),
                                          np.stack(streamed))

    run(body())


def test_compute_output_sets_the_robots_base_in_the_tracker(cell, world):
    """INITIALIZE (8.3.2) without the robot relaying: frame → Get Matrix → Set Base."""
    world(cell.name, "TMAC_I").publish(pose(BASE) @ pose(ROBOT_POSE) @ pose(PROBE))

    async def body():
        async with Client("INIT", cell=cell.name) as robot:
            assert await robot.wait_for("TRACKER") and await robot.wait_for("COMPUTE")
            await ok(robot, "COMPUTE", "Set Matrix", "base", BASE)
            await ok(robot, "COMPUTE", "Set Matrix", "probe", PROBE)
            await ok(robot, "COMPUTE", "Get Matrix", "base; to=TRACKER:Set Base:euler2tr")
            await ok(robot, "COMPUTE", "Get Matrix", "probe; to=TRACKER:Set Probe:euler2tr")
            await ok(robot, "TRACKER", "Move", "", ROBOT_POSE)  # with INIT's BASE and PROBE
            measured = await ok(robot, "TRACKER", "Single Measurement", "tr2euler", 500)
            np.testing.assert_allclose(pose(measured), pose(ROBOT_POSE), atol=2e-4)

    run(body())


def test_delivery_failures_and_forged_requesters_are_refused_with_the_reason(cell, world):
    world(cell.name, "TMAC_F").publish(pose(BASE) @ pose(ROBOT_POSE) @ pose(PROBE))

    async def body():
        async with Client("FAILS", cell=cell.name) as robot:
            assert await robot.wait_for("TRACKER")
            await ok(robot, "TRACKER", "Set Base", "euler2tr", BASE)
            await ok(robot, "TRACKER", "Set Probe", "euler2tr", PROBE)
            await ok(robot, "TRACKER", "Move", "", ROBOT_POSE)
            final = await final_of(robot, "TRACKER", "Single Measurement",
                                   "; to=COMPUTE:Set Matrix:9lives", 100)
            assert final.state is F
            assert final.reason == (
                "Single Measurement: measured, but delivery of Single Measurement data to "
                "COMPUTE:Set Matrix failed: Set Matrix: bad matrix name '9lives': a letter, "
                "then letters, digits or '_' (at most 63 characters)")
            final = await final_of(robot, "TRACKER", "Single Measurement",
                                   "; to=COMPUTE:Get Rich:x", 100)
            assert "unknown command 'Get Rich' for COMPUTE" in final.reason
            final = await final_of(robot, "TRACKER", "Set Base", "euler2tr; to=COMPUTE:x:y", BASE)
            assert final.reason == "Set Base: no output data to route (to=)"
            # a client cannot claim to act for another robot: only services forward
            final = await final_of(robot, "COMPUTE", "Set Matrix", "mT; for=ROUTED", [1.0])
            assert final.reason == ("Set Matrix: for=ROUTED: only a service may act on behalf "
                                    "of another participant (FAILS is not a live service)")
            final = await final_of(robot, "COMPUTE", "Set Matrix", "mT; via=X", [1.0])
            assert final.reason == "Set Matrix: unknown option clause 'via' (known: to=, for=)"
            # a stream whose data cannot be delivered ends with the reason
            stream = await robot.create_process("TRACKER", "Continuous Measurement",
                                                "; to=COMPUTE:Set Matrix:bad name", 20)
            final = await stream.result()
            assert final.state is F and "bad matrix name 'bad name'" in final.reason
            # and the tracker is free again
            assert (await final_of(robot, "TRACKER", "Single Measurement", "", 50)).state is C

    run(body())
