"""The streaming tracker model (sim/twin/tracker_stream.py): rate, clocks, noise at rate,
the servo's lag and beam breaks, recovery."""

from __future__ import annotations

import math

import numpy as np
import pytest

from plugcell.sim.twin.tracker import BeamNotLockedError, LaserTracker, TrackerSpec
from plugcell.sim.twin.tracker_stream import StreamSpec, TrackerStream

CENTRE = np.array([3.0, 0.0, 0.3])


def _pose(p):
    T = np.eye(4)
    T[:3, 3] = p
    return T


def _lateral(speed, ramp=0.05, start=0.1):
    """A reflector at 3 m that accelerates smoothly (over ``ramp`` s) to ``speed`` m/s
    along y, across the beam."""
    def target(t):
        tau = max(0.0, t - start)
        y = speed * tau**2 / (2 * ramp) if tau < ramp else speed * (ramp / 2 + tau - ramp)
        return _pose(np.add(CENTRE, [0.0, y, 0.0]))
    return target


def _stream(target, rate=1000.0, **kw):
    tracker = LaserTracker(seed=kw.pop("tracker_seed", 0))
    tracker.point_at(target(0.0)[:3, 3])
    return TrackerStream(tracker, target, rate, **kw)


def test_the_stream_runs_at_its_rate_with_monotonic_evenly_spaced_tracker_stamps():
    spec = StreamSpec(clock_offset_s=123.0, clock_drift_ppm=30.0, latency_s=0.002)
    s = _stream(lambda t: _pose(CENTRE), 1000.0, spec=spec)
    samples = s.advance(1.0)
    assert len(samples) == 998  # the first leaves at 1 ms + 2 ms latency
    stamps = np.array([x.tracker_time_s for x in samples])
    np.testing.assert_allclose(np.diff(stamps), 1e-3 * (1 + 30e-6), rtol=1e-9)
    assert stamps[0] == pytest.approx(123.0 + 0.0005 * (1 + 30e-6))
    # each leaves the tracker half a window + latency after its stamp (true time)
    for x in samples[:5]:
        assert x.available_s - x.true_time_s == pytest.approx(0.0005 + 0.002)
    assert all(x.status == "ok" and x.six_dof for x in samples)
    assert s.advance(1.0) == []  # nothing twice


def test_six_dof_gives_a_pose_and_three_dof_a_position():
    R = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1.0]])
    T = _pose(CENTRE)
    T[:3, :3] = R
    six = _stream(lambda t: T, 100.0).advance(0.2)
    three = _stream(lambda t: T, 100.0, six_dof=False).advance(0.2)
    assert np.abs(six[5].pose[:3, :3] - R).max() < 1e-3
    np.testing.assert_array_equal(three[5].pose[:3, :3], np.eye(3))
    assert not three[5].six_dof
    assert np.linalg.norm(three[5].pose[:3, 3] - CENTRE) < 2e-4


def test_noise_per_sample_grows_with_the_rate_as_the_model_says():
    """Scatter of a static target's samples about their mean: the white part grows as
    √f, the floor and systematic parts do not; lateral σ from the spec's shares."""
    ts = TrackerSpec()
    scatter = {}
    for rate in (10.0, 1000.0):
        s = _stream(lambda t: _pose(CENTRE), rate, tracker_seed=1,
                    spec=StreamSpec(floor_correlation_s=1e-4))  # floor ~ fresh
        p = np.array([x.pose[:3, 3] for x in s.advance(400.0 / rate)])
        scatter[rate] = float(np.std(p[:, 1]))  # lateral (azimuth) at az = 0
        _, sl = ts.position_sigma(np.linalg.norm(CENTRE), 1.0 / rate,
                                  include_systematic=False)
        assert scatter[rate] == pytest.approx(float(sl), rel=0.15)
    assert scatter[1000.0] > 2 * scatter[10.0]


def test_the_servo_lags_by_v_over_k_and_the_beam_breaks_beyond_k_times_the_window():
    spec = StreamSpec()
    assert spec.max_lateral_speed_m_s == pytest.approx(5.0)
    slow = _stream(_lateral(2.0, ramp=0.3)).advance(0.8)
    assert all(x.status == "ok" for x in slow)
    # steady: the lag is the speed across the beam over K (2 m/s along y at x = 3 m)
    last = slow[-1]
    y = _lateral(2.0, ramp=0.3)(last.true_time_s)[1, 3]
    across = 2.0 * 3.0 / math.hypot(3.0, y)
    assert last.lateral_offset_m == pytest.approx(across / spec.servo_gain_per_s, rel=0.02)
    fast = _stream(_lateral(6.0, ramp=0.3)).advance(0.8)
    statuses = [x.status for x in fast]
    assert "tracking_speed" in statuses
    first_bad = statuses.index("tracking_speed")
    after = statuses[first_bad:]  # each re-acquisition loses it again within a sample or two
    assert after.count("tracking_speed") > 0.95 * len(after)
    # it breaks where the speed passes K·w = 5 m/s: 0.1 s + 5/6 of the 0.3 s ramp
    assert fast[first_bad].true_time_s == pytest.approx(0.35, abs=0.01)


