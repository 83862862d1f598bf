"""Correction while settling on the Smart H4 twin in time (issue 38 §3): the dynamic twin
and the streaming tracker behind the protocols (``plugcell.sim.dynamic_cell``)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from plugcell.compensation import (
    CorrectionError,
    CorrectionSettings,
    IdentifiedModel,
    JointRobot,
    MetrologyFrames,
    MovingRobot,
    PoseSensor,
    PoseStream,
    SettlingSettings,
    compensate_joints,
    correct_6dof,
    correct_while_settling,
    nominal_joints,
)
from plugcell.kinematics.pose_error import pose_error_exact
from plugcell.kinematics.rotations import zyz_to_matrix
from plugcell.sim.dynamic_cell import (
    LINEAR_RAD,
    AveragingSensor,
    DynamicCell,
    StopAndGoRobot,
)
from plugcell.sim.twin.dynamics import DynamicTwin
from plugcell.sim.twin.robot import RobotTwin
from plugcell.sim.twin.tracker import LaserTracker
from plugcell.sim.twin.tracker_stream import StreamSpec


def _setup(calibrated, y=0.15, **kw):
    """The twin at the model-compensated joints of an 8.3-like target one step away."""
    model = IdentifiedModel(calibrated.result.model)
    frames = MetrologyFrames(model.base, model.probe)
    T = np.eye(4)
    T[:3, :3] = zyz_to_matrix(0.0, math.pi / 2, 0.0) @ model.probe[:3, :3]
    T[:3, 3] = [1.6, y, 1.1]
    targets = np.stack([T, T.copy()])
    targets[0, 1, 3] -= 0.15  # start 150 mm away, as on the 8.3 lines
    robot = RobotTwin(calibrated.scenario)
    qn, ok, _ = nominal_joints(model, targets, robot.description.home)
    assert ok.all()
    q = compensate_joints(model, targets, qn, 36.0).q
    arm = DynamicTwin(robot, q0=q[0])
    cell = DynamicCell(arm, LaserTracker(seed=3), frames, **kw)
    return cell, model, targets[1], q[1]


def test_the_cell_faces_implement_the_protocols(calibrated):
    cell, *_ = _setup(calibrated)
    assert isinstance(cell.robot_device(), MovingRobot)
    assert isinstance(cell.stream_device(), PoseStream)
    assert isinstance(StopAndGoRobot(cell), JointRobot)
    assert isinstance(AveragingSensor(cell), PoseSensor)


def test_linearised_reflector_matches_the_exact_physics(calibrated):
    cell, *_ = _setup(calibrated)
    cell.advance(0.2, sample=False)  # at rest: the cell linearises here
    assert cell._lin is not None
    q0 = cell._lin[0]
    rng = np.random.default_rng(0)
    links = q0 + rng.uniform(-0.95, 0.95, (20, q0.size)) * LINEAR_RAD
    lin, exact = cell._reflector(links), cell._exact(links)
    assert np.max(np.abs(lin[:, :3, 3] - exact[:, :3, 3])) < 1e-7
    assert np.max(np.abs(lin[:, :3, :3] - exact[:, :3, :3])) < 1e-7


def test_stream_samples_the_arm_at_rest_within_the_tracker_noise(calibrated):
    cell, *_ = _setup(calibrated)
    got = cell.advance(0.5)
    assert len(got) >= 495 and all(s.status == "ok" for s in got)
    t = np.array([s.time_s for s in got])
    assert np.all(np.diff(t) == pytest.approx(1e-3))
    P = np.array([s.position for s in got])
    truth = cell.true_tool()[:3, 3]
    assert np.linalg.norm(P.mean(axis=0) - truth) < 0.05e-3
    assert 20e-6 < P.std(axis=0).max() < 0.3e-3


def test_uncertainty_matches_the_stream_at_rest(calibrated):
    """The tracker stream's own noise (white, Gauss–Markov floor): over 16 windows of
    0.25 s at rest the stated uncertainty matches the scatter of the estimates."""
    from plugcell.compensation import estimate_rest_pose

    cell, _, target, _ = _setup(calibrated)
    got = cell.advance(4.05)
    t = np.array([s.time_s for s in got])
    E = pose_error_exact(target, np.array([s.pose for s in got]))
    est = [estimate_rest_pose(t[m], E[m]) for m in
           ((t >= t[0] + 0.25 * k) & (t < t[0] + 0.25 * (k + 1)) for k in range(16))]
    spread = np.linalg.norm(np.std([e.error[:3] for e in est], axis=0))
    stated = np.mean([e.position_uncertainty_m for e in est])
    assert 0.6 < stated / spread < 1.6


def test_converges_within_tolerance_on_the_twin(calibrated):
    """One point of the 8.3 layout, 150 mm from the last: moved, estimated while
    settling, corrected, confirmed — the true rest pose (after a further second) is
    inside the thesis's tolerance, and the point took less than 2 s of simulated time."""
    cell, model, target, q = _setup(calibrated)
    s = SettlingSettings()
    res = correct_while_settling(cell.robot_device(), cell.stream_device(), model, target, q,
                                 s, payload_kg=36.0)
    assert res.converged
    assert res.final_position_error_m < s.position_tol_m
    assert res.time_s < 2.0
    assert 0.0 < res.move_end_s < res.steps[0].time_s
    cell.advance(1.0, sample=False)
    e = pose_error_exact(target, cell.true_tool())
    assert np.linalg.norm(e[:3]) < 0.08e-3
    assert np.linalg.norm(e[3:]) < math.radians(0.05)
    assert np.array_equal(cell.command, res.q_final)


