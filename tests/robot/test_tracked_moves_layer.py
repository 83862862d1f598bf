"""A calibration's learned residual layer in the robot service (``--param
calibration=PARAMS.json`` naming a layer): :func:`read_calibration` loads it as
``plugcell compensate`` does, the tracked moves predict with the hybrid model and
``CORRECT compensation`` compensates with it; a layer that cannot be used is refused
with the reason.

On the twin over UDP (the link in its child process, simulated time; the pieces of
tests/robot/test_tracked_moves_learning.py): a move whose beam is blocked throughout runs
on the model alone, once with the calibration's physical model and once with its layer;
the true end moves between the two by what the offline compensation predicts
(``compensate_joints`` — ``plugcell compensate``'s solver — with and without the layer).
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from test_tracked_moves_learning import cell  # noqa: F401  (the fixture)

from plugcell.calibration.data import CalibrationData
from plugcell.calibration.identify import Calibrator
from plugcell.calibration.residual_model import ResidualLearner
from plugcell.compensation import IdentifiedModel, compensate_joints
from plugcell.devices.robot.arm_model import matrix_from_position, position_from_tcp
from plugcell.devices.robot.calibration_file import read_calibration
from plugcell.devices.robot.tracked_moves import TrackedMoves
from plugcell.io.params import params_json
from plugcell.io.residual_models import residual_path, save_residual
from plugcell.kinematics import forward
from plugcell.sim.twin.campaign import measure_poses, working_volume_joints
from plugcell.sim.twin.robot import RobotTwin
from plugcell.sim.twin.scenario import TwinScenario
from plugcell.sim.twin.tracker import LaserTracker

pytestmark = pytest.mark.timeout(1200)

#: The systematic error the layer is taught on top of the twin's residual (base frame, m):
#: a layer whose correction at the move is large against the runs' scatter.
SHIFT_M = np.array([0.0, 0.0, 3e-4])


@pytest.fixture(scope="module")
def hybrid(tmp_path_factory):
    """The twin of ``cell`` (seed 0, 36 kg) calibrated with model 5 from 220 poses of its
    working volume and 60 around home, and a learned layer on the same campaign with the
    measurements shifted by :data:`SHIFT_M`; its PARAMS.json and side file, as ``plugcell
    calibrate --residual-model learned`` writes them."""
    twin = RobotTwin(TwinScenario(robot="smart_h4", seed=0, payload_kg=36.0))
    desc = twin.description
    q = working_volume_joints(desc, twin.reveal_truth().profile, 220,
                              np.random.default_rng(1))
    home = np.asarray(desc.home, float)
    q = np.vstack([q, home + np.random.default_rng(2).normal(0.0, 0.08, (60, 6))])
    ms, _ = measure_poses(twin, LaserTracker(seed=0), q)
    result = Calibrator(desc, 5).fit(ms)
    data = CalibrationData.from_measurements(ms)
    shifted = dataclasses.replace(data, positions=data.positions
                                  + result.model.base()[:3, :3] @ SHIFT_M)
    layer = ResidualLearner(grid=({"max_leaf_nodes": 15, "min_samples_leaf": 10},),
                            trees=40).fit(result.model, shifted, robot=desc.name)
    folder = tmp_path_factory.mktemp("hybrid")
    path = folder / "params.json"
    entry = save_residual(layer, residual_path(path))
    path.write_text(params_json(result.with_residual_model(layer), residual_file=entry))
    return path


def test_read_calibration_loads_the_layer_and_refuses_one_it_cannot_use(hybrid, tmp_path):
    cal = read_calibration(str(hybrid), "smart_h4")
    assert cal.residual_model is not None
    moves = TrackedMoves(None, lambda name: None, calibration=cal,
                         calibration_name="params.json")
    assert moves.model_text == ("the calibrated model (params.json, 36 kg, with its learned "
                                "residual layer)")
    doc = json.loads(hybrid.read_text())
    doc["residual_model"]["sha256"] = "0" * 64
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(doc))
    (tmp_path / doc["residual_model"]["file"]).write_bytes(
        (hybrid.parent / doc["residual_model"]["file"]).read_bytes())
    with pytest.raises(ValueError, match=rf"calibration {bad}: its learned residual layer "
                       "cannot be used: "):
        read_calibration(str(bad))


@pytest.mark.slow
def test_the_layer_moves_the_model_based_end_as_compensate_predicts(cell, hybrid):  # noqa: F811
    arm, _, motion, feed = cell
    cal = read_calibration(str(hybrid), "smart_h4")
    em = cal.model
    desc = arm.twin.description
    fk = forward(desc, None, np.asarray(desc.home, float), "nominal")
    tool = np.linalg.inv(fk.flange) @ fk.tcp
    truth = arm.twin.reveal_truth()
    saved = feed.base, feed.probe, feed.to_tcp
    # the program set the tracker's BASE and PROBE to the calibration's
    feed.base, feed.base_inv = em.base(), np.linalg.inv(em.base())
    feed.to_tcp = np.linalg.inv(em.probe()) @ tool
    feed._truth = lambda: truth.base @ arm.true_flanges(arm.link[None])[0] @ truth.probe
    said: list[str] = []
    ends, starts = {}, {}
    try:
        T_b = forward(desc, None, motion.joint_readings(), "nominal").tcp
        T_b[:3, 3] += [0.0, 0.08, 0.0]
        target = position_from_tcp(T_b)
        T_target = matrix_from_position(target)
        start = position_from_tcp(forward(desc, None, motion.joint_readings(), "nominal").tcp)
        for name, c in (("physical", dataclasses.replace(cal, residual_model=None)),
                        ("hybrid", cal)):
            motion.move_to(start, linear=True)
            starts[name] = motion.joint_readings().copy()
            tracked = TrackedMoves(motion, lambda name: feed, settle_s=0.5, realtime=False,
                                   calibration=c, calibration_name="params.json",
                                   say=said.append)
            feed.blocked = (0.0, 1e9)
            tracked.move_tracked(target, "TRACKER")
            assert tracked.last_loop.state == "acquiring"  # the model alone throughout
            ends[name] = (feed.base_inv @ feed._truth() @ feed.to_tcp)[:3, 3]
    finally:
        feed.blocked = None
        feed.base, feed.probe, feed.to_tcp = saved
        feed.base_inv = np.linalg.inv(saved[0])
        del feed._truth
    # offline: the joints plugcell compensate gives the target with and without the layer,
    # and where the physical model puts the TCP at each (the change is millimetres' worth
    # of joints, where the physical model's error is a fraction of a per cent)
    m = em.payload_ref_kg
    phys = IdentifiedModel(em, tool)
    q0 = starts["hybrid"]
    q_p = compensate_joints(phys, T_target[None], q0, m).q
    q_h = compensate_joints(IdentifiedModel(em, tool, residual=cal.residual_model),
                            T_target[None], q0, m).q
    predicted = (phys.pose(q_h, m) - phys.pose(q_p, m))[0, :3, 3]
    measured = ends["hybrid"] - ends["physical"]
    print(f"\nthe layer's change of the model-based end (mm): predicted "
          f"{np.round(predicted * 1e3, 4)}, measured {np.round(measured * 1e3, 4)}; end "
          f"error physical {np.linalg.norm(ends['physical'] - T_target[:3, 3]) * 1e3:.4f} "
          f"mm, hybrid {np.linalg.norm(ends['hybrid'] - T_target[:3, 3]) * 1e3:.4f} mm")
    assert np.linalg.norm(predicted) > 0.1e-3, predicted  # the layer matters here
    assert np.linalg.norm(measured - predicted) < 0.25 * np.linalg.norm(predicted) + 20e-6, \
        (measured, predicted)
    assert "with its learned residual layer" in said[1] and "layer" not in said[0], said


def test_correct_compensation_follows_the_hybrid_model(hybrid):
    """``CORRECT compensation calibration=PARAMS.json`` of a calibration with a layer:
    cycle by cycle along a path near home (the layer's trained region), the offset becomes
    the hybrid model's compensation of the path's joints (``compensate_joints`` with the
    layer, as ``plugcell compensate``), not the physical model's."""
    from test_corrections import RSI_JOINT, _corrections, _state

    from plugcell.compensation import NominalModel
    from plugcell.devices.robot.stream.correcting import make_source

    cal = read_calibration(str(hybrid))
    spec = _corrections(RSI_JOINT, max_deg=1.0).spec(["compensation",
                                                      f"calibration={hybrid}", "ramp=0.1"])
    running = make_source(spec, RSI_JOINT)
    running.close()  # g computed here, cycle by cycle
    model = IdentifiedModel(cal.model, residual=cal.residual_model)
    nominal = NominalModel(model.description, tool=model.tool)
    m = cal.model.payload_ref_kg
    home = np.asarray(model.description.home, float)
    offset = np.zeros(6)
    for k in range(150):  # 0.6 s at 4 ms; the path turns A1 at 2 °/s
        q_path = home + np.radians([2.0 * 0.004 * k, 0, 0, 0, 0, 0])
        offset = running.goal_now(_state(q_path, offset, 0.004 * k))
    T_n = nominal.evaluate(q_path)[0]
    want = compensate_joints(model, T_n, q_path, m).q.reshape(-1) - q_path
    physical = compensate_joints(model.physical(), T_n, q_path, m).q.reshape(-1) - q_path
    assert model.in_domain(q_path[None], m)[0]
    assert np.max(np.abs(want - physical)) > np.radians(0.002)  # the layer matters here
    np.testing.assert_allclose(offset, want, atol=np.radians(2e-5))
