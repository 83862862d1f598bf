"""The BASE and PROBE procedures of thesis appendix D, carried out on the twin.

What an operator does with a real robot and tracker, step by step, using the
simulated tracker in 3-DOF (SMR) mode and the metrology fits of
:mod:`plugcell.metrology.frames`:

* **PROBE (D.1)** — an SMR sits in a dowel hole of the flange while joint n turns
  full round (a circle: flange origin and z_n); the SMR is measured in the two
  dowel holes (a line: y_n); then the T-MAC is mounted and measured once (D.3).
* **BASE (D.2)** — an SMR on the outer surface of joint 1 while joint 1 turns (a
  circle: the joint-1 axis, z_0); SMR positions on the base surface (the plane
  z = 0); the robot moves along its x axis while the T-MAC is measured (a line: x_0).

The operator "catches the beam" on each SMR by hand (a real procedure), which
the simulation expresses as pointing the tracker at the SMR's true position.
The estimates are what calibration starts from; their error has two sources —
tracker noise, and the robot's own errors (e.g. a true a6 ≠ 0 puts the flange
origin off the joint-6 axis; the x-move follows the *nominal* model) — which is
why calibration refines them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from plugcell.kinematics import inverse
from plugcell.kinematics.rotations import zyz_to_matrix
from plugcell.metrology.frames import (
    SMR_RADIUS_HALF_INCH,
    BaseEstimate,
    ProbeEstimate,
    base_from_features,
    probe_from_flange_features,
)
from plugcell.sim.twin.robot import RobotTwin, true_link_frames
from plugcell.sim.twin.tracker import LaserTracker

#: Dowel holes on the flange face, flange frame (m): on the y axis, 50 mm from the centre.
DOWEL_HOLES = np.array([[0.0, -0.05, 0.0], [0.0, 0.05, 0.0]])


@dataclass(frozen=True)
class FrameProcedureSetup:
    """Where the operator puts things (m).  Defaults suit a 200 kg-class robot."""

    smr_offset: float = SMR_RADIUS_HALF_INCH
    #: SMR on joint 1's outer surface, in the link-1 frame F1.
    joint1_smr: tuple[float, float, float] = (-0.25, 0.55, 0.35)
    #: SMR positions on the base surface, in F0 (z = 0 is the mounting plane).
    base_points: tuple[tuple[float, float], ...] = (
        (0.7, 0.0), (0.0, 0.7), (-0.7, 0.0), (0.0, -0.7), (0.5, 0.5), (-0.5, -0.5))
    joint6_angles_deg: tuple[float, ...] = tuple(np.arange(-150.0, 151.0, 25.0))
    joint1_angles_deg: tuple[float, ...] = tuple(np.arange(-60.0, 61.0, 10.0))
    x_move_from: tuple[float, float, float] = (1.25, 0.0, 1.1)
    x_move_length: float = 0.7
    x_move_steps: int = 8
    duration_s: float = 1.0


def _smr(tracker: LaserTracker, position: np.ndarray, duration: float) -> np.ndarray:
    tracker.point_at(position)  # the operator catches the beam on the SMR
    return tracker.measure(position, duration, mode="3dof").position


def measure_probe(robot: RobotTwin, tracker: LaserTracker, q: np.ndarray,
                  setup: FrameProcedureSetup = FrameProcedureSetup()) -> ProbeEstimate:
    """Appendix D.1 at joint configuration ``q`` (rad)."""
    truth = robot.reveal_truth()  # the physical world: where the SMR really is
    j6 = robot.description.n_readings - 1
    hole = DOWEL_HOLES[1] + [0.0, 0.0, setup.smr_offset]
    circle = []
    for a in np.deg2rad(setup.joint6_angles_deg):
        qq = np.array(q, dtype=float)
        qq[j6] = a
        robot.move_joints(qq)
        p = (truth.base @ robot.true_flange() @ np.r_[hole, 1.0])[:3]
        circle.append(_smr(tracker, p, setup.duration_s))
    robot.move_joints(q)
    flange = truth.base @ robot.true_flange()
    holes = [_smr(tracker, (flange @ np.r_[h + np.array([0.0, 0.0, setup.smr_offset]), 1.0])[:3],
                  setup.duration_s) for h in DOWEL_HOLES]
    tmac_true = flange @ truth.probe
    tracker.point_at(tmac_true[:3, 3])
    tmac = tracker.measure(tmac_true, setup.duration_s, mode="6dof").pose
    return probe_from_flange_features(np.array(circle), np.array(holes), tmac,
                                      smr_offset=setup.smr_offset)


def measure_base(robot: RobotTwin, tracker: LaserTracker,
                 setup: FrameProcedureSetup = FrameProcedureSetup(),
                 reference_zyz: tuple[float, float, float] = (0.0, np.pi / 2, 0.0)
                 ) -> BaseEstimate:
    """Appendix D.2: joint-1 circle, base plane, and a move along x."""
    truth = robot.reveal_truth()
    desc = robot.description
    i1 = desc.index(desc.actuated[0])
    circle = []
    q0 = np.array(desc.home, dtype=float)
    for a in np.deg2rad(setup.joint1_angles_deg):
        qq = q0.copy()
        qq[0] = a
        robot.move_joints(qq)
        F1 = true_link_frames(truth, robot.joint_readings())[i1]
        p = (truth.base @ F1 @ np.r_[setup.joint1_smr, 1.0])[:3]
        circle.append(_smr(tracker, p, setup.duration_s))
    plane = [_smr(tracker, (truth.base @ np.r_[x, y, setup.smr_offset, 1.0])[:3],
                  setup.duration_s) for x, y in setup.base_points]
    # the move along x_0, commanded with the controller's nominal model
    nominal = desc.nominal_parameters()
    start = np.array(setup.x_move_from)
    targets = np.broadcast_to(np.eye(4), (setup.x_move_steps, 4, 4)).copy()
    targets[:, :3, :3] = zyz_to_matrix(*reference_zyz)
    targets[:, :3, 3] = start + np.outer(np.linspace(0, setup.x_move_length, setup.x_move_steps),
                                         [1.0, 0.0, 0.0])
    q_line = inverse(desc, nominal, targets, seed=desc.home).q
    line = []
    for q in q_line:
        robot.move_joints(q)
        tmac = truth.base @ robot.true_flange() @ truth.probe
        tracker.point_at(tmac[:3, 3])
        line.append(tracker.measure(tmac, setup.duration_s, mode="6dof").position)
    return base_from_features(np.array(circle), np.array(plane), np.array(line),
                              smr_offset=setup.smr_offset)
