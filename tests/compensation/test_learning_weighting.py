"""The learning's input weighted by its signal-to-noise per frequency
(plugcell.compensation.tracking.smoothing): the Wiener estimate of a record beats the raw
samples by the factor its equation predicts, the Kalman gain of the runs is the running
mean where the error is far above the noise and small where it is below, the weighted
law keeps the contraction condition (property-tested), the learning with it on a plant
with modes, and bad input.  Seeded and deterministic."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.fft import irfft, rfft, rfftfreq
from scipy.signal import stft
from test_learning_inverse import F, T, arm, disturbance, identified, true_response

from plugcell.compensation.tracking import (
    DEFAULT_WEIGHTING,
    InverseSettings,
    IterativeLearning,
    LearningSettings,
    SpectralGain,
    TileGain,
    WeightingSettings,
    contraction_inverse,
    weighting_for,
)
from plugcell.compensation.tracking.smoothing import noise_power, smoothed_power, wiener_gain

SIGMA = 45e-6   # the twin's tracker noise per 4 ms cycle and axis (m)
G = 4096
FC = F[::4]                  # a coarser grid for the property test (fast)
TRUE = true_response(FC)


def signal(seed: int = 0) -> np.ndarray:
    """A repeating error in a few bands below 20 Hz (m, (G, 3)): a slow drift, a 12 Hz
    mode rung at 2 s."""
    t = np.arange(G) * T
    x = np.zeros((G, 3))
    x[:, 0] = 80e-6 * np.sin(2 * np.pi * 0.3 * t)
    x[:, 1] = 40e-6 * np.cos(2 * np.pi * 0.7 * t + 0.4)
    after = np.clip(t - 2.0, 0.0, None)
    x[:, 2] = 60e-6 * np.exp(-0.04 * 2 * np.pi * 12 * after) * np.sin(2 * np.pi * 12 * after) \
        * (t >= 2.0)
    return x


def test_the_wiener_estimate_beats_the_raw_samples_by_the_predicted_factor():
    """(1): X̂ = K E with K = S/(S + N) from the record alone; its error power is
    Σ S N/(S + N) against the raw record's Σ N — predicted from the true S (|X|²) and N
    (G σ² a bin), measured on seeded white noise."""
    x = signal()
    f = rfftfreq(G, T)
    X = rfft(x, axis=0)
    ratios = []
    for seed in range(4):
        n = SIGMA * np.random.default_rng(seed).standard_normal(x.shape)
        E = rfft(x + n, axis=0)
        K = SpectralGain(WeightingSettings())(E, f)
        est = irfft(K[:, None] * E, G, axis=0)
        ratios.append(np.mean((est - x) ** 2) / np.mean(n ** 2))
    S = (np.abs(X) ** 2).sum(axis=1)
    N = 3 * G * SIGMA ** 2
    predicted = float(np.sum(S * N / (S + N)) / np.sum(np.full(f.size, N)))
    measured = float(np.mean(ratios))
    assert measured < 0.1                           # the noise falls ten times and more
    assert 0.5 * predicted < measured < 3.0 * predicted, (measured, predicted)
    # not learning by the weight (K = 1) would keep all of it
    assert np.mean((irfft(E, G, axis=0) - x) ** 2) / np.mean(n ** 2) > 0.99


def test_the_tile_estimate_beats_the_raw_samples_by_the_predicted_factor():
    """The same per tile of a short-time FFT (1 s Hann windows): the error power
    Σ S N/(S + N) over the tiles against Σ N, S from the noiseless signal's tiles (the
    frame is tight: both sums count each sample's energy the same number of times)."""
    x = signal()
    kw = {"fs": 1 / T, "window": "hann", "nperseg": 250, "noverlap": 187}
    _, _, X = stft(x.T, boundary="even", padded=True, **kw)
    ratios = []
    for seed in range(4):
        n = SIGMA * np.random.default_rng(seed).standard_normal(x.shape)
        est = TileGain(WeightingSettings(window_s=1.0), T)(x + n)
        ratios.append(np.mean((est - x) ** 2) / np.mean(n ** 2))
    _, _, Nx = stft(SIGMA * np.random.default_rng(99).standard_normal(x.shape).T,
                    boundary="even", padded=True, **kw)
    S, N = (np.abs(X) ** 2).sum(axis=0), float((np.abs(Nx) ** 2).sum(axis=0).mean())
    predicted = float(np.sum(S * N / (S + N)) / (N * S.size))
    measured = float(np.mean(ratios))
    assert measured < 0.1
    assert 0.5 * predicted < measured < 3.0 * predicted, (measured, predicted)


