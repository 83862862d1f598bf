"""Drift watch: BASE re-registered from a few fixed reference nests (issue 19 §3).

During production the tracker (or the floor under it) moves a little — a warming
hall, a knocked tripod — and BASE, the robot base in the tracker frame, with it.
Reference nests fixed to the robot's foundation are measured once when BASE is
identified; their positions in the robot base frame ``n_k = BASE⁻¹ m_k`` are then
constants.  Re-measured later (``m'_k``, tracker frame) they give the current BASE
by rigid registration (Kabsch, :func:`~plugcell.metrology.frames.fit_rigid_transform`)::

    BASE' = argmin Σ |m'_k − BASE' n_k|²        D = BASE' · BASE⁻¹   (tracker frame)

``D`` is the 6-DOF drift.  Its effect is judged where it matters: the largest
displacement ``|(BASE' − BASE) p|`` over points ``p`` of the work volume (robot base
frame; default the nests themselves).  Above ``threshold_m`` the watch alarms; the
fit's rms tells whether the nests still agree with each other (a knocked nest
breaks the rigid fit: :attr:`DriftEstimate.consistent`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from plugcell.kinematics.transforms import invert, so3_log
from plugcell.metrology._validate import MetrologyError, as_points
from plugcell.metrology.frames import fit_rigid_transform

Array = NDArray[np.float64]

__all__ = ["MIN_NEST_SPACING_M", "DriftEstimate", "estimate_base_drift", "likely_mix_up",
           "nests_in_base", "too_close"]

#: Factors between the nests' mutual distances in the two files that name a unit mistake.
_UNIT_FACTORS = ((1000.0, "metres"), (25.4, "inches"))
#: Nests closer together than this (median of their mutual distances) are a unit mistake:
#: nests fixed to a robot's foundation are decimetres apart.
MIN_NEST_SPACING_M = 0.01


def nests_in_base(base: ArrayLike, measured: ArrayLike) -> Array:
    """Nest positions in the robot base frame from their tracker measurements, ``n_k = BASE⁻¹ m_k``.

    Parameters
    ----------
    base : (4, 4) array_like, m
        The identified BASE (robot base in the tracker frame).
    measured : (K, 3) array_like, m
        Nest positions in the tracker frame, ``K ≥ 3``.

    Returns
    -------
    (K, 3) array, m
        Nest positions in the robot base frame.

    Raises
    ------
    MetrologyError
        Fewer than 3 nests or non-finite values.
    """
    m = as_points(measured, "nests", 3)
    Bi = invert(np.asarray(base, float))
    return m @ Bi[:3, :3].T + Bi[:3, 3]


@dataclass(frozen=True)
class DriftEstimate:
    """The drift of BASE since registration (module docstring).

    Attributes
    ----------
    base : (4, 4) array, m
        The re-registered BASE'.
    drift : (4, 4) array, m
        ``D = BASE' · BASE⁻¹`` in the tracker frame.
    translation_m : (3,) array, m
        D's translation.
    rotation_rad : (3,) array, rad
        D's rotation vector ``log(R_D)∨``.
    displacement_m : float, m
        ``max_p ‖(BASE' − BASE) p‖`` over the work points.
    rms_m : float, m
        rms of the rigid fit of the nests.
    threshold_m : float, m
        The alarm threshold used.
    alarm : bool
        ``displacement_m > threshold_m``.
    consistent : bool
        ``rms_m ≤ fit_tolerance_m`` (the nests still agree with each other).
    """

    base: Array
    drift: Array
    translation_m: Array
    rotation_rad: Array
    displacement_m: float
    rms_m: float
    threshold_m: float
    alarm: bool
    consistent: bool

    def as_dict(self) -> dict[str, object]:
        """The estimate in mm and degrees, for ``--json`` and the journal.

        Returns
        -------
        dict
            ``displacement_mm``, ``translation_mm``, ``rotation_deg``, ``fit_rms_mm``,
            ``threshold_mm``, ``alarm``, ``consistent`` and ``base`` (m, nested lists).
        """
        return {"displacement_mm": self.displacement_m * 1e3,
                "translation_mm": (self.translation_m * 1e3).tolist(),
                "rotation_deg": np.degrees(self.rotation_rad).tolist(),
                "fit_rms_mm": self.rms_m * 1e3, "threshold_mm": self.threshold_m * 1e3,
                "alarm": self.alarm, "consistent": self.consistent,
                "base": self.base.tolist()}


def estimate_base_drift(base: ArrayLike, nests: ArrayLike, measured: ArrayLike, *,
                        threshold_m: float = 0.05e-3, work_points: ArrayLike | None = None,
                        fit_tolerance_m: float = 0.05e-3) -> DriftEstimate:
    """Re-register BASE on re-measured nests (module docstring).

    ``BASE' = argmin Σ_k ‖m'_k − BASE' n_k‖²`` (Kabsch), ``D = BASE' · BASE⁻¹``,
    displacement ``max_p ‖(BASE' − BASE) p‖``.

    Parameters
    ----------
    base : (4, 4) array
        BASE in use (robot base in the tracker frame, m).
    nests : (K, 3) array
        Nest positions in the robot base frame (:func:`nests_in_base`), K ≥ 3, not
        collinear.
    measured : (K, 3) array
        The same nests measured now, tracker frame (m).
    threshold_m : float
        Alarm above this displacement (m).
    work_points : (P, 3) array, optional
        Where the displacement is judged (robot base frame, m); default the nests.
    fit_tolerance_m : float
        rms of the nests' rigid fit above which they disagree (a nest moved).

    Returns
    -------
    DriftEstimate
        BASE' (m), the drift D and the alarm/consistency flags.

    Raises
    ------
    MetrologyError
        Malformed BASE, non-positive thresholds, fewer than 3 or mismatched nests,
        collinear nests.
    """
    B = np.asarray(base, float)
    if B.shape != (4, 4) or not np.all(np.isfinite(B)):
        raise MetrologyError(f"base: expected a finite 4x4 transform, got shape {B.shape}")
    if not (threshold_m > 0 and fit_tolerance_m > 0):
        raise MetrologyError("threshold_m and fit_tolerance_m must be > 0")
    n = as_points(nests, "nests", 3)
    m = as_points(measured, "measured nests", 3)
    if n.shape != m.shape:
        raise MetrologyError(f"{len(n)} registered nests but {len(m)} measured")
    fit = fit_rigid_transform(n, m)
    B_new = fit.transform
    D = B_new @ invert(B)
    pts = n if work_points is None else as_points(work_points, "work_points", 1)
    delta = pts @ (B_new[:3, :3] - B[:3, :3]).T + (B_new[:3, 3] - B[:3, 3])
    disp = float(np.max(np.linalg.norm(delta, axis=1)))
    return DriftEstimate(base=B_new, drift=D, translation_m=D[:3, 3].copy(),
                         rotation_rad=so3_log(D[:3, :3]), displacement_m=disp,
                         rms_m=float(fit.rms), threshold_m=float(threshold_m),
                         alarm=disp > threshold_m, consistent=float(fit.rms) <= fit_tolerance_m)


def _pair_distances(p: Array) -> Array:
    i, j = np.triu_indices(len(p), 1)
    return np.linalg.norm(p[i] - p[j], axis=1)


def too_close(points: ArrayLike, which: str = "") -> str:
    """Whether nests are too close together to be nests in mm (a file in metres).

    Parameters
    ----------
    points : (N, 3) array_like, m
        The nests' positions as read.
    which : str
        Which file's nests, for the message (e.g. ``"measured"``).

    Returns
    -------
    str
        ``"units: …"`` naming the spacing if the nests' median mutual distance is below
        :data:`MIN_NEST_SPACING_M`, else ``""``.
    """
    p = as_points(points, "nests", 2)
    spacing = float(np.median(_pair_distances(p)))
    if spacing >= MIN_NEST_SPACING_M:
        return ""
    nests = f"the {which} nests" if which else "the nests"
    return (f"units: {nests} are only {spacing * 1e3:.3g} mm apart (median) — a file in "
            "metres? (nest files are in mm)")


def likely_mix_up(base: ArrayLike, nests: ArrayLike, measured: ArrayLike, *,
                  tolerance_m: float = 5e-3) -> str:
    """The likely input mistake behind a drift far larger than a real one, or "".

    Two checks, both independent of the drift itself:

    * **Units.**  Nests less than :data:`MIN_NEST_SPACING_M` apart were metres read as
      mm (:func:`too_close`).  The nests' mutual distances ``‖n_i − n_j‖`` are frame-invariant, so
      ``r = median_ij(‖m_i − m_j‖ / ‖n_i − n_j‖)`` is 1 for any drift.  ``r ≈ 1/1000``
      (``1000``) means the measured (registered) positions were metres read as mm; 25.4
      inches.  Within 5 % of the factor.
    * **Swapped files.**  The registration holds ``n = BASE⁻¹ m``.  If the registered
      file holds tracker measurements and the measured file robot-frame positions,
      ``max_k ‖BASE n_k − m_k‖`` is BASE-sized while ``max_k ‖BASE m_k − n_k‖`` is
      within ``tolerance_m`` and 100 times less (the files fit the other way round).

    Parameters
    ----------
    base : (4, 4) array_like, m
        BASE in use (robot base in the tracker frame).
    nests : (K, 3) array_like, m
        The registered nests (robot base frame), as read.
    measured : (K, 3) array_like, m
        The nests measured now (tracker frame), as read, in the same order.
    tolerance_m : float
        How close the swapped reading must fit to be called a swap (m).

    Returns
    -------
    str
        ``"units: …"`` or ``"swapped: …"`` naming the cause, or "" when neither fits.
    """
    B = np.asarray(base, float)
    n = as_points(nests, "nests", 3)
    m = as_points(measured, "measured nests", 3)
    if n.shape != m.shape:
        return ""
    dn, dm = _pair_distances(n), _pair_distances(m)
    ok = dn > 0
    if np.any(ok) and np.all(dm[ok] > 0):
        ratio = float(np.median(dm[ok] / dn[ok]))
        for factor, unit in _UNIT_FACTORS:
            if abs(ratio * factor - 1.0) < 0.05:  # the measured nests too close together
                return (f"units: the measured nests are {factor:g}× closer together than the "
                        f"registered ones — the measured file in {unit}? (nest files are in mm)")
            if abs(ratio / factor - 1.0) < 0.05:  # the registered nests too close together
                return (f"units: the registered nests are {factor:g}× closer together than "
                        f"the measured ones — registered from a file in {unit}? (nest files "
                        "are in mm)")
    close = too_close(n, "registered") or too_close(m, "measured")
    if close:
        return close
    forward = float(np.max(np.linalg.norm(n @ B[:3, :3].T + B[:3, 3] - m, axis=1)))
    backward = float(np.max(np.linalg.norm(m @ B[:3, :3].T + B[:3, 3] - n, axis=1)))
    if backward <= tolerance_m and forward > 100 * backward:
        return ("swapped: the measured file fits as the registration and the registration as "
                f"the measurement (within {backward * 1e3:.3f} mm; {forward * 1e3:.0f} mm "
                "the other way) — --nests and --measured swapped?")
    return ""
