"""Input validation shared by the metrology modules (private)."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["MetrologyError", "as_points", "as_transform", "as_vector3"]


class MetrologyError(ValueError):
    """Degenerate or malformed input to a metrology computation.

    Raised, with a message naming the argument and the defect, for too few
    points, coincident/collinear points where a plane or circle is needed,
    non-finite values (NaN/inf), wrong shapes and singular parametrisations.
    """


def as_points(
    points: ArrayLike, name: str, min_points: int, noun: str = "points"
) -> NDArray[np.float64]:
    """Return ``points`` as a finite ``(N, 3)`` float array with ``N >= min_points``."""
    try:
        p = np.asarray(points, dtype=float)
    except (TypeError, ValueError) as exc:
        raise MetrologyError(f"{name}: cannot be read as an (N, 3) array of numbers") from exc
    if p.ndim != 2 or p.shape[1] != 3:
        raise MetrologyError(f"{name}: expected an (N, 3) array of {noun}, got shape {p.shape}")
    if p.shape[0] < min_points:
        raise MetrologyError(
            f"{name}: needs at least {min_points} {noun}, got {p.shape[0]}"
        )
    bad = ~np.isfinite(p).all(axis=1)
    if bad.any():
        rows = np.flatnonzero(bad)
        raise MetrologyError(
            f"{name}: non-finite values (NaN or inf) in row(s) {rows[:10].tolist()}"
        )
    return p


def as_vector3(v: ArrayLike, name: str, *, unit: bool = False) -> NDArray[np.float64]:
    """Return ``v`` as a finite 3-vector, normalised when ``unit`` (zero length refused)."""
    try:
        a = np.asarray(v, dtype=float)
    except (TypeError, ValueError) as exc:
        raise MetrologyError(f"{name}: cannot be read as a 3-vector") from exc
    if a.shape != (3,):
        raise MetrologyError(f"{name}: expected a 3-vector, got shape {a.shape}")
    if not np.isfinite(a).all():
        raise MetrologyError(f"{name}: non-finite component (NaN or inf): {a.tolist()}")
    if unit:
        n = float(np.linalg.norm(a))
        if n < 1e-12:
            raise MetrologyError(f"{name}: zero-length vector has no direction")
        a = a / n
    return a


def as_transform(T: ArrayLike, name: str, *, rtol: float = 1e-6) -> NDArray[np.float64]:
    """Return ``T`` as a finite 4×4 homogeneous rigid transform (rotation checked)."""
    try:
        a = np.asarray(T, dtype=float)
    except (TypeError, ValueError) as exc:
        raise MetrologyError(f"{name}: cannot be read as a 4x4 matrix") from exc
    if a.shape != (4, 4):
        raise MetrologyError(f"{name}: expected a 4x4 homogeneous transform, got shape {a.shape}")
    if not np.isfinite(a).all():
        raise MetrologyError(f"{name}: non-finite entry (NaN or inf)")
    if not np.allclose(a[3], [0.0, 0.0, 0.0, 1.0], atol=1e-9):
        raise MetrologyError(f"{name}: last row must be [0, 0, 0, 1], got {a[3].tolist()}")
    R = a[:3, :3]
    err = float(np.max(np.abs(R.T @ R - np.eye(3))))
    if err > rtol or np.linalg.det(R) <= 0.0:
        raise MetrologyError(
            f"{name}: upper-left 3x3 block is not a proper rotation "
            f"(max |RᵀR − I| = {err:.3g}, det = {np.linalg.det(R):.6g})"
        )
    return a
