"""The weighting's inflation where the last update made the error fall
(plugcell.compensation.tracking.smoothing, (5)): the sign rule on the factor ``c_j``
(bounded, monotone, 1 when switched off), the gain it gives (never below (2)'s, below 1,
0 where no signal is seen; the law without it exactly when off), and bad input.  Seeded
and deterministic."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.fft import rfft, rfftfreq

from plugcell.compensation.tracking import SpectralGain, TileGain, WeightingSettings
from plugcell.compensation.tracking.smoothing import inflation

T = 0.004
G = 2048
SIGMA = 45e-6

powers = st.lists(st.floats(0.0, 1e3, allow_nan=False), min_size=1, max_size=12)


def test_the_sign_rule_multiplies_where_the_power_fell_and_divides_elsewhere():
    c = inflation(None, [4.0, 1.0], None, 8.0, 2.0)
    np.testing.assert_array_equal(c, [1.0, 1.0])          # c_0 = 1: no record before
    c = inflation(c, [3.0, 1.0], [4.0, 1.0], 8.0, 2.0)      # fell / equal (not fell)
    np.testing.assert_array_equal(c, [2.0, 1.0])
    for _ in range(5):                                       # keeps falling: up to c_max
        c = inflation(c, [1.0, 1.0], [2.0, 1.0], 8.0, 2.0)
    np.testing.assert_array_equal(c, [8.0, 1.0])
    c = inflation(c, [2.0, 0.5], [1.0, 1.0], 8.0, 2.0)      # rose / fell
    np.testing.assert_array_equal(c, [4.0, 2.0])
    # a margin: a fall of 10 % counts at 0.05, not at 0.2 (then ÷ a)
    np.testing.assert_array_equal(inflation([2.0, 2.0], [0.9, 0.9], [1.0, 1.0], 8.0, 2.0,
                                            0.05), [4.0, 4.0])
    np.testing.assert_array_equal(inflation([2.0, 2.0], [0.9, 0.9], [1.0, 1.0], 8.0, 2.0,
                                            0.2), [1.0, 1.0])
    # another shape of the last record (another grid): a first update
    np.testing.assert_array_equal(inflation(c, [1.0, 1.0, 1.0], [2.0, 2.0], 8.0, 2.0),
                                  [1.0, 1.0, 1.0])


@settings(max_examples=60, deadline=None)
@given(powers, st.floats(1.0, 16.0), st.floats(1.01, 4.0), st.integers(0, 2**31 - 1))
def test_the_factor_is_bounded_and_monotone_in_the_power(p, c_max, a, seed):
    rng = np.random.default_rng(seed)
    P = np.asarray(p)
    last = rng.uniform(0.0, 1e3, P.size)
    c0 = rng.uniform(1.0, c_max, P.size)
    c = inflation(c0, P, last, c_max, a)
    assert np.all((c >= 1.0) & (c <= c_max))
    lower = inflation(c0, 0.5 * P - 1.0, last, c_max, a)    # a lower power: never less
    assert np.all(lower >= c)
    if c_max == 1.0:
        np.testing.assert_array_equal(c, 1.0)


def records(runs: int, fall: float) -> list[np.ndarray]:
    """Spectra of ``runs`` records: a 12 Hz tone whose amplitude is multiplied by ``fall``
    each run, plus fresh white noise (seeded per run)."""
    t = np.arange(G) * T
    out = []
    for k in range(runs):
        x = np.zeros((G, 3))
        x[:, 0] = 60e-6 * fall ** k * np.sin(2 * np.pi * 12 * t)
        n = SIGMA * np.random.default_rng(10 + k).standard_normal(x.shape)
        out.append(rfft(x + n, axis=0))
    return out


def test_switched_off_it_is_the_law_without_it_exactly():
    f = rfftfreq(G, T)
    a = SpectralGain(WeightingSettings())
    b = SpectralGain(WeightingSettings(adapt_max=1.0, adapt_step=3.0))
    for E in records(5, 0.7):
        np.testing.assert_array_equal(a(E, f), b(E, f))
    np.testing.assert_array_equal(a.prior, b.prior)
    assert b.scale is None and b.power is not None


@pytest.mark.parametrize("gamma", [1.0, 0.6])
def test_the_gain_is_never_below_the_law_without_it_and_stays_below_one(gamma):
    """With the same records and the matching off, ``K_j`` with (5) ≥ ``K_j`` of (2) in
    every bin and update (the prior inflated, its posterior ≥ (2)'s), < 1 where the noise
    is finite, 0 where no signal was seen; where the tone keeps falling ``c`` reaches
    ``c_max`` and the gain no longer decays like (2)'s."""
    f = rfftfreq(G, T)
    plain = SpectralGain(WeightingSettings(), gamma)
    adapt = SpectralGain(WeightingSettings(adapt_max=4.0), gamma)
    tone = np.argmin(np.abs(f - 12.0))
    for j, E in enumerate(records(6, 0.6)):
        K0, K1 = plain(E, f), adapt(E, f)
        assert np.all(K1 >= K0 - 1e-15) and np.all(K1 < 1.0)
        np.testing.assert_array_equal(K1[K0 == 0], 0.0)
        if j >= 3:
            assert adapt.scale[tone] == 4.0
            assert K1[tone] > 1.5 * K0[tone]
    assert np.all((adapt.scale >= 1.0) & (adapt.scale <= 4.0))


def test_where_the_error_rises_the_factor_returns_to_one():
    f = rfftfreq(G, T)
    w = SpectralGain(WeightingSettings(adapt_max=8.0))
    tone = np.argmin(np.abs(f - 12.0))
    for E in records(4, 0.5):             # falls: 1, 2, 4, 8
        w(E, f)
    assert w.scale[tone] == 8.0
    for E in records(4, 1.0)[1:][::-1] + records(3, 2.0)[1:]:
        w(E, f)
    # the tone now at 60 µm then rising: c falls back, ÷ 2 an update, to its floor 1
    assert w.scale[tone] == 1.0


def test_the_tiles_inflate_where_a_tile_falls():
    """:class:`TileGain` applies (5) per (bin, tile): a burst at 12 Hz in the record's
    second half that halves every run inflates its tiles, not the first half's."""
    t = np.arange(G) * T
    w = TileGain(WeightingSettings(window_s=1.0, adapt_max=4.0), T)
    for k in range(4):
        x = np.zeros((G, 3))
        x[:, 0] = 200e-6 * 0.5 ** k * np.sin(2 * np.pi * 12 * t) * (t > 5.0)
        w(x + SIGMA * np.random.default_rng(k).standard_normal(x.shape))
    fb = np.fft.rfftfreq(w.nperseg, T)
    row = np.argmin(np.abs(fb - 12.0))
    tiles = w.scale.shape[1]
    assert np.all(w.scale[row, int(0.7 * tiles):-2] == 4.0)
    quiet = slice(0, int(0.3 * tiles))     # noise alone: the sign a coin's, the gain small
    assert w.scale[row, quiet].mean() < 3.0 and w.last_gain[row, quiet].mean() < 0.1
    assert w.last_gain[row, int(0.7 * tiles):-2].min() > 0.5


@pytest.mark.parametrize("kw, msg", [
    ({"adapt_max": 0.5}, "adapt_max must be ≥ 1"),
    ({"adapt_step": 1.0}, "adapt_step > 1"),
    ({"adapt_max": math.inf}, "adapt_max must be a finite number"),
    ({"adapt_step": math.nan}, "adapt_step must be a finite number"),
    ({"adapt_margin": -1.0}, "adapt_margin ≥ 0"),
])
def test_bad_settings_are_refused_with_the_reason(kw, msg):
    with pytest.raises(ValueError, match=msg):
        WeightingSettings(**kw)
    with pytest.raises(ValueError, match="adapt_max ≥ 1, adapt_step > 1 and 0 ≤ margin < 1"):
        inflation(None, [1.0], None, 0.5, 2.0)


def test_the_matching_only_where_the_error_fell():
    """(6): with ``detect_fell`` the covariance matching resets ``S_j`` only where the
    record's power also fell below the last record's.  A tone that the runs do not
    lower (the same amplitude every run, fresh noise) is re-matched by the plain matching
    and not with (6); a tone that falls, but slower than (2) predicts, by both."""
    f = rfftfreq(G, T)
    tone = np.argmin(np.abs(f - 12.0))
    for fall, both in ((1.0, False), (0.9, True)):
        plain = SpectralGain(WeightingSettings(detect=3.0))
        fell = SpectralGain(WeightingSettings(detect=3.0, detect_fell=1))
        for E in records(5, fall):
            K0, K1 = plain(E, f), fell(E, f)
        assert K0[tone] > 0.5                    # the plain matching keeps re-raising it
        assert (K1[tone] > 0.5) == both


def test_the_matching_only_where_the_error_fell_is_off_by_default():
    f = rfftfreq(G, T)
    a = SpectralGain(WeightingSettings(detect=3.0))
    b = SpectralGain(WeightingSettings(detect=3.0, detect_fell=0))
    for E in records(4, 0.9):
        np.testing.assert_array_equal(a(E, f), b(E, f))
    with pytest.raises(ValueError, match="detect_fell must be 0 or 1"):
        WeightingSettings(detect_fell=2)
