"""Iterative learning for repeated paths (plugcell.compensation.tracking.learning): the
law's convergence on a linear plant with a known dead time (monotone where the
contraction condition holds, divergent where it fails, property-tested), the noise it
keeps with fresh noise every run, the measured error on the cycle grid, bad input."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.signal import cont2discrete, freqz, lfilter

from plugcell.compensation.tracking import (
    IterativeLearning,
    LearnedOffset,
    LearningSettings,
    contraction,
    path_error,
)

T = 0.004
F = np.linspace(0.0, 0.5 / T, 2001)


def servo(fn: float = 8.0, zeta: float = 0.7) -> tuple[np.ndarray, np.ndarray]:
    """A servo's closed loop ω²/(s² + 2ζωs + ω²), zero-order hold at T."""
    w = 2 * np.pi * fn
    b, a, _ = cont2discrete(([w * w], [1.0, 2 * zeta * w, w * w]), T, method="zoh")
    return np.ravel(b), np.ravel(a)


def respond(u: np.ndarray, dead: int, disturbance: np.ndarray) -> np.ndarray:
    """e = d + z^{-dead} G u: the arm's error when the target moves by u."""
    b, a = servo()
    y = lfilter(b, a, u, axis=0)
    return disturbance + np.vstack([np.zeros((dead, 3)), y[: len(y) - dead]])


def plant(dead: int) -> np.ndarray:
    b, a = servo()
    _, H = freqz(b, a, worN=F, fs=1 / T)
    return H * np.exp(-2j * np.pi * F * dead * T)


def disturbance(grid: np.ndarray, fast: bool = False) -> np.ndarray:
    """A repeating error over a 3 s motion: slow drifts, a reversal, (a 12 Hz ringing)."""
    d = np.zeros((grid.size, 3))
    on = np.clip(np.minimum(grid, 3.0 - grid) / 0.3, 0.0, 1.0)
    on = 0.5 - 0.5 * np.cos(np.pi * on)          # fades in and out over 0.3 s
    d[:, 0] = 0.2e-3 * np.sin(2 * np.pi * 0.5 * grid) * on
    d[:, 1] = 0.1e-3 * np.tanh((grid - 1.0) / 0.2) * on
    d[:, 2] = 0.05e-3 * (1 - np.cos(2 * np.pi * grid / 3.0)) * on
    if fast:
        d[:, 2] += 0.05e-3 * np.sin(2 * np.pi * 12.0 * grid) * on
    return d


def learn(s: LearningSettings, dead: int, runs: int, noise: float = 0.0,
          fast: bool = False) -> tuple[list[float], IterativeLearning, np.ndarray]:
    """Norms of the true error per run; noise fresh every run (a seed per run)."""
    il = IterativeLearning(3.0, s)
    d = disturbance(il.grid, fast)
    norms = []
    for k in range(runs):
        e = respond(il.u, dead, d)
        norms.append(float(np.linalg.norm(e)))
        measured = e + noise * np.random.default_rng(100 + k).standard_normal(e.shape)
        il.step(measured)
    return norms, il, d


def test_the_error_converges_where_the_lead_covers_the_dead_time():
    s = LearningSettings(gain=0.8, lead_s=2 * T, cutoff_hz=4.0)
    assert contraction(s, F, plant(2)) < 0.5
    norms, _, _ = learn(s, dead=2, runs=10)
    assert norms[-1] < 0.03 * norms[0]
    # (2) makes u contract monotonically; the error follows it down to its floor
    assert all(b <= a + 1e-3 * norms[0] for a, b in itertools.pairwise(norms))


def test_above_the_cut_off_the_error_stays_what_it_was():
    s = LearningSettings(gain=0.8, lead_s=2 * T, cutoff_hz=4.0)
    norms, il, d = learn(s, dead=2, runs=10, fast=True)
    slow = learn(s, dead=2, runs=1)[0][0]
    assert norms[-1] == pytest.approx(np.linalg.norm(d - disturbance(il.grid)), rel=0.1)
    assert norms[-1] < 0.5 * norms[0] and norms[0] == pytest.approx(
        np.linalg.norm(d), rel=1e-12) and slow < norms[0]


def test_without_the_lead_a_large_gain_and_a_wide_filter_diverge():
    s = LearningSettings(gain=1.5, lead_s=0.0, cutoff_hz=20.0)
    assert contraction(s, F, plant(3)) > 1.0
    norms, _, _ = learn(s, dead=3, runs=12)
    assert norms[-1] > norms[0] and norms[-1] > 4 * min(norms)


@settings(max_examples=25, deadline=None)
@given(gain=st.floats(0.3, 1.5), cutoff=st.floats(1.0, 6.0), dead=st.integers(0, 4))
def test_where_the_contraction_holds_the_learning_contracts(gain, cutoff, dead):
    """(2): each run changes u by at most ρ times the previous run's change (monotone,
    geometric convergence), and the error ends below where it started."""
    s = LearningSettings(gain=gain, lead_s=dead * T, cutoff_hz=cutoff)
    rho = contraction(s, F, plant(dead))
    assert rho < 1.0
    il = IterativeLearning(3.0, s)
    d = disturbance(il.grid)
    us, norms = [il.u.copy()], []
    for _ in range(8):
        e = respond(il.u, dead, d)
        norms.append(float(np.linalg.norm(e)))
        us.append(il.step(e))
    du = [np.linalg.norm(b - a) for a, b in itertools.pairwise(us)]
    for a, b in itertools.pairwise(du):
        assert b <= rho * a + 1e-15
    assert norms[-1] < 0.5 * norms[0]


