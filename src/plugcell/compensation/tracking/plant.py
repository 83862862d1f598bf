"""The plant of a learned offset, identified from the runs: how the measured path error
answers a change of the target (issue 38 §4, the learning above the arm's modes).

What the learning of :mod:`.learning` changes is ``u``, the offset added to the target;
what it sees is the tracker's error ``e``.  Between them lies the arm: the controller's
dead time, the servo, and the structural modes of the joints — on the Smart H4 twin
9–14 Hz with damping 0.04, a gain of ≈ 12 at resonance and the phase turning through
180°, mixed between the Cartesian axes by the arm's Jacobian.  Around a path that
repeats, two runs that differ only in ``u`` differ in their error by the plant's answer
(the path's own disturbance ``d`` repeats; the tracker's noise is fresh)::

    e_b − e_a = P (u_b − u_a) + (n_b − n_a)                                  (1)

so one run with a known excitation added to its offset (:func:`excitation`) identifies
``P`` from nothing but the tracker's samples — what a real cell can do.  Several such
pairs ``r = 1 … R`` (the excited run against the run before it and against each run
after it) identify one ``P`` together: (1) holds for each, and the least squares below
sums their residuals (each pair's regressors start from rest at its own first cycle).

The model (a few-mode model, discrete time, cycle ``T``): the impulse response from
input axis ``j`` to output axis ``i`` is a free FIR head plus a sum of lightly damped
modes shared by all the nine channels::

    h_ij[k] = D_ij[k] (0 ≤ k < K)  +  Σ_m (B_m,ij z⁻¹ + C_m,ij z⁻²) / A_m(z)       (2)
    A_m(z) = 1 − 2 r_m cos θ_m z⁻¹ + r_m² z⁻²,
    r_m = exp(−ζ_m ω_m T),  θ_m = ω_m √(1 − ζ_m²) T,  ω_m = 2π f_m

The head ``D`` takes the dead time and the servo's fast response (any ``K`` first taps);
each mode's two numerator terms give any amplitude and phase of its damped sinusoid
(after the first taps, an impulse response of (2) is the head plus ``Σ_m`` damped
sinusoids at ``f_m`` decaying as ``r_m^k``).  For given ``(f_m, ζ_m)`` (2) is linear in
``D, B, C``: a least-squares fit (variable projection; Golub & Pereyra, SIAM J. Numer.
Anal. 10(2), 1973) whose residual the modes' parameters minimise
(``scipy.optimize.least_squares``), each new mode started from a grid search over the
frequency with the others fixed (greedy), then all refined together.

Pure math: numpy and scipy, SI units, no I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import least_squares
from scipy.signal import butter, lfilter, sosfiltfilt

Array = NDArray[np.float64]

__all__ = ["ModalPlant", "excitation", "identify_plant"]


def _denominator(f_hz: float, zeta: float, cycle_s: float) -> Array:
    """``A_m`` of (2): ``[1, −2r cos θ, r²]``."""
    w = 2 * math.pi * f_hz
    r = math.exp(-zeta * w * cycle_s)
    th = w * math.sqrt(max(1.0 - zeta * zeta, 0.0)) * cycle_s
    return np.array([1.0, -2.0 * r * math.cos(th), r * r])


def _shift(x: Array, k: int) -> Array:
    """``x[t − k]`` (zeros before the start)."""
    if k == 0:
        return x
    out = np.zeros_like(x)
    out[k:] = x[:-k]
    return out


def _basis(u: Array, taps: int, modes: list[tuple[float, float]], cycle_s: float) -> Array:
    """The regressors of (2): ``(G, 3 (K + 2M))``, block ``b`` and input ``j`` in column
    ``3 b + j`` (head taps first, then ``z⁻¹/A_m`` and ``z⁻²/A_m`` per mode)."""
    cols = [_shift(u, k) for k in range(taps)]
    for f, z in modes:
        s = lfilter([0.0, 1.0], _denominator(f, z, cycle_s), u, axis=0)
        cols += [s, _shift(s, 1)]
    return np.hstack(cols)


@dataclass(frozen=True)
class ModalPlant:
    """An identified plant (module docstring, (2)); 3 inputs (the offset, m) to 3 outputs
    (the measured error, m), F0 axes.

    Attributes
    ----------
    cycle_s : float
        ``T`` (s).
    head : (K, 3, 3) array
        ``D[k, i, j]``: the free taps at lags ``0 … K − 1``.
    frequency_hz, damping : (M,) arrays
        ``f_m`` (Hz) and ``ζ_m`` of the modes.
    residues : (M, 2, 3, 3) array
        ``[B_m, C_m][i, j]``: the modes' numerators.
    fit : float
        Share of the identification data's variance the model explains (``R²``, 0–1).
    """

    cycle_s: float
    head: Array
    frequency_hz: Array
    damping: Array
    residues: Array
    fit: float = math.nan

    def response(self, frequency_hz: ArrayLike) -> NDArray[np.complex128]:
        """``P(e^{jωT})`` at ``frequency_hz`` (m,): ``(m, 3, 3)`` complex, ``[f, i, j]``."""
        f = np.asarray(frequency_hz, dtype=float).reshape(-1)
        z1 = np.exp(-2j * np.pi * f * self.cycle_s)  # z⁻¹
        H = np.einsum("fk,kij->fij", z1[:, None] ** np.arange(self.head.shape[0]), self.head)
        for m in range(self.frequency_hz.size):
            a = _denominator(self.frequency_hz[m], self.damping[m], self.cycle_s)
            den = a[0] + a[1] * z1 + a[2] * z1 ** 2
            B, C = self.residues[m]
            H = H + (z1 / den)[:, None, None] * B + (z1 ** 2 / den)[:, None, None] * C
        return H

    def simulate(self, u: ArrayLike) -> Array:
        """``y = P u`` for an input ``(G, 3)`` (m) starting from rest: ``(G, 3)`` (m)."""
        x = np.asarray(u, dtype=float)
        if x.ndim != 2 or x.shape[1] != 3:
            raise ValueError(f"ModalPlant.simulate: expected an input (G, 3), got {x.shape}")
        modes = list(zip(self.frequency_hz.tolist(), self.damping.tolist(), strict=True))
        return _basis(x, self.head.shape[0], modes, self.cycle_s) @ self._coefficients()

    def _coefficients(self) -> Array:
        """The columns of :func:`_basis` → outputs: ``(3 (K + 2M), 3)``."""
        blocks = list(self.head) + [r for m in self.residues for r in m]  # each (i, j)
        return np.vstack([b.T for b in blocks])


def _basis_runs(u: Array, taps: int, modes: list[tuple[float, float]], cycle_s: float
                ) -> Array:
    """:func:`_basis` of each pair ``u[r]`` (R, G, 3), from rest, stacked: ``(R G, ·)``."""
    return np.vstack([_basis(x, taps, modes, cycle_s) for x in u])


def identify_plant(u: ArrayLike, y: ArrayLike, cycle_s: float, *, modes: int = 5,
                   taps: int = 8, mask: ArrayLike | None = None,
                   band_hz: tuple[float, float] = (3.0, 40.0), grid_hz: float = 0.25,
                   damping0: float = 0.05) -> ModalPlant:
    """Identify (2) from an input ``u`` and the output ``y`` it caused (1).

    Parameters
    ----------
    u : (G, 3) or (R, G, 3) array_like
        The change of the offset between the two runs (m), on the cycle grid; it should
        start and end at rest (windowed) and excite the band of interest
        (:func:`excitation`).  ``(R, G, 3)``: ``R`` pairs of runs, fitted together
        (module docstring).
    y : (G, 3) or (R, G, 3) array_like
        The change of the measured error (m) on the same grid.
    cycle_s : float
        ``T`` (s).
    modes : int
        ``M``, modes to fit (0: the FIR head alone).
    taps : int
        ``K``, the FIR head's taps (≥ the dead time and the servo's fast response).
    mask : (G,) or (R, G) bool array_like, optional
        Cycles whose ``y`` was measured in both runs (default: all); the input runs on
        all of them, the residual counts only these.
    band_hz : (float, float)
        Where the modes are searched (Hz), within ``(0, 0.5/T)``.
    grid_hz : float
        The frequency grid of the greedy start (Hz).
    damping0 : float
        ``ζ`` the greedy start assumes.

    Returns
    -------
    ModalPlant

    Raises
    ------
    ValueError
        Shapes that do not match, non-finite data, too few measured cycles for the
        parameters, a band outside ``(0, 0.5/T)``, or an input without energy.
    """
    U, Y, m = _checked(u, y, mask, modes, taps, band_hz, cycle_s)
    found = _search_modes(U, Y, m, taps, modes, band_hz, grid_hz, damping0, cycle_s)
    Ym = Y[m]
    X = _basis_runs(U, taps, found, cycle_s)[m]
    C, *_ = np.linalg.lstsq(X, Ym, rcond=None)
    r = (Ym - X @ C).ravel()
    fit = 1.0 - float(r @ r) / max(float(((Ym - Ym.mean(0)) ** 2).sum()), 1e-300)
    blocks = [C[3 * b: 3 * b + 3].T for b in range(taps + 2 * len(found))]
    return ModalPlant(cycle_s, np.array(blocks[:taps]).reshape(taps, 3, 3),
                      np.array([f for f, _ in found]), np.array([z for _, z in found]),
                      np.array(blocks[taps:]).reshape(len(found), 2, 3, 3), fit)


def _checked(u: ArrayLike, y: ArrayLike, mask: ArrayLike | None, modes: int, taps: int,
             band_hz: tuple[float, float], cycle_s: float) -> tuple[Array, Array, NDArray]:
    """:func:`identify_plant`'s input, checked: ``u`` (R, G, 3), ``y`` (R G, 3) and the
    mask (R G,)."""
    U = np.asarray(u, dtype=float)
    Y = np.asarray(y, dtype=float)
    if U.ndim not in (2, 3) or U.shape[-1] != 3 or U.shape != Y.shape or 0 in U.shape:
        raise ValueError(f"identify_plant: u and y must both be (G, 3) or (R, G, 3), got "
                         f"{U.shape} and {Y.shape}")
    if not (np.all(np.isfinite(U)) and np.all(np.isfinite(Y))):
        raise ValueError("identify_plant: u and y must be finite")
    U, Y = U.reshape(-1, *U.shape[-2:]), Y.reshape(-1, 3)
    m = np.ones(U.shape[:2], bool) if mask is None else np.asarray(mask, bool)
    if m.shape == U.shape[1:2]:  # one mask (G,) for every pair
        m = np.broadcast_to(m, U.shape[:2])
    m = m.reshape(-1)
    if m.size != Y.shape[0]:
        raise ValueError(f"identify_plant: mask has {m.size} cycles, u has "
                         f"{U.shape[0]} × {U.shape[1]}")
    if not (isinstance(modes, int) and 0 <= modes <= 12 and isinstance(taps, int)
            and 1 <= taps <= 200):
        raise ValueError(f"identify_plant: modes must be 0–12 and taps 1–200, got {modes!r} "
                         f"and {taps!r}")
    nyq = 0.5 / cycle_s
    if not 0 < band_hz[0] < band_hz[1] < nyq:
        raise ValueError(f"identify_plant: band_hz {band_hz!r} must lie within (0, {nyq:g}) Hz")
    n_par = 3 * (taps + 2 * modes)
    if m.sum() < 3 * n_par:
        raise ValueError(f"identify_plant: {int(m.sum())} measured cycles for {n_par} "
                         f"coefficients per axis; need at least {3 * n_par}")
    if not np.any(U):
        raise ValueError("identify_plant: the input u is zero: nothing to identify")
    return U, Y, m


def _search_modes(U: Array, Y: Array, m: NDArray, taps: int, modes: int,
                  band_hz: tuple[float, float], grid_hz: float, damping0: float,
                  cycle_s: float) -> list[tuple[float, float]]:
    """The modes ``(f_m, ζ_m)`` by variable projection: each new one from a grid search
    over the frequency (the others fixed), then all refined together; sorted by ``f``."""
    Ym = Y[m]
    lo, hi = band_hz

    def residual(found: list[tuple[float, float]]) -> Array:
        # the normal equations, columns scaled: fast inside the search (lstsq at the end)
        X = _basis_runs(U, taps, found, cycle_s)[m]
        scale = np.maximum(np.linalg.norm(X, axis=0), 1e-300)
        Xs = X / scale
        C = np.linalg.solve(Xs.T @ Xs + 1e-12 * np.eye(Xs.shape[1]), Xs.T @ Ym)
        return (Ym - Xs @ C).ravel()

    found: list[tuple[float, float]] = []
    lb, ub = [lo, 0.01], [hi, 0.5]
    for _ in range(modes):
        grid = np.arange(lo, hi, grid_hz)
        cost = [float(np.sum(residual([*found, (f, damping0)]) ** 2)) for f in grid]
        found.append((float(grid[int(np.argmin(cost))]), damping0))
        x0 = np.array([v for fz in found for v in fz])
        sol = least_squares(lambda x: residual(list(zip(x[::2], x[1::2], strict=True))), x0,
                            bounds=(lb * len(found), ub * len(found)), x_scale="jac")
        found = list(zip(sol.x[::2].tolist(), sol.x[1::2].tolist(), strict=True))
    return sorted(found)


def excitation(cycles: int, cycle_s: float, rms_m: float,
               band_hz: tuple[float, float] = (1.0, 30.0), seed: int = 0) -> Array:
    """A seeded excitation for (1): white noise through a zero-phase Butterworth band-pass
    (order 4), each of the three axes independent and scaled to ``rms_m``.

    Parameters
    ----------
    cycles : int
        ``G``, the grid's length.
    cycle_s : float
        ``T`` (s).
    rms_m : float
        The rms per axis (m), > 0.
    band_hz : (float, float)
        The band (Hz), within ``(0, 0.5/T)``.
    seed : int

    Returns
    -------
    (G, 3) array
        m; not windowed (the learning fades it in and out with its window).
    """
    nyq = 0.5 / cycle_s
    if not (isinstance(cycles, int) and cycles >= 64):
        raise ValueError(f"excitation: cycles must be an integer ≥ 64, got {cycles!r}")
    if not 0 < band_hz[0] < band_hz[1] < nyq:
        raise ValueError(f"excitation: band_hz {band_hz!r} must lie within (0, {nyq:g}) Hz")
    if not (math.isfinite(rms_m) and rms_m > 0):
        raise ValueError(f"excitation: rms_m must be > 0, got {rms_m!r}")
    sos = butter(4, band_hz, btype="bandpass", fs=1.0 / cycle_s, output="sos")
    x = sosfiltfilt(sos, np.random.default_rng(seed).standard_normal((cycles, 3)), axis=0)
    return x * (rms_m / x.std(axis=0))
