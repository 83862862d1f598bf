"""Iterative learning control for a path that repeats (issue 38 §2: "iterative learning for
repeated paths").

What the calibrated model leaves along a path on a moving arm is largely *repeatable*:
the servo's following error, the structural modes rung by the path's own accelerations,
the gears changing flank at the same places.  A feed-forward that a run learns from the
tracker's view of the previous runs of the same path removes it; what the tracker term
of :mod:`.loop` cannot (it sees each error a sample's age plus a dead time too late).

The law (P-type ILC with a phase lead and a zero-phase robustness filter; Bristow,
Tharayil & Alleyne, "A survey of iterative learning control", IEEE Control Systems
26(3), 2006, eq. 5 and section "Robustness")::

    u_{k+1}(t) = W(t) · Q[ u_k(t) − L · e_k(t + δ) ]                     (1)

* ``t`` — the path's time (s from the start of the motion), on the robot's cycle grid
  ``t_i = −pre + i T``; ``u_k(t)`` (m, 3 axes, F0) is added to the target of run ``k``
  (the model-based feed-forward then aims the arm at it, :class:`.loop.TrackingLoop`);
* ``e_k(t)`` — run ``k``'s measured error, the tracker's samples against the path
  commanded at the same time, ``p_meas(t_s) − p_cmd(t_s)``, averaged over each cycle
  (:func:`path_error`); a cycle without a good sample (a beam break) has ``e = 0`` —
  not measured, not learned there;
* ``L`` — the learning gain; ``δ`` — the phase lead, the dead time from the target to
  the arm (the loop's lead ``τ``): a change of ``u`` at ``t`` shows in ``e`` at
  ``t + δ``;
* ``Q`` — a Butterworth low-pass of order ``n`` and cut-off ``f_c`` run forwards and
  backwards (``scipy.signal.filtfilt``: zero phase, ``|Q| = |B(f)|²``), below the arm's
  first structural mode, where the plant's phase is no longer known well enough;
* ``W`` — a Tukey window that takes ``u`` to zero over ``taper`` at both ends of the
  learning window (from ``pre`` before the motion to ``post`` after it), so the learned
  offset fades in and out while the arm stands still.

**Convergence** (the lifted linear case, ``e_k = d + P u_k`` with a causal linear plant
``P`` and a repeating disturbance ``d``): (1) gives
``u_{k+1} = W Q (I − L S_δ P) u_k − W Q L S_δ d`` (``S_δ`` the shift by ``δ``); with
``‖W‖ ≤ 1`` the iteration contracts in the 2-norm, monotonically and from any start, if

    ρ = sup_ω |Q(e^{jωT})| · |1 − L e^{jωδ} P(e^{jωT})| < 1                  (2)

(:func:`contraction` evaluates it for a plant's frequency response).  For a plant that is
a dead time ``δ`` and a unit gain in ``Q``'s pass band, ``|1 − L| < 1``: ``0 < L < 2``;
where ``Q ≈ 1`` the error converges to ``≈ 0``, above ``f_c`` it stays what it was.
Fresh measurement noise ``n_k`` (rms ``σ`` per cycle) enters ``u`` every run through
``L Q``: in the pass band ``u`` keeps a noise of ``σ_Q √(L / (2 − L))`` (``σ_Q`` the noise
after ``Q``) — the price of a large gain.  Hence the optional decreasing gain
``L_k = L / (1 + λ k)`` (``k`` the updates so far, ``λ`` = ``gain_decay``): each ``L_k``
in (0, 2) keeps (2) for that run, and a gain that falls as ``1/k`` averages the noise of
the runs (stochastic approximation: ``Σ L_k = ∞``, ``L_k → 0``) — fast at first, quiet
later.

**Learning above the modes: the model-inverting law.**  (1) must keep ``Q`` below the
arm's first structural mode: near a lightly damped mode ``|P|`` is large and its phase
turns through 180°, so ``|1 − L e^{jωδ} P| > 1`` there whatever ``L``.  With a plant
identified from the runs themselves (:mod:`.plant`: one run carries a known excitation,
``e_b − e_a = P (u_b − u_a)``), the learning filter inverts it instead — the norm-optimal
ILC (Amann, Owens & Rogers, IEE Proc. D 143(2), 1996; Bristow et al. 2006, "Plant
inversion" and "Norm-optimal" ILC) in the frequency domain, each frequency a 3×3
complex matrix (the Jacobian mixes the axes)::

    u_{k+1} = W · Q_I[ u_k − γ_j L̂ e_k ],   L̂(ω) = (P̂ᴴ P̂ + β I)⁻¹ P̂ᴴ           (3)

(``L̂`` minimises ``|e_{k+1}|² + β |u_{k+1} − u_k|²`` per frequency for the model ``P̂``;
``Q_I`` a zero-phase Butterworth of ``cutoff_hz``, above the modes; no phase lead: ``P̂``
holds the dead time; ``γ_j = γ / (1 + λ_I j)`` for the ``j``-th update by (3)).  With the
true plant ``P``: ``u_{k+1} = W Q_I (I − γ_j L̂ P) u_k + …``; the iteration contracts if

    ρ_I = sup_ω |Q_I(ω)| · σ_max(I − γ L̂(ω) P(ω)) < 1                           (4)

(:func:`contraction_inverse`).  For an exact model (``P̂ = P``), ``L̂ P = (Pᴴ P + β I)⁻¹
Pᴴ P`` is Hermitian with eigenvalues ``s_i = σ_i² / (σ_i² + β)`` in ``[0, 1)`` (``σ_i``
the singular values of ``P``), so ``I − γ L̂ P`` has the eigenvalues ``1 − γ s_i``:
``|1 − γ s_i| < 1`` for ``0 < γ < 2`` wherever ``P`` is non-singular — ``ρ_I < 1`` at
every frequency, modes included; the error falls there by ``1 − γ s_i`` a run.  ``β``
buys robustness to the model's error (at a frequency where ``|P|`` is small the
inverse's gain is at most ``1 / (2√β)``) at the price of a slower convergence there.
Noise: a run's fresh noise ``n_k`` enters ``u`` through ``γ_j L̂``; the arm turns it back
into ``≈ γ_j Q_I n_k`` of error — in ``Q_I``'s whole band, however large ``|P|`` is — hence
``γ_j = 1/(1 + j)`` (``gain_decay`` 1) for an unweighted input: the running mean of the
runs' estimates, whose noise falls as ``1/√(j+1)``.

**Weighting by the signal-to-noise per frequency** (``LearningSettings.weighting``, the
default with (3), :mod:`.smoothing`): the update learns ``K_j(f) E_j(f)`` instead of
``E_j(f)``, ``K_j`` the Kalman gain of the runs at each frequency (``S_j / (S_j + N)``:
the error still to learn against the tracker's noise, both estimated from the records),
and ``γ_j = γ`` (``K_j`` holds the ``1/(1 + j)`` where the error is far above the noise);
(4) becomes
``ρ_I = sup_ω |Q_I| σ_max(I − γ K L̂ P)``, never above (4)'s factor where that is < 1.

Pure math: numpy and scipy, SI units, no I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.fft import irfft, next_fast_len, rfft, rfftfreq
from scipy.signal import butter, filtfilt, freqz
from scipy.signal.windows import tukey

from .plant import ModalPlant, excitation, identify_plant
from .smoothing import SpectralGain, TileGain, WeightingSettings

#: The weighting of a new learning by (3): the Kalman gain per 1 s tile, raised again by
#: the covariance matching at ``κ`` = 3 only where the last update made the error fall
#: ((6) of :mod:`.smoothing`).  On the twin's six benchmark paths (Smart H4, 36 kg; docs/
#: results/dynamic-correction.md) it ends six runs below the whole-run gain without the
#: matching on five (the circle at 100 mm/s 0.058 → 0.047 mm perpendicular 3σ) and above it
#: on one (the line at 250 mm/s 0.028 → 0.036 mm, still 5.5× below the model).  A record
#: shorter than two tiles (a path under ≈ 1.3 s with the learning's margins) is one tile:
#: the whole-run gain without the matching (:func:`weighting_for`).
DEFAULT_WEIGHTING = WeightingSettings(window_s=1.0, detect=3.0, detect_fell=1)

Array = NDArray[np.float64]

__all__ = ["DEFAULT_WEIGHTING", "InverseSettings", "InverseState", "IterativeLearning",
           "LearnedOffset", "LearningSettings", "contraction", "contraction_inverse",
           "inverse_gain", "path_error", "weighting_for"]


@dataclass(frozen=True)
class InverseSettings:
    """The model-inverting law (3) and the identification its plant comes from; SI.

    Attributes
    ----------
    gain : float
        ``γ`` in (0, 2).
    gain_decay : float
        ``λ_I`` ≥ 0 of ``γ_j = γ / (1 + λ_I j)`` (1: the running mean of the runs).
    regularisation : float
        ``β`` > 0 of ``L̂ = (P̂ᴴ P̂ + β I)⁻¹ P̂ᴴ`` (``P̂`` is m/m: dimensionless).
    cutoff_hz : float
        ``Q_I``'s cut-off (Hz), above the modes to be learned, below the Nyquist rate.
    order : int
        ``Q_I``'s Butterworth order (zero phase: ``|Q_I| = |B|²``).
    modes, taps : int
        The identified model's modes ``M`` and FIR head ``K`` (:func:`.plant.identify_plant`).
    band_low_hz, band_high_hz : float
        Where the modes are searched (Hz).
    excitation_m : float
        The identifying run's excitation, rms per axis (m) (:func:`.plant.excitation`).
    excitation_low_hz, excitation_high_hz : float
        Its band (Hz).
    seed : int
        Its noise.
    pad_s : float
        The signals' extension at each end for the FFT (s), longer than ``L̂``'s impulse
        response.
    backoff : float
        The supervisor (class :class:`IterativeLearning`): when a run's measured rms
        error exceeds ``backoff`` times the best run's, ``u`` returns to the best run's
        and ``β`` grows tenfold (≥ 1; 0 switches it off).
    reidentify : int
        1: after each run by (3) the plant is identified again, from the excited run
        against the run before it *and against every run after it* (class
        :class:`IterativeLearning`, "Re-identification"; the default); 0: once, from the
        first pair.
    """

    gain: float = 1.0
    gain_decay: float = 1.0
    regularisation: float = 0.05
    cutoff_hz: float = 20.0
    order: int = 4
    modes: int = 4
    taps: int = 8
    band_low_hz: float = 3.0
    band_high_hz: float = 40.0
    excitation_m: float = 20e-6
    excitation_low_hz: float = 1.0
    excitation_high_hz: float = 30.0
    seed: int = 0
    pad_s: float = 2.0
    backoff: float = 1.15
    reidentify: int = 1

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if not (isinstance(v, int | float) and not isinstance(v, bool)
                    and math.isfinite(v)):
                raise ValueError(f"InverseSettings.{f.name} must be a finite number, got {v!r}")
        if not 0 < self.gain < 2:
            raise ValueError(f"InverseSettings.gain (γ) must lie in (0, 2) for the iteration "
                             f"to contract, got {self.gain!r}")
        if self.reidentify not in (0, 1):
            raise ValueError(f"InverseSettings.reidentify must be 0 or 1, "
                             f"got {self.reidentify!r}")
        for name in ("order", "modes", "taps", "seed"):
            if not isinstance(getattr(self, name), int):
                raise ValueError(f"InverseSettings.{name} must be an integer, "
                                 f"got {getattr(self, name)!r}")
        if not (1 <= self.order <= 8 and 0 <= self.modes <= 12 and 1 <= self.taps <= 200):
            raise ValueError(f"InverseSettings: order must be 1–8, modes 0–12 and taps 1–200, "
                             f"got {self.order!r}, {self.modes!r} and {self.taps!r}")
        for name in ("regularisation", "cutoff_hz", "excitation_m", "pad_s"):
            if getattr(self, name) <= 0:
                raise ValueError(f"InverseSettings.{name} must be > 0, "
                                 f"got {getattr(self, name)!r}")
        if self.gain_decay < 0:
            raise ValueError(f"InverseSettings.gain_decay must be ≥ 0, got {self.gain_decay!r}")
        if not (self.backoff == 0 or self.backoff >= 1):
            raise ValueError(f"InverseSettings.backoff must be 0 (off) or ≥ 1, "
                             f"got {self.backoff!r}")
        for lo, hi in (("band_low_hz", "band_high_hz"),
                       ("excitation_low_hz", "excitation_high_hz")):
            if not 0 < getattr(self, lo) < getattr(self, hi):
                raise ValueError(f"InverseSettings: need 0 < {lo} < {hi}, got "
                                 f"{getattr(self, lo)!r} and {getattr(self, hi)!r}")

    def check(self, cycle_s: float) -> None:
        """The frequencies against the Nyquist rate of ``cycle_s``."""
        nyq = 0.5 / cycle_s
        for name in ("cutoff_hz", "band_high_hz", "excitation_high_hz"):
            if getattr(self, name) >= nyq:
                raise ValueError(f"InverseSettings.{name} {getattr(self, name)!r} must lie "
                                 f"below the Nyquist rate {nyq:g} Hz")


def inverse_gain(plant: ArrayLike, regularisation: float) -> NDArray[np.complex128]:
    """``L̂ = (P̂ᴴ P̂ + β I)⁻¹ P̂ᴴ`` of (3) at each frequency.

    Parameters
    ----------
    plant : (m, 3, 3) array_like of complex
        ``P̂(e^{jωT})``, ``[f, i, j]``.
    regularisation : float
        ``β`` > 0.

    Returns
    -------
    (m, 3, 3) complex array
    """
    P = np.asarray(plant, dtype=complex)
    if P.ndim != 3 or P.shape[1:] != (3, 3):
        raise ValueError(f"inverse_gain: expected a plant (m, 3, 3), got {P.shape}")
    if not regularisation > 0:
        raise ValueError(f"inverse_gain: regularisation must be > 0, got {regularisation!r}")
    Ph = np.conj(np.swapaxes(P, 1, 2))
    return np.linalg.solve(Ph @ P + regularisation * np.eye(3), Ph)


def contraction_inverse(settings: InverseSettings, cycle_s: float, frequency_hz: ArrayLike,
                        plant: ArrayLike, model: ArrayLike,
                        weight: ArrayLike | None = None) -> float:
    """``ρ_I`` of (4): ``max |Q_I| · σ_max(I − γ K L̂ P)``, ``L̂`` from ``model``.

    Parameters
    ----------
    settings : InverseSettings
    cycle_s : float
        ``T`` (s).
    frequency_hz : (m,) array_like
        Frequencies (Hz), 0 to the Nyquist rate.
    plant, model : (m, 3, 3) array_like of complex
        The true ``P`` and the model ``P̂`` the learning inverts, at those frequencies.
    weight : (m,) array_like, optional
        ``K`` in [0, 1] per frequency (:mod:`.smoothing`; default 1).

    Returns
    -------
    float
        ``ρ_I``; the iteration (3) contracts monotonically (2-norm) when ``ρ_I < 1``.
    """
    f = np.asarray(frequency_hz, dtype=float).reshape(-1)
    P = np.asarray(plant, dtype=complex)
    if P.shape != (f.size, 3, 3) or np.shape(model) != P.shape:
        raise ValueError(f"contraction_inverse: plant and model must be ({f.size}, 3, 3), "
                         f"got {P.shape} and {np.shape(model)}")
    K = np.ones(f.size) if weight is None else np.asarray(weight, dtype=float).reshape(-1)
    if K.size != f.size or not np.all((K >= 0) & (K <= 1)):
        raise ValueError(f"contraction_inverse: weight must be {f.size} values in [0, 1]")
    b, a = butter(settings.order, settings.cutoff_hz, fs=1.0 / cycle_s)
    _, B = freqz(b, a, worN=f, fs=1.0 / cycle_s)
    M = np.eye(3) - settings.gain * K[:, None, None] * \
        (inverse_gain(model, settings.regularisation) @ P)
    return float(np.max(np.abs(B) ** 2 * np.linalg.norm(M, 2, axis=(1, 2))))


@dataclass(frozen=True)
class LearningSettings:
    """The learning law's parameters (module docstring, (1)); SI units.

    Attributes
    ----------
    gain : float
        ``L`` in (0, 2).
    lead_s : float
        ``δ`` (s), ≥ 0: the dead time from the target to the arm.
    cutoff_hz : float
        ``f_c`` of ``Q`` (Hz), below the first structural mode and the Nyquist rate.
    order : int
        ``n`` of ``Q``'s Butterworth prototype (zero phase: ``|Q| = |B|²``).
    cycle_s : float
        ``T``, the robot's cycle (s).
    pre_s, post_s : float
        The learning window from ``pre_s`` before the motion to ``post_s`` after it (s).
    taper_s : float
        The window ``W``'s cosine fade at each end (s), ≤ the window's half length.
    max_offset_m : float
        Bound on ``|u|`` per axis (m): a safety clip, not part of the law.
    gain_decay : float
        ``λ`` ≥ 0 of the decreasing gain ``L_k = L / (1 + λ k)`` (0: constant).
    inverse : InverseSettings or None
        The model-inverting law (3) after an identifying run (``None``: (1) alone).
    weighting : WeightingSettings or None
        (3) learns each frequency by its Kalman gain (module docstring, :mod:`.smoothing`;
        the default, :data:`DEFAULT_WEIGHTING`); ``None``: all of the error, ``γ_j``.  Used
        by the law (3) only: without ``inverse`` it is inert (the P-type law (1) learns
        all of the error), so ``dataclasses.replace(settings, inverse=…)`` switches the
        law without touching it.
    """

    gain: float = 0.8
    lead_s: float = 0.008
    cutoff_hz: float = 4.0
    order: int = 2
    cycle_s: float = 0.004
    pre_s: float = 0.3
    post_s: float = 0.4
    taper_s: float = 0.15
    max_offset_m: float = 2e-3
    gain_decay: float = 0.0
    inverse: InverseSettings | None = None
    weighting: WeightingSettings | None = field(default_factory=lambda: DEFAULT_WEIGHTING)

    def __post_init__(self) -> None:
        if not (self.inverse is None or isinstance(self.inverse, InverseSettings)):
            raise ValueError(f"LearningSettings.inverse must be InverseSettings or None, got "
                             f"{self.inverse!r}")
        if self.inverse is not None:
            self.inverse.check(self.cycle_s)
        if self.weighting is not None:
            if not isinstance(self.weighting, WeightingSettings):
                raise ValueError(f"LearningSettings.weighting must be WeightingSettings or "
                                 f"None, got {self.weighting!r}")
            if self.inverse is not None:  # inert without the law (3)
                self.weighting.check(self.cycle_s)
        for f in fields(self):
            if f.name in ("inverse", "weighting"):
                continue
            v = getattr(self, f.name)
            if not (isinstance(v, int | float) and not isinstance(v, bool)
                    and math.isfinite(v)):
                raise ValueError(f"LearningSettings.{f.name} must be a finite number, got {v!r}")
        if not 0 < self.gain < 2:
            raise ValueError(f"LearningSettings.gain (L) must lie in (0, 2) for the "
                             f"iteration to contract, got {self.gain!r}")
        if not (isinstance(self.order, int) and 1 <= self.order <= 8):
            raise ValueError(f"LearningSettings.order must be an integer 1–8, "
                             f"got {self.order!r}")
        for name in ("cycle_s", "cutoff_hz", "max_offset_m"):
            if getattr(self, name) <= 0:
                raise ValueError(f"LearningSettings.{name} must be > 0, "
                                 f"got {getattr(self, name)!r}")
        for name in ("lead_s", "pre_s", "post_s", "taper_s", "gain_decay"):
            if getattr(self, name) < 0:
                raise ValueError(f"LearningSettings.{name} must be ≥ 0, "
                                 f"got {getattr(self, name)!r}")
        if self.cutoff_hz >= 0.5 / self.cycle_s:
            raise ValueError(f"LearningSettings.cutoff_hz {self.cutoff_hz!r} must lie below "
                             f"the Nyquist rate {0.5 / self.cycle_s:g} Hz of cycle_s")

    def q_filter(self) -> tuple[Array, Array]:
        """``Q``'s Butterworth prototype ``(b, a)`` (run forwards and backwards)."""
        b, a = butter(self.order, self.cutoff_hz, fs=1.0 / self.cycle_s)
        return np.asarray(b, float), np.asarray(a, float)


