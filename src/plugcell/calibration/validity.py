"""Where a calibration can be trusted: the region its poses covered, and checks against it.

A calibrated model interpolates well between the poses it was identified on and may
extrapolate badly away from them (on the IPA UR10 data, a model identified in one joint
region makes another region *worse*; docs/planning.md).  :class:`ValidityRegion` records
the region of the calibration poses; :meth:`ValidityRegion.check` says, for any joint
configurations (validation poses, compensated targets), which lie outside and how far.

The measure (chosen on the IPA data, docs/planning.md):

* **Joint ranges**: ``[min_i q_ij, max_i q_ij]`` of every actuated joint j over the
  calibration poses; the *excess* of a configuration is how far (rad) its worst joint
  lies beyond its range — worst by the target motion ``ℓ_j · excess_j`` (below), which
  must exceed ``τ / 20`` to count.
* **Distance to the nearest calibration pose** in a scaled joint space, in metres of
  target motion: ``d(q) = min_i ‖ℓ ∘ (q − q_i)‖``, ``ℓ_j`` the RMS over the calibration
  poses of ``|∂p/∂q_j|`` (the lever arm of joint j at the target, m/rad), at least a tenth
  of the largest one so that no joint is ignored.
* **Threshold** ``τ``: the 99th percentile of the (kept) calibration poses' own nearest-
  neighbour distances (leave-one-out) — how far apart the campaign's poses are; a sparse,
  well-spread campaign covers a region with larger gaps than a dense one.
* **Payload** range ``[min m, max m]``, and the **Cartesian** box of the targets (robot
  base frame) — for the report and for compensated targets.

A configuration is *outside* when a joint exceeds its range, its distance exceeds ``τ``
or its payload lies outside the range.  At most :data:`MAX_POSES` calibration poses are
kept (a farthest-point subsample, nearly uniform over the region; its covering radius —
the largest distance of a dropped pose to a kept one — is recorded, and τ is at least
that, so every calibration pose lies inside).
Pure math (numpy, scipy's k-d tree), SI units; PARAMS.json's ``validity`` (mm and degrees)
is written and read by :mod:`plugcell.io.params`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from plugcell.calibration.model import ErrorModel

Array = NDArray[np.float64]

#: Calibration poses stored in a region (farthest-point subsample beyond).
MAX_POSES = 1000
#: Percentile of the leave-one-out nearest-neighbour distances taken as the threshold.
THRESHOLD_PERCENTILE = 99.0
#: Poses the lever arms are averaged over (evenly spaced among the calibration poses).
LEVER_POSES = 2000
#: Smallest lever arm, as a fraction of the largest (no joint is ignored).
LEVER_FLOOR = 0.1
#: A joint counts as beyond its calibrated range when the target motion of the excess,
#: ``ℓ_j · excess_j``, exceeds this fraction of the threshold τ: a step shorter than a
#: twentieth of the campaign's own spacing is no extrapolation (e.g. the correction a
#: compensation adds to a pose at the edge of a range, or a joint the campaign held
#: nearly fixed).
RANGE_TOL_FRACTION = 0.05

__all__ = ["MAX_POSES", "RegionCheck", "ValidityRegion"]


@dataclass(frozen=True, eq=False)
class RegionCheck:
    """Configurations checked against a :class:`ValidityRegion`, one entry per pose.

    ``outside = beyond_range ∨ (d > τ) ∨ (payload excess > 0) ∨ (target excess > 0)``.

    Attributes
    ----------
    distance_m : (N,) array, m
        ``d(q) = min_i ‖ℓ ∘ (q − q_i)‖`` to the nearest calibration pose (scaled joint
        space, m of target motion).
    threshold_m : float, m
        τ.
    joint_excess_rad : (N,) array, rad
        How far the worst joint lies beyond its range (0 inside).
    worst_joint : (N,) int array
        That joint (0-based; worst by ``ℓ_j · excess_j``).
    payload_excess_kg : (N,) array, kg
        How far the payload lies outside the calibrated range.
    target_excess_m : (N,) array, m
        Distance beyond the Cartesian box (0 inside, or when no targets were given).
    outside : (N,) bool array
        The pose lies outside the region.
    beyond_range : (N,) bool array
        The joint excess counts: ``ℓ_j · excess_j > τ / 20``.
    """

    distance_m: Array
    threshold_m: float
    joint_excess_rad: Array
    worst_joint: NDArray[np.int64]
    payload_excess_kg: Array
    target_excess_m: Array
    outside: NDArray[np.bool_]
    beyond_range: NDArray[np.bool_]

    def __len__(self) -> int:
        return int(self.outside.shape[0])

    @property
    def count(self) -> int:
        """Number of poses outside."""
        return int(np.count_nonzero(self.outside))

    def reasons(self, i: int, joint_names: tuple[str, ...] | None = None) -> str:
        """Why pose ``i`` is outside, e.g. ``"joint 1 12.5° beyond its range; 340 mm from
        the nearest calibration pose (region 110 mm)"``.

        Parameters
        ----------
        i : int
            Pose index.
        joint_names : tuple of str, optional
            Joint names (default: 1-based numbers).

        Returns
        -------
        str
            The reasons, ``''`` when inside.
        """
        if not self.outside[i]:
            return ""
        out = []
        if self.beyond_range[i]:
            j = int(self.worst_joint[i])
            name = joint_names[j] if joint_names else str(j + 1)
            out.append(f"joint {name} {math.degrees(self.joint_excess_rad[i]):.1f}° "
                       "beyond its calibrated range")
        if self.distance_m[i] > self.threshold_m:
            out.append(f"{self.distance_m[i] * 1e3:.0f} mm from the nearest calibration pose "
                       f"(region {self.threshold_m * 1e3:.0f} mm)")
        if self.payload_excess_kg[i] > 0:
            out.append(f"payload {self.payload_excess_kg[i]:g} kg beyond the calibrated range")
        if self.target_excess_m[i] > 0:
            out.append(f"target {self.target_excess_m[i] * 1e3:.0f} mm outside the calibrated "
                       "volume")
        return "; ".join(out)

    def summary(self) -> dict[str, Any]:
        """JSON-ready: counts, the largest distance and joint excess (mm, degrees).

        Returns
        -------
        dict
            ``poses``, ``outside``, ``threshold_mm``, ``max_distance_mm``, the counts per
            reason, ``max_joint_excess_deg`` and ``outside_indices``.
        """
        o = self.outside
        return {
            "poses": len(self), "outside": self.count,
            "threshold_mm": self.threshold_m * 1e3,
            "max_distance_mm": float(self.distance_m.max() * 1e3) if len(self) else 0.0,
            "beyond_joint_range": int(np.count_nonzero(self.beyond_range)),
            "max_joint_excess_deg": float(np.degrees(self.joint_excess_rad[self.beyond_range]
                                                     .max()))
            if self.beyond_range.any() else 0.0,
            "beyond_distance": int(np.count_nonzero(self.distance_m > self.threshold_m)),
            "beyond_payload": int(np.count_nonzero(self.payload_excess_kg > 0)),
            "beyond_volume": int(np.count_nonzero(self.target_excess_m > 0)),
            "outside_indices": np.flatnonzero(o).tolist(),
        }

    def message(self, what: str = "poses") -> str:
        """One line for a warning, '' when every pose is inside.

        Parameters
        ----------
        what : str
            What the poses are called in the message.

        Returns
        -------
        str
            The warning.
        """
        if not self.count:
            return ""
        s = self.summary()
        parts = []
        if s["beyond_joint_range"]:
            parts.append(f"{s['beyond_joint_range']} beyond a joint's calibrated range (up to "
                         f"{s['max_joint_excess_deg']:.1f}°)")
        if s["beyond_distance"]:
            parts.append(f"{s['beyond_distance']} farther than {s['threshold_mm']:.0f} mm from "
                         f"every calibration pose (up to {s['max_distance_mm']:.0f} mm)")
        if s["beyond_payload"]:
            parts.append(f"{s['beyond_payload']} with a payload outside the calibrated range")
        if s["beyond_volume"]:
            parts.append(f"{s['beyond_volume']} with the target outside the calibrated volume")
        return (f"{self.count} of {len(self)} {what} outside the calibrated region — the model "
                f"extrapolates there: " + "; ".join(parts))


@dataclass(frozen=True, eq=False)
class ValidityRegion:
    """The region a calibration was identified on (module docstring).

    Attributes
    ----------
    joint_lower, joint_upper : (n,) array, rad
        ``min_i q_ij``, ``max_i q_ij`` per joint.
    lever_m : (n,) array, m/rad
        Lever arms ``ℓ_j = RMS_i |∂p/∂q_j|`` (floored at a tenth of the largest).
    poses : (P, n) array, rad
        Kept calibration poses (≤ :data:`MAX_POSES`).
    threshold_m : float, m
        τ.
    cover_m : float, m
        Covering radius of the kept poses.
    payload_kg : (float, float), kg
        ``(min, max)`` payload.
    target_lower, target_upper : (3,) array, m
        Cartesian box of the targets, robot base frame.
    n_poses : int
        The calibration poses it was built from.

    Raises
    ------
    ValueError
        ``poses`` not ``(P, n)`` or ``lever_m`` not ``(n,)``.
    """

    joint_lower: Array
    joint_upper: Array
    lever_m: Array
    poses: Array
    threshold_m: float
    cover_m: float
    payload_kg: tuple[float, float]
    target_lower: Array
    target_upper: Array
    n_poses: int

    def __post_init__(self) -> None:
        n = len(self.joint_lower)
        for name in ("joint_lower", "joint_upper", "lever_m", "poses", "target_lower",
                     "target_upper"):
            a = np.array(getattr(self, name), dtype=float)
            a.setflags(write=False)
            object.__setattr__(self, name, a)
        if self.poses.ndim != 2 or self.poses.shape[1] != n or self.lever_m.shape != (n,):
            raise ValueError(f"validity region: poses must be (P, {n}) and lever ({n},)")

    @cached_property
    def _tree(self) -> Any:
        """The k-d tree of the scaled poses, built on the first distance asked: a process
        that reads a calibration without checking poses (the robot's link process) does
        not import SciPy for it."""
        from scipy.spatial import cKDTree

        return cKDTree(self.poses * self.lever_m)

    # ------------------------------------------------------------------ building
    @classmethod
    def from_poses(cls, model: ErrorModel, q: ArrayLike, payload_kg: ArrayLike | None = None,
                   *, targets: ArrayLike | None = None, max_poses: int = MAX_POSES
                   ) -> ValidityRegion:
        """The region of calibration readings ``q`` for ``model`` (module docstring).

        Lever arms by central differences (h = 1e-6 rad) of the predicted target
        position, ``ℓ_j = √(mean_i ‖∂p/∂q_j‖²)``; τ = max(99th percentile of the kept
        poses' nearest-neighbour distances, covering radius).

        Parameters
        ----------
        model : ErrorModel
            The model (its geometry gives the lever arms; BASE is not used).
        q : (N, n) array_like, rad
            Calibration readings.
        payload_kg : (N,) array_like, kg, optional
            Their payloads (default 0).
        targets : (N, 3) array_like, m, optional
            Target positions in the robot base frame if known, else predicted by
            ``model``.
        max_poses : int
            Most poses kept (farthest-point subsample).

        Returns
        -------
        ValidityRegion
            The region.
        """
        q = np.atleast_2d(np.asarray(q, dtype=float))
        m = np.zeros(len(q)) if payload_kg is None else np.asarray(payload_kg, dtype=float)
        robot = model.with_references(base=np.eye(4))
        p0 = (robot.predict(q, m)[:, :3, 3] if targets is None
              else np.asarray(targets, dtype=float).reshape(len(q), 3))
        # lever arms: central differences, on at most LEVER_POSES evenly spaced poses
        s = np.unique(np.linspace(0, len(q) - 1, min(len(q), LEVER_POSES)).astype(int))
        h = 1e-6
        lever = np.empty(q.shape[1])
        for j in range(q.shape[1]):
            dq = np.zeros(q.shape[1])
            dq[j] = h
            dp = (robot.predict(q[s] + dq, m[s])[:, :3, 3]
                  - robot.predict(q[s] - dq, m[s])[:, :3, 3]) / (2 * h)
            lever[j] = float(np.sqrt(np.mean(np.sum(dp**2, axis=1))))
        lever = np.maximum(lever, LEVER_FLOOR * max(float(lever.max()), 1e-3))
        X = q * lever
        # farthest points among at most 10·max_poses evenly spaced poses (the cover radius
        # below is measured against all of them)
        pre = np.unique(np.linspace(0, len(q) - 1, min(len(q), 10 * max_poses)).astype(int))
        keep = pre[_farthest_points(X[pre], max_poses)]
        from scipy.spatial import cKDTree

        cover = 0.0
        if len(keep) < len(q):
            cover = float(cKDTree(X[keep]).query(X)[0].max())
        threshold = 0.0
        if len(keep) > 1:
            d, _ = cKDTree(X[keep]).query(X[keep], k=2)
            # ≥ the covering radius (farthest-point sampling), so every calibration pose
            # lies inside its own region
            threshold = max(float(np.percentile(d[:, 1], THRESHOLD_PERCENTILE)), cover)
        return cls(joint_lower=q.min(axis=0), joint_upper=q.max(axis=0), lever_m=lever,
                   poses=q[keep], threshold_m=threshold, cover_m=cover,
                   payload_kg=(float(m.min()), float(m.max())), target_lower=p0.min(axis=0),
                   target_upper=p0.max(axis=0), n_poses=len(q))

    # ------------------------------------------------------------------ checking
    def distance(self, q: ArrayLike) -> Array:
        """Distance to the nearest calibration pose, ``d(q) = min_i ‖ℓ ∘ (q − q_i)‖``.

        Parameters
        ----------
        q : (N, n) array_like, rad
            Configurations.

        Returns
        -------
        (N,) array, m
            Distances in m of target motion.
        """
        q = np.atleast_2d(np.asarray(q, dtype=float))
        d, _ = self._tree.query(q * self.lever_m)
        return np.asarray(d, dtype=float)

    def check(self, q: ArrayLike, payload_kg: ArrayLike | float | None = None,
              targets: ArrayLike | None = None) -> RegionCheck:
        """Check configurations, their payloads and optionally their target positions.

        Parameters
        ----------
        q : (N, n) array_like, rad
            Configurations.
        payload_kg : float or (N,) array_like, kg, optional
            Payloads (default 0).
        targets : (N, 3) array_like, m, optional
            Target positions, robot base frame.

        Returns
        -------
        RegionCheck
            Per-pose distances, excesses and the ``outside`` flags.

        Raises
        ------
        ValueError
            ``q`` with the wrong number of joints.
        """
        q = np.atleast_2d(np.asarray(q, dtype=float))
        if q.shape[1] != len(self.joint_lower):
            raise ValueError(f"q: expected (N, {len(self.joint_lower)}), got {q.shape}")
        below = self.joint_lower - q
        above = q - self.joint_upper
        excess = np.maximum(np.maximum(below, above), 0.0)
        motion = excess * self.lever_m  # m of target motion beyond each range
        worst = np.argmax(motion, axis=1).astype(np.int64)
        rows = np.arange(len(q))
        jexc = excess[rows, worst] if len(q) else np.zeros(0)
        beyond = (motion[rows, worst] > RANGE_TOL_FRACTION * self.threshold_m) if len(q) \
            else np.zeros(0, dtype=bool)
        m = np.zeros(len(q)) if payload_kg is None else np.broadcast_to(
            np.asarray(payload_kg, dtype=float), (len(q),))
        lo, hi = self.payload_kg
        pexc = np.maximum(np.maximum(lo - m, m - hi), 0.0)
        pexc = np.where(pexc > 1e-9, pexc, 0.0)
        texc = np.zeros(len(q))
        if targets is not None:
            t = np.asarray(targets, dtype=float).reshape(len(q), 3)
            out = np.maximum(np.maximum(self.target_lower - t, t - self.target_upper), 0.0)
            texc = np.linalg.norm(out, axis=1)
        d = self.distance(q)
        outside = beyond | (d > self.threshold_m) | (pexc > 0) | (texc > 0)
        return RegionCheck(distance_m=d, threshold_m=self.threshold_m, joint_excess_rad=jexc,
                           worst_joint=worst, payload_excess_kg=pexc, target_excess_m=texc,
                           outside=outside, beyond_range=beyond)


def _farthest_points(X: Array, k: int) -> NDArray[np.int64]:
    """Indices of at most ``k`` rows of ``X`` chosen by farthest-point sampling (a greedy
    k-centre cover), starting from the row nearest the mean; all rows if ``len(X) ≤ k``."""
    n = len(X)
    if n <= k:
        return np.arange(n, dtype=np.int64)
    X = np.ascontiguousarray(X)
    first = int(np.argmin(np.sum((X - X.mean(axis=0)) ** 2, axis=1)))
    chosen = [first]
    d2 = np.sum((X - X[first]) ** 2, axis=1)
    for _ in range(k - 1):
        i = int(np.argmax(d2))
        chosen.append(i)
        np.minimum(d2, np.sum((X - X[i]) ** 2, axis=1), out=d2)
    return np.sort(np.asarray(chosen, dtype=np.int64))
