"""Joint (PTP) moves: synchronised axes, limits, blends, continuity and their errors (#37)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from plugcell.kinematics import RobotDescription
from plugcell.motion import PTP, JointLimits, JointRangeError, MoveError, plan


def _fd_limits(traj, jl: JointLimits, dt: float = 2e-3) -> None:
    """Max |v|, |a|, |j| of the sampled positions' difference quotients within the limits."""
    t = np.arange(-3, int(traj.duration / dt) + 4) * dt
    q = traj.sample(t, 0).q
    for k, lim in ((1, jl.velocity), (2, jl.acceleration), (3, jl.jerk)):
        fd = np.diff(q, k, axis=0) / dt**k
        assert np.all(np.max(np.abs(fd), axis=0) <= lim * (1 + 1e-6) + 1e-6 / dt**k)


def test_axes_start_and_end_together_and_the_leader_is_at_its_limit(
        elbow: RobotDescription, jl: JointLimits) -> None:
    q0 = np.asarray(elbow.home, float)
    q1 = q0 + np.radians([40.0, -20.0, 5.0, 90.0, -30.0, 0.0])
    tr = plan(elbow, q0, [PTP(target=q1)], jl)
    T = tr.duration
    s = tr.sample(np.linspace(0.0, T, 4001))
    assert np.array_equal(s.q[0], q0) and np.allclose(s.q[-1], q1, atol=1e-15)
    assert np.all(s.qd[-1] == 0.0) and np.all(s.qd[0] == 0.0)
    # synchronised: every joint's progress (q − q0)/(q1 − q0) is the same at every time
    moving = q1 != q0
    prog = (s.q[:, moving] - q0[moving]) / (q1 - q0)[moving]
    assert np.allclose(prog, prog[:, :1], atol=1e-12)
    assert np.all(s.q[:, ~moving] == q0[~moving])
    # still moving just before the end: all joints arrive at T, not earlier
    just = tr.sample(T - 1e-3)
    assert np.all(np.abs(just.qd[moving]) > 0.0)
    # the leading joint reaches one of its limits (the fastest synchronised move)
    ratio = max(np.max(np.abs(s.qd) / jl.velocity), np.max(np.abs(s.qdd) / jl.acceleration))
    assert ratio == pytest.approx(1.0, rel=1e-3)
    _fd_limits(tr, jl)


def test_analytic_rates_match_central_differences(elbow: RobotDescription,
                                                  jl: JointLimits) -> None:
    q0 = np.asarray(elbow.home, float)
    moves = [PTP(target=q0 + 0.3, blend=0.2), PTP(target=q0 + np.array([0.5, 0, 0.3, -0.2, 0.1,
                                                                        0.4]))]
    tr = plan(elbow, q0, moves, jl)
    sec = tr.sections[0]
    h = 1e-6
    t = np.linspace(0.01, tr.duration - 0.01, 301)
    _q, qd, qdd, _ = sec.path.sample(t)
    qp, qdp, _qddp, _ = sec.path.sample(t + h)
    qm, qdm, _qddm, _ = sec.path.sample(t - h)
    assert np.allclose((qp - qm) / (2 * h), qd, atol=1e-8)
    # the jerk is piecewise constant: a difference straddling a switch errs by ≤ h·Δjerk
    assert np.allclose((qdp - qdm) / (2 * h), qdd, atol=2 * h * jl.jerk.max())
    assert np.median(np.abs((qdp - qdm) / (2 * h) - qdd)) < 1e-8


