"""The closest serial tree of a calibrated loop robot — what a URDF can carry.

A URDF is a tree of joints, each an independent joint or a ``mimic`` of *one*
other (``θ = multiplier · θ_other + offset``).  In the nominal parallelogram of a
loop robot (Smart H4, thesis 6.1) the forearm turns with the crank, so the cut
joint at the end of the arm turns by ``θ_cut = q_crank − q_arm + c`` (the serial
equivalent of eq. 6.3, :func:`~plugcell.calibration.structure.kinematic_structure`
family ``"serial"``): a sum of two readings, which a tree carries exactly as two
coaxial joints — a mimic of the arm's reading with multiplier −1 and the crank's
reading itself.  The calibrated loop is no parallelogram: its passive angles are
the exact four-bar closure of its calibrated lengths (a non-linear function of
``q_arm − q_crank``, appendix C) and the twists and offsets of its links act along
the flange chain 2'–3'–4', which no fixed joint origin reproduces.  The closest
tree is therefore *fitted*: the serial model (model 1) is identified
(:class:`~plugcell.calibration.identify.Calibrator`) on noise-free poses of the
calibrated loop's geometric model

    T_loop(q) = BASE · T_n^0(q; g) · PROBE        (6.23 without the deflections Δθ)

at configurations drawn uniformly in the robot's working volume
(:func:`~plugcell.calibration.planning.sample_candidates`, seeded), and its error
``T_tree(q)`` vs ``T_loop(q)`` measured at other configurations drawn the same
way — in the working volume and in the whole joint range.  Compliance, payload
and thermal terms are left out on both sides: they are not geometry (every export
writes them beside the file).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from plugcell.calibration.data import CalibrationData
from plugcell.calibration.identify import Calibrator
from plugcell.calibration.model import ErrorModel
from plugcell.calibration.planning import sample_candidates
from plugcell.calibration.result import CalibrationResult
from plugcell.kinematics import forward
from plugcell.kinematics.pose_error import rotation_error

Array = NDArray[np.float64]

__all__ = ["TreeError", "TreeFit", "closest_serial_tree", "loop_geometric_poses"]


@dataclass(frozen=True)
class TreeError:
    """How far the fitted tree is from the calibrated loop over one region.

    Attributes
    ----------
    region : str
        ``"working volume"`` (the description's ``working_volume`` box, targets in the
        robot base frame) or ``"joint limits"`` (the whole joint range with the
        coupled limits).
    poses : int
        Configurations compared (drawn uniformly in the region, seeded).
    position_max_m, position_mean_m : float, m
        Largest and mean ``‖p_tree − p_loop‖`` of the measured target.
    orientation_max_rad, orientation_mean_rad : float, rad
        Largest and mean angle of ``R_tree R_loopᵀ``.
    """

    region: str
    poses: int
    position_max_m: float
    position_mean_m: float
    orientation_max_rad: float
    orientation_mean_rad: float

    def as_dict(self) -> dict[str, object]:
        """The figures in file units: mm and degrees."""
        return {"region": self.region, "poses": self.poses,
                "position_max_mm": self.position_max_m * 1e3,
                "position_mean_mm": self.position_mean_m * 1e3,
                "orientation_max_deg": float(np.degrees(self.orientation_max_rad)),
                "orientation_mean_deg": float(np.degrees(self.orientation_mean_rad))}

    def line(self) -> str:
        """One line: ``worst 3.974 mm / 0.2080° (mean 0.547 mm / 0.0398°) over 2000 …``."""
        return (f"worst {self.position_max_m * 1e3:.3f} mm / "
                f"{np.degrees(self.orientation_max_rad):.4f}° (mean "
                f"{self.position_mean_m * 1e3:.3f} mm / "
                f"{np.degrees(self.orientation_mean_rad):.4f}°) over {self.poses} "
                f"configurations in the {self.region}")


@dataclass(frozen=True)
class TreeFit:
    """The closest serial tree of a calibrated loop (module docstring).

    Attributes
    ----------
    result : CalibrationResult
        The serial model (model 1) identified on the loop's poses: its
        ``model.structure.desc`` is the serial chain, ``model.structure.reading_map``
        the readings → chain joints map, ``model.base()``/``probe()`` BASE and PROBE.
    errors : tuple of TreeError
        The tree vs the loop: in the working volume (when the robot has one), then over
        the joint limits.
    fit_poses : int
        Configurations the tree was fitted on.
    seed : int
        Seed of the configurations (fit: ``seed``; checks: ``seed + 1``, ``seed + 2``).
    """

    result: CalibrationResult
    errors: tuple[TreeError, ...]
    fit_poses: int
    seed: int

    @property
    def worst(self) -> TreeError:
        """The error over the largest region compared (the joint limits)."""
        return self.errors[-1]


def loop_geometric_poses(model: ErrorModel, q: ArrayLike) -> Array:
    """The calibrated geometric model ``BASE · T_n^0(q; g) · PROBE`` (eq. 6.23, no Δθ).

    Parameters
    ----------
    model : ErrorModel
        A calibrated model (any family).
    q : (N, n_readings) array_like, rad
        Joint readings.

    Returns
    -------
    (N, 4, 4) array, m
        Target poses in the measurement frame: the chain's geometry
        (``model.geometric_parameters()``, passive angles from the exact four-bar
        closure), BASE and PROBE; compliance, payload and thermal terms left out.
    """
    s = model.structure
    joints = s.joints(np.atleast_2d(np.asarray(q, dtype=float)))
    fk = forward(s.desc, model.geometric_parameters(), joints, closure="fourbar")
    return model.base() @ fk.flange @ model.probe()


def _error(region: str, tree: ErrorModel, loop: ErrorModel, q: Array) -> TreeError:
    A = tree.predict(q)
    B = loop_geometric_poses(loop, q)
    dp = np.linalg.norm(A[:, :3, 3] - B[:, :3, 3], axis=1)
    dr = rotation_error(A, B)
    return TreeError(region, len(q), float(dp.max()), float(dp.mean()), float(dr.max()),
                     float(dr.mean()))


def closest_serial_tree(model: ErrorModel, *, fit_poses: int = 400, check_poses: int = 2000,
                        seed: int = 0) -> TreeFit:
    """Fit the serial tree of eq. (6.3) to a calibrated loop model and measure its error.

    Parameters
    ----------
    model : ErrorModel
        A calibration of the loop family of a robot with loops (models 2, 4, 5).
    fit_poses : int
        Configurations to fit on (uniform in the working volume, else in the joint
        limits; seed ``seed``).
    check_poses : int
        Configurations per region to measure the error on (seeds ``seed + 1`` in the
        working volume, ``seed + 2`` over the joint limits).
    seed : int
        Random seed.

    Returns
    -------
    TreeFit
        The fitted serial model and its errors (module docstring).

    Raises
    ------
    ValueError
        ``model`` is not of the loop family of a robot with loops, or too few poses.
    """
    s = model.structure
    desc = s.source
    if not desc.loops or s.family != "loop":
        raise ValueError("closest_serial_tree needs a calibration of the loop family of a "
                         f"robot with loops (got family {s.family!r} of {desc.name!r})")
    if fit_poses < 50 or check_poses < 1:
        raise ValueError(f"fit_poses must be ≥ 50 and check_poses ≥ 1, got {fit_poses}, "
                         f"{check_poses}")
    volume = desc.working_volume
    q = sample_candidates(model, fit_poses, volume=volume, seed=seed).q
    data = CalibrationData.from_poses(q, loop_geometric_poses(model, q))
    fit = Calibrator(desc, "serial", base=model.base(), probe=model.probe()).fit(data)
    errors = []
    if volume is not None:
        qv = sample_candidates(model, check_poses, volume=volume, seed=seed + 1).q
        errors.append(_error("working volume", fit.model, model, qv))
    qa = sample_candidates(model, check_poses, seed=seed + 2).q
    errors.append(_error("joint limits", fit.model, model, qa))
    return TreeFit(fit, tuple(errors), len(q), seed)
