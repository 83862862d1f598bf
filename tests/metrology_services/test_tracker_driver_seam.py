"""The driver seam: any TrackerDriver plugs into the same service (``driver=module:Class``)."""

from __future__ import annotations

import numpy as np
import pytest
from fake_tracker_driver import ScriptedDriver
from metrology_testlib import pose, run, unique_cell

from plugcell.apps.kinds import load_kind
from plugcell.devices.tracker.driver import TrackerDriver
from plugcell.devices.tracker.service import TrackerService, load_driver
from plugcell.framework import Client, GenericDevice, ProcessCall, ProcessStates

BASE, PROBE, ROBOT = [3000, 0, 0, 90, 0, 0], [0, 0, 100, 0, 0, 0], [1000, 200, 500, 0, 180, 0]


def test_a_driver_is_loaded_by_name_and_checked():
    assert isinstance(load_driver("fake_tracker_driver:ScriptedDriver"), TrackerDriver)
    with pytest.raises(ValueError, match="expected 'sim' or module:Class"):
        load_driver("leica")
    with pytest.raises(ValueError, match="cannot load tracker driver"):
        load_driver("no_such_module:Driver")
    with pytest.raises(ValueError, match="cannot construct tracker driver"):
        load_driver("fake_tracker_driver:BeamNotLockedError")
    with pytest.raises(ValueError, match="is not a TrackerDriver"):
        load_driver("fake_tracker_driver:NotADriver")
    assert load_kind("tracker") is TrackerService


def test_the_service_does_eq_7_1_and_7_2_and_the_driver_only_points_and_measures():
    cell = unique_cell()
    driver = ScriptedDriver()
    driver.reflector = pose(BASE) @ pose(ROBOT) @ pose(PROBE)

    async def body():
        tracker = GenericDevice(TrackerService(driver), cell=cell, journal=False)
        await tracker.start()
        try:
            assert driver.connected and tracker.device.vendor == "scripted tracker (tests)"
            async with Client("ROBOT", cell=cell) as robot:
                assert await robot.wait_for("TRACKER")
                for command, option, data in (("Set Base", "euler2tr", BASE),
                                              ("Set Probe", "euler2tr", PROBE),
                                              ("Move", "", ROBOT)):
                    final = await (await robot.create_process("TRACKER", command, option,
                                                              data)).result()
                    assert final.state is ProcessStates.Completed, final.reason
                np.testing.assert_allclose(driver.pointed[-1], driver.reflector[:3, 3])
                final = await (await robot.create_process("TRACKER", "Single Measurement",
                                                          "tr2euler", 1000)).result()
                np.testing.assert_allclose(pose(ProcessCall.array(final)), pose(ROBOT),
                                           atol=1e-9)
                final = await (await robot.create_process("TRACKER", "Move", "",
                                                          [0, 0, 0, 0, 0, 0])).result()
                assert final.reason == "Move: beam not locked: nothing there"
        finally:
            await tracker.close()
        assert not driver.connected

    run(body())