def test_a_blend_passes_near_the_point_without_stopping(elbow: RobotDescription,
                                                        jl: JointLimits) -> None:
    q0 = np.asarray(elbow.home, float)
    via = q0 + np.radians([80.0, 30.0, -30.0, 60.0, 0.0, 10.0])
    end = via + np.radians([60.0, 20.0, -40.0, 90.0, 20.0, 0.0])
    r = np.radians(20.0)
    exact = plan(elbow, q0, [PTP(target=via), PTP(target=end)], jl)
    blended = plan(elbow, q0, [PTP(target=via, blend=r, line=4), PTP(target=end)], jl)
    assert blended.blends[0] > 0.05 and exact.blends == {}
    # the blended phases run at half the acceleration and jerk: a radius about the
    # braking distance is needed to gain time, beside avoiding the stop
    wide = plan(elbow, q0, [PTP(target=via, blend=1.0), PTP(target=end)], jl)
    assert wide.duration < exact.duration - 0.05
    t = np.linspace(0.0, blended.duration, 20001)
    s = blended.sample(t)
    speed = np.linalg.norm(s.qd, axis=1)
    near = np.linalg.norm(s.q - via, axis=1)
    i = int(np.argmin(near))
    assert near[i] > 1e-4  # the corner is cut…
    assert np.max(near[near < r * 1.5]) <= r * 1.5  # sanity of the window below
    inside = near < r
    assert np.all(near[inside] <= r) and speed[i] > 0.05  # …within r, still moving
    assert np.all(speed[(t > 0.05) & (t < blended.duration - 0.05)] > 1e-3)
    # C1: position and velocity continuous (central differences agree everywhere)
    dt = t[1] - t[0]
    assert np.allclose(np.gradient(s.q, dt, axis=0)[1:-1], s.qd[1:-1], atol=1e-5)
    assert np.max(np.abs(np.diff(s.qd, axis=0))) < 1e-2
    assert np.max(np.abs(np.diff(s.qdd, axis=0))) < jl.jerk.max() * dt * 2.001
    assert np.allclose(s.q[-1], end, atol=1e-15)
    _fd_limits(blended, jl)
    # which move runs: 0, then 1 from the start of the blend
    assert s.move[0] == 0 and s.move[-1] == 1 and s.fraction[-1] == 1.0


def test_a_blend_keeps_the_limits_when_one_joint_reverses(
        elbow: RobotDescription, jl: JointLimits) -> None:
    # joint 2 keeps its direction (at full limits its jerk phases would add up at the
    # ends of a short overlap) while joint 4 reverses (its accelerations add up in a
    # long one): only the plan with halved blend phases flies by
    q0 = np.asarray(elbow.home, float)
    via = q0 + np.radians([0.0, 30.0, 0.0, 40.0, 0.0, 0.0])
    end = via + np.radians([0.0, 30.0, 0.0, -40.0, 0.0, 0.0])
    tr = plan(elbow, q0, [PTP(target=via, blend=0.5), PTP(target=end)], jl)
    assert tr.blends[0] > 0.1
    tm = tr.sections[0].path.timing
    assert tm.t_a2[0] > tm.t_a[0]  # the blended deceleration is the softer one
    s = tr.sample(np.linspace(0, tr.duration, 4001))
    assert np.max(np.linalg.norm(s.q - via, axis=1)) > 0.25  # (moves far from the point)
    assert np.min(np.linalg.norm(s.q - via, axis=1)) < 0.25
    _fd_limits(tr, jl)


def test_sampling_shapes_cycles_and_outside_times(elbow: RobotDescription,
                                                  jl: JointLimits) -> None:
    q0 = np.asarray(elbow.home, float)
    tr = plan(elbow, q0, [PTP(target=q0 + 0.2)], jl)
    assert tr.sample(np.zeros((2, 3))).q.shape == (2, 3, 6)
    cyc = tr.cycle_times(0.004)
    assert cyc[0] == 0.0 and cyc[-1] >= tr.duration and cyc[-2] < tr.duration
    assert np.allclose(tr.at_cycle(len(cyc) - 1, 0.004).q[0], q0 + 0.2)
    assert np.array_equal(tr.sample(-1.0).q, q0) and np.allclose(tr.sample(99.0).q, q0 + 0.2)
    assert tr.tcp(0.0).shape == (4, 4)
    ts, qs = tr.setpoints(0.004)
    assert np.array_equal(ts, cyc) and np.array_equal(qs[7], tr.at_cycle(7, 0.004).q[0])
    empty = plan(elbow, q0, [], jl)
    assert empty.duration == 0.0 and np.array_equal(empty.sample([0.0, 1.0]).q, [q0, q0])
    with pytest.raises(ValueError, match="without moves"):
        empty.tcp(0.0)


