"""Dynamic path correction's math (plugcell.compensation.tracking): the residual filter's
equations, the joint history, the rate limiter's bounds (hypothesis), the loop's law,
beam breaks and hold windows, determinism."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from plugcell.compensation import NominalModel
from plugcell.compensation.tracking import (
    JointHistory,
    RateLimiter,
    ResidualFilter,
    TrackerMeasurement,
    TrackingLoop,
    TrackingSettings,
    steady_state_gain,
)
from plugcell.io.robots import load_robot
from plugcell.kinematics import forward

T = 0.004


# -- the residual filter --------------------------------------------------------------

def test_without_process_noise_the_filter_is_the_running_mean():
    rng = np.random.default_rng(1)
    z = 0.3e-3 + 60e-6 * rng.standard_normal((200, 3))
    f = ResidualFilter([0.0] * 3, [60e-6] * 3, gate=np.inf)
    for k, zk in enumerate(z):
        assert f.update(k * 1e-3, zk)
        np.testing.assert_allclose(f.x, z[: k + 1].mean(axis=0), rtol=0, atol=1e-15)
        np.testing.assert_allclose(f.P, (60e-6) ** 2 / (k + 1), rtol=1e-9)


def test_the_gain_tends_to_the_closed_form_steady_state():
    q, r, dt = 2e-3, 60e-6, 1e-3
    f = ResidualFilter([q], [r], gate=np.inf)
    for k in range(2000):
        f.update(k * dt, [0.0])
    P_pred = f.P[0] + q * q * dt
    assert P_pred / (P_pred + r * r) == pytest.approx(steady_state_gain(q, r, dt), rel=1e-9)


def test_the_gate_rejects_an_outlier_and_counts_it():
    f = ResidualFilter([1e-3] * 3, [50e-6] * 3, gate=6.0)
    for k in range(50):
        f.update(k * 1e-3, [0.0, 0.0, 0.0])
    x = f.x.copy()
    assert not f.update(0.05, [5e-3, 0.0, 0.0])
    assert f.rejected == 1 and np.array_equal(f.x, x)
    assert not f.update(0.01, [0.0, 0.0, 0.0])  # out of order
    assert not f.update(0.06, [np.nan, 0.0, 0.0])
    assert f.rejected == 3


def test_a_lasting_step_restarts_the_filter_after_max_rejections():
    f = ResidualFilter([1e-5], [50e-6], gate=6.0, max_rejections=10)
    for k in range(100):
        f.update(k * 1e-3, [0.0])
    for k in range(100, 111):
        f.update(k * 1e-3, [2e-3])
    assert f.x[0] == pytest.approx(2e-3) and f.rejected == 10


def test_bad_filter_parameters_are_named():
    with pytest.raises(ValueError, match="noise > 0"):
        ResidualFilter([1.0], [0.0])
    with pytest.raises(ValueError, match="gate"):
        ResidualFilter([1.0], [1.0], gate=0.0)


# -- the joint history -----------------------------------------------------------------

def test_joint_history_interpolates_linearly_and_refuses_outside_its_span():
    h = JointHistory(span_s=0.1)
    for k in range(40):
        h.add(k * T, np.full(6, k * 0.01))
    assert h.earliest_time == pytest.approx(39 * T - 0.1, abs=T)
    np.testing.assert_allclose(h.at(30.25 * T), np.full(6, 0.3025))
    np.testing.assert_allclose(h.at([30 * T, 31 * T])[:, 0], [0.30, 0.31])
    with pytest.raises(ValueError, match="span"):
        h.at(0.0)
    with pytest.raises(ValueError, match="not after"):
        h.add(39 * T, np.zeros(6))


# -- the rate limiter -------------------------------------------------------------------

@settings(max_examples=60, deadline=None)
@given(targets=st.lists(st.floats(-5e-3, 5e-3, allow_nan=False), min_size=1, max_size=200),
       v=st.floats(1e-3, 0.05), a=st.floats(0.05, 5.0), c=st.floats(0.0, 3e-3))
def test_the_limiter_never_exceeds_its_bounds(targets, v, a, c):
    lim = RateLimiter(T, [v], [a], [c])
    prev_value, prev_step = 0.0, 0.0
    for x in targets:
        value = lim.apply([x])[0]
        step = value - prev_value
        assert abs(step) <= v * T * (1 + 1e-9) + 1e-18
        assert abs(step - prev_step) <= a * T * T * (1 + 1e-9) + 1e-18
        assert abs(value) <= c * (1 + 1e-9) + 1e-18
        prev_value, prev_step = value, step


def test_the_limiter_reaches_a_constant_target_without_overshoot():
    lim = RateLimiter(T, [0.01], [0.5], [2e-3])
    values = [lim.apply([1e-3])[0] for _ in range(500)]
    assert max(values) <= 1e-3 + 1e-15
    assert values[-1] == pytest.approx(1e-3, abs=1e-12)


@settings(max_examples=150, deadline=None)
@given(moves=st.lists(st.tuples(st.floats(-5e-3, 5e-3, allow_nan=False),
                                st.integers(1, 12)), min_size=2, max_size=150),
       v=st.floats(1e-3, 0.05), a=st.floats(0.05, 5.0), c=st.floats(0.0, 3e-3))
def test_the_limiter_holds_its_bounds_in_robot_time_when_cycles_are_skipped(moves, v, a, c):
    """Updates ``n`` robot cycles apart (a loop that fell behind): speed and acceleration
    of the outputs in robot time never exceed the bounds, nor the total (the old limiter,
    one step a computed update, gave 40 µm after a gap of several cycles: an
    acceleration of v/T in robot time, 2.5 m/s² for 10 mm/s at 4 ms)."""
    lim = RateLimiter(T, [v], [a], [c])
    prev_value, prev_speed = 0.0, 0.0
    for x, n in moves:
        value = lim.apply([x], cycles=n)[0]
        speed = (value - prev_value) / (n * T)
        assert abs(speed) <= v * (1 + 1e-9) + 1e-15
        assert abs(speed - prev_speed) / (n * T) <= a * (1 + 1e-9) + 1e-12
        assert abs(value) <= c + a * T * T / 8 * (1 + 1e-9) + 1e-18  # module docstring
        prev_value, prev_speed = value, speed


@settings(max_examples=60, deadline=None)
@given(gaps=st.lists(st.integers(1, 20), min_size=300, max_size=300),
       target=st.floats(-2e-3, 2e-3).filter(lambda x: abs(x) > 1e-6))
def test_the_limiter_reaches_its_target_without_overshoot_whatever_cycles_are_skipped(
        gaps, target):
    lim = RateLimiter(T, [0.01], [0.5], [2e-3])
    values = np.array([lim.apply([target], cycles=n)[0] for n in gaps])
    # past the target by at most a/8 = a_max T²/8 (1 µm here: the module docstring)
    assert np.all(values * np.sign(target) <= abs(target) + 0.5 * T * T / 8 * (1 + 1e-9))
    assert values[-1] == pytest.approx(target, abs=1e-12)


def test_the_limiter_refuses_a_bad_cycle_count():
    lim = RateLimiter(T, [0.01], [0.5], [2e-3])
    for bad in (0.5, 0.0, math.inf, math.nan):
        with pytest.raises(ValueError, match="cycles must be a finite number ≥ 1, got"):
            lim.apply([1e-3], cycles=bad)


# -- the loop ---------------------------------------------------------------------------

@pytest.fixture(scope="module")
def robot():
    desc = load_robot("smart_h4")
    tool = np.eye(4)
    tool[:3, 3] = [0.0, 0.05, 0.2]
    model = NominalModel(desc, tool)
    q0 = np.radians([0.0, -20.0, -100.0, 0.0, 30.0, 0.0])
    return model, q0


def _run(model, q0, residual, *, blocked=lambda t: False, cycles=300, tracking=True,
         seed=0, s=None):
    """The robot stands at q0 (the path holds still); the true tool is the model's
    shifted by ``residual(t)``; a 1 kHz tracker sees it with 60 µm noise, 3 ms late."""
    rng = np.random.default_rng(seed)
    s = s or TrackingSettings()
    loop = TrackingLoop(model, s, tracking=tracking)
    Tp = model.evaluate(q0)[0][0]
    outs, sample_t = [], 0.0
    for k in range(cycles):
        t = k * T
        ms = []
        while sample_t + 0.003 <= t:
            if blocked(sample_t):
                ms.append(TrackerMeasurement(sample_t, None, True, "line_of_sight"))
            else:
                P = Tp.copy()
                P[:3, 3] += residual(sample_t) + 60e-6 * rng.standard_normal(3)
                ms.append(TrackerMeasurement(sample_t, P, True, "ok"))
            sample_t += 1e-3
        loop.add(ms)
        outs.append(loop.cycle(t, q0, Tp))
    return loop, outs


def test_the_model_feedforward_is_zero_for_the_controllers_own_model(robot):
    model, q0 = robot
    _, outs = _run(model, q0, lambda t: np.zeros(3), tracking=False, cycles=5)
    assert np.abs(outs[-1].offset).max() < 1e-9
    assert outs[-1].state == "model"


def test_a_constant_residual_is_corrected_by_the_tracker_term(robot):
    model, q0 = robot
    e = np.array([0.2e-3, -0.1e-3, 0.05e-3])
    loop, outs = _run(model, q0, lambda t: e)
    assert outs[-1].state == "tracking"
    np.testing.assert_allclose(outs[-1].offset[:3], -e, atol=25e-6)
    assert loop.stats.fresh_cycles >= 295 and loop.stats.samples_bad == 0
    ages = np.array(loop.stats.ages_s)
    assert ages.min() >= 0.003 - 1e-9 and ages.max() <= 0.003 + T + 1e-9


def test_a_beam_break_holds_the_model_records_the_window_and_resumes(robot):
    model, q0 = robot
    e = np.array([0.3e-3, 0.0, 0.0])
    loop, outs = _run(model, q0, lambda t: e, blocked=lambda t: 0.4 <= t < 0.7, cycles=500)
    assert len(loop.windows) == 1
    w = loop.windows[0]
    assert w.reason == "line_of_sight"
    assert 0.4 <= w.start_s <= 0.4 + 0.06 and 0.7 < w.end_s < 0.8
    held = [o for k, o in enumerate(outs) if 0.7 <= k * T < w.end_s]
    assert all(o.state == "holding" for o in held)
    assert held[-1].weight < 1e-9 and abs(held[-1].offset[0]) < 1e-9  # the model alone
    assert outs[-1].state == "tracking"
    np.testing.assert_allclose(outs[-1].offset[:3], -e, atol=30e-6)
    # the correction never jumps: its rate stays inside the limits throughout
    x = np.array([o.tracker[0] for o in outs])
    s = TrackingSettings()
    assert np.abs(np.diff(x)).max() <= s.max_speed_m_s * T * (1 + 1e-9)
    assert np.abs(np.diff(x, 2)).max() <= s.max_accel_m_s2 * T * T * (1 + 1e-9)


@settings(max_examples=20, deadline=None)
@given(skips=st.lists(st.integers(0, 6), min_size=320, max_size=320),
       jump=st.floats(-1.5e-3, 1.5e-3), seed=st.integers(0, 3))
def test_the_loop_bounds_its_term_in_robot_time_when_it_skips_cycles(robot, skips, jump,
                                                                      seed):
    """A loop that fell behind (the robot service's on a loaded PC) is called for robot
    cycles ``1 + skip`` apart; the residual jumps mid-run and the beam breaks: the tracker
    term's speed and acceleration in robot time stay within the settings' bounds."""
    model, q0 = robot
    rng = np.random.default_rng(seed)
    s = TrackingSettings()
    loop = TrackingLoop(model, s)
    Tp = model.evaluate(q0)[0][0]
    ks = np.cumsum([1 + g for g in skips])
    sample_t, out = 0.0, []
    for k in ks:
        t = k * T
        ms = []
        while sample_t + 0.003 <= t:
            if 0.8 <= sample_t < 1.0:
                ms.append(TrackerMeasurement(sample_t, None, True, "line_of_sight"))
            else:
                P = Tp.copy()
                P[:3, 3] += [jump if sample_t > 0.5 else 0.0, 0.3e-3, 0.0]
                P[:3, 3] += 60e-6 * rng.standard_normal(3)
                ms.append(TrackerMeasurement(sample_t, P, True, "ok"))
            sample_t += 1e-3
        loop.add(ms)
        out.append(loop.cycle(t, q0, Tp).tracker[:3])
    c, dt = np.array(out), np.diff(ks * T)
    u = np.diff(c, axis=0) / dt[:, None]
    assert np.abs(u).max() <= s.max_speed_m_s * (1 + 1e-9)
    acc = np.diff(u, axis=0) / dt[1:, None]
    assert np.abs(acc).max() <= s.max_accel_m_s2 * (1 + 1e-9)
    assert loop.stats.cycles == len(ks) and loop.windows  # the break was seen


def test_a_silent_tracker_is_late_and_hold_names_the_reason(robot):
    model, q0 = robot
    loop, _ = _run(model, q0, lambda t: np.zeros(3), cycles=100)
    for k in range(100, 140):  # no more samples
        out = loop.cycle(k * T, q0, model.evaluate(q0)[0][0])
    assert loop.windows[-1].reason == "late" and out.state == "holding"
    loop.hold("tracker stopped")
    assert loop.windows[-1].reason == "late"  # already holding: one window
    loop2, _ = _run(model, q0, lambda t: np.zeros(3), cycles=100)
    loop2.hold("tracker stopped")
    loop2.cycle(100 * T, q0, model.evaluate(q0)[0][0])
    assert loop2.windows[-1].reason == "tracker stopped"


def test_the_lead_extrapolates_the_path_by_tau_within_its_bounds(robot):
    model, q0 = robot
    s = TrackingSettings(lead_s=0.01)
    loop = TrackingLoop(model, s, tracking=False)
    Tp0 = model.evaluate(q0)[0][0]
    v = np.array([0.1, 0.0, 0.0])
    leads = []
    for k in range(80):
        Tp = Tp0.copy()
        Tp[:3, 3] += v * k * T
        if k == 60:
            Tp[:3, 3] += [0.0, 0.05, 0.0]  # a wrongly recovered path pose (late answer)
        leads.append(loop.cycle(k * T, q0, Tp).lead)
    leads = np.array(leads)
    np.testing.assert_allclose(leads[59], v * 0.01, atol=1e-12)
    assert np.abs(leads).max() <= s.max_lead_m
    assert np.abs(np.diff(leads, axis=0)).max() <= s.max_lead_speed_m_s * T * (1 + 1e-9)


def test_the_loop_is_deterministic(robot):
    model, q0 = robot
    a = _run(model, q0, lambda t: np.array([1e-4, 0, 0]), cycles=120, seed=3)[1]
    b = _run(model, q0, lambda t: np.array([1e-4, 0, 0]), cycles=120, seed=3)[1]
    assert all(np.array_equal(x.offset, y.offset) for x, y in zip(a, b, strict=True))


def test_bad_settings_are_named():
    with pytest.raises(ValueError, match="max_age_s"):
        TrackingSettings(max_age_s=0.0)
    with pytest.raises(ValueError, match="lead_s"):
        TrackingSettings(lead_s=-1.0)
    assert math.isfinite(TrackingSettings().fade_s)


def test_the_residual_is_measured_against_the_model_at_the_samples_joints(robot):
    """Age compensation: the robot moves, the samples are 3 ms old — the residual is
    still the constant offset, not the motion over the sample's age."""
    model, q0 = robot
    loop = TrackingLoop(model, TrackingSettings(position_drift=0.0), tracking=True)
    e = np.array([0.1e-3, 0.2e-3, -0.1e-3])
    rate = np.array([0.2, 0.0, 0.0, 0.0, 0.0, 0.0])  # rad/s on A1
    for k in range(60):
        t = k * T
        ms = []
        for j in range(4):
            ts = t - 0.003 - j * 1e-3
            if ts > 0:
                P = model.evaluate(q0 + rate * ts)[0][0]
                P[:3, 3] += e
                ms.append(TrackerMeasurement(ts, P))
        loop.add(sorted(ms, key=lambda m: m.time_s))
        out = loop.cycle(t, q0 + rate * t, forward(model.desc, None, q0 + rate * t,
                                                   "nominal").flange @ model.tool)
    np.testing.assert_allclose(out.residual[:3], e, atol=1e-9)


def test_the_low_pass_keeps_the_terms_noise_away_from_the_arms_modes(robot):
    """The estimate's noise is white; H (2 Hz) takes what of it reaches 8–14 Hz (the
    twin's first modes) down by more than ten, and the constant residual is still met."""
    from scipy.signal import welch

    model, q0 = robot
    e = np.array([0.2e-3, 0.0, 0.0])

    def band(cutoff):
        s = TrackingSettings(output_cutoff_hz=cutoff, position_drift=1e-4)
        outs = _run(model, q0, lambda t: e, cycles=900, s=s)[1]
        c = np.array([o.tracker[0] for o in outs[400:]])
        f, P = welch(c - c.mean(), fs=1 / T, nperseg=256)
        return float(np.sqrt(P[(f >= 8) & (f <= 14)].sum())), float(c.mean())

    raw, _ = band(0.0)
    low, mean = band(2.0)
    assert low < 0.1 * raw
    assert mean == pytest.approx(e[0], abs=10e-6)
    with pytest.raises(ValueError, match=r"output_cutoff_hz 200\.0 must lie below"):
        TrackingSettings(output_cutoff_hz=200.0)


def test_the_learned_offset_moves_the_target_with_or_without_the_tracker(robot):
    model, q0 = robot
    u = np.array([30e-6, -20e-6, 10e-6])
    for tracking in (False, True):
        loop = TrackingLoop(model, tracking=tracking, learned=lambda t: u * (t >= 0.1))
        Tp = model.evaluate(q0)[0][0]
        out0 = loop.cycle(0.0, q0, Tp)
        out1 = loop.cycle(0.104, q0, Tp)
        np.testing.assert_array_equal(out1.learned, u)
        # the nominal model is the controller's own: the offset is the learned one
        np.testing.assert_allclose(out1.offset[:3] - out0.offset[:3], u, atol=1e-9)


# -- the loop's fast path equals the plain computations it replaced ----------------------

def test_the_fast_output_filter_is_sosfilt():
    from scipy.signal import butter, sosfilt

    from plugcell.compensation.tracking.loop import _sos_step

    sos = butter(2, 2.0, fs=250.0, output="sos")
    x = np.random.default_rng(0).standard_normal((400, 6)) * 1e-4
    want = sosfilt(sos, x, axis=0, zi=np.zeros((len(sos), 2, 6)))[0]
    z = np.zeros((len(sos), 2, 6))
    got = np.array([_sos_step(sos, z, xi) for xi in x])
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-18)


