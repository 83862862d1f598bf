"""Measurements into the robot base frame with BASE and PROBE (6.5.2)."""

from __future__ import annotations

import numpy as np
import pytest

from plugcell.compensation import MetrologyFrames, Reading, RobotFrameSensor
from plugcell.compensation.frames import RawSensor
from plugcell.kinematics.rotations import rpy_to_matrix
from plugcell.kinematics.transforms import translation


def _T(xyz, rpy):
    T = translation(np.asarray(xyz, float))
    T[:3, :3] = rpy_to_matrix(*np.radians(rpy))
    return T


BASE = _T([-4.0, 1.0, -0.3], [0.2, -0.1, 197.0])
PROBE = _T([0.045, -0.03, 0.14], [1.5, -2.0, 30.0])
FLANGE = _T([1.6, 0.2, 1.1], [10.0, 80.0, 5.0])


class _Fixed:
    """A raw sensor reading a fixed reflector pose in its own frame."""

    def __init__(self, T):
        self.T = T

    def measure(self, duration_s, mode):
        return Reading(self.T[:3, 3].copy(), self.T.copy() if mode == "6dof" else None,
                       duration_s, duration_s + 0.01)


def test_pose_and_position_to_robot_frame():
    frames = MetrologyFrames(BASE, PROBE)
    meas = BASE @ FLANGE @ PROBE  # eq. 6.23
    np.testing.assert_allclose(frames.pose_to_robot(meas), FLANGE @ PROBE, atol=1e-12)
    np.testing.assert_allclose(frames.position_to_robot(meas[:3, 3]), (FLANGE @ PROBE)[:3, 3],
                               atol=1e-12)
    np.testing.assert_allclose(frames.robot_to_sensor(FLANGE @ PROBE), meas, atol=1e-12)
    tool = _T([0.0, 0.0, 0.3], [0, 0, 0])
    other = MetrologyFrames(BASE, PROBE, tool)
    np.testing.assert_allclose(other.pose_to_robot(meas), FLANGE @ tool, atol=1e-12)


def test_robot_frame_sensor():
    meas = BASE @ FLANGE @ PROBE
    raw: RawSensor = _Fixed(meas)
    s = RobotFrameSensor(raw, MetrologyFrames(BASE, PROBE))
    r = s.measure_pose(0.05)
    np.testing.assert_allclose(r.pose, FLANGE @ PROBE, atol=1e-12)
    assert r.duration_s == 0.05 and r.elapsed_s == pytest.approx(0.06)
    np.testing.assert_allclose(s.measure_position(1.0).position, (FLANGE @ PROBE)[:3, 3],
                               atol=1e-12)
    offset_tool = RobotFrameSensor(raw, MetrologyFrames(BASE, PROBE, np.eye(4)))
    with pytest.raises(ValueError, match="reflector"):
        offset_tool.measure_position(1.0)


def test_frames_validation():
    with pytest.raises(ValueError):
        MetrologyFrames(np.eye(3), PROBE)
    with pytest.raises(ValueError):
        MetrologyFrames(BASE, np.full((4, 4), np.nan))
