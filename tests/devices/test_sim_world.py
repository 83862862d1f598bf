"""The sim-only world channel: reflector truth shared between simulated devices."""

from __future__ import annotations

import time

import numpy as np
import pytest

from plugcell.framework.bus import Bus
from plugcell.framework.keys import KeySpace
from plugcell.framework.transport import TransportConfig, open_session
from plugcell.sim.world import ReflectorPublisher, WorldView


@pytest.fixture
def sessions():
    cfg = TransportConfig.from_env()
    a, b = open_session(cfg), open_session(cfg)
    yield a, b
    a.close()
    b.close()


def _wait(cond, timeout=5.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if cond():
            return True
        time.sleep(0.01)
    return False


def test_late_joiner_gets_the_latest_pose_then_follows_updates(sessions):
    a, b = sessions
    cell = "world-test"
    pub = ReflectorPublisher(Bus(a, KeySpace(cell)), "robot1", "tmac")
    pose = np.eye(4)
    pose[:3, 3] = [1.0, 2.0, 3.0]
    pub.publish(pose)
    assert _wait(lambda: WorldView(Bus(b, KeySpace(cell))).get("robot1") is not None)
    view = WorldView(Bus(b, KeySpace(cell)))
    np.testing.assert_allclose(view.get("robot1").matrix(), pose)
    pose2 = pose.copy()
    pose2[0, 3] = 1.5
    pub.publish(pose2, moving=True)
    assert _wait(lambda: view.get("robot1").matrix()[0, 3] == 1.5)
    assert view.get("robot1").moving
    other = WorldView(Bus(b, KeySpace("another-cell")))
    assert other.get("robot1") is None
    pub.close()


def test_bad_poses_are_refused(sessions):
    a, _ = sessions
    pub = ReflectorPublisher(Bus(a, KeySpace("world-test2")), "r", "smr")
    with pytest.raises(ValueError, match="finite 4x4"):
        pub.publish(np.full((4, 4), np.nan))
    with pytest.raises(ValueError, match="kind"):
        ReflectorPublisher(Bus(a, KeySpace("world-test2")), "r2", "laser")


def test_a_reflector_that_moves_in_time_answers_a_look_with_its_pose_now(sessions):
    a, b = sessions
    cell = "world-test3"
    now = {"x": 1.0}

    def current() -> np.ndarray:
        pose = np.eye(4)
        pose[0, 3] = now["x"]
        return pose

    pub = ReflectorPublisher(Bus(a, KeySpace(cell)), "arm", "tmac", current=current)
    pub.publish(current(), moving=True)
    look = Bus(b, KeySpace(cell))
    assert _wait(lambda: any(look.query_reflectors(1.0)))
    now["x"] = 2.5  # the arm moved on; nothing was published
    view = WorldView(look)
    state = view.get("arm")
    assert state.matrix()[0, 3] == 2.5 and state.moving  # moving, as published last
    pub.close()
