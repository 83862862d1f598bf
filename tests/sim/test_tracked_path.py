"""Dynamic path correction on the twin (issue 38): the closed loop in one process
(sim/tracked_path.py) and the same correction source through the real RSI link over UDP."""

from __future__ import annotations

import numpy as np
import pytest

from plugcell.compensation.tracking import (
    InverseSettings,
    IterativeLearning,
    LearningSettings,
    TrackingSettings,
)
from plugcell.devices.robot.rsi import RsiConfig
from plugcell.devices.robot.rsi.tracking import (
    check_tracking_config,
    kuka_pose,
    path_pose,
)
from plugcell.kinematics.rotations import matrix_to_rpy
from plugcell.sim import tracked_path
from plugcell.sim.tracked_path import CYCLE, Fault, TrackedCell, learn
from plugcell.sim.tracked_udp import run_over_udp

#: simulated cycles in Python: minutes on a loaded 2-core machine
pytestmark = [pytest.mark.slow, pytest.mark.timeout(1500)]


@pytest.fixture(scope="module")
def cell():
    return TrackedCell(seed=0, calibration_poses=60)


def _perp(run):
    w = (run.t >= run.motion[0]) & (run.t <= run.motion[1] + 0.2)
    rel = run.true_pose[w, :3, 3] - run.path_pose[0, :3, 3]
    return np.hypot(rel[:, 0], rel[:, 2])  # the line runs along y


def test_path_pose_removes_the_offset_the_setpoint_carries():
    rng = np.random.default_rng(0)
    for _ in range(5):
        p = np.r_[rng.normal(size=3), rng.uniform(-0.5, 0.5, 3)]
        o = np.r_[1e-3 * rng.normal(size=3), 1e-3 * rng.normal(size=3)]
        Tp = kuka_pose(p)
        Ro = kuka_pose(np.r_[0, 0, 0, o[3:]])[:3, :3]
        Tset = Tp.copy()
        Tset[:3, 3] += o[:3]
        Tset[:3, :3] = Ro @ Tp[:3, :3]
        roll, pitch, yaw = matrix_to_rpy(Tset[:3, :3])
        back = path_pose(np.r_[Tset[:3, 3], yaw, pitch, roll], o)
        np.testing.assert_allclose(back, Tp, atol=1e-12)


def test_the_source_refuses_a_link_it_cannot_drive():
    cfg = RsiConfig(robot_host="127.0.0.1", correction="cartesian", mode="relative")
    with pytest.raises(ValueError, match="absolute Cartesian"):
        check_tracking_config(cfg)


def test_on_the_twin_the_tracker_lowers_what_the_model_leaves(cell):
    traj = cell.plan("line", 250.0, size_m=0.3)
    s = TrackingSettings(lead_s=0.008)
    model = cell.run(traj, "model", settings=s)
    tracked = cell.run(traj, "tracking", settings=s)
    pm, pt = _perp(model), _perp(tracked)
    assert pt.mean() + 3 * pt.std() < pm.mean() + 3 * pm.std()
    assert tracked.windows == [] and tracked.clamped == 0
    st = tracked.stats
    assert st.samples_bad == 0 and st.fresh_cycles > 0.9 * st.cycles


def test_without_the_tracker_term_the_replayed_stream_is_the_live_one(cell, monkeypatch):
    """Runs that do not feed the samples back compute the true poses at the end and
    replay the stream over them: the same poses and samples as cycle by cycle."""
    traj = cell.plan("line", 250.0, size_m=0.05)
    s = TrackingSettings(lead_s=0.008)
    replayed = cell.run(traj, "model", settings=s)
    init = tracked_path._Simulation.__init__

    def live(self, *args, **kwargs):
        init(self, *args, **kwargs)
        self.live = True

    monkeypatch.setattr(tracked_path._Simulation, "__init__", live)
    direct = cell.run(traj, "model", settings=s)
    np.testing.assert_allclose(replayed.true_pose, direct.true_pose, rtol=0, atol=1e-12)
    assert [m.time_s for m in replayed.measurements] == [m.time_s for m in direct.measurements]
    np.testing.assert_allclose([m.pose for m in replayed.measurements if m.ok],
                               [m.pose for m in direct.measurements if m.ok], rtol=0, atol=1e-12)
    assert len(replayed.samples) == len(direct.samples) > 0


