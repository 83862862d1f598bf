"""The simulated controller's EGM side against independent sensor-side code: the EGM
client of ``abb-robot-client`` (Apache-2.0, RPI's ABB driver) reads the simulated robot's
feedback and drives it with joint targets, pose targets and path corrections."""

from __future__ import annotations

import time

import numpy as np
import pytest

from plugcell.io.units import DEG
from plugcell.sim.controller.egm_robot import EgmRobotSim
from plugcell.sim.ports import free_port

egm_client = pytest.importorskip("abb_robot_client.egm")


def drive(mode: str, command, until, seconds: float = 3.0):
    port = free_port("udp")
    client = egm_client.EGM(port=port)
    robot = EgmRobotSim(("127.0.0.1", port), mode=mode).start()
    try:
        end = time.monotonic() + seconds
        first = last = None
        while time.monotonic() < end:
            ok, state = client.receive_from_robot(timeout=0.1)
            if not ok:
                continue
            first = first or state
            last = state
            command(client, first)
            if until(robot, state):
                return first, last, robot
        raise AssertionError(f"not reached in {seconds} s: {robot.state()}")
    finally:
        robot.stop()
        client.close()


def test_the_client_reads_the_simulated_robots_feedback() -> None:
    first, last, _robot = drive("joint", lambda c, s: c.send_to_robot(s.joint_angles),
                               lambda r, s: r.answers > 10)
    np.testing.assert_allclose(first.joint_angles, [0, 0, 0, 0, 0.5 / DEG, 0], atol=1e-9)
    pos, quat = first.cartesian
    np.testing.assert_allclose(pos, [600, 0, 800])
    np.testing.assert_allclose(quat, [0, 0, 1, 0])
    assert first.rapid_running and first.motors_on
    assert last.robot_message.header.seqno > first.robot_message.header.seqno


def test_the_client_drives_the_joints() -> None:
    target = np.array([5.0, -3.0, 2.0, 0.0, 30.0, 10.0])  # degrees
    _, last, robot = drive("joint", lambda c, s: c.send_to_robot(target),
                           lambda r, s: np.allclose(s.joint_angles, target, rtol=0, atol=1e-4))
    np.testing.assert_allclose(robot.state()["joints"], target * DEG, atol=1e-5)
    np.testing.assert_allclose(last.joint_angles_planned, target, atol=1e-9)


def test_the_client_drives_the_pose() -> None:
    pos = np.array([610.0, -5.0, 790.0])
    quat = np.array([0.0, 0.0, 1.0, 0.0])
    _, _last, robot = drive("pose", lambda c, s: c.send_to_robot_cart(pos, quat),
                           lambda r, s: np.allclose(s.cartesian[0], pos, rtol=0, atol=1e-4))
    np.testing.assert_allclose(robot.state()["position"], pos / 1000, atol=1e-6)


def test_the_client_corrects_the_path() -> None:
    corr = np.array([0.0, 1.5, -0.5])  # mm in path coordinates
    _, _last, robot = drive("pathcorr", lambda c, s: c.send_to_robot_path_corr(corr),
                           lambda r, s: np.allclose(r.state()["correction"], corr / 1000))
    assert robot.rejected == 0
