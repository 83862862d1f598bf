"""Accuracy statistics (thesis 8.2.1, eqs. 8.1–8.2; 8.3.1, 8.3.3) and ISO 9283 helpers.

Per-pose errors are *measured − model*: ``Δp_i = p_M,i − p_i`` (m) and, for
orientation, ``Δφ_i = φ_M,i − φ_i`` (rad), the thesis using roll-pitch-yaw
angles (fixed X-Y-Z) — see :func:`pose_errors`.

Statistics (eqs. 8.1, 8.2):

* overall position error per pose ``Δp_i = |Δp_i|``; its mean ``Δp̄`` (8.1) and
  sample standard deviation ``σ_Δp`` with ``m − 1`` (8.2); likewise ``Δφ_i``;
* the same mean/σ per component ``Δp_x, Δp_y, Δp_z`` and ``Δφ_x, Δφ_y, Δφ_z``
  ("the same calculations are also applied for individual components").

**The 3σ figure.** Section 8.3.3 reports "the 3σ absolute accuracies in the
positions" as 6.50 → 0.87 → 0.12 mm. Table 8-5 gives (``Δp̄``, ``σ_Δp``) =
(4.04, 0.82), (0.39, 0.16), (0.06, 0.02) mm and::

    4.04 + 3·0.82 = 6.50,   0.39 + 3·0.16 = 0.87,   0.06 + 3·0.02 = 0.12

exactly, so the thesis's 3σ position accuracy is ``Δp̄ + 3σ_Δp`` of the error
norm — the ISO 9283 form of ``RP = l̄ + 3 S_l``. That is
:attr:`NormStats.three_sigma`. The text's aside "(the square root of these
components)" and the orientation figure 0.44° after model-based compensation
match instead ``3·sqrt(σ_x² + σ_y² + σ_z²)`` of the per-component σ (Table 8-5
row (1): ``3·sqrt(0.104² + 0.008² + 0.105²) = 0.444°``; row (2) gives 0.058°
against the printed 0.05°). That variant is :attr:`NormStats.rss_three_sigma`.
Both are reported; ``three_sigma`` is the one that reproduces every position
figure of the thesis.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._validate import MetrologyError, as_points
from .fitting import LineFit, fit_line

__all__ = [
    "AccuracyStats",
    "ComponentStats",
    "ErrorStats",
    "Iso9283Result",
    "NormStats",
    "StraightnessResult",
    "accuracy_statistics",
    "iso9283_pose_accuracy",
    "pose_errors",
    "straightness",
    "wrap_angle",
]

FloatArray = NDArray[np.float64]
LengthUnit = Literal["m", "mm", "um"]
AngleUnit = Literal["rad", "deg"]
_LENGTH = {"m": 1.0, "mm": 1e3, "um": 1e6}
_ANGLE = {"rad": 1.0, "deg": 180.0 / np.pi}


def _scale(kind: str, unit: str) -> float:
    table = _LENGTH if kind == "length" else _ANGLE
    if unit not in table:
        raise MetrologyError(f"unknown {kind} unit {unit!r}; choose one of {sorted(table)}")
    return table[unit]


def wrap_angle(a: ArrayLike) -> FloatArray:
    """Wrap angles to ``(−π, π]``: ``w = ((a + π) mod 2π) − π``, with −π mapped to π.

    Parameters
    ----------
    a : (...) array_like, rad
        Angles.

    Returns
    -------
    (...) array, rad
        The wrapped angles.
    """
    x = np.asarray(a, dtype=float)
    w = np.mod(x + np.pi, 2.0 * np.pi) - np.pi
    return np.where(w == -np.pi, np.pi, w)


def pose_errors(
    measured: ArrayLike,
    model: ArrayLike,
    *,
    orientation: Literal["rpy", "rotvec"] = "rpy",
) -> tuple[FloatArray, FloatArray]:
    """Per-pose position and orientation errors, measured − model (thesis 8.2.1).

    ``Δp_i = p_M,i − p_i``; ``Δφ_i = wrap(rpy(R_M,i) − rpy(R_i))`` or
    ``Δφ_i = log(R_iᵀ R_M,i)∨``.

    Parameters
    ----------
    measured : (N, 4, 4) or (4, 4) array_like, m
        Measured poses (e.g. tracker T-MAC poses).
    model : (N, 4, 4) or (4, 4) array_like, m
        Poses predicted by a kinematic model, same shape.
    orientation : {"rpy", "rotvec"}
        ``"rpy"`` — difference of roll-pitch-yaw angles (fixed X-Y-Z,
        ``R = Rz(φz) Ry(φy) Rx(φx)``), wrapped to ``(−π, π]``, as in thesis 8.2.1;
        ``"rotvec"`` — rotation vector of ``R_model⁻¹ R_measured`` (exact, in the model
        frame).

    Returns
    -------
    dp : (N, 3) array, m
        Position errors Δp.
    dphi : (N, 3) array, rad
        Orientation errors Δφ.

    Raises
    ------
    MetrologyError
        Shape mismatch, non-finite poses or an unknown ``orientation``.
    """
    M = np.asarray(measured, dtype=float)
    E = np.asarray(model, dtype=float)
    if M.ndim == 2:
        M, E = M[None], E[None]
    if M.shape != E.shape or M.shape[-2:] != (4, 4):
        raise MetrologyError(
            f"pose_errors: measured {M.shape} and model {E.shape} must both be (N, 4, 4)"
        )
    if not (np.isfinite(M).all() and np.isfinite(E).all()):
        raise MetrologyError("pose_errors: non-finite entries (NaN or inf) in the poses")
    from scipy.spatial.transform import Rotation  # here: importing accuracy costs no SciPy

    dp = M[:, :3, 3] - E[:, :3, 3]
    Rm = Rotation.from_matrix(M[:, :3, :3])
    Re = Rotation.from_matrix(E[:, :3, :3])
    if orientation == "rpy":
        dphi = wrap_angle(Rm.as_euler("xyz") - Re.as_euler("xyz"))
    elif orientation == "rotvec":
        dphi = (Re.inv() * Rm).as_rotvec()
    else:
        raise MetrologyError(
            f"pose_errors: orientation must be 'rpy' or 'rotvec', got {orientation!r}"
        )
    return dp, dphi


@dataclass(frozen=True)
class ComponentStats:
    """Per-component statistics of ``(N, 3)`` errors (x, y, z), eqs. 8.1–8.2.

    Attributes
    ----------
    mean : (3,) array
        ``x̄_c = Σᵢ x_i,c / N`` (8.1), in the unit of the errors (m or rad).
    std : (3,) array
        ``σ_c = √(Σᵢ (x_i,c − x̄_c)² / (N − 1))`` (8.2).
    three_sigma : (3,) array
        ``3·std``.
    min, max : (3,) array
        Extremes per component.
    """

    mean: FloatArray
    std: FloatArray
    three_sigma: FloatArray
    min: FloatArray
    max: FloatArray

    @property
    def band(self) -> FloatArray:
        """``max − min`` per component, ``(3,)``, unit of the errors."""
        return self.max - self.min


@dataclass(frozen=True)
class NormStats:
    """Statistics of the per-pose error norms ``|Δ_i|``, eqs. 8.1–8.2.

    All in the unit of the errors (m or rad).

    Attributes
    ----------
    mean : float
        ``Δ̄ = Σᵢ |Δ_i| / m`` (8.1).
    std : float
        ``σ_Δ = √(Σᵢ (|Δ_i| − Δ̄)² / (m − 1))`` (8.2).
    min, max : float
        Extremes of ``|Δ_i|``.
    three_sigma : float
        ``Δ̄ + 3·σ_Δ`` — the thesis's "3σ accuracy" (8.3.3, see module docstring;
        reproduces Table 8-5 → 6.50/0.87/0.12 mm).
    rss_three_sigma : float
        ``3·√(σ_x² + σ_y² + σ_z²)`` of the per-component σ.
    rms : float
        ``√(Σᵢ |Δ_i|² / m)``.
    """

    mean: float
    std: float
    min: float
    max: float
    three_sigma: float
    rss_three_sigma: float
    rms: float


@dataclass(frozen=True)
class ErrorStats:
    """Component and norm statistics of one kind of error (position or orientation).

    Attributes
    ----------
    components : ComponentStats
        Per-axis statistics.
    norm : NormStats
        Statistics of the per-pose norms.
    """

    components: ComponentStats
    norm: NormStats


def _error_stats(e: FloatArray) -> ErrorStats:
    mean = e.mean(axis=0)
    std = e.std(axis=0, ddof=1)
    comps = ComponentStats(
        mean=mean, std=std, three_sigma=3.0 * std, min=e.min(axis=0), max=e.max(axis=0)
    )
    n = np.linalg.norm(e, axis=1)
    nm, ns = float(n.mean()), float(n.std(ddof=1))
    norm = NormStats(
        mean=nm, std=ns, min=float(n.min()), max=float(n.max()),
        three_sigma=nm + 3.0 * ns,
        rss_three_sigma=float(3.0 * np.sqrt(np.sum(std**2))),
        rms=float(np.sqrt(np.mean(n**2))),
    )
    return ErrorStats(components=comps, norm=norm)


@dataclass(frozen=True)
class AccuracyStats:
    """Accuracy statistics of a set of poses (thesis 8.2.1, Tables 8-2, 8-3, 8-5).

    Attributes
    ----------
    count : int
        Number of poses ``m``.
    position : ErrorStats
        Statistics of ``Δp`` (m).
    orientation : ErrorStats or None
        Statistics of ``Δφ`` (rad), or ``None``.
    """

    count: int
    position: ErrorStats
    orientation: ErrorStats | None

    def as_dict(
        self, length_unit: LengthUnit = "mm", angle_unit: AngleUnit = "deg"
    ) -> dict[str, object]:
        """Plain-``float``/``list`` dictionary in the given units (JSON-ready).

        Keys: ``count``, ``length_unit``, ``angle_unit``, ``position`` and (if
        present) ``orientation``, each with ``mean``, ``std``, ``min``, ``max``,
        ``three_sigma``, ``rss_three_sigma``, ``rms`` of the norm and
        ``components`` → ``mean``, ``std``, ``three_sigma``, ``min``, ``max``
        (lists ``[x, y, z]``).

        Parameters
        ----------
        length_unit : {"m", "mm", "um"}
            Unit of the position figures.
        angle_unit : {"rad", "deg"}
            Unit of the orientation figures.

        Returns
        -------
        dict
            The statistics, scaled to the units.

        Raises
        ------
        MetrologyError
            Unknown unit.
        """
        out: dict[str, object] = {
            "count": self.count, "length_unit": length_unit, "angle_unit": angle_unit,
        }
        for key, st, k in (
            ("position", self.position, _scale("length", length_unit)),
            ("orientation", self.orientation, _scale("angle", angle_unit)),
        ):
            if st is None:
                continue
            n, c = st.norm, st.components
            out[key] = {
                "mean": n.mean * k, "std": n.std * k, "min": n.min * k, "max": n.max * k,
                "three_sigma": n.three_sigma * k, "rss_three_sigma": n.rss_three_sigma * k,
                "rms": n.rms * k,
                "components": {
                    "mean": (c.mean * k).tolist(), "std": (c.std * k).tolist(),
                    "three_sigma": (c.three_sigma * k).tolist(),
                    "min": (c.min * k).tolist(), "max": (c.max * k).tolist(),
                },
            }
        return out


def accuracy_statistics(
    position_errors: ArrayLike,
    orientation_errors: ArrayLike | None = None,
) -> AccuracyStats:
    """Accuracy statistics of eqs. 8.1–8.2, per component and overall.

    ``Δ̄ = Σᵢ Δ_i / m`` (8.1), ``σ_Δ = √(Σᵢ (Δ_i − Δ̄)² / (m − 1))`` (8.2), applied to the
    norms ``|Δp_i|`` and to each component (see :class:`NormStats`, :class:`ComponentStats`).

    Parameters
    ----------
    position_errors : (N, 3) array_like, m
        Measured − model positions, ``N ≥ 2``.
    orientation_errors : (N, 3) array_like, rad, optional
        Measured − model orientation angles, e.g. RPY differences from
        :func:`pose_errors`.

    Returns
    -------
    AccuracyStats
        Position statistics (m) and, if given, orientation statistics (rad).

    Raises
    ------
    MetrologyError
        Fewer than 2 poses (σ needs ``N − 1 ≥ 1``), shape mismatch, non-finite values.
    """
    dp = as_points(position_errors, "position_errors", 2, "poses")
    orient = None
    if orientation_errors is not None:
        dphi = as_points(orientation_errors, "orientation_errors", 2, "poses")
        if dphi.shape != dp.shape:
            raise MetrologyError(
                f"orientation_errors {dphi.shape} must match position_errors {dp.shape}"
            )
        orient = _error_stats(dphi)
    return AccuracyStats(count=len(dp), position=_error_stats(dp), orientation=orient)


# ------------------------------------------------------------------- straightness


@dataclass(frozen=True)
class StraightnessResult:
    """Straightness of a travel about its best-fit datum line (thesis 8.3.1).

    Attributes
    ----------
    line : LineFit
        The best-fit datum line.
    directions : (2, 3) array
        Unit directions the deviations are measured along (the requested directions
        made perpendicular to the line).
    labels : (str, str)
        Names of the two directions (e.g. ``("z", "x")``).
    deviations : (N, 2) array, m
        Signed deviations ``(p_i − project(p_i))·e_k`` of the points from the line.
    band : (2,) array, m
        Error band ``max − min`` of the deviations — the thesis's 1.32/0.67 →
        0.43/0.44 → 0.16/0.13 mm (Figs. 8-16, 8-17).
    """

    line: LineFit
    directions: FloatArray
    labels: tuple[str, str]
    deviations: FloatArray
    band: FloatArray

    def as_dict(self, length_unit: LengthUnit = "mm") -> dict[str, object]:
        """``{label: {"band", "min", "max"}}`` in ``length_unit`` (plus unit and count).

        Parameters
        ----------
        length_unit : {"m", "mm", "um"}
            Unit of the figures.

        Returns
        -------
        dict
            JSON-ready figures.

        Raises
        ------
        MetrologyError
            Unknown unit.
        """
        k = _scale("length", length_unit)
        return {
            lab: {
                "band": float(self.band[i] * k),
                "min": float(self.deviations[:, i].min() * k),
                "max": float(self.deviations[:, i].max() * k),
            }
            for i, lab in enumerate(self.labels)
        } | {"length_unit": length_unit, "count": len(self.deviations)}


def straightness(
    points: ArrayLike,
    directions: ArrayLike = ((0.0, 0.0, 1.0), (1.0, 0.0, 0.0)),
    labels: tuple[str, str] = ("z", "x"),
) -> StraightnessResult:
    """Straightness of points measured along a (nominally) straight travel, 8.3.1.

    The datum is the total-least-squares line through the points
    (:func:`fit_line`). Each point's perpendicular deviation from it is
    resolved along two directions — by default the thesis's Z and X for lines
    parallel to Y (Figs. 8-16, 8-17) — each made perpendicular to the line
    first: ``e_k = (d_k − (d_k·u) u) / ‖…‖``, deviation ``δ_ik = (p_i − project(p_i))·e_k``,
    band ``max_i δ_ik − min_i δ_ik``.

    Parameters
    ----------
    points : (N, 3) array_like, m
        Points along the travel, ``N ≥ 3``.
    directions : (2, 3) array_like
        Directions to resolve the deviations along.
    labels : (str, str)
        Names of the two directions.

    Returns
    -------
    StraightnessResult
        Datum line, deviations (m) and bands (m).

    Raises
    ------
    MetrologyError
        Fewer than 3 points, non-finite values, malformed directions or labels, a
        direction (nearly) parallel to the line.
    """
    p = as_points(points, "straightness points", 3)
    d = np.asarray(directions, dtype=float)
    if d.shape != (2, 3) or not np.isfinite(d).all():
        raise MetrologyError(
            f"straightness directions: expected two finite 3-vectors, got shape {d.shape}"
        )
    if len(labels) != 2:
        raise MetrologyError("straightness labels: give two names")
    line = fit_line(p)
    u = line.direction
    dirs = d - np.outer(d @ u, u)
    norms = np.linalg.norm(dirs, axis=1)
    for i, (n0, n1) in enumerate(zip(np.linalg.norm(d, axis=1), norms, strict=True)):
        if n0 == 0.0 or n1 < 1e-6 * n0:
            raise MetrologyError(
                f"straightness directions[{i}] ({labels[i]}) is parallel to the datum line"
            )
    dirs = dirs / norms[:, None]
    dev = line.deviations(p) @ dirs.T
    band = dev.max(axis=0) - dev.min(axis=0)
    return StraightnessResult(
        line=line, directions=dirs, labels=(str(labels[0]), str(labels[1])),
        deviations=dev, band=band,
    )


# ----------------------------------------------------------------------- ISO 9283


@dataclass(frozen=True)
class Iso9283Result:
    """ISO 9283 pose accuracy (AP) and pose repeatability (RP) of one commanded pose.

    Attributes
    ----------
    barycentre : (3,) array, m
        Mean attained position ``x̄``.
    ap : float, m
        Positional accuracy ``AP_p = |x̄ − x_c|``.
    ap_components : (3,) array, m
        ``x̄ − x_c`` per axis.
    rp : float, m
        Positional repeatability ``RP_l = l̄ + 3·S_l`` with ``l_j = |x_j − x̄|`` and
        ``S_l`` the sample σ (``n − 1``).
    orientation_ap : (3,) array, rad, or None
        ``ā − a_c`` per angle (wrapped).
    orientation_rp : (3,) array, rad, or None
        ``3·S_a`` per angle (the half-width of ``±3·S_a``).
    """

    barycentre: FloatArray
    ap: float
    ap_components: FloatArray
    rp: float
    orientation_ap: FloatArray | None = None
    orientation_rp: FloatArray | None = None


def iso9283_pose_accuracy(
    attained: ArrayLike,
    commanded: ArrayLike,
    *,
    attained_angles: ArrayLike | None = None,
    commanded_angles: ArrayLike | None = None,
) -> Iso9283Result:
    """ISO 9283 AP and RP for ``n`` visits of one commanded pose (thesis 8.3.1 cites it).

    ``AP_p = |x̄ − x_c|``, ``RP_l = l̄ + 3·S_l`` with ``l_j = |x_j − x̄|``; for angles
    ``AP_a = ā − a_c`` and ``RP_a = 3·S_a`` (differences wrapped to (−π, π]).

    Parameters
    ----------
    attained : (n, 3) array_like, m
        Attained positions, ``n ≥ 2``.
    commanded : (3,) array_like, m
        Commanded position.
    attained_angles : (n, 3) array_like, rad, optional
        Attained orientation angles.
    commanded_angles : (3,) array_like, rad, optional
        Commanded angles, required with ``attained_angles``.

    Returns
    -------
    Iso9283Result
        AP and RP (m; rad for the angles).

    Raises
    ------
    MetrologyError
        Fewer than 2 visits, malformed or non-finite inputs, angles without
        ``commanded_angles``.
    """
    x = as_points(attained, "attained", 2, "visits")
    xc = np.asarray(commanded, dtype=float)
    if xc.shape != (3,) or not np.isfinite(xc).all():
        raise MetrologyError(f"commanded: expected a finite 3-vector, got shape {xc.shape}")
    bary = x.mean(axis=0)
    dev = bary - xc
    l = np.linalg.norm(x - bary, axis=1)
    rp = float(l.mean() + 3.0 * l.std(ddof=1))
    oap = orp = None
    if attained_angles is not None:
        a = as_points(attained_angles, "attained_angles", 2, "visits")
        if a.shape != x.shape:
            raise MetrologyError("attained_angles must have the same shape as attained")
        if commanded_angles is None:
            raise MetrologyError("commanded_angles is required with attained_angles")
        ac = np.asarray(commanded_angles, dtype=float)
        if ac.shape != (3,):
            raise MetrologyError("commanded_angles: expected a 3-vector")
        abar = ac + wrap_angle(a - ac).mean(axis=0)
        oap = wrap_angle(abar - ac)
        orp = 3.0 * wrap_angle(a - abar).std(axis=0, ddof=1)
    return Iso9283Result(
        barycentre=bary, ap=float(np.linalg.norm(dev)), ap_components=dev, rp=rp,
        orientation_ap=oap, orientation_rp=orp,
    )
