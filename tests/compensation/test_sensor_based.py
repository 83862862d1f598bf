"""Sensor-based correction (6.5.2): the 6-DOF and 3-DOF loops on the twin and on fakes."""

from __future__ import annotations

import math

import numpy as np
import pytest

from plugcell.compensation import (
    CartesianRobot,
    CorrectionError,
    CorrectionSettings,
    IdentifiedModel,
    JointRobot,
    MetrologyFrames,
    NominalModel,
    PoseSensor,
    PositionSensor,
    Reading,
    RobotFrameSensor,
    SensorError,
    compensate,
    correct_3dof,
    correct_6dof,
    nominal_joints,
)
from plugcell.kinematics.pose_error import pose_error_exact
from plugcell.kinematics.rotations import zyz_to_matrix
from plugcell.sim.twin.robot import RobotTwin
from plugcell.sim.twin.tracker import LaserTracker
from plugcell.sim.twin_cell import TwinCell


def _cell(calibrated, seed: int = 5):
    robot = RobotTwin(calibrated.scenario, seed=seed)
    cell = TwinCell(robot, LaserTracker(seed=calibrated.scenario.seed))
    model = IdentifiedModel(calibrated.result.model)
    frames = MetrologyFrames(model.base, model.probe)
    return cell, model, frames


def _target(model, x=1.5, y=0.2, z=1.0):
    T = np.eye(4)
    T[:3, :3] = zyz_to_matrix(0.0, math.pi / 2, 0.0) @ model.probe[:3, :3]
    T[:3, 3] = [x, y, z]
    return T


def _start_at_nominal(cell, model, T):
    q, ok, _ = nominal_joints(model, T[None], cell.robot.description.home)
    assert ok.all()
    cell.move(q[0])
    cell.catch_beam()
    return q[0]


def test_twin_devices_implement_the_protocols(calibrated):
    cell, model, frames = _cell(calibrated)
    robot = cell.robot_device(model.tool)
    sensor = RobotFrameSensor(cell.tracker_device(), frames)
    assert isinstance(robot, JointRobot) and isinstance(robot, CartesianRobot)
    assert isinstance(sensor, PoseSensor) and isinstance(sensor, PositionSensor)


def test_6dof_loop_converges_on_the_twin_and_records_every_iteration(calibrated):
    cell, model, frames = _cell(calibrated)
    T = _target(model)
    _start_at_nominal(cell, model, T)  # ~4 mm off: the loop has work to do
    sensor = RobotFrameSensor(cell.tracker_device(), frames)
    s = CorrectionSettings(overhead_s=0.5)
    res = correct_6dof(cell.robot_device(model.tool), sensor, model, T, s, payload_kg=36.0)
    assert res.converged and res.reason == ""
    assert res.iterations >= 1 and res.measurements == res.iterations + 1
    first, last = res.steps[0], res.steps[-1]
    assert first.position_error_m > 1e-3  # started from the nominal error
    assert last.position_error_m < s.position_tol_m
    assert last.orientation_error_rad < s.orientation_tol_rad
    assert last.move is None and all(st.move is not None for st in res.steps[:-1])
    for st in res.steps:
        assert st.measure_duration_s == pytest.approx(0.05)
        assert st.measure_elapsed_s >= 0.05
    times = [st.measure_elapsed_s + st.move_time_s + st.overhead_s for st in res.steps]
    assert res.time_s == pytest.approx(sum(times))
    # the final 50 ms reading agrees with a 1 s verification within the thresholds
    check = sensor.measure_pose(1.0)
    e = pose_error_exact(T, check.pose)
    assert np.linalg.norm(e[:3]) < 0.12e-3
    d = res.as_dict()
    assert d["iterations"] == res.iterations and len(d["steps"]) == res.measurements


def test_model_stage_reduces_the_tracker_iterations(calibrated):
    """From the model-compensated joints the loop needs fewer moves than from nominal."""
    its = {}
    for stage in ("nominal", "model"):
        cell, model, frames = _cell(calibrated, seed=9)
        T = _target(model, x=1.7, y=-0.4, z=1.2)
        q_nom = _start_at_nominal(cell, model, T)
        if stage == "model":
            cell.move(compensate(model, T[None], 36.0).q[0])
        sensor = RobotFrameSensor(cell.tracker_device(), frames)
        res = correct_6dof(cell.robot_device(), sensor, model, T, payload_kg=36.0)
        its[stage] = res.iterations
        assert res.converged
        assert q_nom is not None
    assert its["model"] < its["nominal"]


def test_iteration_cap_raises_with_the_record(calibrated):
    cell, model, frames = _cell(calibrated)
    T = _target(model)
    _start_at_nominal(cell, model, T)
    sensor = RobotFrameSensor(cell.tracker_device(), frames)
    with pytest.raises(CorrectionError) as ei:
        correct_6dof(cell.robot_device(), sensor, model, T,
                     CorrectionSettings(max_iterations=0), payload_kg=36.0)
    err = ei.value
    assert err.reason == "max_iterations"
    assert err.result is not None and err.result.measurements == 1
    assert not err.result.converged and err.result.iterations == 0


def test_beam_lost_raises_a_correction_error_with_the_reason(calibrated):
    cell, model, frames = _cell(calibrated)
    T = _target(model)
    _start_at_nominal(cell, model, T)
    sensor = RobotFrameSensor(cell.tracker_device(), frames)
    cell.tracker.block_line_of_sight(True)
    with pytest.raises(CorrectionError) as ei:
        correct_6dof(cell.robot_device(), sensor, model, T, payload_kg=36.0)
    assert ei.value.reason == "sensor:line_of_sight"
    assert ei.value.result is not None and ei.value.result.measurements == 0
    assert isinstance(ei.value.__cause__, SensorError)


