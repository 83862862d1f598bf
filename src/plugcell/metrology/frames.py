"""Frames from measured features; BASE and PROBE estimation (thesis App. D).

The laser tracker measures (eq. 6.23 / D.1)::

    T = BASE · T_n^0 · PROBE

with ``BASE`` the robot base frame ``F_0`` in the tracker frame ``F_LT`` and
``PROBE`` the T-MAC frame in the flange frame ``F_n``. Appendix D builds the
initial estimates calibration starts from out of best-fit features:

* PROBE (D.1–D.3): circle of an SMR while joint ``n`` turns → flange origin
  ``O_n`` and ``z_n``; line through two dowel holes → ``y_n``; ``x_n = y_n × z_n``;
  ``T_n^LT`` (D.2); ``PROBE = (T_n^LT)⁻¹ T_TMAC^LT`` (D.3).
* BASE (App. D.2): circle of an SMR on joint 1 → axis (``z_0``) through ``O_0``;
  plane of SMR positions on the base surface → level ``z = 0``; line of T-MAC
  positions while the robot moves along its ``x`` → ``x_0``; ``y_0`` by the
  right-hand rule.

**SMR offset.** An SMR measures the *centre* of its sphere, not the surface it
sits on. Seated on (or in a nest on) a surface, the centre is ``smr_offset``
above it along the surface normal: the sphere radius for a ball resting on a
flat face (a 0.5" SMR: 6.35 mm, the default :data:`SMR_RADIUS_HALF_INCH`),
``sqrt(R² − r²)`` for a ball of radius ``R`` seated on the rim of a hole of
radius ``r``, the nest height for a nest. Appendix D takes the circle centre as
``O_n`` directly, i.e. ``smr_offset = 0`` — which puts the flange frame, and so
PROBE's translation along ``z_n``, off by that height (later absorbed by
identification of the tool parameters). Pass ``smr_offset=0.0`` to reproduce
App. D literally; the default removes the bias.

The BASE parametrisation (6.24 = D.4)::

    BASE = Tran(x,a0) Tran(y,b0) Rot(x,α0) Rot(y,β0) Rot(z,θ0) Tran(z,d0)

and its inverse (D.6) are :func:`base_matrix_from_parameters` and
:func:`base_parameters_from_matrix`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._validate import MetrologyError, as_points, as_transform, as_vector3
from .fitting import CircleFit, LineFit, PlaneFit, fit_circle, fit_line, fit_plane

__all__ = [
    "SMR_RADIUS_HALF_INCH",
    "BaseEstimate",
    "BaseParameters",
    "ProbeEstimate",
    "RigidFit",
    "base_from_features",
    "base_matrix_from_parameters",
    "base_parameters_from_matrix",
    "fit_rigid_transform",
    "frame_from_axes",
    "invert_transform",
    "probe_from_flange_features",
]

FloatArray = NDArray[np.float64]

#: Centre height of a 0.5-inch SMR (12.7 mm ball) resting on a flat face (m).
SMR_RADIUS_HALF_INCH = 0.00635

_PARALLEL_TOL = 1e-9


def invert_transform(T: ArrayLike) -> FloatArray:
    """Inverse of homogeneous rigid transforms, ``T⁻¹ = [Rᵀ  −Rᵀp; 0 1]``.

    Parameters
    ----------
    T : (..., 4, 4) array_like, m
        Rigid transforms ``[R p; 0 1]``.

    Returns
    -------
    (..., 4, 4) array, m
        Their inverses.

    Raises
    ------
    MetrologyError
        Not of shape ``(..., 4, 4)``.
    """
    a = np.asarray(T, dtype=float)
    if a.shape[-2:] != (4, 4):
        raise MetrologyError(f"invert_transform: expected (..., 4, 4), got shape {a.shape}")
    R = a[..., :3, :3]
    p = a[..., :3, 3]
    out = np.zeros_like(a)
    Rt = np.swapaxes(R, -1, -2)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", Rt, p)
    out[..., 3, 3] = 1.0
    return out


def frame_from_axes(
    origin: ArrayLike,
    *,
    z: ArrayLike,
    x: ArrayLike | None = None,
    y: ArrayLike | None = None,
) -> FloatArray:
    """Right-handed frame (4×4) from an origin, the ``z`` axis and one more axis.

    ``z`` is kept exactly (normalised). Exactly one of ``x`` or ``y`` must be
    given; it need not be perpendicular to ``z`` — only its component
    perpendicular to ``z`` is used (re-orthogonalisation):

    * ``y`` given (App. D.1, 8.4.1): ``x = y × z`` (normalised), then ``y = z × x``;
    * ``x`` given (App. D.2): ``y = z × x`` (normalised), then ``x = y × z``.

    The columns of the returned rotation are ``[x y z]`` (eq. D.2's ``n o a``):
    ``T = [x y z origin; 0 0 0 1]``.

    Parameters
    ----------
    origin : (3,) array_like, m
        Frame origin.
    z : (3,) array_like
        The z axis (normalised, kept exactly).
    x, y : (3,) array_like, optional
        Exactly one: the second axis (need not be unit or perpendicular to ``z``).

    Returns
    -------
    T : (4, 4) array, m
        The right-handed frame.

    Raises
    ------
    MetrologyError
        Both or neither of ``x``/``y`` given; zero, non-finite or parallel axes.
    """
    o = as_vector3(origin, "origin")
    zz = as_vector3(z, "z", unit=True)
    if (x is None) == (y is None):
        raise MetrologyError("frame_from_axes: give exactly one of x= or y= besides z=")
    if y is not None:
        yy = as_vector3(y, "y", unit=True)
        xx = np.cross(yy, zz)
        if np.linalg.norm(xx) < _PARALLEL_TOL:
            raise MetrologyError("frame_from_axes: y is parallel to z; the frame is undefined")
        xx /= np.linalg.norm(xx)
        yy = np.cross(zz, xx)
    else:
        xx = as_vector3(x, "x", unit=True)
        yy = np.cross(zz, xx)
        if np.linalg.norm(yy) < _PARALLEL_TOL:
            raise MetrologyError("frame_from_axes: x is parallel to z; the frame is undefined")
        yy /= np.linalg.norm(yy)
        xx = np.cross(yy, zz)
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = xx, yy, zz, o
    return T


# ------------------------------------------------------------- rigid registration


@dataclass(frozen=True)
class RigidFit:
    """Least-squares rigid transform ``b ≈ R a + t`` between paired points.

    Attributes
    ----------
    transform : (4, 4) array, m
        Homogeneous ``[R t; 0 1]`` mapping frame A to frame B.
    residuals : (N, 3) array, m
        ``bᵢ − (R aᵢ + t)`` per point.
    distances : (N,) array, m
        ``‖residualsᵢ‖``.
    rms : float, m
        ``√(Σ distancesᵢ² / N)`` (unweighted).
    weights : (N,) array
        The weights used, normalised to ``Σ wᵢ = 1``.
    """

    transform: FloatArray
    residuals: FloatArray
    distances: FloatArray
    rms: float
    weights: FloatArray

    @property
    def rotation(self) -> FloatArray:
        """3×3 rotation ``R``."""
        return self.transform[:3, :3]

    @property
    def translation(self) -> FloatArray:
        """Translation ``t`` (m)."""
        return self.transform[:3, 3]

    def apply(self, points: ArrayLike) -> FloatArray:
        """Map points from frame A to frame B, ``b = R a + t``.

        Parameters
        ----------
        points : (..., 3) array_like, m
            Points in frame A.

        Returns
        -------
        (..., 3) array, m
            The same points in frame B.
        """
        p = np.asarray(points, dtype=float)
        return p @ self.rotation.T + self.translation

    def inverse(self) -> FloatArray:
        """Transform mapping frame B to frame A, ``[Rᵀ  −Rᵀt; 0 1]``.

        Returns
        -------
        (4, 4) array, m
            The inverse of ``transform``.
        """
        return invert_transform(self.transform)


def fit_rigid_transform(
    points_a: ArrayLike,
    points_b: ArrayLike,
    *,
    weights: ArrayLike | None = None,
) -> RigidFit:
    """Weighted Kabsch/Umeyama registration (rotation + translation, no scale).

    Minimises ``Σ w_i |b_i − (R a_i + t)|²`` over proper rotations ``R``
    (``det R = +1``, reflections excluded). Calibration uses it to initialise
    BASE from nominal flange/T-MAC positions ``a`` (robot frame) and their tracker
    measurements ``b``.  Closed form: with weighted centroids ``ā = Σ wᵢ aᵢ``,
    ``b̄ = Σ wᵢ bᵢ`` and ``H = Σ wᵢ (aᵢ − ā)(bᵢ − b̄)ᵀ = U S Vᵀ``,
    ``R = V diag(1, 1, sign det(V Uᵀ)) Uᵀ`` and ``t = b̄ − R ā``.

    Parameters
    ----------
    points_a : (N, 3) array_like, m
        Points in frame A, ``N ≥ 3``, not collinear.
    points_b : (N, 3) array_like, m
        The same points measured in frame B.
    weights : (N,) array_like, optional
        Non-negative weights, at least 3 positive (normalised to sum 1); default equal.

    Returns
    -------
    RigidFit
        ``[R t; 0 1]`` (m) and the per-point residuals (m).

    Raises
    ------
    MetrologyError
        Shape mismatch, fewer than 3 points, non-finite values, bad weights,
        collinear points (rotation about their line undefined).
    """
    a = as_points(points_a, "fit_rigid_transform points_a", 3)
    b = as_points(points_b, "fit_rigid_transform points_b", 3)
    if a.shape != b.shape:
        raise MetrologyError(
            f"fit_rigid_transform: points_a {a.shape} and points_b {b.shape} differ in shape"
        )
    if weights is None:
        w = np.full(len(a), 1.0 / len(a))
    else:
        w = np.asarray(weights, dtype=float)
        if w.shape != (len(a),):
            raise MetrologyError(
                f"fit_rigid_transform weights: expected shape ({len(a)},), got {w.shape}"
            )
        if not np.isfinite(w).all() or (w < 0).any():
            raise MetrologyError("fit_rigid_transform weights: must be finite and >= 0")
        if np.count_nonzero(w) < 3:
            raise MetrologyError("fit_rigid_transform weights: need at least 3 positive weights")
        w = w / w.sum()
    ca = w @ a
    cb = w @ b
    A = a - ca
    B = b - cb
    sa = np.linalg.svd(A * np.sqrt(w)[:, None], compute_uv=False)
    if sa[0] <= 1e-12 * (1.0 + np.abs(ca).max()) or sa[1] <= 1e-9 * sa[0]:
        raise MetrologyError(
            "fit_rigid_transform points_a: points are coincident or collinear; "
            "the rotation about their line is undefined"
        )
    H = (A * w[:, None]).T @ B
    U, _, Vt = np.linalg.svd(H)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0])
    R = Vt.T @ D @ U.T
    t = cb - R @ ca
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    res = b - (a @ R.T + t)
    dist = np.linalg.norm(res, axis=1)
    return RigidFit(
        transform=T, residuals=res, distances=dist,
        rms=float(np.sqrt(np.mean(dist**2))), weights=w,
    )


# ------------------------------------------------------------------------- PROBE


@dataclass(frozen=True)
class ProbeEstimate:
    """Result of the PROBE procedure of App. D.1.

    Attributes
    ----------
    probe : (4, 4) array, m
        ``PROBE = T_TMAC^n = (T_n^LT)⁻¹ T_TMAC^LT`` (eq. D.3).
    flange_pose : (4, 4) array, m
        ``T_n^LT`` (eq. D.2), the flange frame in the tracker frame.
    circle : CircleFit
        Circle fitted to the SMR positions while joint ``n`` turned.
    hole_line : LineFit
        Line fitted through the dowel-hole measurements.
    smr_offset : float, m
        SMR centre height above the flange face used.
    hole_line_tilt : float, rad
        Angle between the dowel-hole line and the flange plane, ``asin |y·z_n|``;
        ideally 0, a large value flags a bad measurement.
    """

    probe: FloatArray
    flange_pose: FloatArray
    circle: CircleFit
    hole_line: LineFit
    smr_offset: float
    hole_line_tilt: float


def _turned_one_way(circle: CircleFit, name: str, axis: str) -> CircleFit:
    """``circle`` if its normal's sign is known; refused when the points went back and
    forth without a hint (the axis, signed by an arbitrary SVD, would turn the frame by
    180° without a word)."""
    if not circle.oriented:
        raise MetrologyError(
            f"{name}: the points go back and forth around the circle, so the rotation "
            f"sense that signs {axis} is unknown; give them in the order the joint turned "
            "(one way), or give normal_hint")
    return circle


def probe_from_flange_features(
    circle_points: ArrayLike,
    hole_points: ArrayLike,
    tmac_measurement: ArrayLike,
    *,
    smr_offset: float = SMR_RADIUS_HALF_INCH,
    normal_hint: ArrayLike | None = None,
) -> ProbeEstimate:
    """Estimate PROBE from flange features, App. D.1 (eqs. D.2, D.3).

    ``z_n`` = circle normal, ``O_n = centre − smr_offset · z_n``, ``y_n`` = dowel-hole
    line direction, ``x_n = y_n × z_n`` (re-orthogonalised), ``T_n^LT = [x_n y_n z_n O_n]``
    (D.2) and ``PROBE = (T_n^LT)⁻¹ T_TMAC^LT`` (D.3).

    Parameters
    ----------
    circle_points : (N, 3) array_like, m
        SMR positions (tracker frame) while the last joint turns in its *positive*
        direction with the SMR in a flange dowel hole; ``N ≥ 3``.  The circle's
        right-hand normal is ``z_n``.
    hole_points : (M, 3) array_like, m
        SMR positions in the two dowel holes that define ``y_n``, ordered from the
        hole at ``−y_n`` to the hole at ``+y_n`` (repeated readings per hole are
        fine); ``M ≥ 2``.
    tmac_measurement : (4, 4) array_like, m
        T-MAC pose ``T_TMAC^LT`` measured without moving the robot after mounting
        the T-MAC.
    smr_offset : float, m
        SMR centre height above the flange face (module docstring); ``0`` reproduces
        App. D literally.
    normal_hint : (3,) array_like, optional
        Vector to sign ``z_n`` by instead of the rotation sense (e.g. when the joint
        was turned negatively).

    Returns
    -------
    ProbeEstimate
        ``probe`` (4, 4), m, and the fitted features.

    Raises
    ------
    MetrologyError
        Degenerate features (see :func:`fit_circle`, :func:`fit_line`), holes along
        ``z_n`` (line more than 80° out of the flange plane), malformed T-MAC pose,
        non-finite ``smr_offset``.
    """
    T_tmac = as_transform(tmac_measurement, "tmac_measurement")
    if not np.isfinite(smr_offset):
        raise MetrologyError(f"smr_offset: must be finite, got {smr_offset}")
    circle = _turned_one_way(fit_circle(circle_points, normal_hint=normal_hint),
                             "circle_points", "z_n")
    holes = as_points(hole_points, "hole_points", 2)
    line = fit_line(holes)
    z = circle.normal
    tilt = float(np.arcsin(np.clip(abs(line.direction @ z), 0.0, 1.0)))
    if tilt > np.deg2rad(80.0):
        raise MetrologyError(
            f"hole_points: the dowel-hole line is {np.rad2deg(tilt):.1f}° out of the flange "
            "plane (nearly along z_n); y_n is undefined"
        )
    origin = circle.centre - smr_offset * z
    T_n = frame_from_axes(origin, z=z, y=line.direction)
    probe = invert_transform(T_n) @ T_tmac
    return ProbeEstimate(
        probe=probe, flange_pose=T_n, circle=circle, hole_line=line,
        smr_offset=float(smr_offset), hole_line_tilt=tilt,
    )


# -------------------------------------------------------------------------- BASE


@dataclass(frozen=True)
class BaseEstimate:
    """Result of the BASE procedure of App. D.2.

    Attributes
    ----------
    base : (4, 4) array, m
        BASE = frame ``F_0`` in the tracker frame.
    circle : CircleFit
        Circle fitted to the SMR positions while joint 1 turned.
    plane : PlaneFit
        Plane fitted to the SMR positions on the base surface.
    line : LineFit
        Line fitted to the T-MAC positions during the move along ``x_0``.
    smr_offset : float, m
        SMR centre height above the base surface used.
    axis_plane_angle : float, rad
        Angle between the joint-1 axis and the base-plane normal — squareness of
        axis 1 to the mounting surface.
    line_tilt : float, rad
        Angle between the ``x`` move and the plane ``⟂ z_0``, ``asin |d·z_0|``.
    """

    base: FloatArray
    circle: CircleFit
    plane: PlaneFit
    line: LineFit
    smr_offset: float
    axis_plane_angle: float
    line_tilt: float

    @property
    def parameters(self) -> BaseParameters:
        """The BASE parameters of eq. 6.24 from eq. D.6 (:func:`base_parameters_from_matrix`)."""
        return base_parameters_from_matrix(self.base)


def base_from_features(
    joint1_circle_points: ArrayLike,
    base_plane_points: ArrayLike,
    x_axis_line_points: ArrayLike,
    *,
    smr_offset: float = SMR_RADIUS_HALF_INCH,
    normal_hint: ArrayLike | None = None,
) -> BaseEstimate:
    """Estimate BASE from robot features, App. D.2.

    * ``z_0``: the right-hand normal of the circle traced by an SMR on joint 1
      while joint 1 turns in its positive direction (or ``normal_hint``);
      the joint-1 axis is the line through the circle centre along ``z_0``.
    * ``z = 0``: the base plane (SMR centres on the base surface, shifted down
      by ``smr_offset`` along ``z_0``); ``O_0`` = intersection of the joint-1
      axis with it.
    * ``x_0``: direction of the line through the T-MAC positions while the robot
      moves along its ``+x`` (points in the order measured), re-orthogonalised
      against ``z_0``; ``y_0 = z_0 × x_0``.

    Only directions are taken from the line (the T-MAC is offset from the flange).
    The origin is ``O_0 = c + t z_0`` with ``t = ((p₀ − c)·n) / (z_0·n)``, ``c`` the
    circle centre, ``n`` the plane normal and ``p₀ = centroid − smr_offset · n``.

    Parameters
    ----------
    joint1_circle_points : (N, 3) array_like, m
        SMR positions (tracker frame) while joint 1 turns positively, ``N ≥ 3``.
    base_plane_points : (M, 3) array_like, m
        SMR centres on the base surface, ``M ≥ 3``, not collinear.
    x_axis_line_points : (K, 3) array_like, m
        T-MAC positions while the robot moves along its ``+x``, in measured order.
    smr_offset : float, m
        SMR centre height above the base surface (module docstring).
    normal_hint : (3,) array_like, optional
        Vector to sign ``z_0`` by instead of the rotation sense.

    Returns
    -------
    BaseEstimate
        ``base`` (4, 4), m, and the fitted features.

    Raises
    ------
    MetrologyError
        Degenerate features, the move along (nearly) ``z_0`` (> 80°), the base plane
        (nearly) parallel to the joint-1 axis (normal > 80° from it), non-finite
        ``smr_offset``.
    """
    if not np.isfinite(smr_offset):
        raise MetrologyError(f"smr_offset: must be finite, got {smr_offset}")
    circle = _turned_one_way(fit_circle(joint1_circle_points, normal_hint=normal_hint),
                             "joint1_circle_points", "z_0")
    z = circle.normal
    plane = fit_plane(base_plane_points, normal_hint=z)
    line = fit_line(x_axis_line_points)
    cos_axis = float(np.clip(plane.normal @ z, -1.0, 1.0))
    axis_plane_angle = float(np.arctan2(np.linalg.norm(np.cross(plane.normal, z)), cos_axis))
    if cos_axis < np.cos(np.deg2rad(80.0)):
        raise MetrologyError(
            f"base_plane_points: base plane normal is {np.rad2deg(axis_plane_angle):.1f}° "
            "from the joint-1 axis; the axis does not cross the plane at a usable angle"
        )
    line_tilt = float(np.arcsin(np.clip(abs(line.direction @ z), 0.0, 1.0)))
    if line_tilt > np.deg2rad(80.0):
        raise MetrologyError(
            f"x_axis_line_points: the move is {np.rad2deg(line_tilt):.1f}° out of the "
            "x-y plane (nearly along z_0); x_0 is undefined"
        )
    # z = 0 plane: SMR-centre plane moved down by the SMR centre height.
    p0 = plane.centroid - smr_offset * plane.normal
    t = ((p0 - circle.centre) @ plane.normal) / cos_axis
    origin = circle.centre + t * z
    base = frame_from_axes(origin, z=z, x=line.direction)
    return BaseEstimate(
        base=base, circle=circle, plane=plane, line=line, smr_offset=float(smr_offset),
        axis_plane_angle=axis_plane_angle, line_tilt=line_tilt,
    )


# ------------------------------------------------------------- BASE parameters


@dataclass(frozen=True)
class BaseParameters:
    """Parameters of eq. 6.24 (= D.4): lengths in m, angles in rad.

    ``BASE = Tran(x,a0) Tran(y,b0) Rot(x,α0) Rot(y,β0) Rot(z,θ0) Tran(z,d0)``.
    Scalars for one BASE, arrays ``(...)`` for a stack (from the vectorised functions).

    Attributes
    ----------
    a0, b0 : float or (...) array, m
        Translations along x and y.
    alpha0, beta0, theta0 : float or (...) array, rad
        Rotations about x, y, z.
    d0 : float or (...) array, m
        Translation along the final z.
    """

    a0: FloatArray | float
    b0: FloatArray | float
    alpha0: FloatArray | float
    beta0: FloatArray | float
    theta0: FloatArray | float
    d0: FloatArray | float

    def as_array(self) -> FloatArray:
        """The parameters as one vector ``[a0, b0, α0, β0, θ0, d0]``.

        Returns
        -------
        (..., 6) array
            Stacked on the last axis, m and rad.
        """
        return np.stack(
            np.broadcast_arrays(
                *(np.asarray(v, dtype=float) for v in
                  (self.a0, self.b0, self.alpha0, self.beta0, self.theta0, self.d0))
            ),
            axis=-1,
        )

    def matrix(self) -> FloatArray:
        """BASE matrix, eq. 6.24 (:func:`base_matrix_from_parameters`).

        Returns
        -------
        (..., 4, 4) array, m
            The BASE transform(s).
        """
        return base_matrix_from_parameters(
            self.a0, self.b0, self.alpha0, self.beta0, self.theta0, self.d0
        )


def base_matrix_from_parameters(
    a0: ArrayLike,
    b0: ArrayLike,
    alpha0: ArrayLike,
    beta0: ArrayLike,
    theta0: ArrayLike,
    d0: ArrayLike,
) -> FloatArray:
    """BASE = Tran(x,a0) Tran(y,b0) Rot(x,α0) Rot(y,β0) Rot(z,θ0) Tran(z,d0), eq. 6.24.

    Closed form: ``R = Rx(α0) Ry(β0) Rz(θ0)``,
    ``p = (a0 + d0 sβ0, b0 − d0 sα0 cβ0, d0 cα0 cβ0)``.

    Parameters
    ----------
    a0, b0 : (...) array_like, m
        Translations along x and y.
    alpha0, beta0, theta0 : (...) array_like, rad
        Rotations about x, y, z.
    d0 : (...) array_like, m
        Translation along the final z.  All arguments broadcast together.

    Returns
    -------
    BASE : (..., 4, 4) array, m
        Shape ``broadcast_shape + (4, 4)``.
    """
    a, b, al, be, th, d = np.broadcast_arrays(
        *(np.asarray(v, dtype=float) for v in (a0, b0, alpha0, beta0, theta0, d0))
    )
    ca, sa = np.cos(al), np.sin(al)
    cb, sb = np.cos(be), np.sin(be)
    ct, st = np.cos(th), np.sin(th)
    T = np.zeros((*a.shape, 4, 4))
    T[..., 0, 0] = cb * ct
    T[..., 0, 1] = -cb * st
    T[..., 0, 2] = sb
    T[..., 1, 0] = sa * sb * ct + ca * st
    T[..., 1, 1] = -sa * sb * st + ca * ct
    T[..., 1, 2] = -sa * cb
    T[..., 2, 0] = -ca * sb * ct + sa * st
    T[..., 2, 1] = ca * sb * st + sa * ct
    T[..., 2, 2] = ca * cb
    T[..., 0, 3] = a + d * sb
    T[..., 1, 3] = b - d * sa * cb
    T[..., 2, 3] = d * ca * cb
    T[..., 3, 3] = 1.0
    return T


def base_parameters_from_matrix(BASE: ArrayLike, *, singular_tol: float = 1e-6) -> BaseParameters:
    """Initial BASE parameters from a BASE matrix, eq. D.6 (θ0 is D.6's φ0).

    ``α0 = atan2(−B23, B33)``, ``β0 = atan2(B13, −sα0 B23 + cα0 B33)``,
    ``θ0 = atan2(−B12, B11)``, ``d0 = B34 / (cα0 cβ0)``, ``a0 = B14 − d0 sβ0``,
    ``b0 = B24 + d0 sα0 cβ0`` (1-based indices as in the thesis). The returned
    ``β0`` lies in ``[−π/2, π/2]``.

    Parameters
    ----------
    BASE : (4, 4) or (..., 4, 4) array_like, m
        BASE transform(s); the rotation block must be proper (``|RᵀR − I| ≤ 1e-6``).
    singular_tol : float
        Smallest accepted ``|B33| = |cα0 cβ0|``.

    Returns
    -------
    BaseParameters
        Floats for one matrix, ``(...)`` arrays for a stack; m and rad.

    Raises
    ------
    MetrologyError
        Malformed or non-finite matrix, an improper rotation block, or
        ``|B33| < singular_tol`` (robot ``z_0`` perpendicular to the tracker ``z``):
        ``d0`` is then undefined and the parametrisation singular.
    """
    B = np.asarray(BASE, dtype=float)
    if B.shape[-2:] != (4, 4):
        raise MetrologyError(f"BASE: expected (..., 4, 4), got shape {B.shape}")
    if not np.isfinite(B).all():
        raise MetrologyError("BASE: non-finite entry (NaN or inf)")
    R = B[..., :3, :3]
    err = np.abs(np.swapaxes(R, -1, -2) @ R - np.eye(3)).max()
    if err > 1e-6 or (np.linalg.det(R) <= 0).any():
        raise MetrologyError(
            f"BASE: rotation block is not a proper rotation (max |RᵀR−I| = {err:.3g})"
        )
    B33 = B[..., 2, 2]
    if (np.abs(B33) < singular_tol).any():
        raise MetrologyError(
            "BASE: |BASE(3,3)| = |cos α0 cos β0| is below "
            f"{singular_tol:g}; eq. 6.24 is singular (robot z0 ⟂ tracker z), d0 undefined"
        )
    alpha = np.arctan2(-B[..., 1, 2], B33)
    sa, ca = np.sin(alpha), np.cos(alpha)
    beta = np.arctan2(B[..., 0, 2], -sa * B[..., 1, 2] + ca * B33)
    theta = np.arctan2(-B[..., 0, 1], B[..., 0, 0])
    sb, cb = np.sin(beta), np.cos(beta)
    d = B[..., 2, 3] / (ca * cb)
    a = B[..., 0, 3] - d * sb
    b = B[..., 1, 3] + d * sa * cb

    def out(x: FloatArray) -> FloatArray | float:
        return float(x) if np.ndim(x) == 0 else x

    return BaseParameters(
        a0=out(a), b0=out(b), alpha0=out(alpha), beta0=out(beta), theta0=out(theta), d0=out(d)
    )