def test_the_joint_history_interpolates_as_np_interp_over_all_it_keeps():
    h = JointHistory(span_s=0.5)
    rng = np.random.default_rng(1)
    ts, qs = [], []
    for k in range(1000):  # many compactions and one growth of its buffer
        ts.append(k * T + 1e-4 * rng.random())
        qs.append(rng.standard_normal(6))
        h.add(ts[-1], qs[-1])
        kept = [i for i in range(len(ts)) if ts[-1] - ts[i] <= 0.5]
        assert len(h) == len(kept) and h.earliest_time == ts[kept[0]]
        if k % 97 == 0 and len(kept) > 1:
            probe = np.linspace(ts[kept[0]], ts[-1], 7)
            Q = np.array([qs[i] for i in kept])
            want = np.stack([np.interp(probe, [ts[i] for i in kept], Q[:, j])
                             for j in range(6)], axis=-1)
            np.testing.assert_array_equal(h.at(probe), want)


def test_a_models_pose_is_its_evaluate_without_the_jacobian(robot):
    from plugcell.calibration.identify import Calibrator
    from plugcell.compensation import IdentifiedModel
    from plugcell.sim.twin.campaign import measure_poses, working_volume_joints
    from plugcell.sim.twin.robot import RobotTwin
    from plugcell.sim.twin.scenario import TwinScenario
    from plugcell.sim.twin.tracker import LaserTracker

    model, q0 = robot
    q = q0 + np.radians(np.random.default_rng(2).uniform(-10, 10, (5, 6)))
    np.testing.assert_array_equal(model.pose(q), model.evaluate(q)[0])
    twin = RobotTwin(TwinScenario(robot="smart_h4", seed=1, payload_kg=20.0))
    qc = working_volume_joints(twin.description, twin.reveal_truth().profile, 40,
                               np.random.default_rng(3))
    ms, _ = measure_poses(twin, LaserTracker(seed=1), qc)
    identified = IdentifiedModel(Calibrator(twin.description, 5).fit(ms).model)
    np.testing.assert_array_equal(identified.pose(q, 20.0), identified.evaluate(q, 20.0)[0])


def test_an_orientation_residual_is_corrected_when_asked(robot):
    """``correct_orientation=True``: a tool turned 0.05° about z beyond the model is turned
    back; without it only the position is corrected (the estimate's rotation is not kept)."""
    from plugcell.kinematics.transforms import so3_exp

    model, q0 = robot
    Tp = model.evaluate(q0)[0][0]
    phi = np.radians([0.0, 0.0, 0.05])
    out = {}
    for orient in (True, False):
        loop = TrackingLoop(model, TrackingSettings(correct_orientation=orient))
        for k in range(400):
            P = Tp.copy()
            P[:3, :3] = so3_exp(phi) @ Tp[:3, :3]
            loop.add([TrackerMeasurement(k * T - 0.003, P, True, "ok")] if k else [])
            out[orient] = loop.cycle(k * T, q0, Tp)
    np.testing.assert_allclose(out[True].offset[3:], -phi, atol=2e-5)
    np.testing.assert_allclose(out[True].offset[:3], 0.0, atol=1e-5)  # turned about the tool
    assert np.all(np.isnan(out[False].residual[3:])) and not np.any(out[False].offset[3:])