def test_fresh_noise_leaves_the_predicted_floor():
    """σ per cycle 45 µm; in u it leaves σ_Q √(L/(2−L)), σ_Q² = σ² · mean |Q|² over the
    band (|Q| = |B|², zero phase)."""
    sigma, s = 45e-6, LearningSettings(gain=0.5, lead_s=2 * T, cutoff_hz=2.0)
    norms, il, _ = learn(s, dead=2, runs=16, noise=sigma)
    b, a = s.q_filter()
    _, B = freqz(b, a, worN=F, fs=1 / T)
    sigma_q = sigma * math.sqrt(np.mean(np.abs(B) ** 4))
    floor = sigma_q * math.sqrt(s.gain / (2 - s.gain)) * math.sqrt(il.u.size)
    assert norms[-1] < 1.5 * floor + 0.02 * norms[0]
    assert norms[-1] < 0.1 * norms[0]


def test_the_error_is_averaged_per_cycle_against_the_path_at_the_sample_time():
    path_t = np.arange(0.0, 1.0, T)
    path_p = np.column_stack([0.1 * path_t, np.zeros_like(path_t), np.ones_like(path_t)])
    grid = np.arange(0.1, 0.2, T)
    ts = np.arange(0.0985, 0.2, 0.001)          # 1 kHz, offset from the cycles
    ps = np.column_stack([0.1 * ts + 1e-5, np.full_like(ts, 2e-5), np.ones_like(ts)])
    ps[(ts > 0.15) & (ts < 0.16)] = np.nan      # a beam break: nothing measured
    e, measured = path_error(ts, ps, path_t, path_p, grid, T)
    assert np.all(measured[grid < 0.148]) and not np.any(measured[(grid > 0.152) &
                                                                   (grid < 0.158)])
    np.testing.assert_allclose(e[measured], np.tile([1e-5, 2e-5, 0.0], (measured.sum(), 1)),
                               atol=1e-12)
    assert np.all(e[~measured] == 0)


def test_no_sample_at_all_is_nothing_measured():
    """A run the tracker never saw (no sample, or none inside the path) is an all-zero
    float error with nothing measured, not numpy's integer bincount failing to divide."""
    path_t = np.arange(0.0, 1.0, T)
    path_p = np.zeros((path_t.size, 3))
    grid = np.arange(0.1, 0.2, T)
    for ts in (np.zeros(0), np.array([5.0])):       # none; one outside the path
        e, measured = path_error(ts, np.zeros((ts.size, 3)), path_t, path_p, grid, T)
        assert e.dtype == float and e.shape == (grid.size, 3) and not measured.any()
        assert np.all(e == 0)


def test_the_learned_offset_is_linear_between_cycles_and_zero_outside():
    lo = LearnedOffset(np.array([1.0, 1.004, 1.008]),
                       np.array([[0.0, 0, 0], [4e-6, 0, 0], [0, 0, 0]]))
    assert lo(1.002)[0] == pytest.approx(2e-6)
    assert np.all(lo(0.9) == 0) and np.all(lo(1.02) == 0)
    il = IterativeLearning(1.0)
    il.step(np.full(il.u.shape, 1e-4))
    ff = il.feedforward(2.0)
    assert np.all(ff(2.0 - il.settings.pre_s) == 0)   # the window fades to zero
    assert ff(2.5)[0] == pytest.approx(-0.8e-4, rel=1e-3)


@pytest.mark.parametrize(("kw", "words"), [
    ({"gain": 2.0}, "gain (L) must lie in (0, 2)"),
    ({"gain": math.nan}, "gain must be a finite number"),
    ({"cutoff_hz": 130.0}, "below the Nyquist rate 125 Hz"),
    ({"order": 2.5}, "order must be an integer"),
    ({"lead_s": -0.001}, "lead_s must be ≥ 0"),
    ({"cycle_s": 0.0}, "cycle_s must be > 0"),
])
def test_bad_settings_are_named(kw, words):
    with pytest.raises(ValueError, match=words.replace("(", r"\(").replace(")", r"\)")):
        LearningSettings(**kw)


def test_bad_learning_input_is_named():
    with pytest.raises(ValueError, match="duration must be > 0"):
        IterativeLearning(0.0)
    with pytest.raises(ValueError, match="taper_s"):
        IterativeLearning(0.01, LearningSettings(pre_s=0.0, post_s=0.0))
    il = IterativeLearning(1.0)
    with pytest.raises(ValueError, match="expected a finite error of shape"):
        il.step(np.zeros((3, 3)))
    with pytest.raises(ValueError, match="increasing"):
        path_error([0.0], [[0, 0, 0]], [0.0, 0.0], [[0, 0, 0]] * 2, [0.0], T)
    with pytest.raises(ValueError, match="1-D of one length"):
        contraction(LearningSettings(), F, np.ones(3))


def test_a_decreasing_gain_averages_the_noise_of_the_runs():
    """L_k = L/(1 + λk): the same start, and less of the fresh noise kept at the end."""
    sigma = 45e-6
    fixed = LearningSettings(gain=0.8, lead_s=2 * T, cutoff_hz=4.0)
    decaying = LearningSettings(gain=0.8, lead_s=2 * T, cutoff_hz=4.0, gain_decay=0.5)
    a, _, _ = learn(fixed, dead=2, runs=12, noise=sigma)
    b, il_b, _ = learn(decaying, dead=2, runs=12, noise=sigma)
    assert b[1] == pytest.approx(a[1], rel=1e-12) and il_b.steps == 12
    assert b[-1] < 0.8 * a[-1]
