"""The twin's error budget: how wrong the nominal model is, and why.

Every figure is computed from the twin's physics at random configurations whose
nominal flange lies in the working volume (thesis 8.2.1), at the T-MAC point
(the point the tracker measures), in the robot base frame — not read from a
table.  Effects are switched on one at a time to show each one's share.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from plugcell.kinematics import forward
from plugcell.sim.twin.campaign import Progress, working_volume_joints
from plugcell.sim.twin.physics import Payload
from plugcell.sim.twin.robot import RobotTwin, true_flange_poses
from plugcell.sim.twin.scenario import TwinScenario, TwinTruth, make_truth


@dataclass(frozen=True)
class ErrorBudget:
    """Figures in mm (positions) and degrees; see :func:`error_budget`."""

    robot: str
    seed: int
    poses: int
    nominal_mean_mm: float
    nominal_max_mm: float
    nominal_std_mm: float
    geometric_only_mean_mm: float
    transmission_only_mean_mm: float
    gravity_only_mean_mm: float
    deflection_18kg_mm: float
    deflection_36kg_mm: float
    bending_share_36kg: float
    repeatability_sigma_mm: float
    encoder_resolution_deg: float
    orientation_nominal_mean_deg: float

    def as_dict(self) -> dict[str, float | int | str]:
        return dict(self.__dict__)


def _tmac_points(truth: TwinTruth, flange: np.ndarray) -> np.ndarray:
    return (flange @ truth.probe)[..., :3, 3]


def _angle_deg(Ra: np.ndarray, Rb: np.ndarray) -> np.ndarray:
    c = (np.trace(Ra @ np.swapaxes(Rb, -1, -2), axis1=-2, axis2=-1) - 1) / 2
    return np.degrees(np.arccos(np.clip(c, -1, 1)))


def error_budget(scenario: TwinScenario, *, poses: int = 300, seed: int = 7,
                 payload_com_m: tuple[float, float, float] | None = None,
                 progress: Progress | None = None) -> ErrorBudget:
    """Nominal error and deflections of the twin of ``scenario`` (unloaded base case).

    * ``nominal_*``: |p_true − p_nominal| of the T-MAC point, unloaded, all effects;
    * ``geometric_only`` / ``transmission_only`` / ``gravity_only``: the same with
      one effect alone (gravity: link masses and counterweight, with bending);
    * ``deflection_Nkg``: mean |p(N kg) − p(0 kg)| of the true robot at the same
      joint readings — the payload deflection of thesis Fig. 8-6;
    * ``bending_share_36kg``: the part of the 36 kg deflection due to link bending;
    * ``repeatability_sigma_mm``: 1-σ TCP scatter of repeated moves to one pose.
    """
    truth = make_truth(scenario.with_payload(0.0))
    desc = truth.description
    rng = np.random.default_rng(seed)
    q = working_volume_joints(desc, truth.profile, poses, rng)
    if progress:
        progress(1, 4)
    nominal = forward(desc, desc.nominal_parameters(), q).flange
    p_nom = _tmac_points(truth, nominal)
    full = true_flange_poses(truth, q, Payload())
    err = np.linalg.norm(_tmac_points(truth, full) - p_nom, axis=-1)
    def alone(**switches: object) -> np.ndarray:
        t = make_truth(replace(scenario, payload_kg=0.0, **switches))
        return np.linalg.norm(_tmac_points(t, true_flange_poses(t, q, Payload())) - p_nom, axis=-1)

    geo = alone(gravity=False, transmission=False)
    trans = alone(gravity=False, error_scale=0.0)
    grav = alone(transmission=False, error_scale=0.0)
    if progress:
        progress(2, 4)
    com = payload_com_m or scenario.payload_com_m
    defl = {}
    for kg in (18.0, 36.0):
        loaded = true_flange_poses(truth, q, Payload(kg, com))
        defl[kg] = np.linalg.norm(_tmac_points(truth, loaded) - _tmac_points(truth, full), axis=-1)
    no_bend = np.linalg.norm(
        _tmac_points(truth, true_flange_poses(truth, q, Payload(36.0, com), bend=False))
        - _tmac_points(truth, true_flange_poses(truth, q, Payload(), bend=False)), axis=-1)
    if progress:
        progress(3, 4)
    twin = RobotTwin(truth, seed=seed)
    reps = []
    for _ in range(60):
        twin.move_joints(q[0])
        reps.append(_tmac_points(truth, twin.true_flange()))
    reps = np.array(reps)
    if progress:
        progress(4, 4)
    return ErrorBudget(
        robot=desc.name,
        seed=scenario.seed,
        poses=poses,
        nominal_mean_mm=float(err.mean() * 1e3),
        nominal_max_mm=float(err.max() * 1e3),
        nominal_std_mm=float(err.std() * 1e3),
        geometric_only_mean_mm=float(geo.mean() * 1e3),
        transmission_only_mean_mm=float(trans.mean() * 1e3),
        gravity_only_mean_mm=float(grav.mean() * 1e3),
        deflection_18kg_mm=float(defl[18.0].mean() * 1e3),
        deflection_36kg_mm=float(defl[36.0].mean() * 1e3),
        bending_share_36kg=float(1.0 - no_bend.mean() / defl[36.0].mean()),
        repeatability_sigma_mm=float(np.sqrt(reps.var(axis=0).sum() / 3) * 1e3),
        encoder_resolution_deg=float(np.degrees(truth.profile.encoder_resolution)),
        orientation_nominal_mean_deg=float(_angle_deg(full[..., :3, :3],
                                                      nominal[..., :3, :3]).mean()),
    )
