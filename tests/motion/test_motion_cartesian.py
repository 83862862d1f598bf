"""Cartesian moves (LIN, CIRC) through the robots' inverse kinematics: geometry, limits,
derivatives, blends, branch consistency and the checks' errors (#37)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from motion_testlib import moved, tcp

from plugcell.kinematics import RobotDescription, so3_log
from plugcell.motion import (
    CIRC,
    LIN,
    PTP,
    CartesianLimits,
    JointLimits,
    JointRangeError,
    JointSpeedError,
    MoveError,
    SingularityError,
    UnreachablePoseError,
    plan,
)

#: A working configuration of each robot (degrees), wrist well away from q5 = 0.
START = {"elbow6": [10.0, -80.0, 20.0, 30.0, 60.0, -20.0],
         "smart_h4": [10.0, -80.0, -190.0, 30.0, 60.0, -20.0]}


@pytest.fixture(params=["elbow6", "smart_h4"])
def robot(request: pytest.FixtureRequest, elbow: RobotDescription,
          h4: RobotDescription) -> RobotDescription:
    return elbow if request.param == "elbow6" else h4


def _start(desc: RobotDescription) -> np.ndarray:
    q = np.radians(START[desc.name])
    assert desc.within_limits(q)
    return q


def _line_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    u = (b - a) / np.linalg.norm(b - a)
    d = p - a
    return np.linalg.norm(d - (d @ u)[:, None] * u, axis=1)


def test_lin_tcp_stays_on_the_line_and_slerps(robot: RobotDescription, jl: JointLimits,
                                              cl: CartesianLimits) -> None:
    q0 = _start(robot)
    Ta = tcp(robot, q0)
    Tb = moved(Ta, [0.25, -0.2, -0.15], axis=[0.3, 0.2, 1.0], angle=0.5)
    tr = plan(robot, q0, [LIN(target=Tb, line=5)], jl, cl)
    t = np.linspace(0.0, tr.duration, 301)
    s = tr.sample(t)
    T = tcp(robot, s.q)  # where the joints put the TCP
    assert np.max(_line_distance(T[:, :3, 3], Ta[:3, 3], Tb[:3, 3])) <= 1e-9
    along = (T[:, :3, 3] - Ta[:3, 3]) @ (Tb[:3, 3] - Ta[:3, 3])
    assert np.all(np.diff(along) >= -1e-12)  # monotone, no overshoot
    # exact start and end
    assert np.array_equal(s.q[0], q0)
    assert np.max(np.abs(T[-1] - Tb)) <= 1e-9
    # orientation: the slerp R(σ) = exp(σ·log(R_b R_aᵀ))·R_a, with σ the position's
    # path fraction
    sigma = along / np.sum((Tb[:3, 3] - Ta[:3, 3]) ** 2)
    w = so3_log(Tb[:3, :3] @ Ta[:3, :3].T)
    from plugcell.kinematics import so3_exp
    R_slerp = so3_exp(sigma[:, None] * w) @ Ta[:3, :3]
    assert np.max(np.linalg.norm(so3_log(np.swapaxes(R_slerp, 1, 2) @ T[:, :3, :3]),
                                 axis=1)) <= 1e-9
    # the moves and fractions reported
    assert np.all(s.move == 0) and s.fraction[0] == 0.0 and s.fraction[-1] == 1.0


def test_circ_keeps_its_radius_and_passes_the_via_point(robot: RobotDescription,
                                                        jl: JointLimits,
                                                        cl: CartesianLimits) -> None:
    q0 = _start(robot)
    Ta = tcp(robot, q0)
    via = Ta[:3, 3] + [0.15, 0.15, 0.05]
    Tb = moved(Ta, [0.3, 0.0, 0.1], axis=[0, 0, 1], angle=0.3)
    tr = plan(robot, q0, [CIRC(via=via, target=Tb)], jl, cl)
    seg = tr.sections[0].path.segments[0]
    t = np.linspace(0.0, tr.duration, 401)
    T = tcp(robot, tr.sample(t, 0).q)
    p = T[:, :3, 3]
    rho = np.linalg.norm(p - seg.centre, axis=1)
    assert np.max(np.abs(rho - seg.radius)) <= 1e-9
    n = np.cross(seg.u, seg.w)
    assert np.max(np.abs((p - seg.centre) @ n)) <= 1e-9  # in the circle's plane
    assert np.linalg.norm(seg.centre + seg.radius * seg.u - Ta[:3, 3]) < 1e-12
    # the arc goes through the via point: its angle lies inside the sweep
    e = via - seg.centre
    ang = np.arctan2(e @ seg.w, e @ seg.u) % (2 * np.pi)
    assert 0.0 < ang < seg.sweep
    assert abs(np.linalg.norm(e) - seg.radius) < 1e-12
    assert np.max(np.abs(T[-1] - Tb)) <= 1e-9


def _cart_fd_limits(path, cl: CartesianLimits, dt: float = 2e-3) -> None:
    """Max TCP speed, acceleration, jerk, angular speed and acceleration from the
    difference quotients of the sampled poses, within the limits."""
    t = np.arange(-3, int(path.duration / dt) + 4) * dt
    T = path.sample(t).T
    p = T[:, :3, 3]
    for k, lim in ((1, cl.velocity), (2, cl.acceleration), (3, cl.jerk)):
        fd = np.diff(p, k, axis=0) / dt**k
        assert np.max(np.linalg.norm(fd, axis=1)) <= lim * (1 + 1e-6) + 1e-9 / dt**k
    # angular velocity from consecutive rotations: ω ≈ log(R_{i+1} R_iᵀ)/Δt
    w = so3_log(T[1:, :3, :3] @ np.swapaxes(T[:-1, :3, :3], 1, 2)) / dt
    assert np.max(np.linalg.norm(w, axis=1)) <= cl.angular_velocity * (1 + 1e-6)
    alpha = np.diff(w, axis=0) / dt
    assert np.max(np.linalg.norm(alpha, axis=1)) <= cl.angular_acceleration * (1 + 1e-4)


def _analytic_vs_fd(path) -> None:
    h = 1e-6
    t = np.linspace(0.0, path.duration, 503)[1:-1]
    m, pl, mi = path.sample(t), path.sample(t + h), path.sample(t - h)
    jmax = 100.0
    assert np.allclose((pl.T[:, :3, 3] - mi.T[:, :3, 3]) / (2 * h), m.v, atol=1e-8)
    assert np.allclose((pl.v - mi.v) / (2 * h), m.a, atol=2 * h * jmax)
    assert np.median(np.abs((pl.v - mi.v) / (2 * h) - m.a)) < 1e-7
    fd_j = (pl.a - mi.a) / (2 * h)
    assert np.median(np.abs(fd_j - m.jerk)) < 1e-5
    w = so3_log(pl.T[:, :3, :3] @ np.swapaxes(mi.T[:, :3, :3], 1, 2)) / (2 * h)
    assert np.allclose(w, m.omega, atol=1e-8)
    assert np.allclose((pl.omega - mi.omega) / (2 * h), m.alpha, atol=2 * h * jmax)
    assert np.median(np.abs((pl.omega - mi.omega) / (2 * h) - m.alpha)) < 1e-7


def _chain(desc: RobotDescription, blend: float) -> tuple[np.ndarray, list]:
    q0 = _start(desc)
    Ta = tcp(desc, q0)
    T1 = moved(Ta, [0.3, 0.0, 0.0], axis=[0, 0, 1], angle=0.3)
    T2 = moved(T1, [0.0, 0.3, -0.1], axis=[1, 0, 0], angle=0.2)
    via = T2[:3, 3] + [-0.1, 0.1, 0.05]
    T3 = moved(T2, [-0.3, 0.15, 0.0])
    return q0, [LIN(target=T1, blend=blend, line=10), LIN(target=T2, blend=blend, line=11),
                CIRC(via=via, target=T3, line=12)]


@pytest.mark.slow
def test_cartesian_limits_and_analytic_derivatives(elbow: RobotDescription, jl: JointLimits,
                                                   cl: CartesianLimits) -> None:
    for blend in (0.0, 0.08):
        q0, moves = _chain(elbow, blend)
        tr = plan(elbow, q0, moves, jl, cl)
        path = tr.sections[0].path
        _cart_fd_limits(path, cl)
        _analytic_vs_fd(path)


def test_a_cartesian_blend_cuts_the_corner_within_the_radius(
        elbow: RobotDescription, jl: JointLimits, cl: CartesianLimits) -> None:
    r = 0.08
    q0, moves = _chain(elbow, r)
    tr = plan(elbow, q0, moves, jl, cl)
    assert tr.blends[0] > 0.0 and tr.blends[1] > 0.0
    path = tr.sections[0].path
    t = np.linspace(0.0, tr.duration, 8001)
    st_ = path.sample(t)
    p = st_.T[:, :3, 3]
    for corner in (moves[0].target[:3, 3], moves[1].target[:3, 3]):
        dist = np.linalg.norm(p - corner, axis=1)
        i = int(np.argmin(dist))
        assert 1e-4 < dist[i] <= r  # not through the point, but within the radius
        near = dist < r
        assert np.linalg.norm(st_.v[near], axis=1).min() > 0.05  # never stops there
    # C1: the velocity has no jump
    assert np.max(np.linalg.norm(np.diff(st_.v, axis=0), axis=1)) <= cl.acceleration * (
        t[1] - t[0]) * 1.0001
    # the joints follow the blended path exactly, continuous
    s = tr.sample(t[::20])
    assert np.max(np.linalg.norm(tcp(elbow, s.q)[:, :3, 3] - p[::20], axis=1)) <= 1e-9


def test_joint_rates_match_central_differences(robot: RobotDescription, jl: JointLimits,
                                               cl: CartesianLimits) -> None:
    q0, moves = _chain(robot, 0.05)
    tr = plan(robot, q0, moves[:2], jl, cl)
    h = 1e-5
    t = np.linspace(0.02, tr.duration - 0.02, 41)
    s, sp, sm = tr.sample(t), tr.sample(t + h, 1), tr.sample(t - h, 1)
    assert np.allclose((sp.q - sm.q) / (2 * h), s.qd, atol=1e-6)
    assert np.allclose((sp.qd - sm.qd) / (2 * h), s.qdd, atol=2e-3)
    assert np.median(np.abs((sp.qd - sm.qd) / (2 * h) - s.qdd)) < 1e-5


def test_sampling_order_does_not_change_the_branch(elbow: RobotDescription, jl: JointLimits,
                                                   cl: CartesianLimits) -> None:
    q0, moves = _chain(elbow, 0.05)
    tr = plan(elbow, q0, moves, jl, cl)
    t = np.linspace(0.0, tr.duration, 157)
    rng = np.random.default_rng(7)
    order = rng.permutation(t.size)
    in_order = tr.sample(t, 0).q
    shuffled = np.empty_like(in_order)
    for i in order:  # one at a time, in random order (as a late reader would)
        shuffled[i] = tr.at_cycle(i, t[1] - t[0]).q[0]
    assert np.max(np.abs(shuffled - in_order)) <= 1e-9
    # …and every sample stays near the planner's table (one branch, no flips)
    assert np.max(np.abs(np.diff(in_order, axis=0))) < 0.2


def test_mixed_sections_follow_each_other(elbow: RobotDescription, jl: JointLimits,
                                          cl: CartesianLimits) -> None:
    q0 = _start(elbow)
    q1 = q0 + np.radians([10.0, 5.0, -5.0, 10.0, 5.0, 10.0])
    T1 = tcp(elbow, q1)
    moves = [PTP(target=q1), LIN(target=moved(T1, [0.0, 0.2, 0.0])), PTP(target=q0)]
    tr = plan(elbow, q0, moves, jl, cl)
    assert len(tr.sections) == 3
    s = tr.sample(tr.starts[1:] + np.array([[-1e-9], [1e-9]]))
    assert np.allclose(s.q[0], s.q[1], atol=1e-7)  # continuous across the sections
    assert np.allclose(tr.sample(tr.duration).q, q0)


# ----------------------------------------------------------------------------- errors
def test_unreachable_target_names_the_move(robot: RobotDescription, jl: JointLimits,
                                           cl: CartesianLimits) -> None:
    q0 = _start(robot)
    Ta = tcp(robot, q0)
    far = moved(Ta, [4.0, 0.0, 0.0])
    with pytest.raises(UnreachablePoseError) as info:
        plan(robot, q0, [LIN(target=moved(Ta, [0.05, 0, 0])), LIN(target=far, line=33)], jl, cl)
    e = info.value
    assert (e.move, e.line, e.kind, e.fraction) == (1, 33, "LIN", 1.0)
    assert str(e).startswith("move 1 (LIN, line 33)") and "out of reach" in str(e)


def _through_the_wrist_singularity(desc: RobotDescription) -> tuple[np.ndarray, np.ndarray]:
    """A start and a LIN target whose line passes through a pose with q5 = 0."""
    from plugcell.kinematics import inverse

    q_mid = _start(desc)
    q_mid[4] = 0.0  # axes 4 and 6 aligned: the wrist singularity
    T_mid = tcp(desc, q_mid)
    d = T_mid[:3, :3] @ np.array([0.1, 0.0, 0.0])  # along the tool's x
    Ta, Tb = moved(T_mid, list(-d)), moved(T_mid, list(d))
    seed = q_mid.copy()
    seed[4] = np.radians(5.0)
    qa = inverse(desc, None, Ta, seed=seed, target="tcp", closure="nominal").q
    return qa, Tb


def test_a_line_through_the_wrist_singularity_is_refused(robot: RobotDescription,
                                                         jl: JointLimits,
                                                         cl: CartesianLimits) -> None:
    qa, Tb = _through_the_wrist_singularity(robot)
    with pytest.raises(SingularityError) as info:  # (slowly: else a joint speed trips first)
        plan(robot, qa, [LIN(target=Tb, line=8, speed=0.1)], jl, cl)
    e = info.value
    assert (e.move, e.line, e.kind) == (0, 8, "LIN")
    assert 0.0 < e.fraction < 0.6 and e.time is not None and e.time > 0.0
    assert e.limit == 0.005 and e.value < e.limit
    assert "near a singularity" in str(e) or "jumps" in str(e)


def test_joint_speed_limit_on_a_cartesian_move(robot: RobotDescription,
                                               cl: CartesianLimits) -> None:
    q0 = _start(robot)
    slow = JointLimits.uniform(6, 0.3, 3.0, 30.0)
    Tb = moved(tcp(robot, q0), [0.3, 0.0, 0.0])
    with pytest.raises(JointSpeedError) as info:
        plan(robot, q0, [LIN(target=Tb, line=3)], slow, cl)
    e = info.value
    assert e.move == 0 and e.joint in robot.reading_names
    assert e.value > e.limit == 0.3 and 0.0 < e.fraction < 1.0
    assert f"joint {e.joint} speed" in str(e) and "exceeds its limit" in str(e)
    # slower Cartesian speed: the same move passes
    plan(robot, q0, [LIN(target=Tb, speed=0.2)], slow, cl)


def test_the_path_leaves_a_joint_range(elbow: RobotDescription, jl: JointLimits,
                                       cl: CartesianLimits) -> None:
    q0 = _start(elbow)
    q0[5] = np.radians(340.0)  # joint 6: [-350°, 350°]
    Ta = tcp(elbow, q0)
    Tb = moved(Ta, [0.0, 0.0, 0.0], axis=list(Ta[:3, 2]), angle=np.radians(30.0))
    with pytest.raises(JointRangeError) as info:
        plan(elbow, q0, [LIN(target=Tb, line=21)], jl, cl)
    e = info.value
    assert (e.move, e.line, e.joint) == (0, 21, "6")
    assert e.limit == pytest.approx(np.radians(350.0))
    assert e.fraction == pytest.approx(1 / 3, abs=0.05)


def test_bad_cartesian_moves(elbow: RobotDescription, jl: JointLimits,
                             cl: CartesianLimits) -> None:
    q0 = _start(elbow)
    Ta = tcp(elbow, q0)
    with pytest.raises(MoveError, match="collinear"):
        plan(elbow, q0, [CIRC(via=Ta[:3, 3] + [0.1, 0, 0],
                              target=moved(Ta, [0.2, 0, 0]))], jl, cl)
    with pytest.raises(MoveError, match="coincide"):
        plan(elbow, q0, [CIRC(via=Ta[:3, 3], target=moved(Ta, [0.2, 0, 0]))], jl, cl)
    with pytest.raises(MoveError, match="needs Cartesian limits"):
        plan(elbow, q0, [LIN(target=Ta)], jl)
    with pytest.raises(MoveError, match="blending a PTP into a LIN") as info:
        plan(elbow, q0, [PTP(target=q0 + 0.1, blend=0.1, line=2), LIN(target=Ta)], jl, cl)
    assert info.value.move == 0 and info.value.line == 2
    with pytest.raises(ValueError, match="not a rigid transform"):
        LIN(target=np.diag([2.0, 1.0, 1.0, 1.0]))
    with pytest.raises(ValueError, match="positive and finite"):
        CartesianLimits(1.0, 0.0, 1.0, 1.0, 1.0, 1.0)


@settings(max_examples=6, deadline=None)
@given(dp=st.lists(st.floats(-0.2, 0.2), min_size=3, max_size=3),
       ang=st.floats(-0.4, 0.4), speed=st.floats(0.2, 1.0))
def test_random_lines_stay_straight_and_keep_the_limits(
        h4: RobotDescription, jl: JointLimits, cl: CartesianLimits, dp: list[float],
        ang: float, speed: float) -> None:
    q0 = _start(h4)
    Ta = tcp(h4, q0)
    Tb = moved(Ta, dp, axis=[0.2, -0.5, 1.0], angle=ang)
    tr = plan(h4, q0, [LIN(target=Tb, speed=speed)], jl, cl)
    T = tcp(h4, tr.sample(np.linspace(0.0, tr.duration, 60), 0).q)
    if np.linalg.norm(dp) > 1e-6:
        assert np.max(_line_distance(T[:, :3, 3], Ta[:3, 3], Tb[:3, 3])) <= 1e-9
    assert np.max(np.abs(T[-1] - Tb)) <= 1e-9
    _cart_fd_limits(tr.sections[0].path, cl.scaled(speed))


@pytest.mark.parametrize("speed", [0.1, 0.25])
def test_two_tangent_circs_fly_by_at_speed(elbow: RobotDescription, jl: JointLimits,
                                            speed: float) -> None:
    """A full circle as two CIRCs blended: the moves are tangent at the junction, so a
    blend whose window ``r/2`` holds the braking distance keeps the path's speed there
    (the superposed speed of mirrored profiles); the scalar edge bound of joint moves
    had forced the overlap down to a quarter of the speed at the junction."""
    cl = CartesianLimits(speed, 2.0, 20.0, 1.0, 4.0, 40.0)
    q0 = _start(elbow)
    Ta = tcp(elbow, q0)
    rho = 0.1
    half = moved(Ta, [0.0, 2 * rho, 0.0])
    moves = [CIRC(via=Ta[:3, 3] + [rho, rho, 0.0], target=half, blend=0.1),
             CIRC(via=Ta[:3, 3] + [-rho, rho, 0.0], target=Ta.copy())]
    tr = plan(elbow, q0, moves, jl, cl)
    path = tr.sections[0].path
    tm = path.timing
    assert tr.blends[0] > 0.0
    t = np.linspace(tm.start[1], tm.start[0] + tm.durations[0], 301)
    v = np.linalg.norm(path.sample(t).v, axis=1)
    assert v.min() >= 0.95 * speed and v.max() <= speed * (1 + 1e-6)
    _cart_fd_limits(path, cl)


@pytest.mark.slow
@settings(max_examples=5, deadline=None)
@given(r=st.floats(0.005, 0.2), turn=st.floats(-2.5, 2.5), ang=st.floats(-0.6, 0.6),
       speed=st.floats(0.3, 1.0))
def test_random_cartesian_blends_stay_within_the_radius_and_the_limits(
        elbow: RobotDescription, jl: JointLimits, cl: CartesianLimits, r: float, turn: float,
        ang: float, speed: float) -> None:
    q0 = _start(elbow)
    Ta = tcp(elbow, q0)
    T1 = moved(Ta, [0.25, 0.0, 0.0], axis=[0, 0, 1], angle=ang)
    T2 = moved(T1, [0.2 * np.cos(turn), 0.2 * np.sin(turn), 0.05], axis=[1, 0, 0], angle=ang)
    tr = plan(elbow, q0, [LIN(target=T1, blend=r, speed=speed), LIN(target=T2, speed=speed)],
              jl, cl)
    path = tr.sections[0].path
    p = path.sample(np.linspace(0.0, tr.duration, 4001)).T[:, :3, 3]
    dist = np.linalg.norm(p - T1[:3, 3], axis=1)
    assert np.min(dist) <= r + 1e-12
    if tr.blends[0] > 0.0:  # while both moves run the TCP stays within r of the corner
        tm = path.timing
        t = np.linspace(tm.start[1], tm.start[0] + tm.durations[0], 501)
        assert np.max(np.linalg.norm(path.sample(t).T[:, :3, 3] - T1[:3, 3], axis=1)) <= r
    _cart_fd_limits(path, cl.scaled(speed))