def test_a_target_outside_the_limits_names_move_line_joint_value_limit(
        elbow: RobotDescription, jl: JointLimits) -> None:
    q0 = np.asarray(elbow.home, float)
    bad = q0.copy()
    bad[1] = np.radians(-178.0)  # joint 2: [-175°, -5°]
    with pytest.raises(JointRangeError) as info:
        plan(elbow, q0, [PTP(target=q0 + 0.1), PTP(target=bad, line=17)], jl)
    e = info.value
    assert (e.move, e.line, e.kind, e.joint) == (1, 17, "PTP", "2")
    assert e.value == pytest.approx(np.radians(-178.0)) and e.limit == pytest.approx(
        np.radians(-175.0))
    assert str(e).startswith("move 1 (PTP, line 17)") and "joint 2" in str(e)
    assert "-178.000°" in str(e) and "[-175°, -5°]" in str(e)


def test_bad_moves_and_arguments(elbow: RobotDescription, jl: JointLimits) -> None:
    q0 = np.asarray(elbow.home, float)
    with pytest.raises(MoveError, match="has 5 joint values, elbow6 has 6"):
        plan(elbow, q0, [PTP(target=q0[:5])], jl)
    with pytest.raises(ValueError, match="speed must be a fraction"):
        PTP(target=q0, speed=1.5)
    with pytest.raises(ValueError, match="blend must be"):
        PTP(target=q0, blend=-1.0)
    with pytest.raises(ValueError, match="joint_limits has 3 joints"):
        plan(elbow, q0, [], JointLimits.uniform(3, 1.0, 1.0, 1.0))
    with pytest.raises(JointRangeError, match="the start: joint 2"):
        plan(elbow, np.zeros(6), [], jl)
    with pytest.raises(ValueError, match="positive and finite"):
        JointLimits.uniform(6, 1.0, -1.0, 1.0)


def test_speed_override_slows_the_move(elbow: RobotDescription, jl: JointLimits) -> None:
    q0 = np.asarray(elbow.home, float)
    fast = plan(elbow, q0, [PTP(target=q0 + 0.5)], jl)
    slow = plan(elbow, q0, [PTP(target=q0 + 0.5, speed=0.25)], jl)
    assert slow.duration > fast.duration
    assert np.max(np.abs(slow.sample(np.linspace(0, slow.duration, 2001)).qd)
                  / jl.velocity) <= 0.25 * (1 + 1e-9)


@settings(max_examples=15, deadline=None)
@given(data=st.data())
def test_random_ptp_chains_keep_limits_and_stay_continuous(
        elbow: RobotDescription, data: st.DataObject) -> None:
    lo, hi = elbow.joint_limits[:, 0], elbow.joint_limits[:, 1]
    frac = st.lists(st.floats(0.05, 0.95), min_size=6, max_size=6)
    n_moves = data.draw(st.integers(1, 4))
    targets = [lo + np.array(data.draw(frac)) * (hi - lo) for _ in range(n_moves + 1)]
    blends = [data.draw(st.sampled_from([0.0, 0.05, 0.3, 2.0])) for _ in range(n_moves)]
    scale = data.draw(st.floats(0.2, 5.0))
    jl = JointLimits(np.radians([120, 115, 120, 190, 180, 260]) * scale,
                     np.radians([400, 350, 400, 600, 600, 800]) * scale,
                     np.radians([3000, 2500, 3000, 5000, 5000, 7000]) * scale)
    moves = [PTP(target=q, blend=b) for q, b in zip(targets[1:], blends, strict=True)]
    tr = plan(elbow, targets[0], moves, jl)
    s = tr.sample(np.array([0.0, tr.duration]))
    assert np.array_equal(s.q[0], targets[0]) and np.allclose(s.q[1], targets[-1], atol=1e-12)
    _fd_limits(tr, jl, dt=max(tr.duration / 3000, 1e-3))
    t = np.linspace(0, tr.duration, 5001)
    q = tr.sample(t, 1)
    # C1 everywhere: no jump of position or velocity between close samples
    assert np.max(np.abs(np.diff(q.q, axis=0))) <= jl.velocity.max() * (t[1] - t[0]) * 1.0001
    assert np.max(np.abs(np.diff(q.qd, axis=0))) <= jl.acceleration.max() * (t[1] - t[0]) * 1.0001
