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

Pure math: numpy and scipy, SI units, no I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.signal import butter, filtfilt, freqz
from scipy.signal.windows import tukey

Array = NDArray[np.float64]

__all__ = ["IterativeLearning", "LearnedOffset", "LearningSettings", "contraction",
           "path_error"]


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

    def __post_init__(self) -> None:
        for f in fields(self):
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
    e = np.column_stack([np.bincount(idx, d[:, i], minlength=g.size) for i in range(3)])
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
class IterativeLearning:
    """The learning of one repeated path (module docstring, (1)).

    Parameters
    ----------
    duration_s : float
        The path's motion (s): the window runs from ``−pre_s`` to ``duration_s + post_s``.
    settings : LearningSettings

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
        ``u_max_m``.

    API note: ``feedforward(start_s)`` → the next run's :class:`LearnedOffset`;
    ``update(sample_t, sample_p, path_t, path_p, start_s)`` after the run.
    """

    duration_s: float
    settings: LearningSettings = field(default_factory=LearningSettings)
    grid: Array = field(init=False)
    u: Array = field(init=False)
    history: list[dict[str, float]] = field(init=False, default_factory=list)
    steps: int = field(init=False, default=0)

    def __post_init__(self) -> None:
        s = self.settings
        if not (math.isfinite(self.duration_s) and self.duration_s > 0):
            raise ValueError(f"IterativeLearning: the path's duration must be > 0 s, "
                             f"got {self.duration_s!r}")
        n = round((self.duration_s + s.pre_s + s.post_s) / s.cycle_s) + 1
        if 2 * s.taper_s > (n - 1) * s.cycle_s:
            raise ValueError(f"LearningSettings.taper_s {s.taper_s!r} s is longer than half "
                             f"the learning window ({(n - 1) * s.cycle_s:g} s)")
        self.grid = -s.pre_s + s.cycle_s * np.arange(n)
        self.u = np.zeros((n, 3))
        span = (n - 1) * s.cycle_s
        self._window = tukey(n, 2 * s.taper_s / span) if span > 0 else np.ones(n)
        self._b, self._a = s.q_filter()

    @property
    def iterations(self) -> int:
        """Updates so far."""
        return len(self.history)

    def feedforward(self, start_s: float) -> LearnedOffset:
        """The offset for the next run whose motion starts at robot time ``start_s``."""
        return LearnedOffset(self.grid + float(start_s), self.u.copy())

    def step(self, e: ArrayLike) -> Array:
        """One update (1) from the error ``e`` (G, 3) on :attr:`grid` (m), with the gain
        ``L_k`` of :attr:`steps` updates so far; the new ``u``."""
        s = self.settings
        err = np.asarray(e, dtype=float)
        if err.shape != self.u.shape or not np.all(np.isfinite(err)):
            raise ValueError(f"IterativeLearning.step: expected a finite error of shape "
                             f"{self.u.shape}, got {err.shape}")
        ahead = np.column_stack([np.interp(self.grid + s.lead_s, self.grid, err[:, i],
                                           right=0.0) for i in range(3)])
        x = self.u - s.gain / (1.0 + s.gain_decay * self.steps) * ahead
        self.steps += 1
        u = filtfilt(self._b, self._a, x, axis=0) * self._window[:, None]
        self.u = np.clip(u, -s.max_offset_m, s.max_offset_m)
        return self.u.copy()

    def update(self, sample_t: ArrayLike, sample_p: ArrayLike, path_t: ArrayLike,
               path_p: ArrayLike, start_s: float) -> Array:
        """Learn from one run: :func:`path_error` on the grid (robot times
        ``start_s + grid``), then :meth:`step`.  Arguments as :func:`path_error`'s;
        ``start_s`` the robot time the run's motion started.  Returns the error (G, 3)."""
        e, measured = path_error(sample_t, sample_p, path_t, path_p,
                                 self.grid + float(start_s), self.settings.cycle_s)
        motion = (self.grid >= 0) & (self.grid <= self.duration_s) & measured
        mag = np.linalg.norm(e[motion], axis=1)
        self.history.append({
            "rms_m": float(np.sqrt(np.mean(mag ** 2))) if mag.size else math.nan,
            "max_m": float(mag.max()) if mag.size else math.nan,
            "measured": float(measured.mean()),
            "u_max_m": float(np.abs(self.u).max())})
        self.step(e)
        return e
