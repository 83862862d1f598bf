"""The robot's joint state for the 3-D view (devices/robot/joint_state.py): the link frames
it publishes are plugcell.kinematics.forward's, it survives the wire, garbage is refused,
and the publisher reads, skips and recovers as documented."""

from __future__ import annotations

import asyncio

import msgspec
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from plugcell.devices.robot.joint_state import (
    JointStatePublisher,
    decode_joint_state,
    encode_joint_state,
    joint_state,
)
from plugcell.framework.keys import KeySpace
from plugcell.io.robots import load_robot
from plugcell.kinematics import forward

ROBOTS = ("smart_h4", "fanuc_m20ia")


@pytest.mark.parametrize("name", ROBOTS)
def test_link_frames_are_forward_kinematics(name: str) -> None:
    desc = load_robot(name)
    rng = np.random.default_rng(7)
    lo, hi = desc.joint_limits[:, 0], desc.joint_limits[:, 1]
    for _ in range(5):
        q = desc.home + 0.3 * rng.uniform(lo - desc.home, hi - desc.home)
        state = decode_joint_state(encode_joint_state(joint_state(desc, q, seq=3)))
        fk = forward(desc, None, q)
        frames = np.asarray(state.frames).reshape(-1, 4, 4)
        np.testing.assert_allclose(frames, fk.frames, atol=1e-12)
        assert [lk.name for lk in state.links] == list(desc.link_names)
        assert [lk.parent for lk in state.links] == [lk.parent for lk in desc.links]
        assert [lk.joint for lk in state.links] == [lk.joint for lk in desc.links]
        np.testing.assert_allclose(state.q, q)
        flange = frames[list(desc.link_names).index(state.flange)]
        np.testing.assert_allclose(flange, fk.flange, atol=1e-12)
        np.testing.assert_allclose(np.reshape(state.base, (4, 4)),
                                   desc.nominal_parameters().base)
        assert state.robot == desc.name and state.seq == 3


def test_the_dh_path_of_each_link_ends_at_its_frame() -> None:
    """O_parent + d·z_parent + a·x_link = O_link: what the view draws is the DH row."""
    desc = load_robot("smart_h4")
    state = joint_state(desc, desc.home)
    frames = {lk.name: np.reshape(f, (4, 4)) for lk, f in zip(state.links, state.frames,
                                                              strict=True)}
    frames["base"] = np.eye(4)
    for lk, row in zip(state.links, desc.links, strict=True):
        parent, own = frames[lk.parent], frames[lk.name]
        corner = parent[:3, 3] + lk.d * parent[:3, 2]
        np.testing.assert_allclose(corner + row.a * own[:3, 0], own[:3, 3], atol=1e-12)


def test_a_loop_that_cannot_close_gives_no_frames() -> None:
    desc = load_robot("smart_h4")
    q = np.zeros(desc.n_readings)  # arm and crank aligned: the parallelogram collapses
    state = joint_state(desc, q)
    assert state.frames == []


@pytest.mark.parametrize("q", [[0.0] * 5, [0.0] * 5 + [float("nan")]])
def test_bad_readings_are_refused_by_name(q: list[float]) -> None:
    with pytest.raises(ValueError, match="smart_h4: expected 6 finite joint readings"):
        joint_state(load_robot("smart_h4"), np.asarray(q))


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=400))
def test_any_payload_decodes_or_is_refused(payload: bytes) -> None:
    try:
        decode_joint_state(payload)
    except msgspec.DecodeError as exc:
        assert isinstance(exc, ValueError)


def test_the_key_of_a_robot_and_back() -> None:
    keys = KeySpace("c1")
    assert keys.joints("R1") == "plugcell/c1/joints/R1"
    assert keys.parse_joints("plugcell/c1/joints/R1") == "R1"
    assert keys.parse_joints("plugcell/c2/joints/R1") is None
    assert keys.parse_joints("plugcell/c1/svc/R1/state") is None


def test_the_publisher_reads_publishes_skips_and_recovers() -> None:
    desc = load_robot("smart_h4")
    sent: list[bytes] = []
    answers: list[object] = [desc.home, None, RuntimeError("link down"), desc.home + 0.1]

    async def read() -> np.ndarray | None:
        answer = answers.pop(0)
        if isinstance(answer, Exception):
            raise answer
        return answer  # type: ignore[return-value]

    async def run() -> list[bool]:
        pub = JointStatePublisher(read, lambda: desc, sent.append, rate_hz=50)
        return [await pub.once() for _ in range(4)]

    assert asyncio.run(run()) == [True, False, False, True]
    states = [decode_joint_state(p) for p in sent]
    assert [s.seq for s in states] == [1, 2]
    np.testing.assert_allclose(states[1].q, desc.home + 0.1)


def test_the_publisher_runs_at_its_rate_and_stops() -> None:
    desc = load_robot("smart_h4")
    sent: list[bytes] = []

    async def read() -> np.ndarray:
        return desc.home

    async def run() -> None:
        pub = JointStatePublisher(read, lambda: desc, sent.append, rate_hz=100)
        pub.start()
        while len(sent) < 5:
            await asyncio.sleep(0.01)
        await pub.close()

    asyncio.run(run())
    n = len(sent)
    assert n >= 5
    with pytest.raises(ValueError, match="rate must be positive"):
        JointStatePublisher(read, lambda: desc, sent.append, rate_hz=0)
