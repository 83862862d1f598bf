"""``plugcell path run --program``: a robot program's straight moves as the path, those
``WITH TRACKING`` tracked; what a path cannot hold is refused at its line."""

from __future__ import annotations

import numpy as np
import pytest

from plugcell.io.robots import load_robot
from plugcell.sim.path_program import path_of_program

HEAD = """PROGRAM tracked
VAR start, p, q : POSITION
BEGIN
  start := POS(1473.3, -231.7, 2488.4, -60, 30, -90)
  p := start
  p.Y := p.Y + 100
  q := p
  q.Z := q.Z - 30
"""


@pytest.fixture(scope="module")
def robot():
    return load_robot("smart_h4")


def _path(tmp_path, robot, body, speed=100.0):
    f = tmp_path / "tracked.pdl"
    f.write_text(HEAD + body + "END tracked\n")
    return path_of_program(f, robot, speed)


def test_the_straight_moves_are_the_segments_the_tracked_ones_tracked(tmp_path, robot):
    path, trackers = _path(tmp_path, robot, """  MOVE TO start
  MOVE LINEAR TO p WITH TRACKING
  MOVE LINEAR TO q
  MOVE RELATIVE VEC(0, 0, 20) IN BASE
  MOVE LINEAR TO start WITH TRACKING TRACKER
""", speed=50.0)
    xyz = path.poses[:, :3, 3] * 1e3
    np.testing.assert_allclose(xyz, [[1473.3, -231.7, 2488.4], [1473.3, -131.7, 2488.4],
                                     [1473.3, -131.7, 2458.4], [1473.3, -131.7, 2478.4],
                                     [1473.3, -231.7, 2488.4]], atol=1e-6)
    assert path.tracking.tolist() == [True, False, False, True]
    assert path.lines.tolist() == [9, 10, 11, 12, 13]  # the program's lines
    np.testing.assert_allclose(path.speeds, 0.05)
    assert path.oriented and trackers == {"TRACKER"}


def test_without_a_joint_move_the_path_starts_at_home(tmp_path, robot):
    path, _ = _path(tmp_path, robot, "  MOVE LINEAR TO q WITH TRACKING\n")
    from plugcell.kinematics import forward

    home = forward(robot, None, np.asarray(robot.home, float), "nominal").tcp
    np.testing.assert_allclose(path.poses[0], home, atol=1e-12)
    assert path.tracking.tolist() == [True]


@pytest.mark.parametrize(("body", "message"), [
    ("  MOVE LINEAR TO p\n  MOVE TO q\n",
     "tracked.pdl:10:3: MOVE TO q failed: a joint move after the path's first MOVE LINEAR"),
    ("  MOVE TO start\n", "no MOVE LINEAR: a path needs at least one straight move"),
    ("  MOVE LINEAR TO p\n  MOVE LINEAR TO p WITH TRACKING\n",
     "tracked.pdl:10:3: MOVE LINEAR TO p WITH TRACKING TRACKER failed: the same pose as the "
     "move before"),
    ("  WRITE pc_client ('ACTIVATE TRACKER #Move#')\n",
     "a path run has no services to talk to"),
    ("  p.X := p.X + 5000\n  MOVE LINEAR TO p\n",
     "tracked.pdl:10:3: MOVE LINEAR TO p failed: the pose is out of the robot's reach"),
    ("  MOVE JOINT TO p WITH TRACKING\n", "tracked.pdl:9:3: MOVE JOINT TO … WITH TRACKING: only"),
])
def test_what_a_path_cannot_hold_is_refused_at_its_line(tmp_path, robot, body, message):
    with pytest.raises(ValueError) as info:
        _path(tmp_path, robot, body)
    assert message in str(info.value)