def test_the_tiles_give_back_a_signal_without_noise():
    """istft(stft(e)) = e: with no noise in the noise band every tile's K is 1."""
    x = signal()
    tiles = TileGain(WeightingSettings(window_s=0.5), T)
    assert np.abs(tiles(x) - x).max() < 0.01 * 80e-6
    assert tiles.last_gain is not None and tiles.last_gain.shape == tiles.shape(x.shape[0])


def test_the_noise_power_is_that_of_white_noise_in_every_bin():
    n = SIGMA * np.random.default_rng(5).standard_normal((G, 3))
    f = rfftfreq(G, T)
    N = noise_power(rfft(n, axis=0), f, (50.0, 110.0))
    assert np.allclose(N, G * SIGMA ** 2, rtol=0.1)
    p, averaged = smoothed_power(rfft(n, axis=0), f, 0.5)
    bins = 2 * int(0.5 / (f[1] - f[0])) + 1
    assert averaged == bins
    assert abs(p[(f > 2) & (f < 40)].mean() / (G * SIGMA ** 2) - 1.0) < 0.1


def test_the_kalman_gain_is_the_running_mean_where_the_error_is_large_and_small_where_not():
    """(2): with an error far above the noise at 5 Hz learned away each run, K_j(5 Hz) =
    1/(1 + j); at 30 Hz, where there is only noise, K stays near 0."""
    t = np.arange(G) * T
    f = rfftfreq(G, T)
    gain = SpectralGain(WeightingSettings())
    at5, at30 = np.argmin(np.abs(f - 5.0)), (f > 25.0) & (f < 35.0)
    x = 2e-3 * np.sin(2 * np.pi * f[at5] * t)[:, None] * np.ones(3)  # on a bin: no leak
    for j in range(6):
        n = SIGMA * np.random.default_rng(10 + j).standard_normal((G, 3))
        assert (gain.last_gain is None) == (j == 0)
        K = gain(rfft((x if j == 0 else 0.0) + n, axis=0), f)
        np.testing.assert_array_equal(gain.last_gain, K)   # kept for a look, a copy
        assert gain.last_gain is not K
        assert K[at5] == pytest.approx(1.0 / (1.0 + j), rel=0.05)
        assert K[at30].mean() < 0.05
    assert len(gain.history) == 6


def test_covariance_matching_raises_the_gain_where_a_new_error_shows():
    """A run whose 8 Hz power exceeds what (2) expects (the model's residual): K rises
    there again, and nowhere else; with the matching off (the default) it does not."""
    t = np.arange(G) * T
    f = rfftfreq(G, T)
    gain, off = SpectralGain(WeightingSettings(detect=3.0)), SpectralGain(WeightingSettings())
    at8 = np.argmin(np.abs(f - 8.0))
    big = 1e-3 * np.sin(2 * np.pi * f[at8] * t)[:, None] * np.ones(3)
    rng = np.random.default_rng(20)
    for j in range(4):
        E = rfft((big if j == 0 else 0.0) + SIGMA * rng.standard_normal((G, 3)), axis=0)
        gain(E, f)
        off(E, f)
    E = rfft(0.3 * big + SIGMA * rng.standard_normal((G, 3)), axis=0)
    K = gain(E, f)
    assert K[at8] > 0.9
    assert K[(f > 20.0) & (f < 40.0)].mean() < 0.05
    assert off(E, f)[at8] == pytest.approx(1.0 / 5.0, rel=0.05)      # 1/(1 + j), j = 4


@settings(max_examples=25, deadline=None)
@given(gain=st.floats(0.05, 1.95), reg=st.floats(1e-3, 1.0), shift=st.floats(0.97, 1.05),
       weight=st.floats(0.0, 1.0), seed=st.integers(0, 1000))