def test_a_jump_faster_than_the_angular_acceleration_breaks_the_lock():
    # a velocity step (no ramp) at 1 m/s at 3 m: the beam needs ω/α to catch up
    s = _stream(_lateral(1.0, ramp=1e-6))
    assert "tracking_speed" in {x.status for x in s.advance(0.5)}
    assert all(x.status == "ok" for x in _stream(_lateral(1.0, ramp=0.2)).advance(0.8))


def test_a_line_of_sight_break_is_reported_and_the_beam_recovers_by_itself():
    spec = StreamSpec(reacquire_s=0.3)
    s = _stream(_lateral(0.2, ramp=0.1), 1000.0, spec=spec,
                blocked=lambda t: 0.2 <= t < 0.4)
    out = s.advance(1.2)
    bad = [x.true_time_s for x in out if x.status != "ok"]
    assert {x.status for x in out if x.status != "ok"} == {"line_of_sight"}
    assert min(bad) == pytest.approx(0.2, abs=1.5e-3)
    assert max(bad) == pytest.approx(0.7, abs=1.5e-3)  # 0.4 + the 0.3 s search
    after = [x for x in out if x.true_time_s > 0.72]
    assert after and all(x.status == "ok" for x in after)
    y = np.array([x.pose[1, 3] for x in after])
    truth = np.array([_lateral(0.2, ramp=0.1)(x.true_time_s)[1, 3] for x in after])
    _, sl = TrackerSpec().position_sigma(3.0, 1e-3)
    assert np.abs(y - truth).max() < 5 * sl  # measuring the moving reflector again

    stuck = _stream(lambda t: _pose(CENTRE), 1000.0, spec=StreamSpec(auto_reacquire=False),
                    blocked=lambda t: 0.2 <= t < 0.4)
    assert stuck.advance(1.0)[-1].status == "line_of_sight"


def test_bad_rates_and_an_unlocked_start_are_refused():
    with pytest.raises(ValueError, match=r"rate 2000.0 Hz outside 1…1000 Hz"):
        _stream(lambda t: _pose(CENTRE), 2000.0)
    with pytest.raises(ValueError, match="outside"):
        _stream(lambda t: _pose(CENTRE), math.nan)
    tracker = LaserTracker()
    tracker.point_at(np.add(CENTRE, [0, 0.05, 0]))
    with pytest.raises(BeamNotLockedError, match="capture radius"):
        TrackerStream(tracker, lambda t: _pose(CENTRE), 100.0)
    with pytest.raises(ValueError, match="servo_gain_per_s must be > 0"):
        StreamSpec(servo_gain_per_s=0.0)


def test_out_of_range_samples_say_so():
    far = np.array([14.9, 0.0, 0.0])
    s = _stream(lambda t: _pose(np.add(far, [0.2 * t, 0, 0])), 100.0)
    statuses = [x.status for x in s.advance(1.0)]
    assert statuses[0] == "ok" and statuses[-1] == "out_of_range"  # beyond 15 m (6-DOF)


def test_the_clocks_are_aligned_from_the_stream_itself_and_the_error_reported():
    """Tracker clock (offset, 20 ppm) → PC clock by the one-way envelope, then the constant
    latency by comparing with the robot's record of the same motion: the samples'
    acquisition times on the PC's clock come out within a tenth of a sample."""
    from plugcell.metrology.timing import estimate_delay, fit_clock_map

    def target(t):
        return _pose(np.add(CENTRE, [0.0, 0.2 * math.sin(2 * math.pi * 0.5 * t),
                                     0.05 * math.sin(2 * math.pi * 1.7 * t)]))

    spec = StreamSpec(clock_offset_s=5000.0, clock_drift_ppm=20.0, latency_s=0.002)
    samples = [x for x in _stream(target, 1000.0, spec=spec).advance(6.0) if x.status == "ok"]
    assert len(samples) > 5000  # (the start at 0.63 m/s is a velocity step: lock re-found)
    rng = np.random.default_rng(0)
    arrival = np.array([x.available_s for x in samples]) + rng.exponential(4e-4, len(samples))
    tracker_t = np.array([x.tracker_time_s for x in samples])
    clock = fit_clock_map(tracker_t, arrival)
    assert abs(clock.skew_ppm + 20.0) < 1.0  # the tracker's clock runs 20 ppm fast
    on_pc = clock(tracker_t)  # still late by the latency + half a window (+ least jitter)
    robot_t = np.arange(0.0, 6.0, 0.004)  # the robot's own cycle stamps (true time here)
    robot = np.array([target(t)[:3, 3] for t in robot_t])
    measured = np.array([x.pose[:3, 3] for x in samples])
    est = estimate_delay(robot_t, robot, on_pc, measured, max_delay_s=0.02)
    acquired = on_pc - est.delay_s
    truth = np.array([x.true_time_s for x in samples])
    error = np.abs(acquired - truth).max()
    assert est.delay_s == pytest.approx(0.0025, abs=2e-4)
    assert error < 1e-4 and est.std_s < 1e-4
