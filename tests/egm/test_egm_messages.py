"""EgmRobot in (SI out of ABB units), EgmSensor out, and the quaternion arithmetic the
pose targets use — checked against scipy's rotations and protobuf's own parser."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from egm_testlib import robot_message
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from plugcell.devices.robot.egm.messages import (
    egm_pb2,
    encode_joints,
    encode_path_correction,
    encode_pose,
    parse_egm_robot,
    quat_multiply,
    rotvec_to_quat,
)
from plugcell.devices.robot.stream import PacketError
from plugcell.io.units import DEG


def test_a_robot_message_is_read_in_si() -> None:
    s = parse_egm_robot(robot_message(7, tm=1234, joints_deg=(0, 10, 20, 0, 30, -45),
                                      pos_mm=(600, -5, 800)))
    assert (s.seqno, s.tm) == (7, 1234)
    np.testing.assert_allclose(s.joints, np.array([0, 10, 20, 0, 30, -45]) * DEG)
    np.testing.assert_allclose(s.position, [0.6, -0.005, 0.8])
    np.testing.assert_allclose(s.quaternion, [0, 0, 1, 0])
    assert s.motors_on and s.rapid_running and s.mci_running
    assert s.test_signals == (1.0, 2.0)
    np.testing.assert_allclose(s.planned_joints, s.joints)


@pytest.mark.parametrize(("data", "kind", "says"), [
    (b"\x0a\x05abc", "malformed", "not an EgmRobot"),
    (b"x" * 2000, "oversized", "2000 bytes"),
    (robot_message(1)[:20], "malformed", "not an EgmRobot"),
])
def test_what_is_no_robot_message_is_dropped_with_the_reason(data, kind, says) -> None:
    with pytest.raises(PacketError, match=says) as err:
        parse_egm_robot(data)
    assert err.value.kind == kind


def test_a_sensor_message_or_a_foreign_one_is_foreign() -> None:
    sensor = egm_pb2.EgmSensor()
    sensor.header.seqno, sensor.header.tm = 1, 1
    sensor.header.mtype = egm_pb2.EgmHeader.MSGTYPE_CORRECTION
    sensor.planned.joints.joints.extend([0.0] * 6)
    with pytest.raises(PacketError, match="not a robot's data message") as err:
        parse_egm_robot(sensor.SerializeToString())
    assert err.value.kind == "foreign"
    no_feedback = egm_pb2.EgmRobot()
    no_feedback.header.seqno, no_feedback.header.tm = 1, 1
    with pytest.raises(PacketError, match="no feedback joints"):
        parse_egm_robot(no_feedback.SerializeToString())
    with pytest.raises(PacketError, match="fields that EgmRobot does not have"):
        parse_egm_robot(robot_message(1) + b"\xa0\x06\x01")  # field 100, varint


def test_numbers_that_are_none_are_malformed() -> None:
    with pytest.raises(PacketError, match=r"feedBack\.joints: nan"):
        parse_egm_robot(robot_message(1, joints_deg=(0, math.nan, 0, 0, 0, 0)))
    with pytest.raises(PacketError, match="not a unit quaternion"):
        parse_egm_robot(robot_message(1, quat=(1, 1, 0, 0)))


def test_the_answers_carry_abb_units() -> None:
    m = egm_pb2.EgmSensor()
    m.ParseFromString(encode_joints(5, 20, np.array([0, 10, 20, 0, 30, 0]) * DEG))
    assert m.header.mtype == egm_pb2.EgmHeader.MSGTYPE_CORRECTION and m.header.seqno == 5
    np.testing.assert_allclose(m.planned.joints.joints, [0, 10, 20, 0, 30, 0])
    m = egm_pb2.EgmSensor()
    m.ParseFromString(encode_pose(6, 24, np.array([0.6, 0.0, 0.8]), (0.0, 0.0, 1.0, 0.0)))
    c = m.planned.cartesian
    assert (c.pos.x, c.pos.y, c.pos.z) == (600.0, 0.0, 800.0)
    assert (c.orient.u0, c.orient.u1, c.orient.u2, c.orient.u3) == (0.0, 0.0, 1.0, 0.0)
    p = egm_pb2.EgmSensorPathCorr()
    p.ParseFromString(encode_path_correction(7, 28, np.array([0.0, 0.001, -0.002]), 3))
    assert p.header.mtype == egm_pb2.EgmHeader.MSGTYPE_PATH_CORRECTION
    assert (p.pathCorr.pos.y, p.pathCorr.pos.z, p.pathCorr.age) == (1.0, -2.0, 3)


vec = st.lists(st.floats(-3.0, 3.0), min_size=3, max_size=3)


@settings(max_examples=300, deadline=None)
@given(vec, st.lists(st.floats(-1, 1), min_size=4, max_size=4).filter(
    lambda q: np.linalg.norm(q) > 0.1))
def test_quaternion_arithmetic_matches_scipy(w, q) -> None:
    q = np.array(q) / np.linalg.norm(q)
    ours = np.array(quat_multiply(rotvec_to_quat(w), q))
    ref = (Rotation.from_rotvec(w) * Rotation.from_quat(q, scalar_first=True)).as_matrix()
    got = Rotation.from_quat(ours, scalar_first=True).as_matrix()
    np.testing.assert_allclose(got, ref, atol=1e-12)
    assert abs(np.linalg.norm(ours) - 1) < 1e-12


def test_a_tiny_rotation_vector_is_exact() -> None:
    for t in (0.0, 1e-9, 1e-5, 9.9e-5, 1.01e-4):
        w = np.array([t, -2 * t, 0.5 * t])
        np.testing.assert_allclose(rotvec_to_quat(w), Rotation.from_rotvec(w).as_quat(
            scalar_first=True), atol=1e-15)


@settings(max_examples=300, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(0, 2**32 - 1),
       st.lists(st.floats(-360, 360), min_size=6, max_size=6))
def test_any_valid_message_reads_back(seqno, tm, joints) -> None:
    s = parse_egm_robot(robot_message(seqno, tm=tm, joints_deg=joints))
    assert (s.seqno, s.tm) == (seqno, tm)
    np.testing.assert_allclose(s.joints, np.array(joints) * DEG)


@settings(max_examples=2000, deadline=None)
@given(st.binary(max_size=600))
def test_any_bytes_are_read_or_dropped_with_a_reason(data) -> None:
    try:
        s = parse_egm_robot(data)
    except PacketError as exc:
        assert exc.kind in ("malformed", "oversized", "foreign")
    else:  # what is read is a robot's message with finite joints
        assert len(s.joints) in (6, 7) and np.all(np.isfinite(s.joints))


# ---- the messages a link keeps from cycle to cycle


@given(st.integers(0, 2**32 - 1), st.lists(st.floats(-1e3, 1e3), min_size=6, max_size=7))
def test_a_kept_sensor_message_serializes_as_a_new_one(seqno, joints) -> None:
    kept = egm_pb2.EgmSensor()
    encode_joints(5, 6, np.zeros(7), kept)  # an earlier, longer answer
    assert encode_joints(seqno, 8, np.array(joints), kept) == \
        encode_joints(seqno, 8, np.array(joints))


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc/self/statm").exists(), reason="reads /proc (Linux)")
def test_a_kept_sensor_message_does_not_grow() -> None:
    """Written over 60 000 times (four minutes of a 4 ms stream) the kept answer takes no
    memory cycle by cycle — unlike a kept EgmRobot parsed into (upb's arena grows with
    each parse, which is why the link parses into a new one): checked in a fresh process
    by its resident size, with a parse into a kept message as the control."""
    code = """
import os
import numpy as np
from plugcell.devices.robot.egm.messages import egm_pb2, encode_joints
page = os.sysconf("SC_PAGE_SIZE") // 1024
def rss():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * page
kept, robot, q = egm_pb2.EgmSensor(), egm_pb2.EgmRobot(), np.zeros(6)
msg = egm_pb2.EgmRobot()
msg.header.seqno = msg.header.tm = 1
msg.feedBack.joints.joints.extend([0.5] * 6)
c = msg.feedBack.cartesian
c.pos.x = c.pos.y = c.pos.z = c.orient.u1 = c.orient.u2 = c.orient.u3 = 0.0
c.orient.u0 = 1.0
raw = msg.SerializeToString()
encode_joints(1, 2, q, kept)
robot.ParseFromString(raw)
r0 = rss()
for i in range(60000):
    encode_joints(i, i, q + i * 1e-6, kept)
r1 = rss()
for _ in range(60000):
    robot.ParseFromString(raw)
print(r1 - r0, rss() - r1)
"""
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr
    encode_kb, parse_kb = map(int, done.stdout.split())
    assert encode_kb < 2048, encode_kb
    assert parse_kb > 8 * 1024, parse_kb  # the control: the growth this test would see