def contraction(settings: LearningSettings, frequency_hz: ArrayLike,
                plant: ArrayLike) -> float:
    """``ρ`` of the convergence condition (2): ``max |Q| · |1 − L e^{jωδ} P|``.

    Parameters
    ----------
    settings : LearningSettings
    frequency_hz : (m,) array_like
        Frequencies (Hz), 0 to the Nyquist rate.
    plant : (m,) array_like of complex
        ``P(e^{jωT})``: the response of the measured error to the learned offset (dead
        time included) at those frequencies.

    Returns
    -------
    float
        ``ρ``; the iteration contracts monotonically (2-norm) when ``ρ < 1``.
    """
    f = np.asarray(frequency_hz, dtype=float)
    P = np.asarray(plant, dtype=complex)
    if f.shape != P.shape or f.ndim != 1:
        raise ValueError(f"frequency_hz and plant must be 1-D of one length, got shapes "
                         f"{f.shape} and {P.shape}")
    b, a = settings.q_filter()
    _, B = freqz(b, a, worN=f, fs=1.0 / settings.cycle_s)
    w = 2 * np.pi * f
    return float(np.max(np.abs(B) ** 2 * np.abs(1 - settings.gain *
                                                  np.exp(1j * w * settings.lead_s) * P)))


def path_error(sample_t: ArrayLike, sample_p: ArrayLike, path_t: ArrayLike,
               path_p: ArrayLike, grid_t: ArrayLike, cycle_s: float) -> tuple[Array, Array]:
    """The measured error on the cycle grid: ``e_i`` = mean over the samples within
    ``[t_i − T/2, t_i + T/2)`` of ``p_meas(t_s) − p_cmd(t_s)``, ``p_cmd`` linear between
    the commanded path's cycles.

    Parameters
    ----------
    sample_t : (m,) array_like
        Acquisition times of the good tracker samples (s, the robot's clock).
    sample_p : (m, 3) array_like
        Their positions (m, F0).
    path_t : (N,) array_like
        Times of the commanded path (s, increasing).
    path_p : (N, 3) array_like
        The commanded path's positions (m, F0).
    grid_t : (G,) array_like
        The cycle grid (s, on the robot's clock), spaced ``cycle_s``.
    cycle_s : float
        ``T`` (s).

    Returns
    -------
    e : (G, 3) array
        The error per cycle (m); 0 where no sample fell.
    measured : (G,) bool array
        Cycles with at least one sample.
    """
    ts = np.asarray(sample_t, dtype=float).reshape(-1)
    ps = np.asarray(sample_p, dtype=float).reshape(-1, 3)
    tp = np.asarray(path_t, dtype=float).reshape(-1)
    pp = np.asarray(path_p, dtype=float).reshape(-1, 3)
    g = np.asarray(grid_t, dtype=float).reshape(-1)
    if ts.size != ps.shape[0] or tp.size != pp.shape[0]:
        raise ValueError(f"path_error: {ts.size} sample times for {ps.shape[0]} positions, "
                         f"{tp.size} path times for {pp.shape[0]} path positions")
    if tp.size < 2 or np.any(np.diff(tp) <= 0):
        raise ValueError("path_error: the path's times must be at least two, increasing")
    keep = (ts >= tp[0]) & (ts <= tp[-1]) & np.all(np.isfinite(ps), axis=1)
    ts, ps = ts[keep], ps[keep]
    cmd = np.column_stack([np.interp(ts, tp, pp[:, i]) for i in range(3)])
    idx = np.floor((ts - g[0]) / cycle_s + 0.5).astype(int)
    inside = (idx >= 0) & (idx < g.size)
    idx, d = idx[inside], (ps - cmd)[inside]
    count = np.bincount(idx, minlength=g.size).astype(float)
    # (bincount gives integers when there is no sample at all, whatever its weights)
    e = np.column_stack([np.bincount(idx, d[:, i], minlength=g.size)
                         for i in range(3)]).astype(float)
    measured = count > 0
    e[measured] /= count[measured, None]
    return e, measured


