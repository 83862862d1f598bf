"""Clock alignment (plugcell.metrology.timing): delays and clock maps of known truth."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from plugcell.metrology import MetrologyError
from plugcell.metrology.timing import estimate_delay, fit_clock_map


def _motion(t: np.ndarray) -> np.ndarray:
    """A smooth 3-D motion with several frequencies (metres)."""
    return np.column_stack([0.3 * np.sin(2 * np.pi * 0.4 * t) + 0.05 * np.sin(2 * np.pi * 3 * t),
                            0.2 * np.cos(2 * np.pi * 0.7 * t),
                            0.1 * np.sin(2 * np.pi * 1.3 * t + 0.4)])


@pytest.mark.parametrize("delay", [0.0, 0.0037, -0.0113, 0.0208])
def test_a_known_delay_is_recovered_to_a_fraction_of_a_sample(delay):
    rng = np.random.default_rng(1)
    t_a = np.arange(0.0, 6.0, 0.004)  # the robot's 250 Hz feedback
    t_b = np.arange(0.0003, 6.0, 0.001)  # the tracker's 1 kHz stream, another phase
    a = _motion(t_a)
    b = _motion(t_b - delay) + rng.normal(0.0, 20e-6, (t_b.size, 3)) + [1.0, -2.0, 0.5]
    est = estimate_delay(t_a, a, t_b, b, max_delay_s=0.05)
    assert abs(est.delay_s - delay) < 0.1 * 0.001  # a tenth of the finer sample
    assert est.std_s < 0.1 * 0.001
    assert abs(est.delay_s - delay) < 5 * est.std_s + 1e-5  # the error bar is honest
    assert est.residual_rms < 1e-4


def test_the_error_bar_grows_with_noise_and_covers_the_truth():
    t = np.arange(0.0, 4.0, 0.001)
    errors, stds = [], []
    for seed in range(20):
        rng = np.random.default_rng(seed)
        b = _motion(t - 0.0042)[:, :1] + rng.normal(0.0, 2e-3, (t.size, 1))
        est = estimate_delay(t, _motion(t)[:, :1], t, b, max_delay_s=0.02)
        errors.append(est.delay_s - 0.0042)
        stds.append(est.std_s)
    errors = np.asarray(errors)
    assert np.sqrt(np.mean(errors**2)) < 3 * np.mean(stds)
    assert np.mean(stds) > 1e-6  # noise shows in the error bar


def test_bad_records_are_refused_with_the_reason():
    t = np.arange(0.0, 1.0, 0.01)
    x = np.sin(t)
    with pytest.raises(MetrologyError, match="times must increase strictly"):
        estimate_delay(t[::-1], x, t, x, max_delay_s=0.01)
    with pytest.raises(MetrologyError, match="non-finite"):
        estimate_delay(t, np.where(t > 0.5, np.nan, x), t, x, max_delay_s=0.01)
    with pytest.raises(MetrologyError, match="overlap"):
        estimate_delay(t, x, t + 0.95, x, max_delay_s=0.01)
    with pytest.raises(MetrologyError, match="no motion"):
        estimate_delay(t, np.ones_like(t), t, x, max_delay_s=0.01)
    with pytest.raises(MetrologyError, match="channels"):
        estimate_delay(t, np.column_stack([x, x]), t, x, max_delay_s=0.01)
    with pytest.raises(MetrologyError, match="max_delay_s"):
        estimate_delay(t, x, t, x, max_delay_s=0.0)
    with pytest.raises(MetrologyError, match="at least 8"):
        estimate_delay(t[:3], x[:3], t, x, max_delay_s=0.01)


def test_the_clock_map_recovers_offset_and_drift_under_one_sided_jitter():
    rng = np.random.default_rng(3)
    device = np.arange(0.0, 60.0, 0.001)  # a minute of tracker samples
    offset, rate, latency = 1.7e9 + 0.123, 1.0 + 40e-6, 0.0008
    pc = offset + rate * device + latency + rng.exponential(0.0005, device.size)
    m = fit_clock_map(device, pc)
    assert abs(m.skew_ppm - 40.0) < 0.5
    # the envelope sits at the smallest delay: offset + latency, to within 10 µs
    assert abs(m(30.0) - (offset + rate * 30.0 + latency)) < 10e-6
    assert m.jitter_s.min() >= 0 and np.median(m.jitter_s) == pytest.approx(
        0.0005 * np.log(2), rel=0.1)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(allow_nan=True, allow_infinity=True, width=32), min_size=0,
                max_size=30))
def test_the_clock_map_reads_or_refuses_any_stamps(values):
    device = np.cumsum(np.abs(np.nan_to_num(values, nan=1.0, posinf=1.0, neginf=1.0)) + 1e-3)
    try:
        m = fit_clock_map(device, values)
    except MetrologyError as exc:
        assert str(exc)
    else:
        assert np.isfinite(m.offset_s) and np.isfinite(m.rate)
        assert np.all(m.jitter_s >= 0)
