"""The twin's thermal drift (issue 19 §3): BASE and the arm's lengths follow the
temperature; the drift watch recovers BASE from nests measured by the twin tracker."""

from __future__ import annotations

import numpy as np
import pytest

from plugcell.metrology.drift import estimate_base_drift, nests_in_base
from plugcell.sim.twin.robot import RobotTwin
from plugcell.sim.twin.scenario import TwinScenario
from plugcell.sim.twin.thermal import ThermalDrift, shift_temperature
from plugcell.sim.twin.tracker import LaserTracker

NESTS = np.array([[1.0, -1.3, 0.0], [2.4, 0.2, 0.05], [1.2, 1.5, 0.0], [0.3, -0.2, 0.4]])


def test_shift_profile_warms_up_and_dips_at_the_gate():
    t = shift_temperature([0.0, 3.9, 4.2, 8.0])
    assert t[0] == 20.0 and 25.0 < t[1] < 26.0 and t[2] < t[1] - 1.0 and t[3] > 25.5


def test_temperature_moves_base_and_scales_the_arm():
    robot = RobotTwin(TwinScenario(seed=0))
    T0 = robot.true_reflector_in_tracker()
    F0 = robot.true_flange()
    drift = ThermalDrift()
    robot.set_thermal_drift(drift)
    np.testing.assert_allclose(robot.true_reflector_in_tracker(), T0, atol=1e-15)
    robot.set_temperature(25.0)
    np.testing.assert_allclose(robot.true_flange()[:3, 3], F0[:3, 3] * (1 + 5 * 12e-6),
                               atol=1e-15)
    B = robot.true_base()
    np.testing.assert_allclose(B, drift.base_drift(25.0) @ robot.reveal_truth().base,
                               atol=1e-15)
    np.testing.assert_allclose(robot.true_reflector_in_tracker(),
                               B @ robot.true_flange() @ robot.reveal_truth().probe, atol=1e-15)
    with pytest.raises(ValueError, match="finite"):
        robot.set_temperature(float("nan"))


def test_watch_recovers_the_twin_base_from_tracker_measurements():
    robot = RobotTwin(TwinScenario(seed=1))
    robot.set_thermal_drift(ThermalDrift(), 20.0)
    tracker = LaserTracker(seed=1)

    def measure() -> np.ndarray:
        out = []
        for p in NESTS:
            true = robot.true_point_in_tracker(p)
            tracker.point_at(true)
            out.append(tracker.measure(true, 1.0, mode="3dof").position)
        return np.array(out)

    B0 = robot.true_base()
    nests = nests_in_base(B0, measure())
    robot.set_temperature(26.0)
    est = estimate_base_drift(B0, nests, measure(), threshold_m=0.05e-3)
    assert est.alarm and est.consistent
    true_move = max(np.linalg.norm(robot.true_point_in_tracker(p) - B0[:3, :3] @ p - B0[:3, 3])
                    for p in NESTS)
    assert est.displacement_m == pytest.approx(true_move, abs=0.03e-3)
    p = robot.true_point_in_tracker(NESTS[0])
    assert np.linalg.norm(est.base[:3, :3] @ NESTS[0] + est.base[:3, 3] - p) < 0.03e-3