@dataclass(frozen=True)
class LearnedOffset:
    """The learned offset of one run: ``u(t)`` (m, F0) at robot time ``t``, linear between
    the cycles, 0 outside the learning window.

    Attributes
    ----------
    t : (G,) array
        Robot times of the grid (s).
    u : (G, 3) array
        The offset there (m).
    """

    t: Array
    u: Array

    def __call__(self, t: float) -> Array:
        """``u(t)`` (3,), m."""
        T = self.t[1] - self.t[0]
        x = (t - self.t[0]) / T
        i = math.floor(x)
        if i < 0 or i >= self.t.size - 1:
            return np.zeros(3)
        a = x - i
        return (1.0 - a) * self.u[i] + a * self.u[i + 1]


@dataclass
class InverseState:
    """What the law (3) of :class:`IterativeLearning` carries from run to run besides the
    offset, the plant, its updates and ``β``'s factor: what a saved learning needs to go
    on exactly (:meth:`IterativeLearning.inverse_state`, :meth:`~IterativeLearning.
    resume_inverse`); SI.

    Attributes
    ----------
    excited : ((G, 3), (G, 3), (G,) bool) arrays or None
        The excited run's offset ``u_x``, measured error ``e_x`` and measured cycles
        (class docstring, "Re-identification"; None before the identification).
    pairs : list of ((G, 3), (G, 3), (G,) bool) arrays
        The identification's pairs so far ``(Δu, Δe, mask)``: the excited run against the
        run before it, then against each later run by (3).
    best : (float, (G, 3), (G, 3)) or None
        The supervisor's best run by (3): its measured rms (m), offset and error (m).
    prior : (m,) or (bins, tiles) array or None
        The weighting's ``S_j`` (:mod:`.smoothing`; None: before its first update or no
        weighting).
    noise : float
        The weighting's last ``N`` (NaN: none yet).
    weighting_history : list of dict
        The weighting's per-update figures (``noise``, ``mean_gain``, ``rematched``).
    scale, power : (m,) or (bins, tiles) arrays or None
        The weighting's inflation ``c_j`` and the power ``P_j`` of its last record
        (:mod:`.smoothing` (5); None: not used or no update yet).
    identifying : ((G, 3), (G, 3), (G,) bool) arrays or None
        Before the identification, while the next run carries the excitation: the run
        before it — its offset ``u_a``, measured error ``e_a`` and measured cycles, the
        reference of the identifying pair ``e_x − e_a = P (u_x − u_a)`` and the run the
        first update by (3) starts from (class docstring); None otherwise.
    """

    excited: tuple[Array, Array, Array] | None = None
    pairs: list[tuple[Array, Array, Array]] = field(default_factory=list)
    best: tuple[float, Array, Array] | None = None
    prior: Array | None = None
    noise: float = math.nan
    weighting_history: list[dict[str, float]] = field(default_factory=list)
    identifying: tuple[Array, Array, Array] | None = None
    scale: Array | None = None
    power: Array | None = None


