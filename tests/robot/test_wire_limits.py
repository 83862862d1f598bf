"""The joint correction on the wire moves at bounded rates in the robot's time, whatever
cycles the service's loop skipped (issue 38 §2: the robot never jumps).

The link's child (:class:`~plugcell.devices.robot.stream.adjusting.ChildAdjust`) is fed,
through the same seqlocked blocks the service's :class:`AdjustPump` writes, the newest
adjustment at random gaps of robot cycles (a loaded machine: the loop computed a cycle
``n`` after its last); what it sends each robot cycle keeps its step within ``v T`` and
its change of step within ``a T²``, and comes to a held target without passing it.
"""

from __future__ import annotations

import math
import multiprocessing

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from plugcell.compensation.tracking import RateLimiter, TrackingSettings
from plugcell.devices.robot.stream.adjusting import (
    CYCLE_SLOTS,
    OFFSET_SLOTS,
    ChildAdjust,
    SeqVector,
    WireLimits,
)
from plugcell.devices.robot.stream.source import CycleState
from plugcell.devices.robot.tracked_moves import wire_limits
from plugcell.io.robots import load_robot
from plugcell.kinematics import forward
from plugcell.kinematics.jacobian import jacobian_from_fk

T = 0.004
#: per joint: rad/s and rad/s² (the loop's 10 mm/s, 0.5 m/s² through a ~1 m arm)
V = np.array([0.01, 0.012, 0.015, 0.02, 0.03, 0.05])
A = np.array([0.5, 0.6, 0.8, 1.0, 1.5, 2.0])
MOTION = 3


class _Robot:
    joints = np.zeros(6)


def _blocks():
    return (SeqVector(multiprocessing.RawArray("d", CYCLE_SLOTS)),
            SeqVector(multiprocessing.RawArray("d", OFFSET_SLOTS)))


def _on_the_wire(updates: list[tuple[int, np.ndarray]], limits: WireLimits | None,
                 hold: int = 0) -> np.ndarray:
    """What the child sends each robot cycle (rows) when the service's adjustment ``dq``
    arrives ``gap`` robot cycles after the last (``updates``: ``(gap, dq)``), then ``hold``
    more cycles; the blocks written as :class:`AdjustPump` writes them.  The peaks the
    child publishes in the cycle block are what was sent."""
    cycle, offset = _blocks()
    tail = np.zeros(13) if limits is None else limits.slots()
    offset.write(np.r_[MOTION, -1, np.zeros(6), tail])  # the pump's first write
    child = ChildAdjust(cycle, offset, MOTION)
    sent, k = [], 0
    for gap, dq in [*updates, (hold, None)]:
        for _ in range(gap):
            state = CycleState(robot=_Robot(), offset=np.zeros(6), session=1, cycle=k,
                               t=k * T)
            sent.append(child(state, k, np.zeros(6)))
            k += 1
        if dq is not None:
            offset.write(np.r_[MOTION, k - 1, dq, tail])
    sent = np.array(sent)
    step, change = _rates(sent)
    published = cycle.read()
    np.testing.assert_array_equal(published[10:16], step)
    np.testing.assert_array_equal(published[16:22], change)
    return sent


def _rates(sent: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per joint: the largest step a robot cycle and change of step (rad)."""
    wire = np.vstack([np.zeros((2, 6)), sent])  # at rest at zero before the motion
    step = np.diff(wire, axis=0)
    return np.abs(step).max(axis=0), np.abs(np.diff(step, axis=0)).max(axis=0)


_dq = st.lists(st.floats(-5e-3, 5e-3, allow_nan=False), min_size=6, max_size=6)


@settings(max_examples=40, deadline=None)
@given(updates=st.lists(st.tuples(st.integers(1, 25), _dq), min_size=1, max_size=60))
def test_the_wire_keeps_its_rates_in_robot_time_whatever_the_gaps(updates):
    """Any targets at any gaps: step ≤ v T and change of step ≤ a T² every robot cycle."""
    limits = WireLimits(T, V, A)
    sent = _on_the_wire([(g, np.array(d)) for g, d in updates], limits, hold=300)
    step, change = _rates(sent)
    assert np.all(step <= V * T * (1 + 1e-9)), step / (V * T)
    assert np.all(change <= A * T * T * (1 + 1e-9)), change / (A * T * T)
    np.testing.assert_allclose(sent[-1], updates[-1][1], atol=1e-12)  # the held target


@settings(max_examples=40, deadline=None)
@given(gaps=st.lists(st.integers(1, 20), min_size=5, max_size=120),
       goal=st.lists(st.floats(-4e-3, 4e-3).filter(lambda x: abs(x) > 1e-6),
                     min_size=6, max_size=6))
def test_a_loop_that_skips_cycles_reaches_the_robot_at_its_own_rates(gaps, goal):
    """The service's loop (its limiter at the same bounds, ``n`` robot cycles a computed
    update) moves towards a constant goal with random skips: on the wire the rates hold
    every robot cycle, the goal is reached and never passed by more than the limiters'
    ``a T²/8`` each.  Without the wire's limits the same updates break them (the bug)."""
    goal = np.array(goal)
    loop = RateLimiter(T, V, A, np.full(6, 1.0))
    updates = [(n, loop.apply(goal, n)) for n in [*gaps, *[1] * 150]]
    assert np.array_equal(updates[-1][1], goal)  # the loop got there
    sent = _on_the_wire(updates, WireLimits(T, V, A), hold=200)
    step, change = _rates(sent)
    assert np.all(step <= V * T * (1 + 1e-9)), step / (V * T)
    assert np.all(change <= A * T * T * (1 + 1e-9)), change / (A * T * T)
    # the loop may pass its goal by a T²/8 (its limiter's rounding), the wire may pass
    # the loop's output by as much again (the limiter's module docstring)
    loop_past = max(0.0, float(np.max((np.array([u[1] for u in updates]) - goal)
                                      * np.sign(goal) / (A * T * T))))
    assert loop_past <= 1 / 8 * (1 + 1e-9)
    past = (sent - goal) * np.sign(goal)
    assert np.all(past <= A * T * T / 4 * (1 + 1e-9) + 1e-18), past.max(axis=0) / (A * T * T)
    np.testing.assert_allclose(sent[-1], goal, atol=1e-12)


