"""How much of a run's measured error to learn, frequency by frequency: a Kalman gain per
frequency between the runs of a repeated path (issue 38 §4, the learning's input).

Between two runs the learning (:mod:`.learning`, law (3)) is offline: it sees a whole
run's measured error ``e_k = x_k + n_k`` at once — ``x_k`` the path's repeating error
that run left, ``n_k`` the tracker's fresh noise (white at the cycle rate: 90 µm per
1 kHz sample, ≈ 45 µm per 4 ms cycle on the Smart H4 twin).  The law learns ``γ_j`` of
all of ``e_k`` in ``Q_I``'s band, so each run puts ``γ_j n_k`` into the offset wherever
the arm follows — also at the frequencies where the path has no error worth learning.
Per frequency (the DFT bin ``f`` of the padded record, axis ``i``) the repeating part
and the noise are independent; with ``S_j(f)`` the expected power of ``X_j(f)`` still to
learn before run ``j``'s update and ``N(f)`` the noise's, the minimum-variance estimate
of ``X_j`` from ``E_j`` (the non-causal Wiener smoother of the record; Wiener 1949;
Kailath, Sayed & Hassibi, *Linear estimation*, 2000, §7) is::

    X̂_j = K_j E_j,   K_j = S_j / (S_j + N)                                   (1)

with the error power ``S_j N / (S_j + N)`` — below both ``S_j`` and ``N``: the noise
the update lets through falls by ``K_j²`` where ``S_j ≪ N``.  Learning ``X̂_j`` with
(3) of :mod:`.learning` at ``γ = 1`` on an exact model removes it, and what remains has
the power (the Kalman recursion of a constant state observed once a run)::

    S_{j+1} = (1 − γ K_j)² S_j + γ² K_j² N   =   S_j N / (S_j + N)   (γ = 1)       (2)

so ``1/S_j = 1/S_0 + j/N`` and ``K_j = 1 / (1 + j + N/S_0)``: at a frequency where the
first run's error is far above the noise, ``K_j = 1/(1 + j)`` — the running mean of
(3)'s default; where it is below, the gain is small from the first run on, and the
offset keeps ``S_0 N / (S_0 + (j + 1) N)`` instead of ``N / (j + 1)`` of noise there.

**Estimates, from the measured records alone.**  ``N(f)``: the noise is white, so its
power is the mean of ``|E_j|²`` in a band where the arm does not answer (``noise_band``,
above the modes and ``Q_I``; its bins' noise is that of every bin, the padding of the
record included).  ``S_0``: the first run's power, smoothed over ``±smooth_hz`` (``M``
bins, a Bartlett–Welch average: its relative spread ``1/√M``), less ``N``, not below 0.
**Covariance matching** (optional, ``detect``; Mehra, IEEE Trans. Autom. Control 15(2),
1970): an
update on a model with errors leaves more than (2) predicts; when a run's smoothed
power exceeds what (2) expects, ``S_j + N``, by more than ``κ`` standard deviations of
the average (``(S_j + N)(1 + κ/√M)``), ``S_j`` is reset to that power less ``N`` — the
gain rises again where the model's residual or a new error shows, and only there.

**Inflation where the last update made the error fall** (optional, ``adapt_max`` > 1):
(2) lets ``K_j`` decay like a whole run's Wiener gain, also where the error that is left
sits in a small part of the run (a second of ringing at a stop) and is learnt only
slowly.  Each bin (each tile, :class:`TileGain`) keeps a factor ``c_j ∈ [1, c_max]`` on
its prior, updated from the powers ``P`` the update sees (the smoothed ``|E|²`` summed
over the axes, :math:`S + N`'s estimate) of this record and the last one::

    c_0 = 1,   c_j = clip(c_{j−1} · a,  1, c_max)   where P_j < P_{j−1} (1 − κ_a/√M)   (5)
               c_j = clip(c_{j−1} / a,  1, c_max)   elsewhere

    K_j = c_j S_j / (c_j S_j + N),   S_{j+1} = (1 − γ K_j)² c_j S_j + γ² K_j² N

— the sign rule of resilient back-propagation (Riedmiller & Braun, IEEE ICNN 1993) on the
fading-memory Kalman filter's inflation of the prior (Sorenson & Sacks, Inf. Sci. 3,
1971; Jazwinski, *Stochastic processes and filtering theory*, 1970, §7.6): where the
last update lowered the error the learning forgets its older runs faster and learns more
of this one; where the error rose (a model wrong there, or the noise floor reached) the
factor falls back to 1, (2)'s gain.  ``K_j`` is monotone in ``c_j`` and in ``[K_j(c=1),
c_max S_j/(c_max S_j + N)]``: never below (2)'s gain, never 1 where ``S_j`` is finite, 0
where ``S_j`` is 0 (no signal seen, no inflation); ``c_max`` = 1 is (2) exactly.  ``κ_a``
(``adapt_margin``, ≥ 0) asks the fall to exceed that many standard deviations of the
average of ``M`` values (as the matching's ``κ``): where the power is the noise's, the
sign of a difference is a coin's, and ``c`` then falls back to 1 more often than not.
(With ``c_j = c`` held, (2) from the inflated prior settles where ``S = c S N/(c S + N)``:
``S* = (c − 1) N``, ``K* = 1 − 1/c`` at ``γ`` = 1 — the gain no longer decays to 0.)

**The matching only where the error fell** (optional, ``detect_fell`` 1): the matching
raises ``S_j`` where a run's error stays above (2)'s prediction — the residual a model
learns slowly, but also where the model is wrong and a larger gain makes it worse (the
twin's line at 250 mm/s).  With ``detect_fell`` the reset acts only where, besides,
``P_j < P_{j−1}``: the last update lowered the error there, so the model's direction is
right and only its step was short::

    S_j ← max(P_j − N, S_j)   where P_j > (S_j + N)(1 + κ/√M)  and  P_j < P_{j−1}     (6)

The three axes share one gain per frequency (``S`` and ``N`` are the powers summed
over the axes): the weight is then a scalar ``K ∈ [0, 1]`` at each frequency and

**convergence is kept**: (3)'s iteration matrix with the weight is
``I − γ K L̂ P = (1 − K) I + K (I − γ L̂ P)``, so by the triangle inequality
``σ_max(I − γ K L̂ P) ≤ (1 − K) + K σ_max(I − γ L̂ P)`` — a convex combination of 1 and
(4)'s factor: below 1 wherever (4) holds and ``K > 0``, never above 1 where it holds
(:func:`.learning.contraction_inverse` with ``weight``).

Pure math: numpy and scipy, SI units, no I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.ndimage import uniform_filter, uniform_filter1d
from scipy.signal import istft, stft

Array = NDArray[np.float64]

__all__ = ["SpectralGain", "TileGain", "WeightingSettings", "inflation", "noise_power",
           "smoothed_power", "wiener_gain"]


@dataclass(frozen=True)
class WeightingSettings:
    """The per-frequency gain (module docstring); SI.

    ``WeightingSettings()`` is the whole-run gain (2) without the options; the learning's
    default is ``DEFAULT_WEIGHTING`` of :mod:`.learning` (per 1 s tile, (6) at ``κ`` = 3).

    Attributes
    ----------
    noise_low_hz, noise_high_hz : float
        The band where the measured error is noise alone (Hz): above the arm's modes and
        the learning's ``Q_I``, below the Nyquist rate.
    smooth_hz : float
        Half width of the moving average of the power over frequency (Hz).
    detect : float
        ``κ`` of the covariance matching, in standard deviations of the average (≥ 0);
        ``math.inf`` (the default) switches it off: then ``K_j ≤ 1/(1 + j)`` everywhere,
        never more gain than the running mean (on the twin's line at 250 mm/s the
        matching at ``κ`` = 3 raised the gain where the model is wrong, and diverged).
    window_s : float
        0: one gain per frequency over the whole run (:class:`SpectralGain`); > 0: one per
        tile of a short-time Fourier transform with Hann windows of this length (s), 3/4
        overlap (:class:`TileGain`: the error the path keeps is where and when it rings).
    adapt_max : float
        ``c_max`` ≥ 1 of the inflation (5) where the last update made the error fall;
        1 (the default) switches it off: (2) exactly.
    adapt_step : float
        ``a`` > 1 of (5): the factor on ``c`` per update.
    adapt_margin : float
        ``κ_a`` ≥ 0 of (5): how many standard deviations of the average the power must
        fall by to count as fallen (0: any fall).
    detect_fell : int
        1: the covariance matching acts only where the power fell below the last
        record's ((6)); 0 (the default): wherever it exceeds the prediction.
    """

    noise_low_hz: float = 50.0
    noise_high_hz: float = 110.0
    smooth_hz: float = 0.5
    detect: float = math.inf
    window_s: float = 0.0
    adapt_max: float = 1.0
    adapt_step: float = 2.0
    adapt_margin: float = 0.0
    detect_fell: int = 0

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if not (isinstance(v, int | float) and not isinstance(v, bool)
                    and (math.isfinite(v) or (f.name == "detect" and v == math.inf))):
                raise ValueError(f"WeightingSettings.{f.name} must be a finite number "
                                 f"(detect: or inf), got {v!r}")
        if not 0 < self.noise_low_hz < self.noise_high_hz:
            raise ValueError(f"WeightingSettings: need 0 < noise_low_hz < noise_high_hz, got "
                             f"{self.noise_low_hz!r} and {self.noise_high_hz!r}")
        if self.smooth_hz <= 0 or self.detect < 0 or self.window_s < 0:
            raise ValueError(f"WeightingSettings: smooth_hz must be > 0, detect and window_s "
                             f"≥ 0, got {self.smooth_hz!r}, {self.detect!r} and "
                             f"{self.window_s!r}")
        if self.detect_fell not in (0, 1):
            raise ValueError(f"WeightingSettings.detect_fell must be 0 or 1, "
                             f"got {self.detect_fell!r}")
        if not (self.adapt_max >= 1 and self.adapt_step > 1 and self.adapt_margin >= 0):
            raise ValueError(f"WeightingSettings: adapt_max must be ≥ 1 (1: off), "
                             f"adapt_step > 1 and adapt_margin ≥ 0, got {self.adapt_max!r}, "
                             f"{self.adapt_step!r} and {self.adapt_margin!r}")

    def check(self, cycle_s: float) -> None:
        """The noise band against the Nyquist rate of ``cycle_s``."""
        if self.noise_high_hz >= 0.5 / cycle_s:
            raise ValueError(f"WeightingSettings.noise_high_hz {self.noise_high_hz!r} must "
                             f"lie below the Nyquist rate {0.5 / cycle_s:g} Hz")


def _spectrum(spectrum: ArrayLike, frequency_hz: ArrayLike, who: str) -> tuple[Array, Array]:
    X = np.asarray(spectrum)
    f = np.asarray(frequency_hz, dtype=float).reshape(-1)
    if X.ndim != 2 or X.shape[0] != f.size or X.shape[0] < 2:
        raise ValueError(f"{who}: expected a spectrum (m ≥ 2, a) for {f.size} frequencies, "
                         f"got {X.shape}")
    if not np.all(np.isfinite(X)):
        raise ValueError(f"{who}: the spectrum must be finite")
    return np.abs(X) ** 2, f


def noise_power(spectrum: ArrayLike, frequency_hz: ArrayLike, band_hz: tuple[float, float]
                ) -> Array:
    """``N``: the mean of ``|E(f)|²`` over the bins in ``band_hz`` (white noise: every
    bin's), per column.

    Parameters
    ----------
    spectrum : (m, a) array_like of complex
        ``E(f)`` (an ``rfft`` of the record, m·s when scaled by nothing: any unit²).
    frequency_hz : (m,) array_like
        The bins' frequencies (Hz), increasing.
    band_hz : (float, float)
        The noise band (Hz).

    Returns
    -------
    (a,) array
        The noise power per bin, the spectrum's unit squared.
    """
    p, f = _spectrum(spectrum, frequency_hz, "noise_power")
    sel = (f >= band_hz[0]) & (f <= band_hz[1])
    if sel.sum() < 8:
        raise ValueError(f"noise_power: the band {band_hz!r} Hz holds {int(sel.sum())} bins, "
                         "need at least 8")
    return p[sel].mean(axis=0)


def smoothed_power(spectrum: ArrayLike, frequency_hz: ArrayLike, half_width_hz: float
                   ) -> tuple[Array, int]:
    """``|E(f)|²`` averaged over ``±half_width_hz`` (a moving average over ``M`` bins, the
    ends reflected).

    Parameters
    ----------
    spectrum : (m, a) array_like of complex
    frequency_hz : (m,) array_like
        Evenly spaced bins (Hz).
    half_width_hz : float
        > 0.

    Returns
    -------
    power : (m, a) array
    bins : int
        ``M``, the bins averaged (odd, ≥ 1).
    """
    p, f = _spectrum(spectrum, frequency_hz, "smoothed_power")
    df = f[1] - f[0]
    if not (math.isfinite(half_width_hz) and half_width_hz > 0 and df > 0):
        raise ValueError(f"smoothed_power: need half_width_hz > 0 and increasing bins, got "
                         f"{half_width_hz!r} and a spacing {df!r}")
    M = 2 * int(half_width_hz / df) + 1
    return uniform_filter1d(p, M, axis=0, mode="reflect"), M


def wiener_gain(signal: ArrayLike, noise: ArrayLike) -> Array:
    """(1): ``K = S / (S + N)`` (0 where both are 0).

    Parameters
    ----------
    signal : (m, a) array_like
        ``S ≥ 0``.
    noise : (a,) or (m, a) array_like
        ``N ≥ 0``.

    Returns
    -------
    (m, a) array in [0, 1]
    """
    S = np.asarray(signal, dtype=float)
    N = np.broadcast_to(np.asarray(noise, dtype=float), S.shape)
    if np.any(S < 0) or np.any(N < 0) or not (np.all(np.isfinite(S))
                                              and np.all(np.isfinite(N))):
        raise ValueError("wiener_gain: signal and noise powers must be finite and ≥ 0")
    total = S + N
    return np.divide(S, total, out=np.zeros_like(S), where=total > 0)


def inflation(scale: ArrayLike | None, power: ArrayLike, last_power: ArrayLike | None,
              adapt_max: float, adapt_step: float, margin: float = 0.0) -> Array:
    """(5): the prior's factor ``c_j`` per bin (or tile) from the last one and the powers
    of this record and the last.

    Parameters
    ----------
    scale : array_like or None
        ``c_{j−1}`` (None: the first update, ``c_0`` = 1).
    power, last_power : array_like
        ``P_j`` and ``P_{j−1}`` (any power unit, one shape; ``last_power`` None or of
        another shape: the first update).
    adapt_max : float
        ``c_max`` ≥ 1.
    adapt_step : float
        ``a`` > 1.
    margin : float
        ``κ_a/√M`` in [0, 1): the relative fall that counts (0: any).

    Returns
    -------
    array of ``power``'s shape
        ``c_j`` in ``[1, c_max]``: ``c_{j−1} a`` where ``P_j < P_{j−1} (1 − margin)``,
        ``c_{j−1} / a`` elsewhere, clipped.
    """
    P = np.asarray(power, dtype=float)
    if not (adapt_max >= 1 and adapt_step > 1 and 0 <= margin < 1):
        raise ValueError(f"inflation: need adapt_max ≥ 1, adapt_step > 1 and 0 ≤ margin < 1, "
                         f"got {adapt_max!r}, {adapt_step!r} and {margin!r}")
    if scale is None or last_power is None or np.shape(last_power) != P.shape \
            or np.shape(scale) != P.shape:
        return np.ones(P.shape)
    c, last = np.asarray(scale, dtype=float), np.asarray(last_power, dtype=float)
    fell = np.less(P, last * (1.0 - margin))
    step = np.where(fell, adapt_step, 1.0 / adapt_step)
    return np.clip(c * step, 1.0, adapt_max)


class _RunGain:
    """What :class:`SpectralGain` and :class:`TileGain` share: the state of (1), (2), the
    covariance matching and (5), and one update of it from a record's smoothed power."""

    settings: WeightingSettings
    gain: float

    def _init_state(self) -> None:
        self.prior: Array | None = None
        self.noise = math.nan
        self.history: list[dict[str, float]] = []
        self.last_gain: Array | None = None
        #: (5): ``c_j`` of the last update and the power ``P_j`` it saw (None: none yet)
        self.scale: Array | None = None
        self.power: Array | None = None

    def _advance(self, power: Array, N: float, M: int, low: NDArray[np.bool_]) -> Array:
        """``K_j`` for the smoothed power ``P`` (the record's ``S + N``, any shape) of
        ``M`` averaged values, the noise ``N``; ``low`` the bins below the noise band
        (the history's mean); advances ``S`` by (2) from the prior inflated by (5)."""
        s = self.settings
        seen = np.maximum(power - N, 0.0)
        if self.prior is None or self.prior.shape != power.shape:
            S, raised = seen, np.zeros(power.shape, bool)
        else:
            raised = power > (self.prior + N) * (1.0 + s.detect / math.sqrt(M))
            if s.detect_fell and self.power is not None and self.power.shape == power.shape:
                raised &= np.less(power, self.power)  # (6)
            S = np.where(raised, np.maximum(seen, self.prior), self.prior)
        if s.adapt_max > 1:
            self.scale = inflation(self.scale, power, self.power, s.adapt_max, s.adapt_step,
                                   min(s.adapt_margin / math.sqrt(M), 0.99))
            S = self.scale * S
        self.power = power.copy()
        K = wiener_gain(S.reshape(S.shape[0], -1), N).reshape(S.shape)
        g = self.gain * K
        self.prior = (1.0 - g) ** 2 * S + g ** 2 * N
        self.noise = N
        self.history.append({"noise": N, "mean_gain": float(K[low].mean()),
                             "rematched": float(raised[low].mean())})
        self.last_gain = K.copy()
        return K


class SpectralGain(_RunGain):
    """The per-frequency Kalman gain of the runs (module docstring, (1), (2)), one for the
    three axes (the powers summed over them).

    Parameters
    ----------
    settings : WeightingSettings
    gain : float
        ``γ`` of the update the gain feeds ((2)'s posterior), in (0, 2).

    Attributes
    ----------
    prior : (m,) array or None
        ``S_j`` per bin before the next update (``None`` before the first).
    noise : float
        ``N`` of the last record (NaN before the first).
    history : list of dict
        Per call: ``noise`` (``N``), ``mean_gain`` (``K`` averaged over the bins below
        ``noise_low_hz``), ``rematched`` (share of those bins whose ``S`` the covariance
        matching raised).
    last_gain : (m,) array or None
        ``K_j`` of the last call (``None`` before the first; not part of the saved state).
    scale, power : (m,) arrays or None
        (5)'s ``c_j`` (None while ``adapt_max`` is 1) and the power ``P_j`` of the last
        record ((5), (6)); None before the first call.

    API note: ``gain = SpectralGain(settings); K = gain(E, f)`` once per update, ``E``
    the record's spectrum (m, a), then learn ``K[:, None] * E``.
    """

    def __init__(self, settings: WeightingSettings, gain: float = 1.0) -> None:
        if not 0 < gain < 2:
            raise ValueError(f"SpectralGain: gain must lie in (0, 2), got {gain!r}")
        self.settings = settings
        self.gain = float(gain)
        self._init_state()

    def __call__(self, spectrum: ArrayLike, frequency_hz: ArrayLike) -> Array:
        """``K_j`` (m,) for the record ``E_j`` (m, a) on the bins ``frequency_hz`` (m,);
        advances ``S`` by (2) (and ``c`` by (5))."""
        s = self.settings
        f = np.asarray(frequency_hz, dtype=float).reshape(-1)
        N = float(noise_power(spectrum, f, (s.noise_low_hz, s.noise_high_hz)).sum())
        power, M = smoothed_power(spectrum, f, s.smooth_hz)
        return self._advance(power.sum(axis=1), N, M, f < s.noise_low_hz)


class TileGain(_RunGain):
    """(1) and (2) per tile of a short-time Fourier transform (Hann windows of
    ``window_s``, 3/4 overlap: a tight frame up to the record's ends (extended evenly),
    ``istft(stft(e)) = e``): the error a path
    keeps after a few runs sits in a few places (its start, its stop, where a joint turns)
    at the modes' frequencies, so a tile there holds far more of it than the whole run's
    bin does, against the same noise per tile.  ``N``: the mean tile power in the noise
    band; ``S``: the tiles' power averaged over 3 × 3 neighbours less ``N`` (``M`` = 9 ×
    the axes), the covariance matching as :class:`SpectralGain`'s.  The estimate
    ``ê = istft(K ⊙ stft(e))`` with ``0 ≤ K ≤ 1`` is ``𝒦 e``, ``𝒦 = A* diag(K) A``
    Hermitian with eigenvalues in [0, 1] (``A`` the frame's analysis, ``A* A = I``); for
    an exact model (``L̂ P ≈ I`` in ``Q_I``'s band) the iteration ``I − γ 𝒦`` has its
    eigenvalues in ``[1 − γ, 1]``: it never expands.  (With a model error ``𝒦`` and
    ``L̂ P`` do not commute: no frequency-wise bound; the supervisor watches.)

    Parameters
    ----------
    settings : WeightingSettings
        ``window_s`` > 0.
    cycle_s : float
        ``T`` (s).
    gain : float
        ``γ`` in (0, 2).

    API note: ``ê = TileGain(settings, T)(e)`` with ``e`` (G, 3) on the cycle grid; the
    state (``prior``, ``history``, ``last_gain``, ``scale``, ``power``: (bins, tiles)) as
    :class:`SpectralGain`'s.
    """

    def __init__(self, settings: WeightingSettings, cycle_s: float, gain: float = 1.0) -> None:
        if not 0 < gain < 2:
            raise ValueError(f"TileGain: gain must lie in (0, 2), got {gain!r}")
        self.nperseg = round(settings.window_s / cycle_s)
        if self.nperseg < 16:
            raise ValueError(f"TileGain: window_s {settings.window_s!r} s is under 16 cycles")
        settings.check(cycle_s)
        self.settings, self.cycle_s, self.gain = settings, float(cycle_s), float(gain)
        self._init_state()

    def _stft(self) -> dict[str, Any]:
        n = self.nperseg
        return {"fs": 1.0 / self.cycle_s, "window": "hann", "nperseg": n,
                "noverlap": 3 * n // 4}

    def shape(self, cycles: int) -> tuple[int, int]:
        """``(bins, tiles)``: the shape of ``S`` (:attr:`prior`) for a record of
        ``cycles``."""
        _, _, X = stft(np.zeros(cycles), boundary="even", padded=True, **self._stft())
        return X.shape

    def __call__(self, error: ArrayLike) -> Array:
        """``ê`` (G, 3) for the run's error ``e`` (G, 3) (m); advances ``S`` by (2)."""
        e = np.asarray(error, dtype=float)
        if e.ndim != 2 or e.shape[0] < 2 * self.nperseg or not np.all(np.isfinite(e)):
            raise ValueError(f"TileGain: expected a finite error (G ≥ {2 * self.nperseg}, a), "
                             f"got {e.shape}")
        s, kw = self.settings, self._stft()
        f, _, X = stft(e.T, boundary="even", padded=True, **kw)     # (a, F, tiles)
        power = (np.abs(X) ** 2).sum(axis=0)
        band = (f >= s.noise_low_hz) & (f <= s.noise_high_hz)
        if band.sum() < 2:
            raise ValueError(f"TileGain: the noise band holds {int(band.sum())} bins of "
                             f"{f[1] - f[0]:g} Hz; need 2 (a longer window_s)")
        N = float(power[band].mean())
        avg = uniform_filter(power, size=3, mode="nearest")
        K = self._advance(avg, N, 9 * e.shape[1], f < s.noise_low_hz)
        _, est = istft(K[None] * X, boundary=True, **kw)
        return np.ascontiguousarray(est[:, :e.shape[0]].T)