#: The most cycles a learning's grid may have (its offset, window and FFT buffers are
#: held in memory: 2**20 cycles ≈ 70 min of path at 4 ms, ≈ 25 MB an array of 3 axes).
MAX_GRID = 2**20


def weighting_for(settings: WeightingSettings, gain: float, cycle_s: float,
                  cycles: int) -> SpectralGain | TileGain:
    """The weighting of (3) for a learning over ``cycles`` cycles of ``cycle_s`` (s); ``gain``
    is ``γ``.

    ``settings.window_s`` > 0: per tile (:class:`.smoothing.TileGain`) where the record
    holds two tiles or more (``cycles ≥ 2 round(window_s / cycle_s)``); a shorter record
    is one tile, learned by the whole-run gain (2) without the covariance matching
    (:class:`.smoothing.SpectralGain` with ``window_s`` 0, ``detect`` ∞: on the 80 mm path
    of docs/tracked-paths.md, 1.8 s of record, the matching per frequency ended at
    0.119 mm perpendicular 3σ against its 0.092 mm).  ``window_s`` 0: ``settings`` as
    they are, per frequency over the run."""
    if settings.window_s == 0:
        return SpectralGain(settings, gain)
    if cycles >= 2 * round(settings.window_s / cycle_s):
        return TileGain(settings, cycle_s, gain)
    return SpectralGain(replace(settings, window_s=0.0, detect=math.inf), gain)