def test_the_weight_never_breaks_the_contraction(gain, reg, shift, weight, seed):
    """ρ_I with a weight K ∈ [0, 1] per frequency: σ_max(I − γ K L̂ P) ≤ (1 − K) +
    K σ_max(I − γ L̂ P) — never above 1 where (4) holds; the model's modes sit off by
    ``shift`` (its response is the arm's at ``f / shift``)."""
    s = InverseSettings(gain=gain, regularisation=reg, cutoff_hz=20.0)
    P, M = TRUE, true_response(FC / shift)
    K = np.clip(weight + 0.2 * np.random.default_rng(seed).standard_normal(FC.size), 0.0, 1.0)
    rho1 = contraction_inverse(s, T, FC, P, M)
    rhok = contraction_inverse(s, T, FC, P, M, weight=K)
    assert rhok <= max(1.0, rho1) + 1e-12
    if rho1 < 1.0:
        assert rhok <= 1.0 + 1e-12
    if rho1 < 1.0 and K.min() > 0.0:
        assert rhok < 1.0
    c = weight
    assert contraction_inverse(s, T, FC, P, M, weight=np.full(FC.size, c)) <= \
        (1.0 - c) + c * rho1 + 1e-12


def test_a_weight_keeps_a_model_that_contracts_contracting_and_one_that_does_not_not():
    """The bound is not vacuous: a model 10 % off breaks (4) (ρ_I > 1), and a weight
    K < 1 everywhere does not mend it where K stays near 1 at the broken frequencies."""
    s = InverseSettings(gain=1.0, regularisation=1e-3, cutoff_hz=30.0)
    wrong = true_response(FC / 1.1)
    assert contraction_inverse(s, T, FC, TRUE, wrong) > 1.0
    assert contraction_inverse(s, T, FC, TRUE, wrong, weight=np.full(FC.size, 0.9)) > 1.0
    assert contraction_inverse(s, T, FC, TRUE, TRUE, weight=np.full(FC.size, 0.5)) < 1.0


def run(weighting: WeightingSettings | None, runs: int) -> list[float]:
    """True rms error of each run of the inverse law on the arm, 45 µm noise per cycle."""
    il = IterativeLearning(3.0, LearningSettings(inverse=InverseSettings(),
                                                 weighting=weighting), plant=identified())
    d = disturbance(il.grid)
    out = []
    for k in range(runs):
        e = d + arm(il.u)
        out.append(float(np.sqrt(np.mean(e[100:-100] ** 2))))
        il.step(e + SIGMA * np.random.default_rng(300 + k).standard_normal(e.shape))
    return out


@pytest.mark.slow  # the identification of the plant (a minute on a loaded machine)
@pytest.mark.parametrize("window_s", [0.0, 1.0])
def test_the_weighted_learning_converges_and_learns_less_noise(window_s):
    """On the plant with modes, the same noise: the weighted law's first runs keep well
    under the running mean's error (per frequency and per 1 s tile); it goes on
    converging."""
    plain = run(None, 4)
    weighted = run(WeightingSettings(window_s=window_s), 4)
    assert weighted[0] == plain[0]
    assert weighted[1] < 0.7 * plain[1]
    assert weighted[3] < plain[3]
    assert weighted[3] < weighted[0] / 5


@pytest.mark.parametrize("kw, words", [
    ({"noise_low_hz": 0.0}, "noise_low_hz"), ({"noise_high_hz": 40.0}, "noise_low_hz"),
    ({"smooth_hz": 0.0}, "smooth_hz"), ({"detect": -1.0}, "detect"),
    ({"detect": math.nan}, "finite"), ({"smooth_hz": True}, "finite"),
    ({"smooth_hz": math.inf}, "finite"),
])
def test_bad_weighting_settings_are_named(kw, words):
    with pytest.raises(ValueError, match=words):
        WeightingSettings(**kw)


