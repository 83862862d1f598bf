"""The calibration of Fig. 8-4 at the service level, with the data sent where needed (9.3).

The test plays the robot program: it moves the digital twin (whose T-MAC the simulated
world publishes), catches the beam with Move, and at each pose asks the tracker for a
1 s measurement routed straight into ``mT`` of its compute workspace, adds its joint
readings to ``mJ``, and finally evaluates ``calibrate`` — the tracker and compute
services are real OS processes.  The identified model is as accurate on validation
poses as the calibration engine on a campaign of the same kind.
"""

from __future__ import annotations

import numpy as np
import pytest
from metrology_testlib import run

from plugcell.calibration import CalibrationData, Calibrator
from plugcell.framework import Client, ProcessCall, ProcessStates
from plugcell.io.units import robot_from_pose
from plugcell.kinematics import forward
from plugcell.sim.twin.campaign import measure_poses, working_volume_joints
from plugcell.sim.twin.robot import RobotTwin
from plugcell.sim.twin.scenario import TwinScenario
from plugcell.sim.twin.tracker import LaserTracker

pytestmark = pytest.mark.timeout(90)

C = ProcessStates.Completed
ROUTE = "tr2euler; to=COMPUTE:Set Matrix:{}:append"


async def ok(client: Client, service: str, command: str, option: str = "", data=None):
    final = await (await client.create_process(service, command, option, data,
                                               timeout=60)).result()
    assert final.state is C, f"{command} {option}: {final.reason}"
    return None if final.data is None else ProcessCall.array(final)


def test_calibration_program_with_routed_measurements_matches_the_engine(cell, world):
    twin = RobotTwin(TwinScenario(seed=4))
    truth = twin.reveal_truth()
    desc = twin.description
    q_cal = working_volume_joints(desc, truth.profile, 40, np.random.default_rng(11))
    q_val = working_volume_joints(desc, truth.profile, 25, np.random.default_rng(12))
    tmac = world(cell.name, "H4_TMAC")
    # appendix-D estimates of BASE and PROBE: good to a millimetre and a few hundredths of °
    off_base = np.array([1.0, -0.8, 0.5, 0.02, 0.0, -0.03])
    off_probe = np.array([0.5, 0.5, -0.5, 0.0, 0.02, 0.0])
    base_estimate = robot_from_pose(truth.base, "zyz") + off_base
    probe_estimate = robot_from_pose(truth.probe, "zyz") + off_probe

    async def body():
        async with Client("H4", cell=cell.name) as robot:
            assert await robot.wait_for("TRACKER") and await robot.wait_for("COMPUTE")
            # catch the beam with the estimates, then measure raw (identity frames)
            twin.move_joints(q_cal[0])
            tmac.publish(twin.true_reflector_in_tracker())
            flange = forward(desc, None, twin.joint_readings()).flange  # the controller's idea
            await ok(robot, "TRACKER", "Set Base", "euler2tr", base_estimate)
            await ok(robot, "TRACKER", "Set Probe", "euler2tr", probe_estimate)
            await ok(robot, "TRACKER", "Move", "", robot_from_pose(flange, "zyz"))
            await ok(robot, "TRACKER", "Set Base", "euler2tr", np.zeros(6))
            await ok(robot, "TRACKER", "Set Probe", "euler2tr", np.zeros(6))
            for joints, mj, mt in ((q_cal, "mJ", "mT"), (q_val, "vJ", "vT")):
                for q in joints:
                    twin.move_joints(q)
                    tmac.publish(twin.true_reflector_in_tracker())  # the beam follows it
                    await ok(robot, "TRACKER", "Single Measurement", ROUTE.format(mt), 1000)
                    await ok(robot, "COMPUTE", "Set Matrix", f"{mj}:append",
                             np.rad2deg(twin.joint_readings()))
            await ok(robot, "COMPUTE", "Evaluate", "",
                     "params = calibrate(mJ, mT, model=4); v = validate(params, vJ, vT)")
            return (await ok(robot, "COMPUTE", "Get Matrix", "v"))[0]

    v = run(body(), timeout=80)
    assert v[0] == 25

    # the same kind of data, measured by the campaign of `plugcell twin measure`
    twin2 = RobotTwin(TwinScenario(seed=4))
    tracker = LaserTracker(seed=99)
    cal, _ = measure_poses(twin2, tracker, q_cal, rotation="zyz")
    val, _ = measure_poses(twin2, tracker, q_val, rotation="zyz")
    engine = Calibrator(desc, model=4).fit(CalibrationData.from_measurements(cal),
                                           validation=CalibrationData.from_measurements(val))
    expected = engine.validation.position.norm.mean * 1e3
    assert v[2] < 0.3  # mm, well below the thesis's 1 mm objective
    assert v[2] == pytest.approx(expected, abs=0.03)
    assert v[1] == pytest.approx(engine.validation_before.position.norm.mean * 1e3, rel=0.05)
