"""A twin for any robot: the cell and the physics a description does not say, estimated.

The shipped robots have a twin profile written by hand (``sim/twin/profiles/<robot>.toml``).
A robot imported from a vendor URDF, or described by the user, has none, and its
description may lack what the twin needs beyond kinematics — a working volume to draw
poses in and joint stiffnesses.  :func:`generic_twin` estimates them from the
description alone, reproducibly (no randomness):

* **Working volume** (when the description has none): the flange positions ``p(q)`` of
  ``N`` configurations spread over the joint limits (a golden-ratio Kronecker sequence)
  give the reach ``R`` (95th percentile of the horizontal distance ``‖p_xy‖``) and the
  shoulder height ``h`` (median ``p_z``); the box is centred at ``(0.55 R, 0, h)`` with edges
  ``(0.30 R, 0.60 R, 0.35 R)`` — the region in front of the robot where the thesis's
  campaigns were drawn (Fig. 8-4).
* **Joint stiffness** (when it has none): ``k_j = max(τ_j, 0.1 max_i τ_i, 1 N·m) / δ``
  with ``τ_j`` the largest gravity torque of joint ``j`` over the same configurations
  (its link masses, no payload) and ``δ = 0.02°`` — a joint deflects at most that much
  under the arm's own weight, the order of the shipped robots' deflections; the floor
  keeps the wrist and the vertical axis from being soft where the arm's weight does not
  load them (a payload does).
* **Profile**: the generic estimates of ``elbow6``'s profile (σ 0.5 mm / 0.05° per
  parameter, 0.001° encoders, 0.008° lost motion, 1st/2nd/31st-order transmission error
  of 0.004°) without link bending (a URDF does not give cross-sections); the preload
  that hides backlash is 5 % of the largest gravity torque; the tracker stands 3 m from
  the volume's centre, 40° to the robot's right, 0.4 m high, facing it; the T-MAC sits
  0.05 m along the flange's z axis and the poses' reference orientation points it at
  the tracker (spread 20°).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from plugcell.kinematics import RobotDescription, forward
from plugcell.kinematics.description import Box
from plugcell.sim.twin.physics import gravity_torques
from plugcell.sim.twin.profile import TwinProfile

#: Configurations that estimate the working volume and the gravity torques.
SAMPLES = 512
#: Largest deflection of a joint under the arm's own weight (rad).
DEFLECTION = math.radians(0.02)
#: Distance of the tracker from the volume's centre (m), bearing (rad), height (m).
TRACKER_DISTANCE, TRACKER_BEARING, TRACKER_HEIGHT = 3.0, math.radians(-40.0), 0.4


def _samples(desc: RobotDescription) -> np.ndarray:
    """``(SAMPLES, n_readings)`` readings spread over the joint limits (a fixed
    low-discrepancy sequence: the golden-ratio Kronecker sequence, deterministic)."""
    n = desc.n_readings
    lo, hi = desc.joint_limits[:, 0], desc.joint_limits[:, 1]
    # generalised golden ratio φ_n: 1/φ_n^k are the Kronecker steps of each dimension
    phi = 2.0
    for _ in range(30):
        phi = (1.0 + phi) ** (1.0 / (n + 1))
    steps = (1.0 / phi) ** np.arange(1, n + 1)
    u = (0.5 + np.outer(np.arange(1, SAMPLES + 1), steps)) % 1.0
    return lo + u * (hi - lo)


def working_volume(desc: RobotDescription, q: np.ndarray) -> Box:
    """The box in front of the robot (module docstring) from flange positions at ``q``."""
    p = forward(desc, desc.nominal_parameters(), q, closure="fourbar").flange[:, :3, 3]
    reach = float(np.percentile(np.linalg.norm(p[:, :2], axis=1), 95))
    height = float(np.median(p[:, 2]))
    return Box((0.55 * reach, 0.0, height), (0.30 * reach, 0.60 * reach, 0.35 * reach))


def joint_stiffness(desc: RobotDescription, q: np.ndarray) -> np.ndarray:
    """``(n_actuated,)`` N·m/rad: ``max(τ_j, 0.1 max τ, 1 N·m) / δ`` (module docstring)."""
    tau = np.abs(gravity_torques(desc, desc.nominal_parameters(), q)).max(axis=0)
    return np.maximum(tau, max(0.1 * float(tau.max()), 1.0)) / DEFLECTION


def generic_twin(desc: RobotDescription) -> tuple[RobotDescription, TwinProfile]:
    """``desc`` completed for the twin (working volume, stiffness where missing) and its
    estimated :class:`TwinProfile` (module docstring)."""
    q = _samples(desc)
    if desc.working_volume is None:
        desc = replace(desc, working_volume=working_volume(desc, q))
    if desc.stiffness is None:
        desc = replace(desc, stiffness=joint_stiffness(desc, q))
    tau = np.abs(gravity_torques(desc, desc.nominal_parameters(), q)).max()
    box = desc.working_volume
    assert box is not None
    centre = np.asarray(box.center, dtype=float)
    tracker = centre + TRACKER_DISTANCE * np.array(
        [math.cos(TRACKER_BEARING), math.sin(TRACKER_BEARING), 0.0])
    tracker[2] = TRACKER_HEIGHT
    facing = math.atan2(centre[1] - tracker[1], centre[0] - tracker[0])  # tracker → robot
    rad = math.radians
    profile = TwinProfile(
        robot=desc.name,
        sigma_length=0.5e-3,
        sigma_angle=rad(0.05),
        encoder_resolution=rad(0.001),
        repeatability=rad(0.0005),
        lost_motion=rad(0.008),
        preload_torque=0.05 * float(tau),
        transmission_orders=(1, 2, 31),
        transmission_amplitude=rad(0.004),
        beams=(),
        tracker_position=(float(tracker[0]), float(tracker[1]), float(tracker[2])),
        tracker_yaw=facing,
        probe_position=(0.0, 0.0, 0.05),
        probe_rpy=(0.0, 0.0, 0.0),
        # flange z axis (the T-MAC's normal) horizontal, pointing at the tracker
        reference_zyz=(TRACKER_BEARING, rad(90.0), 0.0),
        spread=rad(20.0),
    )
    return desc, profile