def test_bad_weighting_input_is_named():
    # the default weighting is inert without the law (3): the P-type law learns all of
    # the error, whatever the cycle (its noise band is checked only with the law (3))
    assert LearningSettings().weighting == DEFAULT_WEIGHTING
    assert IterativeLearning(3.0, LearningSettings()).prior_shape() is None
    LearningSettings(cycle_s=0.012)
    with pytest.raises(ValueError, match=r"noise_high_hz 110.0 must lie below the Nyquist "
                       r"rate 41.6667 Hz"):
        LearningSettings(cycle_s=0.012, inverse=InverseSettings(
            cutoff_hz=20.0, band_high_hz=40.0, excitation_high_hz=30.0))
    with pytest.raises(ValueError, match="Nyquist"):
        LearningSettings(inverse=InverseSettings(),
                         weighting=WeightingSettings(noise_high_hz=130.0))
    with pytest.raises(ValueError, match="WeightingSettings"):
        LearningSettings(inverse=InverseSettings(), weighting="yes")  # type: ignore[arg-type]
    f = rfftfreq(256, T)
    E = np.ones((f.size, 3), complex)
    with pytest.raises(ValueError, match="at least 8"):
        noise_power(E, f, (100.0, 101.0))
    with pytest.raises(ValueError, match="finite"):
        noise_power(E * np.nan, f, (50.0, 110.0))
    with pytest.raises(ValueError, match="spectrum"):
        smoothed_power(E[:, 0], f, 0.5)
    with pytest.raises(ValueError, match="half_width"):
        smoothed_power(E, f, 0.0)
    with pytest.raises(ValueError, match="≥ 0"):
        wiener_gain(-np.ones((3, 3)), 1.0)
    with pytest.raises(ValueError, match="gain"):
        SpectralGain(WeightingSettings(), gain=2.0)
    with pytest.raises(ValueError, match="16 cycles"):
        TileGain(WeightingSettings(window_s=0.02), T)
    with pytest.raises(ValueError, match="G ≥"):
        TileGain(WeightingSettings(window_s=1.0), T)(np.zeros((100, 3)))
    with pytest.raises(ValueError, match="window_s"):
        WeightingSettings(window_s=-1.0)
    with pytest.raises(ValueError, match="weight"):
        contraction_inverse(InverseSettings(), T, F, true_response(), true_response(),
                            weight=np.full(F.size, 1.5))


def test_a_record_shorter_than_two_tiles_is_learned_by_one_gain_per_frequency():
    """The default weighting tiles by 1 s: a record of ≥ 2 tiles (500 cycles of 4 ms) gets
    :class:`TileGain`, a shorter one (a short path) the whole-run :class:`SpectralGain`
    without the matching — the learning of a 1 s path runs its updates instead of
    refusing the record; ``window_s`` 0 keeps the settings as asked."""
    assert DEFAULT_WEIGHTING.window_s == 1.0 and DEFAULT_WEIGHTING.detect == 3.0
    assert isinstance(weighting_for(DEFAULT_WEIGHTING, 1.0, T, 500), TileGain)
    short = weighting_for(DEFAULT_WEIGHTING, 1.0, T, 499)
    assert isinstance(short, SpectralGain)
    assert short.settings == WeightingSettings(adapt_max=DEFAULT_WEIGHTING.adapt_max,
                                               detect_fell=DEFAULT_WEIGHTING.detect_fell)
    whole = weighting_for(WeightingSettings(detect=3.0), 1.0, T, 5000)
    assert isinstance(whole, SpectralGain) and whole.settings.detect == 3.0  # as asked
    settings = LearningSettings(lead_s=0.008, inverse=InverseSettings())
    short, long = IterativeLearning(0.5, settings), IterativeLearning(3.0, settings)
    assert isinstance(short.weighting, SpectralGain) and isinstance(long.weighting, TileGain)
    rng = np.random.default_rng(3)
    for learning in (short, long):
        G = learning.grid.size
        learning.learn_error(1e-4 * rng.standard_normal((G, 3)), np.ones(G, bool))
        excited = learning.u.copy()
        for _ in range(2):
            learning.learn_error(1e-4 * rng.standard_normal((G, 3)), np.ones(G, bool))
        assert learning.inverse_steps >= 1 and np.all(np.isfinite(learning.u))
        assert not np.array_equal(learning.u, excited)