def test_learning_from_the_trackers_samples_lowers_the_error_of_the_next_run(cell):
    """Iterative learning on the twin: the model's run, then one with the offset learned
    from its tracker samples (fresh noise) — the true error falls; nominal refuses it."""
    traj = cell.plan("line", 250.0, size_m=0.3)
    s = TrackingSettings(lead_s=0.008)
    model = cell.run(traj, "model", settings=s)
    learning = IterativeLearning(traj.duration, LearningSettings(lead_s=0.008))
    e = learn(learning, model)
    assert e.shape == learning.u.shape and learning.history[0]["measured"] > 0.9
    learned = cell.run(traj, "model", settings=s, learning=learning, stream_seed=7)
    pm, pl = _perp(model), _perp(learned)
    assert pl.mean() + 3 * pl.std() < 0.6 * (pm.mean() + 3 * pm.std())
    with pytest.raises(ValueError, match="needs the correction loop"):
        cell.run(traj, "nominal", learning=learning)


def test_the_learning_identifies_the_arms_modes_from_the_tracker_and_inverts_them(cell):
    """The model-inverting law on the twin: the model's run, the excited run (P-type
    update + the excitation), then a run learned with the plant identified from the two
    runs' tracker samples — the twin's first modes (9 and 12 Hz) are found, and the
    learned run's true error is well below the model's."""
    traj = cell.plan("line", 250.0, size_m=0.3)
    s = TrackingSettings(lead_s=0.008)
    learning = IterativeLearning(traj.duration, LearningSettings(
        lead_s=0.008, cutoff_hz=6.0, order=4, inverse=InverseSettings(modes=4)))
    model = cell.run(traj, "model", settings=s)
    learn(learning, model)
    assert learning.history[0]["excited"] == 1.0 and learning.plant is None
    excited = cell.run(traj, "model", settings=s, learning=learning, stream_seed=11)
    learn(learning, excited)
    assert learning.plant is not None and learning.history[1]["law"] == "inverse"
    f = learning.plant.frequency_hz
    assert np.min(np.abs(f - 9.0)) < 0.3 and np.min(np.abs(f - 12.0)) < 0.4
    learned = cell.run(traj, "model", settings=s, learning=learning, stream_seed=12)
    pm, pl = _perp(model), _perp(learned)
    assert pl.mean() + 3 * pl.std() < 0.5 * (pm.mean() + 3 * pm.std())


def test_a_beam_break_on_the_twin_holds_the_model_and_the_robot_never_jumps(cell):
    traj = cell.plan("line", 250.0, size_m=0.3)
    s = TrackingSettings(lead_s=0.008)
    run = cell.run(traj, "tracking", settings=s, faults=(Fault("beam_break", 0.3, 0.4),))
    assert len(run.windows) == 1
    w = run.windows[0]
    assert w.reason == "line_of_sight" and w.end_s is not None
    assert run.motion[0] + 0.3 <= w.start_s <= run.motion[0] + 0.3 + s.max_age_s + 2 * CYCLE
    # the offset sent moves at a bounded rate throughout (the model's ramp and lead plus
    # the tracker term's bounds), far below a jump
    step = np.abs(np.diff(run.offset[:, :3], axis=0)).max()
    assert step < 0.2e-3  # the link's 0.2 mm per cycle never reached
    held = np.array(run.state) == "holding"
    assert held.any() and run.weight[held].min() == 0.0


def test_the_same_source_corrects_the_twin_through_the_rsi_link_over_udp(cell):
    """Real sockets and real time: RsiRobot runs the path in its thread, RsiLink asks the
    TrackingSource every cycle; the tracker here is the twin's true reflector (noise-free,
    from the controller's own log), added in the link's thread before each answer."""
    traj = cell.plan("line", 100.0, size_m=0.1)
    udp = run_over_udp(cell, traj, lead_s=0.012)
    robot, loop, source, config = udp.robot, udp.loop, udp.source, udp.config
    assert robot.path_done and robot.stopped is None
    assert loop.stats.samples_used > 0 and loop.stats.fresh_cycles > 0
    assert source.last is not None and source.last.state == "tracking"
    assert loop.windows == []  # a sample every cycle: never stale
    # the controller's offset never stepped beyond the link's bound, whatever the load: one
    # bound a cycle — after m answers missed in a row (absolute mode keeps the offset) the
    # next answer carries up to m + 1 cycles' steps
    log = robot.stats().log
    applied = np.array([entry[3] for entry in log])
    missed, run = np.zeros(len(log)), 0
    for i, entry in enumerate(log):
        missed[i], run = run, (0 if entry[4] else run + 1)
    bound = np.array(config.limits.step_bound(CYCLE))
    allowed = np.outer(missed[1:] + 1, bound)
    assert np.all(np.abs(np.diff(applied, axis=0)) <= allowed * (1 + 1e-9) + 1e-9)