def test_beam_never_pointed_is_reported(calibrated):
    cell, model, frames = _cell(calibrated)
    T = _target(model)
    q, _, _ = nominal_joints(model, T[None])
    cell.robot.move_joints(q[0])  # no catch_beam: the tracker was never pointed
    with pytest.raises(CorrectionError) as ei:
        correct_6dof(cell.robot_device(), RobotFrameSensor(cell.tracker_device(), frames),
                     model, T)
    assert ei.value.reason == "sensor:not_pointed"


def test_3dof_loop_on_the_twin(calibrated):
    cell, model, frames = _cell(calibrated)
    T = _target(model, x=1.4, y=0.5, z=0.9)
    _start_at_nominal(cell, model, T)
    sensor = RobotFrameSensor(cell.tracker_device(), frames)
    res = correct_3dof(cell.robot_device(model.tool), sensor, T[:3, 3])
    assert res.converged and res.mode == "3dof"
    assert res.iterations >= 1
    assert res.steps[0].position_error_m > 1e-3
    assert res.steps[-1].position_error_m < 0.08e-3
    assert all(math.isnan(st.orientation_error_rad) for st in res.steps)
    for st in res.steps[:-1]:  # the relative move is the measured Δp
        np.testing.assert_allclose(st.move, st.error)


# ----------------------------------------------------------------------------- fakes
class _FakeRobot:
    """A robot whose joints act 20 % weaker than the model's Jacobian says (the loop
    must iterate), with a nominal-model pose as the truth."""

    def __init__(self, model: NominalModel, q0: np.ndarray, gain: float = 0.8):
        self.model, self.q, self.gain = model, q0.copy(), gain
        self.moves = 0

    def read_joints(self):
        return self.q.copy()

    def move_joints(self, q):
        self.q = self.q + self.gain * (np.asarray(q) - self.q)
        self.moves += 1
        return 0.25

    def pose(self):
        return self.model.pose(self.q)[0]


class _FakeSensor:
    def __init__(self, robot: _FakeRobot):
        self.robot = robot
        self.fail_after: int | None = None
        self.calls = 0

    def measure_pose(self, duration_s):
        self.calls += 1
        if self.fail_after is not None and self.calls > self.fail_after:
            raise SensorError("beam broken", reason="line_of_sight")
        T = self.robot.pose()
        return Reading(T[:3, 3].copy(), T, duration_s, duration_s + 0.01)


def test_fake_devices_loop_contracts_by_the_gain(h4, workspace_q):
    model = NominalModel(h4)
    q0 = workspace_q[0]
    target = model.pose(q0 + np.radians([0.1, -0.1, 0.1, 0.2, -0.2, 0.1]))[0]
    robot = _FakeRobot(model, q0)
    res = correct_6dof(robot, _FakeSensor(robot), model, target,
                       CorrectionSettings(duration_s=0.05, overhead_s=0.1))
    assert res.converged
    errs = [st.position_error_m for st in res.steps]
    ratios = np.array(errs[1:]) / np.array(errs[:-1])
    assert np.all(ratios < 0.3)  # ≈ 0.2 per move: 1 − gain
    assert res.iterations == robot.moves >= 3
    assert res.time_s == pytest.approx(res.measurements * 0.06 + res.iterations * (0.25 + 0.1))


def test_fake_sensor_failure_midway_keeps_the_steps(h4, workspace_q):
    model = NominalModel(h4)
    q0 = workspace_q[1]
    target = model.pose(q0 + np.radians([0.2, 0, 0, 0, 0, 0]))[0]
    robot = _FakeRobot(model, q0)
    sensor = _FakeSensor(robot)
    sensor.fail_after = 2
    with pytest.raises(CorrectionError) as ei:
        correct_6dof(robot, sensor, model, target)
    assert ei.value.reason == "sensor:line_of_sight"
    assert ei.value.result.measurements == 2 and ei.value.result.iterations == 2


def test_joint_limit_is_refused_before_moving(h4):
    model = NominalModel(h4)
    q0 = np.array([h4.joint_limits[0, 1] - 1e-4, -1.4, -2.6, 0.1, 1.2, 0.2])
    target = model.pose(q0 + np.array([1e-3, 0, 0, 0, 0, 0]))[0]
    robot = _FakeRobot(model, q0)
    with pytest.raises(CorrectionError) as ei:
        correct_6dof(robot, _FakeSensor(robot), model, target)
    assert ei.value.reason == "joint_limit" and robot.moves == 0


def test_robot_failure_is_reported(h4, workspace_q):
    model = NominalModel(h4)

    class Broken(_FakeRobot):
        def move_joints(self, q):
            raise RuntimeError("servo fault")

    q0 = workspace_q[2]
    robot = Broken(model, q0)
    target = model.pose(q0 + np.radians([0.2, 0, 0, 0, 0, 0]))[0]
    with pytest.raises(CorrectionError) as ei:
        correct_6dof(robot, _FakeSensor(robot), model, target)
    assert ei.value.reason == "robot" and "servo fault" in str(ei.value)


def test_settings_validation():
    with pytest.raises(ValueError):
        CorrectionSettings(position_tol_m=0.0)
    with pytest.raises(ValueError):
        CorrectionSettings(duration_s=0.0)
    with pytest.raises(ValueError):
        CorrectionSettings(max_iterations=-1)