@dataclass
class IterativeLearning:
    """The learning of one repeated path (module docstring, (1) and (3)).

    Parameters
    ----------
    duration_s : float
        The path's motion (s): the window runs from ``−pre_s`` to ``duration_s + post_s``.
    settings : LearningSettings
    plant : ModalPlant, optional
        An identified plant (:func:`.plant.identify_plant`) for the law (3); without one,
        and with ``settings.inverse``, the learning identifies it itself (below).

    Attributes
    ----------
    grid : (G,) array
        The path's time of each cycle (s from the start of the motion).
    u : (G, 3) array
        The offset the next run adds to its target (m, F0).
    steps : int
        Updates of ``u`` so far (:meth:`step`).
    history : list of dict
        Per update from a run (:meth:`update`): ``rms_m`` and ``max_m`` of the measured
        error's magnitude over the motion, ``measured`` (share of cycles measured),
        ``u_max_m``, ``law`` (``"p"`` (1), ``"inverse"`` (3)), ``excited`` (1.0 if the
        next run carries the identifying excitation).

    API note: ``feedforward(start_s)`` → the next run's :class:`LearnedOffset`;
    ``update(sample_t, sample_p, path_t, path_p, start_s)`` after the run (or
    ``learn_error(e, measured)`` with the error already on the grid).  With
    ``settings.inverse`` the runs go: the first update is (1) and adds a known
    excitation (:func:`.plant.excitation`, windowed) to the next run's offset; the update
    after that run identifies the plant from the two runs (``e_b − e_a = P (u_b −
    u_a)``, the cycles measured in both) and makes the first update by (3) from the run
    before the excited one (its offset and error: the excited run serves the
    identification only); from then on every update is (3).  :attr:`plant` is then the
    identified model (keep it with ``u`` to go on learning the same path later).

    Re-identification (``settings.inverse.reidentify``): one pair of runs leaves the
    modes' gains and mixing uncertain (the tracker's noise in one run's difference), and a
    model wrong at a lightly damped mode breaks (4) there.  More pairs help, but not
    any pair: an update by (3) from run ``k`` carries run ``k``'s noise into
    ``u_{k+1}``, so a pair ``(k, k+1)`` has ``Δu`` correlated with the noise ``−n_k``
    of its ``Δe`` (closed-loop data: a biased plant).  The excited run ``x`` is the
    exception: no update is made from its error, so no later ``u_c`` holds ``n_x``, and
    each pair ``(x, c)``, ``c`` after ``x``, is open-loop data,
    ``e_c − e_x = P (u_c − u_x) + n_c − n_x`` with ``u_c − u_x`` independent of
    ``n_c − n_x``.  After every run ``c`` by (3) the plant is identified again
    (:func:`.plant.identify_plant`, a fresh mode search) from the pairs
    ``(x − 1, x), (x, x + 1), …, (x, c)`` together; the noise of ``e_x`` is common to
    them, so the data's noise falls towards that of one run, from two.
    """

    duration_s: float
    settings: LearningSettings = field(default_factory=LearningSettings)
    plant: ModalPlant | None = None
    grid: Array = field(init=False)
    u: Array = field(init=False)
    history: list[dict[str, float | str]] = field(init=False, default_factory=list)
    steps: int = field(init=False, default=0)

    def __post_init__(self) -> None:
        s = self.settings
        if not (math.isfinite(self.duration_s) and self.duration_s > 0):
            raise ValueError(f"IterativeLearning: the path's duration must be > 0 s, "
                             f"got {self.duration_s!r}")
        cycles = (self.duration_s + s.pre_s + s.post_s) / s.cycle_s
        padded = cycles + (0.0 if s.inverse is None else 2 * s.inverse.pad_s / s.cycle_s)
        if not padded <= MAX_GRID:  # also inf: the grid and its FFTs are held in memory
            pad = "" if s.inverse is None else f" and the inverse law's pads of 2 × " \
                f"{s.inverse.pad_s:g} s"
            raise ValueError(f"IterativeLearning: a learning window of "
                             f"{self.duration_s + s.pre_s + s.post_s:g} s{pad} at "
                             f"{s.cycle_s:g} s a cycle is {padded:.3g} cycles; at most "
                             f"{MAX_GRID} (≈ {MAX_GRID * s.cycle_s / 60:.0f} min)")
        n = round(cycles) + 1
        if 2 * s.taper_s > (n - 1) * s.cycle_s:
            raise ValueError(f"LearningSettings.taper_s {s.taper_s!r} s is longer than half "
                             f"the learning window ({(n - 1) * s.cycle_s:g} s)")
        if self.plant is not None and s.inverse is None:
            raise ValueError("IterativeLearning: a plant is given but settings.inverse is "
                             "None: the law (3) needs InverseSettings")
        self.grid = -s.pre_s + s.cycle_s * np.arange(n)
        self.u = np.zeros((n, 3))
        span = (n - 1) * s.cycle_s
        self._window = tukey(n, 2 * s.taper_s / span) if span > 0 else np.ones(n)
        self._b, self._a = s.q_filter()
        self._inverse_steps = 0
        self._excitation: Array | None = None
        self._last: tuple[Array, Array, Array] | None = None  # (u, e, measured) of a run
        self._spectral: tuple[int, int, Array, Array, Array] | None = None
        self._beta_scale = 1.0
        self._best: tuple[float, Array, Array] | None = None  # (rms, u, e) of (3)'s runs
        #: re-identification: the excited run (u, e, measured) and the open-loop pairs
        self._excited: tuple[Array, Array, Array] | None = None
        self._pairs: list[tuple[Array, Array, Array]] = []
        self._weighting = None if s.weighting is None or s.inverse is None else \
            weighting_for(s.weighting, s.inverse.gain, s.cycle_s, n)

    @property
    def weighting(self) -> SpectralGain | TileGain | None:
        """The weighting of (3) (:mod:`.smoothing`; ``None`` without one): its ``prior``,
        ``history`` and ``last_gain`` (``K_j`` of the last update) to look at."""
        return self._weighting

    @property
    def iterations(self) -> int:
        """Updates so far."""
        return len(self.history)

    @property
    def inverse_steps(self) -> int:
        """Updates by (3) so far (``j`` of ``γ_j``)."""
        return self._inverse_steps

    @property
    def regularisation_scale(self) -> float:
        """The factor on ``β`` after the supervisor's back-offs (1: none)."""
        return self._beta_scale

    @property
    def identifying_next(self) -> bool:
        """True while the next run carries the identifying excitation (law (3) before
        its plant is identified): that run is learned from, not judged."""
        return self.plant is None and self._excitation is not None

    def resume_inverse(self, steps: int, regularisation_scale: float,
                       state: InverseState | None = None) -> None:
        """Go on with the law (3) of a saved learning: its updates by (3) so far, ``β``'s
        factor and (``state``, :meth:`inverse_state` of the learning saved) the
        re-identification's runs, the supervisor's best run and the weighting's state —
        with it the learning goes on exactly as the saved one would (:attr:`plant` given
        to the constructor); without it those start anew.  A learning saved between its
        first update and the identifying run (no plant yet, ``state.identifying``) goes
        on with that run: its offset (:attr:`u`, set by the caller) carries the
        excitation, and the run before it is the identification's reference.

        Raises
        ------
        ValueError
            No law (3), no plant and no identifying run ahead, or a state that does not
            fit this learning (why).
        """
        if self.settings.inverse is None:
            raise ValueError("IterativeLearning.resume_inverse: needs settings.inverse")
        ahead = state is not None and state.identifying is not None
        if (self.plant is None) != ahead:
            raise ValueError("IterativeLearning.resume_inverse: needs an identified plant, "
                             "or — before the identification — the run before the "
                             "identifying one (state.identifying), not both")
        if not (steps >= 0 and regularisation_scale >= 1):
            raise ValueError(f"IterativeLearning.resume_inverse: steps ≥ 0 and a scale ≥ 1, "
                             f"got {steps!r} and {regularisation_scale!r}")
        if state is not None:
            self._restore(state)
        self._inverse_steps, self._beta_scale = int(steps), float(regularisation_scale)
        self._spectral = None

    def inverse_state(self) -> InverseState:
        """What the law (3) carries from run to run besides :attr:`u`, :attr:`plant`,
        :attr:`inverse_steps` and :attr:`regularisation_scale` (copies)."""
        w = self._weighting
        return InverseState(
            excited=None if self._excited is None else tuple(x.copy() for x in self._excited),
            pairs=[tuple(x.copy() for x in p) for p in self._pairs],
            best=None if self._best is None else (self._best[0], self._best[1].copy(),
                                                 self._best[2].copy()),
            prior=None if w is None or w.prior is None else w.prior.copy(),
            noise=math.nan if w is None else w.noise,
            weighting_history=[] if w is None else [dict(h) for h in w.history],
            identifying=None if not self.identifying_next or self._last is None else
            tuple(x.copy() for x in self._last),  # type: ignore[arg-type]
            scale=None if w is None or w.scale is None else w.scale.copy(),
            power=None if w is None or w.power is None else w.power.copy())

    def prior_shape(self) -> tuple[int, ...] | None:
        """The shape of the weighting's ``S_j`` for this learning's grid (None: no
        weighting): bins of the padded FFT, or (bins, tiles) of the tiles."""
        if self._weighting is None or self.settings.inverse is None:
            return None
        if isinstance(self._weighting, TileGain):
            return self._weighting.shape(self.grid.size)
        pad = max(round(self.settings.inverse.pad_s / self.settings.cycle_s), 2)
        return (next_fast_len(self.grid.size + 2 * pad) // 2 + 1,)

    def _restore(self, state: InverseState) -> None:
        """:meth:`resume_inverse`'s ``state``, checked against the grid and settings."""
        G, who = self.grid.size, "IterativeLearning.resume_inverse"
        runs = ([] if state.excited is None else [state.excited]) + list(state.pairs) + (
            [] if state.identifying is None else [state.identifying])
        for r in runs:
            if len(r) != 3 or np.shape(r[0]) != (G, 3) or np.shape(r[1]) != (G, 3) \
                    or np.shape(r[2]) != (G,):
                raise ValueError(f"{who}: a run of the re-identification must be (u, e, "
                                 f"measured) of shapes ({G}, 3), ({G}, 3), ({G},)")
        if state.pairs and state.excited is None:
            raise ValueError(f"{who}: pairs of the re-identification without the excited run")
        if state.best is not None and (np.shape(state.best[1]) != (G, 3)
                                       or np.shape(state.best[2]) != (G, 3)):
            raise ValueError(f"{who}: the supervisor's best run must be (rms, u, e) of "
                             f"shapes ({G}, 3)")
        want = self.prior_shape()
        for name in ("prior", "scale", "power"):
            x = getattr(state, name)
            if x is not None and (want is None or np.shape(x) != want):
                raise ValueError(f"{who}: the weighting's {name} must be of shape {want} "
                                 f"(None: no weighting), got {np.shape(x)}")
        self._excited = None if state.excited is None else \
            tuple(np.asarray(x, float if i < 2 else bool).copy()
                  for i, x in enumerate(state.excited))  # type: ignore[assignment]
        self._pairs = [(np.asarray(a, float).copy(), np.asarray(b, float).copy(),
                        np.asarray(m, bool).copy()) for a, b, m in state.pairs]
        self._best = None if state.best is None else (
            float(state.best[0]), np.asarray(state.best[1], float).copy(),
            np.asarray(state.best[2], float).copy())
        if state.identifying is not None:
            u_a, e_a, m_a = state.identifying
            self._last = (np.asarray(u_a, float).copy(), np.asarray(e_a, float).copy(),
                          np.asarray(m_a, bool).copy())
            self._excitation = self._identifying_excitation()
        if self._weighting is not None:
            self._weighting.prior = None if state.prior is None else \
                np.asarray(state.prior, float).copy()
            self._weighting.noise = float(state.noise)
            self._weighting.history = [dict(h) for h in state.weighting_history]
            self._weighting.scale, self._weighting.power = (
                None if x is None else np.asarray(x, float).copy()
                for x in (state.scale, state.power))

    def feedforward(self, start_s: float) -> LearnedOffset:
        """The offset for the next run whose motion starts at robot time ``start_s``."""
        return LearnedOffset(self.grid + float(start_s), self.u.copy())

    def _check_error(self, e: ArrayLike, who: str) -> Array:
        err = np.asarray(e, dtype=float)
        if err.shape != self.u.shape or not np.all(np.isfinite(err)):
            raise ValueError(f"IterativeLearning.{who}: expected a finite error of shape "
                             f"{self.u.shape}, got {err.shape}")
        return err

    def step(self, e: ArrayLike) -> Array:
        """One update from the error ``e`` (G, 3) on :attr:`grid` (m): (3) once
        :attr:`plant` is known (and ``settings.inverse`` set), else (1) with the gain
        ``L_k`` of :attr:`steps` updates so far; the new ``u``."""
        s = self.settings
        err = self._check_error(e, "step")
        if self.plant is not None and s.inverse is not None:
            return self._inverse_step(err)
        ahead = np.column_stack([np.interp(self.grid + s.lead_s, self.grid, err[:, i],
                                           right=0.0) for i in range(3)])
        x = self.u - s.gain / (1.0 + s.gain_decay * self.steps) * ahead
        self.steps += 1
        u = filtfilt(self._b, self._a, x, axis=0) * self._window[:, None]
        self.u = np.clip(u, -s.max_offset_m, s.max_offset_m)
        return self.u.copy()

    def _spectra(self) -> tuple[int, int, Array, Array, Array]:
        """The FFT's length ``n``, the pad, ``Q_I``, ``L̂`` on its bins and the pad's
        fade (computed once per plant)."""
        if self._spectral is None:
            inv, T, G = self.settings.inverse, self.settings.cycle_s, self.grid.size
            assert inv is not None and self.plant is not None
            pad = max(round(inv.pad_s / T), 2)
            n = next_fast_len(G + 2 * pad)
            f = rfftfreq(n, T)
            b, a = butter(inv.order, inv.cutoff_hz, fs=1.0 / T)
            _, B = freqz(b, a, worN=f, fs=1.0 / T)
            Lw = inverse_gain(self.plant.response(f), inv.regularisation * self._beta_scale)
            fade = np.ones(n)
            h = pad // 2  # the pad's outer half fades to 0: no jump where the FFT wraps
            ramp = 0.5 - 0.5 * np.cos(np.pi * np.arange(h) / h)
            fade[:h], fade[G + 2 * pad - h: G + 2 * pad] = ramp, ramp[::-1]
            fade[G + 2 * pad:] = 0.0
            self._spectral = (n, pad, np.abs(B) ** 2, Lw, fade)
        return self._spectral

    def _inverse_step(self, err: Array) -> Array:
        """(3): ``u ← W · Q_I[u − γ_j L̂ e]`` by FFT (the signals extended by their end
        values over ``pad_s`` and faded to zero)."""
        s, inv = self.settings, self.settings.inverse
        assert inv is not None
        n, pad, Qw, Lw, fade = self._spectra()
        G = self.grid.size

        def spectrum(x: Array) -> Array:
            xp = np.pad(x, ((pad, n - G - pad), (0, 0)), mode="edge") * fade[:, None]
            return rfft(xp, axis=0)

        if isinstance(self._weighting, TileGain):  # K_j of .smoothing, not γ_j's decay
            gamma, E = inv.gain, spectrum(self._weighting(err))
        elif self._weighting is not None:
            gamma, E = inv.gain, spectrum(err)
            E = self._weighting(E, rfftfreq(n, s.cycle_s))[:, None] * E
        else:
            E = spectrum(err)
            gamma = inv.gain / (1.0 + inv.gain_decay * self._inverse_steps)
        X = spectrum(self.u) - gamma * np.einsum("fij,fj->fi", Lw, E)
        u = irfft(Qw[:, None] * X, n, axis=0)[pad:pad + G] * self._window[:, None]
        self._inverse_steps += 1
        self.steps += 1
        self.u = np.clip(u, -s.max_offset_m, s.max_offset_m)
        return self.u.copy()

    def identify(self, du: ArrayLike, de: ArrayLike, mask: ArrayLike | None = None
                 ) -> ModalPlant:
        """The plant from two runs (:mod:`.plant`, (1)): ``du`` the change of the offset
        (G, 3), ``de`` the change of the measured error (G, 3) (m), ``mask`` the cycles
        measured in both (or ``R`` pairs: (R, G, 3), (R, G, 3), (R, G)); sets and returns
        :attr:`plant`."""
        inv = self.settings.inverse
        if inv is None:
            raise ValueError("IterativeLearning.identify: settings.inverse is None")
        self.plant = identify_plant(du, de, self.settings.cycle_s, modes=inv.modes,
                                    taps=inv.taps, mask=mask,
                                    band_hz=(inv.band_low_hz, inv.band_high_hz))
        self._spectral = None
        return self.plant

    def learn_error(self, e: ArrayLike, measured: ArrayLike | None = None) -> Array:
        """Learn from one run's error ``e`` (G, 3) on :attr:`grid` (m), ``measured`` (G,)
        the cycles with samples (default all): the history, the identification (with
        ``settings.inverse``, class docstring), :meth:`step`; the new ``u``."""
        err = self._check_error(e, "learn_error")
        meas = np.ones(self.grid.size, bool) if measured is None else \
            np.asarray(measured, bool).reshape(-1)
        if meas.size != self.grid.size:
            raise ValueError(f"IterativeLearning.learn_error: measured has {meas.size} "
                             f"cycles, the grid {self.grid.size}")
        motion = (self.grid >= 0) & (self.grid <= self.duration_s) & meas
        mag = np.linalg.norm(err[motion], axis=1)
        inv = self.settings.inverse
        applied, learn_from = self.u.copy(), err
        if inv is not None and self.plant is None and self._excitation is not None \
                and self._last is not None:
            u_a, e_a, m_a = self._last
            self._excited = (applied, err.copy(), meas.copy())
            self._pairs = [(applied - u_a, err - e_a, m_a & meas)]
            self.identify(applied - u_a, err - e_a, m_a & meas)
            # the excited run served the identification: the first update by (3) starts
            # from the run before it (whose error holds no excitation, and no error of
            # the model's answer to it)
            self.u, learn_from = u_a.copy(), e_a
            self._excitation = None
        self._last = (applied, err.copy(), meas.copy())
        rms = float(np.sqrt(np.mean(mag ** 2))) if mag.size else math.nan
        law = "inverse" if self.plant is not None and inv is not None else "p"
        if law == "inverse" and learn_from is err and inv is not None and inv.reidentify \
                and self._excited is not None:
            self._reidentify(applied, err, meas)
        if law == "inverse" and learn_from is err and math.isfinite(rms):
            learn_from, law = self._supervise(rms, applied, err, law)
        self.history.append({
            "rms_m": rms,
            "max_m": float(mag.max()) if mag.size else math.nan,
            "measured": float(meas.mean()),
            "u_max_m": float(np.abs(self.u).max()),
            "law": law,
            "excited": 0.0})
        u = self.step(learn_from)
        if inv is not None and self.plant is None:
            self._excitation = self._identifying_excitation()
            self.u = u = self.u + self._excitation
            self.history[-1]["excited"] = 1.0
        return u.copy()

    def _identifying_excitation(self) -> Array:
        """The identifying run's excitation (:func:`.plant.excitation`, seeded), windowed
        by ``W`` (G, 3), m."""
        inv = self.settings.inverse
        assert inv is not None
        x = excitation(self.grid.size, self.settings.cycle_s, inv.excitation_m,
                       (inv.excitation_low_hz, inv.excitation_high_hz), inv.seed)
        return x * self._window[:, None]

    def _reidentify(self, applied: Array, err: Array, meas: Array) -> None:
        """The plant again, from the excited run's open-loop pairs and this run's (class
        docstring, "Re-identification")."""
        assert self._excited is not None
        u_x, e_x, m_x = self._excited
        self._pairs.append((applied - u_x, err - e_x, m_x & meas))
        du, de, mask = (np.array(v) for v in zip(*self._pairs, strict=True))
        self.identify(du, de, mask)

    def _supervise(self, rms: float, applied: Array, err: Array, law: str
                   ) -> tuple[Array, str]:
        """The supervisor of (3): a run whose measured rms error exceeds ``backoff``
        times the best run's (more than the noise moves it) says the model's error broke
        (4) somewhere — ``u`` returns to the best run's, the update starts from that
        run's error, and ``β`` grows tenfold (a smaller, more robust step)."""
        inv = self.settings.inverse
        assert inv is not None
        if self._best is None or rms < self._best[0]:
            self._best = (rms, applied.copy(), err.copy())
            return err, law
        if inv.backoff and rms > inv.backoff * self._best[0]:
            self.u = self._best[1].copy()
            self._beta_scale *= 10.0
            self._spectral = None
            return self._best[2], "inverse, backed off"
        return err, law

    def update(self, sample_t: ArrayLike, sample_p: ArrayLike, path_t: ArrayLike,
               path_p: ArrayLike, start_s: float) -> Array:
        """Learn from one run: :func:`path_error` on the grid (robot times
        ``start_s + grid``), then :meth:`learn_error`.  Arguments as :func:`path_error`'s;
        ``start_s`` the robot time the run's motion started.  Returns the error (G, 3)."""
        e, measured = path_error(sample_t, sample_p, path_t, path_p,
                                 self.grid + float(start_s), self.settings.cycle_s)
        self.learn_error(e, measured)
        return e
