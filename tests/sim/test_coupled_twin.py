"""The twin and the simulated controller of a robot with a vendor joint convention.

Motors, encoders and the controller's joint readings are the Fanuc's J1..J6; the
kinematic joints (θ3 = −J2 − J3 …) exist only inside the model.  The controller's
ARM_JNTP / POS_TO_JNTP / joint moves and the limits speak readings; a calibration of
a twin campaign runs on them.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from coupling_testlib import hand_converted

from plugcell.calibration import Calibrator
from plugcell.kinematics import forward
from plugcell.pdl.interfaces import MotionError
from plugcell.pdl.values import JointPos
from plugcell.sim.controller.arm import TwinArm
from plugcell.sim.twin.campaign import measure_poses, working_volume_joints
from plugcell.sim.twin.robot import RobotTwin, true_flange_poses
from plugcell.sim.twin.scenario import TwinScenario, make_truth
from plugcell.sim.twin.tracker import LaserTracker


@pytest.fixture(scope="module")
def truth():
    return make_truth(TwinScenario(robot="fanuc_m20ia", seed=5))


def test_true_pose_equals_the_hand_converted_twin(truth):
    """Same physics for the coupled robot at readings q and its hand-converted twin at M·q
    (gravity deflection and bending on; the per-motor transmission error off)."""
    sc = dataclasses.replace(truth.scenario, transmission=False)
    coupled = dataclasses.replace(truth, scenario=sc,
                                  transmission=dataclasses.replace(
                                      truth.transmission,
                                      amplitude=np.zeros_like(truth.transmission.amplitude)))
    desc = truth.description
    hand = hand_converted(desc)
    shift = hand.nominal_parameters().theta - desc.nominal_parameters().theta
    manual = dataclasses.replace(coupled, description=hand,
                                 params=truth.params.replace(theta=truth.params.theta + shift))
    rng = np.random.default_rng(1)
    q = working_volume_joints(desc, truth.profile, 10, rng)
    M = desc.coupling.matrix
    np.testing.assert_allclose(true_flange_poses(coupled, q), true_flange_poses(manual, q @ M.T),
                               atol=1e-12)
    # and the errors are there: the true pose is not the nominal one
    dev = true_flange_poses(coupled, q)[:, :3, 3] - forward(desc, None, q).flange[:, :3, 3]
    assert np.linalg.norm(dev, axis=1).mean() > 2e-4


def test_controller_speaks_readings(truth):
    arm = TwinArm(RobotTwin(truth, seed=3))
    target = (10.0, 20.0, -15.0, 30.0, -70.0, 45.0)  # J1..J6, degrees
    arm.move_joints(target)
    np.testing.assert_allclose(arm.arm_jntp().joints, target, atol=1e-3)  # encoder counts
    pose = arm.arm_pos()  # nominal FK of the readings
    T = forward(truth.description, None, np.radians(arm.arm_jntp().joints)).tcp
    np.testing.assert_allclose(arm.jntp_to_pos(arm.arm_jntp()).as_tuple(), pose.as_tuple())
    assert pose.as_tuple()[0] == pytest.approx(T[0, 3] * 1e3)
    back = arm.pos_to_jntp(pose)  # POS_TO_JNTP gives readings, nearest the current ones
    np.testing.assert_allclose(back.joints, arm.arm_jntp().joints, atol=1e-6)
    with pytest.raises(MotionError, match=r"joint J5 = -150\.0000° outside \[-140°, 140°\]"):
        arm.move_joints((0.0, 0.0, 0.0, 0.0, -150.0, 0.0))
    # J3 = 200° is a legal Fanuc reading (forearm against the horizon); θ3 = −J2 − J3
    arm.move_joints((0.0, 30.0, 200.0, 0.0, 0.0, 0.0))
    assert isinstance(arm.arm_jntp(), JointPos)


def test_calibration_of_a_twin_campaign_on_readings(truth):
    exact = make_truth(TwinScenario(robot="fanuc_m20ia", seed=5, noise=False, backlash=False,
                                    transmission=False, bending=False))
    twin = RobotTwin(exact, seed=2)
    rng = np.random.default_rng(7)
    desc = truth.description
    q = working_volume_joints(desc, truth.profile, 60, rng)
    data, _ = measure_poses(twin, LaserTracker(seed=4), q)
    np.testing.assert_array_equal(data.joints, twin.quantise(q))  # the file holds readings
    res = Calibrator(desc, "serial+gravity").fit(data)
    assert res.converged
    before = res.calibration_before.position.norm.mean
    after = res.calibration.position.norm.mean
    assert before > 2e-4 and after < 3e-5, (before, after)  # tracker noise remains
