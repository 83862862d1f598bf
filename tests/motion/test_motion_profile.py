"""The double-S time law: its equations, limits, exact ends, derivatives (#37)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from plugcell.motion import DoubleS


@pytest.mark.parametrize(("args", "expect"), [
    # v·j ≥ a²: T_j = a/j = 0.2, T_a = 0.2 + 1/2 = 0.7, T_v = 1/1 − 0.7 = 0.3
    ((1.0, 1.0, 2.0, 10.0), (0.2, 0.7, 0.3)),
    # v·j < a²: T_j = √(v/j) = 1, T_a = 2; T_v = 1 − 2 < 0 and h < 2a³/j² = 16:
    # T_j = (h/2j)^(1/3), T_a = 2 T_j
    ((1.0, 1.0, 2.0, 1.0), (0.5 ** (1 / 3), 2 * 0.5 ** (1 / 3), 0.0)),
    # v not reached, a reached (h ≥ 2a³/j² = 0.16): T_j = 0.2,
    # T_a = 0.1 + √(0.01 + 0.5/2)
    ((0.5, 10.0, 2.0, 10.0), (0.2, 0.1 + math.sqrt(0.01 + 0.25), 0.0)),
    # long move: cruise
    ((10.0, 1.0, 2.0, 10.0), (0.2, 0.7, 9.3)),
])
def test_segment_durations_follow_the_equations(args: tuple[float, ...],
                                                expect: tuple[float, ...]) -> None:
    p = DoubleS.plan(*args)
    assert (p.t_j, p.t_a, p.t_v) == pytest.approx(expect, rel=1e-12)
    assert p.duration == pytest.approx(2 * expect[1] + expect[2], rel=1e-12)


def _check(p: DoubleS, v: float, a: float, j: float) -> None:
    T = p.duration
    # exact ends, at rest
    s0, s1 = p.sample(0.0), p.sample(T)
    assert float(s0.s) == 0.0 and float(s1.s) == pytest.approx(p.h, abs=1e-15 * max(p.h, 1))
    for x in (s0.v, s0.a, s1.v, s1.a):
        assert abs(float(x)) < 1e-12 * max(v, a, 1.0)
    # limits by finite differences of the sampled positions: a k-th difference quotient
    # is a weighted mean of the k-th derivative, so it cannot exceed the maximum
    for k, lim in ((1, v), (2, a), (3, j)):
        dt = T / 4000
        s = p.sample(np.arange(-k, 4001 + k) * dt).s
        fd = np.diff(s, k) / dt**k
        assert np.max(np.abs(fd)) <= lim * (1 + 1e-6) + 1e-9 * p.h / dt**k
    # monotone
    s = p.sample(np.linspace(0, T, 2001)).s
    assert np.all(np.diff(s) >= -1e-15)


@pytest.mark.parametrize("args", [(1.0, 1.0, 2.0, 10.0), (1.0, 1.0, 2.0, 1.0),
                                  (0.5, 10.0, 2.0, 10.0), (1e-4, 1.0, 2.0, 10.0),
                                  (3.0, 0.3, 5.0, 100.0)])
def test_limits_ends_and_monotony(args: tuple[float, ...]) -> None:
    _check(DoubleS.plan(*args), *args[1:])


def test_the_limit_is_reached_time_optimal() -> None:
    p = DoubleS.plan(10.0, 1.0, 2.0, 10.0)
    t = np.linspace(0, p.duration, 20001)
    s = p.sample(t)
    assert np.max(s.v) == pytest.approx(1.0)
    assert np.max(np.abs(s.a)) == pytest.approx(2.0)
    assert np.max(np.abs(s.j)) == pytest.approx(10.0)


@pytest.mark.parametrize("args", [(1.0, 1.0, 2.0, 10.0), (1.0, 1.0, 2.0, 1.0),
                                  (0.5, 10.0, 2.0, 10.0)])
def test_analytic_derivatives_match_central_differences(args: tuple[float, ...]) -> None:
    p = DoubleS.plan(*args)
    h = 1e-6
    t = np.linspace(0.0, p.duration, 997)[1:-1]
    # away from the jerk switches (the jerk itself is piecewise constant)
    sw = np.array([p.t_j, p.t_a - p.t_j, p.t_a, p.t_a + p.t_v, p.t_a + p.t_v + p.t_j,
                   p.duration - p.t_j])
    t = t[np.min(np.abs(t[:, None] - sw[None]), axis=1) > 1e-4]
    mid, plus, minus = p.sample(t), p.sample(t + h), p.sample(t - h)
    assert np.allclose((plus.s - minus.s) / (2 * h), mid.v, atol=1e-8)
    assert np.allclose((plus.v - minus.v) / (2 * h), mid.a, atol=1e-7)
    assert np.allclose((plus.a - minus.a) / (2 * h), mid.j, atol=1e-6)


def test_continuity_at_every_phase_switch() -> None:
    p = DoubleS.plan(1.0, 1.0, 2.0, 10.0)
    for ts in (p.t_j, p.t_a - p.t_j, p.t_a, p.t_a + p.t_v, p.duration - p.t_j):
        lo, hi = p.sample(ts - 1e-12), p.sample(ts + 1e-12)
        assert float(hi.s - lo.s) == pytest.approx(0.0, abs=1e-11)
        assert float(hi.v - lo.v) == pytest.approx(0.0, abs=1e-10)
        assert float(hi.a - lo.a) == pytest.approx(0.0, abs=1e-9)


def test_time_at_inverts_the_position() -> None:
    p = DoubleS.plan(2.0, 1.0, 2.0, 10.0)
    for s in (0.0, 0.001, 0.5, 1.3, 2.0):
        assert float(p.sample(p.time_at(s)).s) == pytest.approx(s, abs=1e-12)


def test_zero_move_and_bad_limits() -> None:
    p = DoubleS.plan(0.0, 1.0, 1.0, 1.0)
    assert p.duration == 0.0 and float(p.sample(1.0).s) == 0.0
    with pytest.raises(ValueError, match="v_max must be positive"):
        DoubleS.plan(1.0, 0.0, 1.0, 1.0)
    with pytest.raises(ValueError, match="displacement"):
        DoubleS.plan(-1.0, 1.0, 1.0, 1.0)
    with pytest.raises(ValueError, match="j_max"):
        DoubleS.plan(1.0, 1.0, 1.0, math.inf)


@settings(max_examples=60, deadline=None)
@given(h=st.floats(1e-5, 50.0), v=st.floats(0.01, 10.0), a=st.floats(0.01, 50.0),
       j=st.floats(0.1, 1000.0))
def test_random_profiles_keep_limits_and_end_exactly(h: float, v: float, a: float,
                                                     j: float) -> None:
    p = DoubleS.plan(h, v, a, j)
    _check(p, v, a, j)
    # minimum time: no faster than the bounds each limit alone implies
    assert p.duration >= h / v * (1 - 1e-12)
    assert p.duration >= 2 * math.sqrt(h / a) * (1 - 1e-9)
    assert p.duration >= 2 * (4 * h / j) ** (1 / 3) * (1 - 1e-9) - 1e-12


# ---------------------------------------------------------------------------- ruckig
# Ruckig (Berscheid & Kröger, RSS 2021) is an independent time-optimal jerk-limited
# generator: the rest-to-rest double-S must take exactly its time and follow its path.
@settings(max_examples=40, deadline=None)
@given(h=st.floats(1e-3, 20.0), v=st.floats(0.05, 5.0), a=st.floats(0.05, 20.0),
       j=st.floats(0.5, 500.0))
def test_same_time_and_path_as_ruckig(h: float, v: float, a: float, j: float) -> None:
    ruckig = pytest.importorskip("ruckig")
    inp = ruckig.InputParameter(1)
    inp.current_position, inp.target_position = [0.0], [h]
    inp.max_velocity, inp.max_acceleration, inp.max_jerk = [v], [a], [j]
    traj = ruckig.Trajectory(1)
    assert ruckig.Ruckig(1).calculate(inp, traj) == ruckig.Result.Working
    p = DoubleS.plan(h, v, a, j)
    assert p.duration == pytest.approx(traj.duration, rel=1e-7)
    for t in np.linspace(0.0, p.duration, 23):
        pos, vel, _acc = traj.at_time(min(t, traj.duration))
        s = p.sample(t)
        assert float(s.s) == pytest.approx(pos[0], abs=1e-7 * max(h, 1.0))
        assert float(s.v) == pytest.approx(vel[0], abs=1e-6 * max(v, 1.0))
