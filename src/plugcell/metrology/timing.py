"""Aligning the clocks of a cell's sensors: delay between two signals, clock maps.

A laser tracker stamps each sample with its own clock at acquisition; the PC stamps it
again when it arrives; the robot's controller numbers its cycles.  Two estimators put
them on one time axis, each from data the cell produces anyway — the latency is
*estimated*, never assumed:

* :func:`estimate_delay` — the delay ``d`` between two records of the same motion
  (e.g. the tracker's reflector position and the robot's joint feedback put through
  the model), by least squares, searched on a grid and refined to a fraction of a sample::

      d̂ = argmin_d  Σ_t ‖ b(t) − a(t − d) ‖²        (residual mean-free; t: b's own sample times)

  with the Gauss–Newton standard error ``σ_d = σ_r / √(Σ_t ‖ȧ(t − d̂)‖²)``.
* :func:`fit_clock_map` — the map from a device clock ``x`` to the PC clock ``y`` from
  one-way time stamps (``y`` = arrival), whose transport delays are never negative:
  the *lower envelope* ``y ≈ offset + rate · x`` with every point on or above it
  (a linear programme, as one-way clock-skew estimation does, Moon, Skelly & Towsley,
  "Estimation and removal of clock skew from network delay measurements", INFOCOM 1999).
  One-way stamps cannot tell a clock offset from a constant delay: the envelope's
  offset includes the smallest transport delay; :func:`estimate_delay` against a
  second, independent clock (the robot's) separates them.

Pure math: seconds in, seconds out; bad input raises :class:`MetrologyError`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import CubicSpline
from scipy.optimize import linprog, minimize_scalar

from ._validate import MetrologyError

Array = NDArray[np.float64]

__all__ = ["ClockMap", "DelayEstimate", "estimate_delay", "fit_clock_map"]


@dataclass(frozen=True)
class DelayEstimate:
    """Result of :func:`estimate_delay`.

    Attributes
    ----------
    delay_s : float
        ``d̂``: ``b`` lags ``a`` by this much (s; negative if it leads).
    std_s : float
        Gauss–Newton standard error of ``d̂`` (s) from the residual scatter.
    residual_rms : float
        RMS of ``b(t) − a(t − d̂)`` per channel, in the signals' unit.
    grid_s : float
        Step of the coarse search (s).
    samples : int
        Grid points in the overlap used.
    """

    delay_s: float
    std_s: float
    residual_rms: float
    grid_s: float
    samples: int


@dataclass(frozen=True)
class ClockMap:
    """``pc ≈ offset_s + rate · device`` (lower envelope of one-way time stamps).

    Attributes
    ----------
    offset_s, rate : float
        The map (``rate``: PC seconds per device second; ``skew_ppm``).
    jitter_s : ndarray, shape (N,)
        Each stamp's height above the envelope: its transport delay minus the smallest.
    """

    offset_s: float
    rate: float
    jitter_s: Array

    @property
    def skew_ppm(self) -> float:
        """``(rate − 1)·10⁶``: PC seconds per device second, minus one, in ppm — a device
        clock that runs 20 ppm fast gives ≈ −20."""
        return (self.rate - 1.0) * 1e6

    def __call__(self, device_s: ArrayLike) -> Array:
        """PC time of device time(s) ``device_s`` (s)."""
        return self.offset_s + self.rate * np.asarray(device_s, dtype=float)


def _series(t: ArrayLike, x: ArrayLike, name: str) -> tuple[Array, Array]:
    try:
        tt = np.asarray(t, dtype=float)
        xx = np.asarray(x, dtype=float)
    except (TypeError, ValueError) as exc:
        raise MetrologyError(f"{name}: cannot be read as numbers") from exc
    if tt.ndim != 1:
        raise MetrologyError(f"{name}: times must be a 1-D array, got shape {tt.shape}")
    if xx.ndim == 1:
        xx = xx[:, None]
    if xx.ndim != 2 or xx.shape[0] != tt.shape[0]:
        raise MetrologyError(
            f"{name}: values must be (N,) or (N, k) with N = {tt.shape[0]} times, "
            f"got shape {np.shape(x)}")
    if tt.shape[0] < 8:
        raise MetrologyError(f"{name}: needs at least 8 samples, got {tt.shape[0]}")
    if not (np.isfinite(tt).all() and np.isfinite(xx).all()):
        raise MetrologyError(f"{name}: non-finite values (NaN or inf); drop them first")
    if np.any(np.diff(tt) <= 0):
        raise MetrologyError(f"{name}: times must increase strictly")
    return tt, xx


def _coarse_delay(ta: Array, xa: Array, inner: Array, xb_in: Array, max_delay_s: float,
                  h: float) -> float:
    """The coarse delay: the whole grid step ``d = k·h``, ``|k| ≤ ⌈max_delay_s/h⌉``, of
    least cost ``Σⱼ var(b_j(t) − a_j(t − d))`` (``a`` interpolated linearly at ``b``'s
    sample times ``inner``)."""
    m = int(np.ceil(max_delay_s / h))
    costs = []
    for k in range(-m, m + 1):
        at = inner - k * h
        a_at = np.column_stack([np.interp(at, ta, xa[:, j]) for j in range(xa.shape[1])])
        costs.append(float(np.sum(np.var(xb_in - a_at, axis=0))))
    return (int(np.argmin(costs)) - m) * h


def estimate_delay(
    t_a: ArrayLike, a: ArrayLike, t_b: ArrayLike, b: ArrayLike, *, max_delay_s: float,
    grid_s: float | None = None,
) -> DelayEstimate:
    """Delay of signal ``b`` behind signal ``a`` (module docstring).

    Parameters
    ----------
    t_a, t_b : array_like, shape (Na,), (Nb,)
        Sample times (s, one clock for both), strictly increasing; any spacing.
    a, b : array_like, shape (Na,) or (Na, k); (Nb,) or (Nb, k)
        The same ``k`` quantities seen by two sources (same units).
    max_delay_s : float
        The search range ``|d| ≤ max_delay_s`` (s).
    grid_s : float, optional
        Step of the coarse search (default: the finer median spacing of the two).

    Returns
    -------
    DelayEstimate

    Raises
    ------
    MetrologyError
        Shapes, non-finite values, no overlap longer than the search range, or a motion
        too small to time (no variation).
    """
    ta, xa = _series(t_a, a, "a")
    tb, xb = _series(t_b, b, "b")
    if xa.shape[1] != xb.shape[1]:
        raise MetrologyError(f"a has {xa.shape[1]} channels, b has {xb.shape[1]}")
    if not (np.isfinite(max_delay_s) and max_delay_s > 0):
        raise MetrologyError(f"max_delay_s must be > 0, got {max_delay_s}")
    h = float(grid_s) if grid_s is not None else float(
        min(np.median(np.diff(ta)), np.median(np.diff(tb))))
    if not (np.isfinite(h) and h > 0):
        raise MetrologyError(f"grid_s must be > 0, got {h}")
    lo, hi = max(ta[0], tb[0]), min(ta[-1], tb[-1])
    if hi - lo <= 2 * max_delay_s + 8 * h:
        raise MetrologyError(
            f"the records overlap for {max(hi - lo, 0.0):.4g} s, not enough for a search "
            f"over ±{max_delay_s:g} s")
    # b is compared at its own sample times (it may have gaps: lost samples, beam
    # breaks), a is interpolated (it must be gap-free over the overlap)
    keep = (tb - ta[0] >= max_delay_s + h) & (ta[-1] - tb >= max_delay_s + h)
    inner, xb_in = tb[keep], xb[keep]
    if inner.size < 8:
        raise MetrologyError("too little overlap left inside the search range")
    if not (np.ptp(xa, axis=0).max() > 0 and np.ptp(xb_in, axis=0).max() > 0):
        raise MetrologyError("a or b does not vary over the overlap: no motion to time")

    d0 = _coarse_delay(ta, xa, inner, xb_in, max_delay_s, h)
    # refinement with a cubic spline of a (a linear one biases the delay where a is
    # sampled coarsely)
    spline = CubicSpline(ta, xa, axis=0)
    coarse = float(max(np.median(np.diff(ta)), np.median(np.diff(tb)), h))

    def cost(d: float) -> float:
        r = xb_in - spline(inner - d)
        r -= r.mean(axis=0)
        return float(np.mean(r * r))

    span = 1.5 * coarse
    res = minimize_scalar(cost, bounds=(d0 - span, d0 + span), method="bounded",
                          options={"xatol": h * 1e-4})
    d = float(res.x)
    r = xb_in - spline(inner - d)
    r -= r.mean(axis=0)
    slope = spline(inner - d, 1)
    s2 = float(np.sum(r * r)) / max(r.size - 1, 1)
    energy = float(np.sum(slope * slope))
    std = float(np.sqrt(s2 / energy)) if energy > 0 else float("inf")
    return DelayEstimate(delay_s=d, std_s=std, residual_rms=float(np.sqrt(np.mean(r * r))),
                         grid_s=h, samples=int(inner.size))


def fit_clock_map(device_s: ArrayLike, pc_s: ArrayLike) -> ClockMap:
    """The lower envelope ``pc ≈ offset + rate · device`` of one-way time stamps.

    Solves the linear programme ``min Σ (y_i − o − r x_i)`` subject to
    ``y_i ≥ o + r x_i`` (x centred for conditioning).

    Parameters
    ----------
    device_s : array_like, shape (N,)
        Device (e.g. tracker) time of each event (s), strictly increasing.
    pc_s : array_like, shape (N,)
        PC time at which each event arrived (s).

    Returns
    -------
    ClockMap

    Raises
    ------
    MetrologyError
        Fewer than 8 stamps, non-finite or non-increasing device times.
    """
    x, y = _series(device_s, pc_s, "device_s/pc_s")
    y = y[:, 0]
    xc = x.mean()
    u = x - xc
    # variables (o, r); minimise −Σ(o + r u) ⇔ maximise the envelope under the points
    n = len(u)
    res = linprog(c=[-n, -float(u.sum())], A_ub=np.column_stack([np.ones(n), u]), b_ub=y,
                  bounds=[(None, None), (None, None)], method="highs")
    if not res.success:  # pragma: no cover - a feasible, bounded LP for increasing x
        raise MetrologyError(f"clock map: the envelope fit failed ({res.message})")
    o, r = float(res.x[0]), float(res.x[1])
    jitter = y - (o + r * u)
    return ClockMap(offset_s=o - r * xc, rate=r, jitter_s=np.maximum(jitter, 0.0))