def test_without_the_wire_limits_a_skipped_cycle_jumps():
    """The hold of the old wire: a loop update 10 cycles after its last arrives in one."""
    loop = RateLimiter(T, V, A, np.full(6, 1.0))
    goal = np.full(6, 0.1)
    updates = [(1, loop.apply(goal, 1)) for _ in range(20)] + [(10, loop.apply(goal, 10))]
    held, _ = _rates(_on_the_wire(updates, None, hold=5))
    limited, _ = _rates(_on_the_wire(updates, WireLimits(T, V, A), hold=5))
    assert np.all(held > 5 * V * T), held / (V * T)
    assert np.all(limited <= V * T * (1 + 1e-9)), limited / (V * T)


def test_another_motions_adjustment_is_not_sent():
    cycle, offset = _blocks()
    offset.write(np.r_[MOTION - 1, 5, np.full(6, 1e-3), WireLimits(T, V, A).slots()])
    child = ChildAdjust(cycle, offset, MOTION)
    state = CycleState(robot=_Robot(), offset=np.zeros(6), session=1, cycle=0, t=0.0)
    np.testing.assert_array_equal(child(state, 0, np.zeros(6)), np.zeros(6))


def test_wire_limits_round_trip_and_refuse_bad_values():
    limits = WireLimits(T, V, A)
    back = WireLimits.from_slots(limits.slots())
    assert back is not None and back.cycle_s == T
    np.testing.assert_array_equal(back.max_speed, V)
    np.testing.assert_array_equal(back.max_accel, A)
    assert WireLimits.from_slots(np.zeros(13)) is None
    for bad in ((T, -V, A), (T, V, np.r_[A[:5], math.nan]), (0.0, V, A), (T, V[:5], A[:5])):
        with pytest.raises(ValueError, match=r"max_speed > 0|cycle_s must be"):
            WireLimits(*bad)


def test_the_wire_limits_pass_what_the_loop_computes_each_cycle():
    """``wire_limits`` maps the loop's bounds on the offset's rate through ``J⁻¹``: an
    offset moving at the loop's bounds, in any direction, becomes joint rates within
    them (so the child does not cut what the loop computes every cycle)."""
    desc = load_robot("smart_h4")
    q = np.radians([0.0, -20.0, -100.0, 0.0, 30.0, 0.0]) + np.linspace(0, 0.3, 50)[:, None]
    J = jacobian_from_fk(desc, forward(desc, None, q, "nominal"), "tcp")
    s = TrackingSettings(cycle_s=T, lead_s=0.01)
    limits = wire_limits(s, J)
    v_o = np.r_[[s.max_speed_m_s + s.max_lead_speed_m_s] * 3, [s.max_speed_rad_s] * 3]
    rng = np.random.default_rng(0)
    for k in range(len(q)):
        corners = rng.choice([-1.0, 1.0], size=(200, 6)) * v_o  # the bounds' corners
        qdot = np.linalg.solve(J[k], corners.T).T
        assert np.all(np.abs(qdot) <= limits.max_speed * (1 + 1e-9))
    # the tracker term alone (no lead): the lead's bounds are not added
    assert np.all(wire_limits(TrackingSettings(cycle_s=T), J).max_speed < limits.max_speed)
