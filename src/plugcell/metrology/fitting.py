"""Best-fit line, plane and circle in 3-D (thesis App. D, 8.3.1, 8.4.1).

All fits are orthogonal (total) least squares on points given as an ``(N, 3)``
array in metres. Each returns a frozen result holding the fitted geometry, the
per-point residuals, their rms and small helpers (distances of new points,
projections).

Orientation conventions (a fitted line or plane has no intrinsic sign):

* **line** — ``direction`` points from the first point towards the last point
  (``(p[-1] − p[0])·direction ≥ 0``), i.e. along the order in which the points
  were measured: "move the robot along +x" (App. D.2) or "from dowel hole 1 to
  dowel hole 2" (App. D.1). A ``direction_hint`` overrides it
  (``direction·hint ≥ 0``).
* **plane** — with ``normal_hint`` the normal satisfies ``normal·hint ≥ 0``;
  without it the normal's component of largest magnitude is positive (a
  horizontal surface measured by an upright tracker gets ``+z``).
* **circle** — the normal follows the right-hand rule along the order of the
  points: if the points are the positions of a reflector while a revolute joint
  turns in its *positive* direction, the fitted normal is the joint's ``+z``
  axis (App. D.1, D.2). ``normal_hint`` overrides it; a point measured twice in a
  row (consecutive points less than ``SAME_ANGLE`` apart) does not count as a turn
  back; if the traversal is ambiguous (points in no angular order) the plane
  convention is used and the fit says so (``CircleFit.oriented`` False) — the frames
  built on a circle's axis (:mod:`plugcell.metrology.frames`) refuse it without a hint.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._validate import MetrologyError, as_points, as_vector3

__all__ = [
    "CircleFit",
    "LineFit",
    "PlaneFit",
    "fit_circle",
    "fit_line",
    "fit_plane",
]

FloatArray = NDArray[np.float64]

#: Default relative tolerance on singular values below which a point cloud is
#: declared coincident (for a line) or collinear (for a plane or circle).
DEGENERACY_RTOL = 1e-9

#: Two consecutive circle points less than this angle apart (rad, 0.057°) are one point
#: measured twice: they neither keep nor break the points' rotation sense.
SAME_ANGLE = 1e-3


def _centred_svd(p: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    c = p.mean(axis=0)
    _, s, vt = np.linalg.svd(p - c, full_matrices=False)
    return c, s, vt


def _check_spread(p: FloatArray, c: FloatArray, s: FloatArray, name: str) -> None:
    scale = 1.0 + float(np.max(np.abs(c)))
    if s[0] / np.sqrt(len(p)) <= 1e-12 * scale:
        raise MetrologyError(f"{name}: all {len(p)} points coincide; no geometry can be fitted")


def _check_not_collinear(s: FloatArray, name: str, rtol: float) -> None:
    if s[1] <= rtol * s[0]:
        raise MetrologyError(
            f"{name}: points are collinear (singular values {s[0]:.3g}, {s[1]:.3g}; "
            f"ratio {s[1] / s[0]:.3g} <= {rtol:g}); a plane or circle is undefined"
        )


def _rms(x: FloatArray) -> float:
    return float(np.sqrt(np.mean(np.square(x)))) if x.size else 0.0


# ---------------------------------------------------------------------------- line


@dataclass(frozen=True)
class LineFit:
    """A 3-D line ``x(t) = point + t·direction`` fitted by total least squares.

    Attributes
    ----------
    point : (3,) array, m
        Centroid of the fitted points, a point on the line.
    direction : (3,) array
        Unit direction (sign: see module docstring).
    residuals : (N,) array, m
        Perpendicular distance ``‖(p − c) − ((p − c)·d) d‖ ≥ 0`` of each fitted point.
    rms : float, m
        ``√(Σ rᵢ² / N)`` of ``residuals``.
    singular_values : (3,) array, m
        Singular values of the centred points (spread along, then across the line).
    """

    point: FloatArray
    direction: FloatArray
    residuals: FloatArray
    rms: float
    singular_values: FloatArray

    @property
    def max_residual(self) -> float:
        """Largest perpendicular distance of a fitted point, ``max rᵢ`` (m)."""
        return float(self.residuals.max()) if self.residuals.size else 0.0

    def parameters(self, points: ArrayLike) -> FloatArray:
        """Line parameter of the orthogonal projection, ``t = (p − point)·direction``.

        Parameters
        ----------
        points : (..., 3) array_like, m
            Points.

        Returns
        -------
        t : (...) array, m
            Signed distance along the line from ``point``.
        """
        p = np.asarray(points, dtype=float)
        return (p - self.point) @ self.direction

    def project(self, points: ArrayLike) -> FloatArray:
        """Closest point on the line, ``point + t·direction`` with ``t`` of :meth:`parameters`.

        Parameters
        ----------
        points : (..., 3) array_like, m
            Points.

        Returns
        -------
        (..., 3) array, m
            Their orthogonal projections onto the line.
        """
        t = self.parameters(points)
        return self.point + t[..., None] * self.direction

    def deviations(self, points: ArrayLike) -> FloatArray:
        """Perpendicular deviation vectors ``p − project(p)``.

        Parameters
        ----------
        points : (..., 3) array_like, m
            Points.

        Returns
        -------
        (..., 3) array, m
            Deviation vectors, perpendicular to ``direction``.
        """
        p = np.asarray(points, dtype=float)
        return p - self.project(p)

    def distance(self, points: ArrayLike) -> FloatArray:
        """Perpendicular distance to the line, ``‖p − project(p)‖``.

        Parameters
        ----------
        points : (..., 3) array_like, m
            Points.

        Returns
        -------
        (...) array, m
            Distances (≥ 0).
        """
        return np.linalg.norm(self.deviations(points), axis=-1)


def fit_line(
    points: ArrayLike,
    *,
    direction_hint: ArrayLike | None = None,
) -> LineFit:
    """Fit a 3-D line by total least squares (principal axis of the points).

    ``c = mean(p)``, ``direction = v₁`` the first right-singular vector of the centred
    points ``P − c = U S Vᵀ`` (it minimises ``Σ ‖(pᵢ − c) − ((pᵢ − c)·d) d‖²``).
    Used for the dowel-hole axis ``y_n`` (App. D.1, eq. D.2), the robot's
    ``x_0`` axis from a linear move (App. D.2) and the straightness datum line
    (8.3.1).

    Parameters
    ----------
    points : (N, 3) array_like, m
        Points, ``N ≥ 2``.
    direction_hint : (3,) array_like, optional
        The direction is signed so that ``direction·hint ≥ 0``.  Default: from the
        first towards the last point.

    Returns
    -------
    LineFit
        Centroid (m), unit direction, residuals (m).

    Raises
    ------
    MetrologyError
        Fewer than 2 points, non-finite values, coincident points.
    """
    p = as_points(points, "fit_line points", 2)
    c, s, vt = _centred_svd(p)
    _check_spread(p, c, s, "fit_line points")
    d = vt[0].copy()
    if direction_hint is not None:
        h = as_vector3(direction_hint, "direction_hint", unit=True)
        if d @ h < 0:
            d = -d
    elif (p[-1] - p[0]) @ d < 0:
        d = -d
    dev = (p - c) - np.outer((p - c) @ d, d)
    res = np.linalg.norm(dev, axis=1)
    return LineFit(point=c, direction=d, residuals=res, rms=_rms(res), singular_values=s)


# --------------------------------------------------------------------------- plane


@dataclass(frozen=True)
class PlaneFit:
    """A plane ``(x − centroid)·normal = 0`` fitted by total least squares.

    Attributes
    ----------
    centroid : (3,) array, m
        Centroid of the fitted points, a point of the plane.
    normal : (3,) array
        Unit normal (sign: see module docstring).
    residuals : (N,) array, m
        Signed distance ``(pᵢ − centroid)·normal`` of each fitted point, positive on
        the side the normal points to.
    rms : float, m
        ``√(Σ rᵢ² / N)`` of ``residuals``.
    singular_values : (3,) array, m
        Singular values of the centred points.
    """

    centroid: FloatArray
    normal: FloatArray
    residuals: FloatArray
    rms: float
    singular_values: FloatArray

    @property
    def offset(self) -> float:
        """``d`` of the Hessian form ``normal·x = d`` (m)."""
        return float(self.normal @ self.centroid)

    @property
    def flatness(self) -> float:
        """Peak-to-valley of the residuals, ``max − min`` (m)."""
        return float(self.residuals.max() - self.residuals.min())

    def basis(self) -> tuple[FloatArray, FloatArray]:
        """Two in-plane unit vectors ``(u, v)`` with ``u × v = normal``.

        Returns
        -------
        u, v : (3,) array
            Orthonormal in-plane basis.
        """
        return _plane_basis(self.normal)

    def signed_distance(self, points: ArrayLike) -> FloatArray:
        """Signed distance to the plane, ``(p − centroid)·normal``.

        Parameters
        ----------
        points : (..., 3) array_like, m
            Points.

        Returns
        -------
        (...) array, m
            Distances, positive on the side the normal points to.
        """
        return (np.asarray(points, dtype=float) - self.centroid) @ self.normal

    def project(self, points: ArrayLike) -> FloatArray:
        """Orthogonal projection onto the plane, ``p − ((p − centroid)·n) n``.

        Parameters
        ----------
        points : (..., 3) array_like, m
            Points.

        Returns
        -------
        (..., 3) array, m
            Their projections.
        """
        p = np.asarray(points, dtype=float)
        return p - self.signed_distance(p)[..., None] * self.normal


def _plane_basis(n: FloatArray) -> tuple[FloatArray, FloatArray]:
    a = np.eye(3)[int(np.argmin(np.abs(n)))]
    u = np.cross(a, n)
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    return u, v


def _sign_by_largest_component(n: FloatArray) -> FloatArray:
    return n if n[int(np.argmax(np.abs(n)))] >= 0 else -n


def fit_plane(
    points: ArrayLike,
    *,
    normal_hint: ArrayLike | None = None,
    rtol: float = DEGENERACY_RTOL,
) -> PlaneFit:
    """Fit a plane by total least squares (normal = least principal axis).

    ``c = mean(p)``, ``normal = v₃`` the last right-singular vector of ``P − c = U S Vᵀ``
    (it minimises ``Σ ((pᵢ − c)·n)²``).  Used for the robot base plane ``z = 0``
    (App. D.2) and the common ``z`` of the target frames (8.4.1).

    Parameters
    ----------
    points : (N, 3) array_like, m
        Points, ``N ≥ 3``, not collinear.
    normal_hint : (3,) array_like, optional
        The normal is signed so that ``normal·hint ≥ 0``; default: its largest
        component positive.
    rtol : float
        Collinearity tolerance: fails when ``s₂ ≤ rtol · s₁``.

    Returns
    -------
    PlaneFit
        Centroid (m), unit normal, signed residuals (m).

    Raises
    ------
    MetrologyError
        Fewer than 3 points, non-finite values, coincident or collinear points.
    """
    p = as_points(points, "fit_plane points", 3)
    c, s, vt = _centred_svd(p)
    _check_spread(p, c, s, "fit_plane points")
    _check_not_collinear(s, "fit_plane points", rtol)
    n = vt[2].copy()
    if normal_hint is not None:
        h = as_vector3(normal_hint, "normal_hint", unit=True)
        if n @ h < 0:
            n = -n
    else:
        n = _sign_by_largest_component(n)
    res = (p - c) @ n
    return PlaneFit(centroid=c, normal=n, residuals=res, rms=_rms(res), singular_values=s)


# -------------------------------------------------------------------------- circle


@dataclass(frozen=True)
class CircleFit:
    """A circle in 3-D: centre, unit normal of its plane, radius.

    Fitted in two stages: the plane by total least squares, then the circle in
    that plane (algebraic Kåsa fit refined by geometric least squares).

    Attributes
    ----------
    centre : (3,) array, m
        Circle centre.
    normal : (3,) array
        Unit normal of the circle's plane (sign: right-hand rule along the point
        order, see module docstring).
    radius : float, m
        Radius.
    residuals : (N,) array, m
        Signed in-plane radial residual ``‖q − centre‖ − radius`` of each point's
        projection ``q`` (> 0 outside).
    out_of_plane : (N,) array, m
        Signed distance of each point to the circle's plane.
    rms : float, m
        rms of the 3-D distances ``hypot(residuals, out_of_plane)``.
    plane : PlaneFit
        The intermediate plane fit.
    sweep : float, rad
        Angle swept from the first to the last point about ``normal`` (unwrapped;
        ``2π`` for one full turn).
    oriented : bool
        Whether ``normal``'s sign means something: it follows the points' rotation
        sense (they turn one way, repeated points aside) or the caller's hint.  False:
        the points go back and forth, and the sign is the plane fit's, arbitrary.
    """

    centre: FloatArray
    normal: FloatArray
    radius: float
    residuals: FloatArray
    out_of_plane: FloatArray
    rms: float
    plane: PlaneFit
    sweep: float
    oriented: bool = True

    @property
    def distances(self) -> FloatArray:
        """3-D distance of each fitted point to the circle, ``hypot(residuals, out_of_plane)``."""
        return np.hypot(self.residuals, self.out_of_plane)

    def basis(self) -> tuple[FloatArray, FloatArray]:
        """In-plane unit vectors ``(u, v)`` with ``u × v = normal``.

        Returns
        -------
        u, v : (3,) array
            Orthonormal basis of the circle's plane.
        """
        return _plane_basis(self.normal)

    def angles(self, points: ArrayLike) -> FloatArray:
        """Angle about ``normal`` from the ``u`` axis, ``φ = atan2((p − c)·v, (p − c)·u)``.

        Parameters
        ----------
        points : (..., 3) array_like, m
            Points.

        Returns
        -------
        (...) array, rad
            Angles in (−π, π].
        """
        u, v = self.basis()
        d = np.asarray(points, dtype=float) - self.centre
        return np.arctan2(d @ v, d @ u)

    def point_at(self, angle: ArrayLike) -> FloatArray:
        """Point of the circle at an angle, ``x(φ) = c + r (cos φ u + sin φ v)``.

        Parameters
        ----------
        angle : (...) array_like, rad
            Angle from the ``u`` axis of :meth:`basis`.

        Returns
        -------
        (..., 3) array, m
            Points of the circle.
        """
        a = np.asarray(angle, dtype=float)
        u, v = self.basis()
        return self.centre + self.radius * (
            np.cos(a)[..., None] * u + np.sin(a)[..., None] * v
        )


def _kasa(x: FloatArray, y: FloatArray) -> tuple[float, float, float]:
    A = np.column_stack([x, y, np.ones_like(x)])
    b = -(x * x + y * y)
    (D, E, F), *_ = np.linalg.lstsq(A, b, rcond=None)
    xc, yc = -D / 2.0, -E / 2.0
    r2 = xc * xc + yc * yc - F
    if not np.isfinite(r2) or r2 <= 0.0:
        raise MetrologyError("fit_circle points: algebraic circle fit failed (radius² ≤ 0)")
    return float(xc), float(yc), float(np.sqrt(r2))


def _geometric_circle(x: FloatArray, y: FloatArray, xc: float, yc: float, r: float
                      ) -> tuple[float, float, float]:
    """The geometric circle fit ``min Σ (‖(xᵢ, yᵢ) − (x_c, y_c)‖ − r)²`` by
    Levenberg–Marquardt from ``(xc, yc, r)`` (the Kåsa fit), with the analytic Jacobian
    ``∂/∂(x_c, y_c, r) = (−(xᵢ − x_c)/ρᵢ, −(yᵢ − y_c)/ρᵢ, −1)``.

    Raises
    ------
    MetrologyError
        The fit did not converge (non-finite or non-positive radius).
    """
    def resid(q: FloatArray) -> FloatArray:
        return np.hypot(x - q[0], y - q[1]) - q[2]

    def jac(q: FloatArray) -> FloatArray:
        rho = np.maximum(np.hypot(x - q[0], y - q[1]), 1e-300)
        return np.column_stack([-(x - q[0]) / rho, -(y - q[1]) / rho, -np.ones_like(x)])

    from scipy.optimize import least_squares  # here: importing fitting costs no SciPy

    sol = least_squares(
        resid, np.array([xc, yc, r]), jac=jac, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15
    )
    xc, yc, r = (float(t) for t in sol.x)
    if not np.isfinite([xc, yc, r]).all() or r <= 0.0:
        raise MetrologyError("fit_circle points: geometric circle fit did not converge")
    return xc, yc, r


def fit_circle(
    points: ArrayLike,
    *,
    normal_hint: ArrayLike | None = None,
    rtol: float = DEGENERACY_RTOL,
) -> CircleFit:
    """Fit a circle to 3-D points (reflector positions while a joint rotates).

    Stage 1: best-fit plane (:func:`fit_plane`). Stage 2: the points projected
    into the plane are fitted by the algebraic (Kåsa) circle, refined by
    geometric least squares (``scipy.optimize.least_squares``, Levenberg–Marquardt)
    on the radial residuals. Works on arcs as well as full turns; on short arcs
    the radius is correspondingly less certain.

    In-plane coordinates ``(xᵢ, yᵢ)``: Kåsa solves ``xᵢ² + yᵢ² + D xᵢ + E yᵢ + F = 0`` in
    the least-squares sense (``x_c = −D/2``, ``y_c = −E/2``, ``r² = x_c² + y_c² − F``),
    then ``min Σ (‖(xᵢ, yᵢ) − (x_c, y_c)‖ − r)²`` refines ``(x_c, y_c, r)``.

    Thesis: App. D.1 (joint ``n`` → origin ``O_n`` and ``z_n`` of the flange),
    App. D.2 (joint 1 → ``O_0`` offset and ``z_0``).

    Parameters
    ----------
    points : (N, 3) array_like, m
        Points, ``N ≥ 3``, not collinear, in angular order if the normal's sign is
        to follow the rotation (a point measured twice in a row, less than
        ``SAME_ANGLE`` apart, does not break the order); otherwise the result says
        ``oriented=False``.
    normal_hint : (3,) array_like, optional
        The normal is signed so that ``normal·hint ≥ 0``.
    rtol : float
        Collinearity tolerance (see :func:`fit_plane`).

    Returns
    -------
    CircleFit
        Centre (m), unit normal, radius (m), residuals (m), swept angle (rad).

    Raises
    ------
    MetrologyError
        Fewer than 3 points, non-finite values, coincident or collinear points,
        failed fit.
    """
    p = as_points(points, "fit_circle points", 3)
    plane = fit_plane(p, normal_hint=normal_hint, rtol=rtol)
    n = plane.normal
    u, v = _plane_basis(n)
    d = p - plane.centroid
    x, y = d @ u, d @ v
    xc, yc, r = _geometric_circle(x, y, *_kasa(x, y))
    # Orientation by the right-hand rule along the point order.
    ang = np.unwrap(np.arctan2(y - yc, x - xc))
    sweep = float(ang[-1] - ang[0])
    # steps below SAME_ANGLE are one point measured twice, not a turn back
    steps = np.diff(ang)
    steps = steps[np.abs(steps) > SAME_ANGLE]
    oriented = normal_hint is not None or bool(
        steps.size and (np.all(steps > 0) or np.all(steps < 0)))
    if normal_hint is None and oriented and sweep < -1e-9:
        n, v, y, yc = -n, -v, -y, -yc
        sweep = -sweep
        plane = PlaneFit(
            centroid=plane.centroid, normal=n, residuals=-plane.residuals,
            rms=plane.rms, singular_values=plane.singular_values,
        )
    centre = plane.centroid + xc * u + yc * v
    res = np.hypot(x - xc, y - yc) - r
    h = plane.residuals
    dist = np.hypot(res, h)
    return CircleFit(
        centre=centre, normal=n, radius=r, residuals=res, out_of_plane=h,
        rms=_rms(dist), plane=plane, sweep=sweep, oriented=oriented,
    )
