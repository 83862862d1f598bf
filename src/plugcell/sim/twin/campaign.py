"""Simulated measurement campaigns: poses in the working volume, measured by the tracker.

The campaign does what an operator does with a real robot and tracker (thesis
8.2.1–8.2.2, Fig. 8-4): choose flange poses in the working volume, turn them into
joint targets with the controller's nominal inverse kinematics, move the robot
through them while the tracker follows the T-MAC, and take a 1 s measurement at
each pose.  The result is a :class:`~plugcell.io.measurements.MeasurementSet`:
joint *readings* and tracker measurements — nothing of the truth.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from plugcell.io.measurements import MeasurementSet
from plugcell.kinematics import RobotDescription, inverse
from plugcell.kinematics.errors import KinematicsError
from plugcell.kinematics.rotations import matrix_to_angles, zyz_to_matrix
from plugcell.kinematics.transforms import so3_exp
from plugcell.sim.twin.profile import TwinProfile
from plugcell.sim.twin.robot import RobotTwin
from plugcell.sim.twin.tracker import LaserTracker

Array = NDArray[np.float64]

#: Joint speed of the simulated moves between measurement poses (rad/s) and the
#: settling time before a measurement (s): a 150-pose campaign then takes ~15 min
#: of simulated time, as in thesis 8.2.3.
JOINT_SPEED = np.deg2rad(40.0)
SETTLE_S = 2.0

Progress = Callable[[int, int], None]


class CampaignError(RuntimeError):
    """A campaign that cannot be carried out (no reachable poses, lost beam...)."""


def random_flange_targets(desc: RobotDescription, profile: TwinProfile, n: int,
                          rng: np.random.Generator) -> Array:
    """``n`` flange poses (n, 4, 4): positions uniform in the description's working
    volume, orientations within ``profile.spread`` of the reference orientation."""
    if desc.working_volume is None:
        raise CampaignError(f"robot {desc.name!r} has no working_volume in its description")
    box = desc.working_volume
    p = rng.uniform(box.lower, box.upper, size=(n, 3))
    axis = rng.standard_normal((n, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    angle = profile.spread * rng.uniform(0.0, 1.0, size=(n, 1)) ** (1 / 3)
    R = so3_exp(axis * angle) @ zyz_to_matrix(*profile.reference_zyz)
    T = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
    T[:, :3, :3] = R
    T[:, :3, 3] = p
    return T


def working_volume_joints(desc: RobotDescription, profile: TwinProfile, n: int,
                          rng: np.random.Generator, *, max_rounds: int = 20) -> Array:
    """``n`` joint configurations (n, n_act) whose nominal flange lies in the working
    volume, found by nominal IK within the joint limits (unreachable draws are
    replaced by new ones)."""
    return _reachable_joints(
        desc, n, lambda k: random_flange_targets(desc, profile, k, rng),
        "poses in the working volume", max_rounds)


def _reachable_joints(desc: RobotDescription, n: int, draw: Callable[[int], Array],
                      what: str, max_rounds: int = 20) -> Array:
    """``n`` joint configurations (n, n_act) reaching flange poses ``draw(k)`` gives
    ((k, 4, 4), k ≥ twice what is missing) by nominal IK within the joint limits; the
    unreachable draws are replaced by new ones, for at most ``max_rounds`` rounds.

    Raises
    ------
    CampaignError
        Fewer than ``n`` reachable poses after ``max_rounds`` rounds (``what`` names them).
    """
    params = desc.nominal_parameters()
    found: list[Array] = []
    for _ in range(max_rounds):
        need = n - sum(len(f) for f in found)
        if need <= 0:
            break
        try:
            res = inverse(desc, params, draw(max(2 * need, 8)), seed=desc.home,
                          raise_errors=False)
        except KinematicsError:
            continue
        ok = np.asarray(res.converged) & np.asarray(res.within_limits)
        found.append(np.asarray(res.q)[ok][:need])
    q = np.concatenate(found) if found else np.empty((0, desc.n_readings))
    if len(q) < n:
        raise CampaignError(f"found only {len(q)} of {n} reachable {what}")
    return q[:n]


def surface_scan_joints(desc: RobotDescription, profile: TwinProfile, n: int,
                        rng: np.random.Generator, *, height: float = 0.5,
                        extent: float = 0.8) -> Array:
    """``n`` joint configurations of a surface scan: flange positions uniform on a
    horizontal patch of the working volume (``extent`` of its x and y sides, at
    ``height`` of its z range), all at the profile's reference orientation — the tool
    orientation held constant, as when a probe follows a surface (the campaign whose
    PROBE position cannot be told apart from BASE, :mod:`plugcell.calibration.determinacy`).

    Parameters
    ----------
    desc : RobotDescription
        The robot (its working volume and nominal geometry).
    profile : TwinProfile
        Its twin profile (the reference orientation).
    n : int
        Poses.
    rng : numpy.random.Generator
        Seeded generator of the positions.
    height : float
        Height of the patch as a fraction of the working volume's z range.
    extent : float
        Fraction of the working volume's x and y sides the patch covers.

    Returns
    -------
    (n, n_act) array, rad
        Joint targets (nominal IK within the joint limits).

    Raises
    ------
    CampaignError
        No working volume, or fewer than ``n`` reachable poses.
    """
    if desc.working_volume is None:
        raise CampaignError(f"robot {desc.name!r} has no working_volume in its description")
    lo, hi = np.asarray(desc.working_volume.lower), np.asarray(desc.working_volume.upper)
    c, ext = 0.5 * (lo + hi), hi - lo

    def patch(k: int) -> Array:
        u = rng.uniform(-0.5, 0.5, size=(k, 2))
        T = np.broadcast_to(np.eye(4), (k, 4, 4)).copy()
        T[:, :3, :3] = zyz_to_matrix(*profile.reference_zyz)
        T[:, 0, 3] = c[0] + extent * ext[0] * u[:, 0]
        T[:, 1, 3] = c[1] + extent * ext[1] * u[:, 1]
        T[:, 2, 3] = lo[2] + height * ext[2]
        return T

    return _reachable_joints(desc, n, patch, "scan poses")


def move_time(q_from: Array, q_to: Array) -> float:
    """Simulated duration of a joint move plus settling (s)."""
    return float(np.max(np.abs(q_to - q_from)) / JOINT_SPEED + SETTLE_S)


def measure_poses(robot: RobotTwin, tracker: LaserTracker, joints: Array, *,
                  duration_s: float = 1.0, rotation: str = "rpy",
                  progress: Progress | None = None,
                  mode: str = "6dof",
                  temperatures_c: Array | None = None) -> tuple[MeasurementSet, float]:
    """Move through ``joints`` and take one tracker measurement at each pose.

    ``mode``: ``"6dof"`` (T-MAC pose) or ``"3dof"`` (the reflector's position only; the
    set then has no angles).

    The operator catches the beam on the T-MAC once at the start (as with a real
    tracker); from then on the tracker follows the reflector through each move.

    Parameters
    ----------
    temperatures_c : (N,) ndarray, °C, optional
        The hall's temperature at each pose: set on the twin before it moves there (its
        thermal drift, :meth:`RobotTwin.set_thermal_drift`, scales the arm and moves
        BASE) and written as the set's ``temperature_c`` — what the cell's temperature
        sensor read.  ``None``: no temperature column, the twin's temperature untouched.

    Returns
    -------
    MeasurementSet, float
        The measurement set and the simulated time (s) the campaign took.
    """
    if mode not in ("6dof", "3dof"):
        raise ValueError(f"mode: '6dof' or '3dof', got {mode!r}")
    n = len(joints)
    if temperatures_c is not None:
        temperatures_c = np.asarray(temperatures_c, dtype=float)
        if temperatures_c.shape != (n,):
            raise ValueError(f"temperatures_c must be ({n},), got {temperatures_c.shape}")
    readings = np.empty_like(joints)
    positions = np.empty((n, 3))
    angles = np.empty((n, 3))
    sim_time = 0.0
    q_prev = robot.joint_readings()
    if temperatures_c is not None:
        robot.set_temperature(float(temperatures_c[0]))
    robot.move_joints(joints[0])
    tracker.point_at(robot.true_reflector_in_tracker()[:3, 3])  # operator catches the beam
    for i, q in enumerate(joints):
        if temperatures_c is not None:
            robot.set_temperature(float(temperatures_c[i]))
        if i > 0:
            robot.move_joints(q)
        dt = move_time(q_prev, q)
        tracker.track(robot.true_reflector_in_tracker(), dt)
        m = tracker.measure(robot.true_reflector_in_tracker(), duration_s,
                            mode="3dof" if mode == "3dof" else "6dof")
        sim_time += dt + duration_s
        readings[i] = robot.joint_readings()
        positions[i] = m.position if m.pose is None else m.pose[:3, 3]
        if m.pose is not None:
            angles[i] = matrix_to_angles(m.pose[:3, :3], rotation)
        q_prev = readings[i]
        if progress is not None:
            progress(i + 1, n)
    payload = np.full(n, robot.payload.mass)
    return MeasurementSet(readings, positions, None if mode == "3dof" else angles, rotation,
                          payload,
                          None if temperatures_c is None else temperatures_c.copy()), sim_time


#: Reference nests fixed to the foundation around the robot (robot base frame, m): what
#: the drift watch re-measures (docs/metrology.md); not on one line, not in one plane.
REFERENCE_NESTS = np.array([[1.0, -1.3, 0.0], [2.4, 0.2, 0.05], [1.2, 1.5, 0.0],
                            [0.3, -0.2, 0.4]])


def measure_nests(robot: RobotTwin, tracker: LaserTracker, nests: Array = REFERENCE_NESTS,
                  *, duration_s: float = 1.0) -> Array:
    """The tracker's 3-DOF measurement of reference nests (tracker frame, m).

    Parameters
    ----------
    nests : (K, 3) ndarray, m
        Nest positions in the robot base frame (fixed to the foundation); where they are in
        the tracker frame now is ``BASE(T) · n_k`` with the twin's true, drifting BASE.
    duration_s : float
        Measuring time per nest (s).

    Returns
    -------
    (K, 3) ndarray, m
        The measured positions, tracker noise included.
    """
    out = []
    for p in np.asarray(nests, dtype=float):
        true = robot.true_point_in_tracker(p)
        tracker.point_at(true)
        out.append(tracker.measure(true, duration_s, mode="3dof").position)
    return np.array(out)
