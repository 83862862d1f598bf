"""Reflectors mounted on reflectors in the simulated world (``sim/world.py``, ``placed``).

An SMR in a dowel hole of a robot's flange moves with the robot.  It is published once,
in its mount's frame, and whoever looks at the world places it on the mount's pose of
the same look — so the simulated tracker measures it where the robot is at that
instant.  Before, a test helper re-published the holes from its own process each time
the robot's pose reached it; under load the tracker measured before that happened (the
live PROBE wizard 282 mm / 180° off, CI of 2026-11-28).
"""

from __future__ import annotations

import msgspec
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from metrology_testlib import run, unique_cell

from plugcell.framework.bus import Bus
from plugcell.framework.keys import KeySpace
from plugcell.kinematics import so3_exp
from plugcell.sim.drivers import tracker as sim_tracker
from plugcell.sim.world import MAX_MOUNT_DEPTH, ReflectorPublisher, ReflectorState, placed

pytestmark = pytest.mark.timeout(60)


def _pose(rotvec: np.ndarray, t: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = so3_exp(rotvec)
    T[:3, 3] = t
    return T


def _state(name: str, T: np.ndarray, mount: str = "", moving: bool = False,
           kind: str = "smr") -> ReflectorState:
    return ReflectorState(name, kind, T.ravel().tolist(), moving, 1, mount)


poses = st.builds(
    _pose,
    st.lists(st.floats(-3, 3), min_size=3, max_size=3).map(np.array),
    st.lists(st.floats(-5, 5), min_size=3, max_size=3).map(np.array),
)


@given(carrier=poses, rel=poses, moving=st.booleans())
def test_a_mounted_reflector_is_where_its_mount_puts_it(carrier, rel, moving):
    world = {"H4": _state("H4", carrier, moving=moving, kind="tmac"),
             "HOLE": _state("HOLE", rel, mount="H4")}
    out = placed(world)
    assert out["H4"] == world["H4"]  # a reflector fixed in the cell is as published
    np.testing.assert_allclose(out["HOLE"].matrix(), carrier @ rel, atol=1e-12)
    assert out["HOLE"].moving is moving and out["HOLE"].mount == ""
    assert out["HOLE"].kind == "smr" and out["HOLE"].name == "HOLE"


@given(chain=st.lists(poses, min_size=1, max_size=MAX_MOUNT_DEPTH + 2))
def test_a_chain_is_composed_up_to_its_depth_and_left_out_beyond(chain):
    world = {"R0": _state("R0", chain[0])}
    for i, T in enumerate(chain[1:], start=1):
        world[f"R{i}"] = _state(f"R{i}", T, mount=f"R{i - 1}")
    out = placed(world)
    expected = np.eye(4)
    for i, T in enumerate(chain):
        expected = expected @ T
        if i <= MAX_MOUNT_DEPTH:
            np.testing.assert_allclose(out[f"R{i}"].matrix(), expected, atol=1e-9)
        else:
            assert f"R{i}" not in out


def test_a_reflector_without_its_mount_or_in_a_cycle_is_nowhere():
    T = _pose(np.zeros(3), np.ones(3))
    world = {"GONE_HOLE": _state("GONE_HOLE", T, mount="GONE"),
             "A": _state("A", T, mount="B"), "B": _state("B", T, mount="A"),
             "FIXED": _state("FIXED", T)}
    assert set(placed(world)) == {"FIXED"}


def test_a_publisher_refuses_a_mount_on_itself_or_a_bad_name(world_session):
    bus = Bus(world_session, KeySpace(unique_cell()))
    with pytest.raises(ValueError, match="cannot be mounted on itself"):
        ReflectorPublisher(bus, "HOLE", "smr", mount="HOLE")
    with pytest.raises(ValueError, match="reflector mount"):
        ReflectorPublisher(bus, "HOLE", "smr", mount="no/slash")


def test_an_older_message_without_a_mount_reads_as_fixed_in_the_cell():
    class Before(msgspec.Struct, frozen=True):  # ReflectorState before the mount
        name: str
        kind: str
        pose: list[float]
        moving: bool = False
        seq: int = 0

    payload = msgspec.msgpack.encode(Before("SMR", "smr", np.eye(4).ravel().tolist()))
    assert msgspec.msgpack.decode(payload, type=ReflectorState).mount == ""


def test_the_tracker_measures_a_mounted_smr_where_its_robot_is_at_that_instant(world_session):
    """The robot moves (its T-MAC re-published); the SMR on it is never re-published,
    yet the very next measurement finds it on the new pose."""
    cell = unique_cell()
    flange = _pose(np.array([0.0, 0.0, 0.4]), np.array([2.0, 0.5, 0.3]))
    hole = _pose(np.zeros(3), np.array([0.05, 0.0, 0.1]))

    async def body() -> list[np.ndarray]:
        bus = Bus(world_session, KeySpace(cell))
        tmac = ReflectorPublisher(bus, "H4", "tmac")
        tmac.publish(flange)
        smr = ReflectorPublisher(bus, "H4_HOLE1", "smr", mount="H4")
        smr.publish(hole)
        try:
            driver = sim_tracker.SimulatedTrackerDriver(bus, seed=3)
            await driver.connect()
            seen = []
            for turn in (0.0, 0.3, 0.6):  # the robot turns its flange, then is measured
                moved = _pose(np.array([0.0, 0.0, 0.4 + turn]), flange[:3, 3])
                tmac.publish(moved)
                await driver.point((moved @ hole)[:3, 3])
                reading = await driver.measure(0.01)
                seen.append((reading.pose[:3, 3], (moved @ hole)[:3, 3]))
            return seen
        finally:
            smr.close()
            tmac.close()

    for measured, true in run(body()):
        assert np.linalg.norm(measured - true) < 1e-4  # the tracker's noise, not a step