def test_a_small_move_is_stretched_to_its_duration_and_rings_less(calibrated):
    """``command_joints(q, duration_s)``: a 0.2 mm correction as a 0.2 s quintic ramp
    ends 0.2 s later and rings the tool far less than the same step at the limits."""
    ring = {}
    for duration in (0.0, 0.2):
        cell, model, *_ = _setup(calibrated)
        cell.advance(1.0, sample=False)
        J = model.evaluate(cell.command, 36.0)[1][0]
        dq = np.linalg.solve(J, np.r_[0.0, 0.2e-3, 0.0, 0.0, 0.0, 0.0])
        t0 = cell.now
        end = cell.command_joints(cell.command + dq, duration)
        if duration:
            assert end - t0 == pytest.approx(duration, abs=cell.cycle_s)
        cell.advance(end - cell.now, sample=False)
        p = []
        for _ in range(100):  # 0.4 s after the move
            cell.advance(cell.cycle_s, sample=False)
            p.append(cell.true_tool()[:3, 3])
        p = np.array(p)
        ring[duration] = float(np.max(np.linalg.norm(p - p[-25:].mean(axis=0), axis=1)))
    assert ring[0.2] < 0.3 * ring[0.0]


def test_a_beam_broken_for_good_on_the_twin(calibrated):
    spec = StreamSpec(auto_reacquire=False)
    cell, model, target, q = _setup(calibrated, spec=spec, blocked=lambda t: t > 0.3)
    with pytest.raises(CorrectionError) as ei:
        correct_while_settling(cell.robot_device(), cell.stream_device(), model, target, q,
                               SettlingSettings(max_gap_s=0.5), payload_kg=36.0)
    assert ei.value.reason == "sensor:line_of_sight"
    assert ei.value.result.breaks[0][0] == pytest.approx(0.3, abs=0.01)


def test_the_iterative_loop_runs_on_the_same_twin(calibrated):
    """The thesis's stop–measure–move loop (``correct_6dof``) on the dynamic twin: a move
    waits for the interpolation and the settling time; a reading averages the stream."""
    cell, model, target, q = _setup(calibrated)
    robot, sensor = StopAndGoRobot(cell, settle_s=1.0), AveragingSensor(cell)
    t_move = robot.move_joints(q)
    assert t_move > 1.0
    res = correct_6dof(robot, sensor, model, target, CorrectionSettings(), payload_kg=36.0)
    assert res.converged
    moved = [st for st in res.steps if st.move is not None]
    assert all(st.move_time_s >= 0.3 for st in moved)
    assert all(st.measure_elapsed_s >= 0.05 for st in res.steps)
