"""The digital twin: deterministic truth, physics cross-checked, magnitudes as the thesis."""

from __future__ import annotations

import json

import numpy as np
import pytest

from plugcell.apps.cli import main
from plugcell.io.measurements import read_measurements
from plugcell.kinematics import forward, manipulator_jacobian
from plugcell.sim.twin.campaign import measure_poses, working_volume_joints
from plugcell.sim.twin.physics import Payload, gravity_torques
from plugcell.sim.twin.report import error_budget
from plugcell.sim.twin.robot import RobotTwin, true_flange_poses
from plugcell.sim.twin.scenario import ScenarioError, TwinScenario, make_truth
from plugcell.sim.twin.tracker import LaserTracker


@pytest.fixture(scope="module")
def truth():
    return make_truth(TwinScenario(seed=3))


@pytest.fixture(scope="module")
def joints(truth):
    rng = np.random.default_rng(11)
    return working_volume_joints(truth.description, truth.profile, 40, rng)


def test_truth_is_deterministic_and_hidden_errors_have_thesis_size(truth):
    again = make_truth(TwinScenario(seed=3))
    np.testing.assert_array_equal(truth.params.to_vector(), again.params.to_vector())
    other = make_truth(TwinScenario(seed=4))
    assert not np.allclose(truth.params.to_vector(), other.params.to_vector())
    nominal = truth.description.nominal_parameters()
    dd = np.abs(truth.params.d - nominal.d)
    da = np.abs(truth.params.a - nominal.a)
    assert 1e-4 < np.max(np.r_[dd, da]) < 5e-3  # ~1 mm lengths (Table 8-4)
    dal = np.abs(truth.params.alpha - nominal.alpha)
    assert 1e-4 < np.max(dal) < np.deg2rad(0.5)  # ~0.1° angles


def test_scenario_json_round_trip_and_errors():
    sc = TwinScenario(robot="smart_h4", seed=9, payload_kg=18.0)
    assert TwinScenario.from_json(sc.to_json()) == sc
    with pytest.raises(ScenarioError, match="unknown scenario keys"):
        TwinScenario.from_json('{"robot": "smart_h4", "colour": "red"}')
    with pytest.raises(ScenarioError, match="payload_kg must be"):
        TwinScenario(payload_kg=-1)
    with pytest.raises(ScenarioError):
        make_truth(TwinScenario(robot="no_such_robot"))


def test_payload_torques_equal_jacobian_transpose_wrench(truth, joints):
    """Virtual work through the exact loop closure == τ = Jᵀ W of thesis eq. (6.35).

    With only a payload (link masses removed by subtracting the unloaded torques),
    the torque the twin computes must equal Jᵀ of the payload's wrench at the
    flange — an independent check of the twin's torques *and* of the manipulator
    Jacobian through the parallelogram (6.37, 6.39).
    """
    desc, params = truth.description, truth.params
    q = joints[:10]
    payload = Payload(36.0, (0.15, 0.0, 0.10))
    tau = gravity_torques(desc, params, q, payload) - gravity_torques(desc, params, q, Payload())
    fk = forward(desc, params, q, closure="fourbar")
    J = manipulator_jacobian(desc, params, q, point="flange", closure="fourbar")
    F = np.array([0.0, 0.0, -9.81 * payload.mass])
    r = fk.flange[:, :3, :3] @ np.array(payload.com)
    W = np.concatenate([np.broadcast_to(F, r.shape), np.cross(r, F)], axis=-1)
    expected = np.einsum("nki,nk->ni", J, W)
    np.testing.assert_allclose(tau, expected, rtol=1e-6, atol=1e-5)


def test_deflection_pulls_the_arm_down(truth, joints):
    q = joints[:20]
    light = true_flange_poses(truth, q, Payload(), bend=False)
    heavy = true_flange_poses(truth, q, Payload(36.0, (0.15, 0.0, 0.10)), bend=False)
    dz = heavy[:, 2, 3] - light[:, 2, 3]
    assert np.all(dz < 0), "a payload must lower the flange"


def test_readings_are_encoder_counts_and_moves_repeat_within_resolution(truth, joints):
    twin = RobotTwin(truth, seed=1)
    res = truth.profile.encoder_resolution
    readings = twin.move_joints(joints[0] + 1.234e-5)
    np.testing.assert_allclose(readings / res, np.round(readings / res), atol=1e-6)
    points = []
    for _ in range(30):
        twin.move_joints(joints[0])
        points.append(twin.true_flange()[:3, 3])
    spread = np.std(points, axis=0)
    assert np.all(spread > 1e-6) and np.all(spread < 5e-5)  # ~0.02 mm: resolution ~0.05 mm


def test_error_budget_matches_thesis_magnitudes():
    """Thesis 8.2: nominal mean ≈ 4 mm; payload deflection ≈ 0.5 / 1.0 mm (Fig. 8-6)."""
    b = error_budget(TwinScenario(seed=0), poses=150)
    assert 2.5 < b.nominal_mean_mm < 6.0
    assert 0.3 < b.deflection_18kg_mm < 0.8
    assert 0.6 < b.deflection_36kg_mm < 1.5
    assert b.deflection_36kg_mm == pytest.approx(2 * b.deflection_18kg_mm, rel=0.1)
    assert 0.08 < b.bending_share_36kg < 0.35
    assert 0.005 < b.repeatability_sigma_mm < 0.04


def test_campaign_measures_the_truth_within_tracker_noise(joints):
    truth = make_truth(TwinScenario(seed=3, noise=False, backlash=False))
    twin = RobotTwin(truth, seed=2)
    tracker = LaserTracker(seed=5)
    data, sim_s = measure_poses(twin, tracker, joints[:12])
    assert len(data) == 12 and sim_s > 12
    # The same joints through the truth: measurements agree to tracker noise (well
    # under 0.1 mm), and disagree with the nominal model by millimetres.
    true_pts = (truth.base @ true_flange_poses(truth, data.joints) @ truth.probe)[:, :3, 3]
    err = np.linalg.norm(data.positions - true_pts, axis=1)
    assert err.max() < 1e-4
    desc = truth.description
    nominal_pts = (truth.base @ forward(desc, desc.nominal_parameters(), data.joints).flange
                   @ truth.probe)[:, :3, 3]
    assert np.linalg.norm(data.positions - nominal_pts, axis=1).mean() > 1e-3


def test_cli_twin_report_json(capsys):
    assert main(["twin", "report", "--json", "--poses", "40"]) == 0
    out = json.loads(capsys.readouterr().out)
    for key in ("nominal_mean_mm", "nominal_max_mm", "deflection_18kg_mm", "deflection_36kg_mm"):
        assert isinstance(out[key], float)


def test_cli_twin_measure_writes_a_measurement_file(tmp_path, capsys):
    out = tmp_path / "cal.csv"
    assert main(["twin", "measure", "--poses", "5", "--payload-kg", "18", "--seed", "2",
                 "--out", str(out), "--quiet"]) == 0
    m = read_measurements(out, n_joints=6)
    assert len(m) == 5 and m.has_orientation
    np.testing.assert_allclose(m.payload_kg, 18.0)
    capsys.readouterr()
    old = tmp_path / "old.csv"  # --payload-kg's old name still works, and says it is old
    assert main(["twin", "measure", "--poses", "5", "--payload", "18", "--seed", "2",
                 "--out", str(old), "--quiet"]) == 0
    assert old.read_bytes() == out.read_bytes()
    assert "plugcell: warning: --payload is deprecated: use --payload-kg" in capsys.readouterr().err


def test_cli_twin_measure_temperature_sweep_writes_the_column_the_thermal_term_needs(tmp_path):
    """--temperature-c FROM:TO: the hall warms linearly over the campaign, the twin's arm
    lengthens with it (κ = 12e-6/K: 12 µm per metre and kelvin) and the file says the
    temperature of each pose (issue 39: calibrate --thermal had no command writing it)."""
    hot, cold = tmp_path / "hot.csv", tmp_path / "cold.csv"
    base = ["twin", "measure", "--poses", "4", "--quiet", "--seed", "1"]
    assert main([*base, "--temperature-c", "18:30", "--out", str(hot)]) == 0
    assert main([*base, "--out", str(cold)]) == 0
    h, c = read_measurements(hot, n_joints=6), read_measurements(cold, n_joints=6)
    np.testing.assert_allclose(h.temperature_c, [18.0, 22.0, 26.0, 30.0])
    assert c.temperature_c is None
    np.testing.assert_allclose(h.joints, c.joints)
    # the same poses further out when hotter: up to ~0.1 mm at 10 K for a 3 m reach
    d = np.linalg.norm(h.positions - c.positions, axis=1)
    assert d[0] < d[-1] and 0.05e-3 < d[-1] < 0.5e-3


def test_cli_twin_nests_drift_with_the_hall_temperature(tmp_path, capsys):
    """twin nests → drift register → drift check: no drift at the reference temperature,
    an alarm (exit 1) when the hall is 6 K warmer (BASE moved ~0.1 mm)."""
    params = tmp_path / "params.json"
    cal = tmp_path / "cal.csv"
    assert main(["twin", "measure", "--poses", "40", "--out", str(cal), "--quiet"]) == 0
    assert main(["calibrate", "--robot", "smart_h4", "--model", "1", "--data", str(cal),
                 "--out", str(params), "--quiet"]) == 0
    ref, at20, at26 = (tmp_path / f for f in ("ref.csv", "n20.csv", "n26.csv"))
    assert main(["twin", "nests", "--out", str(tmp_path / "n.csv")]) == 0
    assert main(["drift", "register", "--params", str(params), "--measured",
                 str(tmp_path / "n.csv"), "--out", str(ref)]) == 0
    assert main(["twin", "nests", "--temperature-c", "20", "--out", str(at20)]) == 0
    assert main(["twin", "nests", "--temperature-c", "26", "--out", str(at26)]) == 0
    capsys.readouterr()
    assert main(["drift", "check", "--params", str(params), "--nests", str(ref),
                 "--measured", str(at20)]) == 0
    assert ": ok" in capsys.readouterr().out
    assert main(["drift", "check", "--params", str(params), "--nests", str(ref),
                 "--measured", str(at26)]) == 1
    assert "ALARM" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["twin", "measure", "--poses", "0", "--out", "x.csv"], "--poses must be positive"),
        (["twin", "measure", "--poses", "3", "--payload-kg", "-2", "--out", "x.csv"],
         "--payload-kg must be a mass"),
        (["twin", "measure", "--robot", "nope", "--poses", "3", "--out", "x.csv"], "nope"),
        (["twin", "report", "--poses", "3"], "--poses must be at least 10"),
        (["twin", "measure", "--poses", "3", "--temperature-c", "293", "--out", "x.csv"],
         "a value in kelvin?"),
        (["twin", "measure", "--poses", "3", "--temperature-c", "20:x", "--out", "x.csv"],
         "--temperature-c must be T or FROM:TO"),
        (["twin", "nests", "--temperature-c", "nan", "--out", "x.csv"],
         "--temperature-c must be T or FROM:TO"),
    ],
)
def test_cli_twin_errors(argv, message, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    assert message in capsys.readouterr().err


def test_backlash_shows_on_reversal_except_where_gravity_preloads_the_gear(joints):
    truth = make_truth(TwinScenario(seed=3, noise=False))
    twin = RobotTwin(truth)
    q = joints[0]
    lost = truth.profile.lost_motion
    step = np.zeros_like(q)
    step[-1] = 0.01  # joint 6: light load, backlash shows
    twin.move_joints(q - step)
    twin.move_joints(q)
    from_below = twin.true_flange()
    twin.move_joints(q + step)
    twin.move_joints(q)
    from_above = twin.true_flange()
    turn = np.arccos(np.clip((np.trace(from_below[:3, :3] @ from_above[:3, :3].T) - 1) / 2, -1, 1))
    assert turn == pytest.approx(lost, rel=0.05)
    step = np.zeros_like(q)
    step[1] = 0.01  # joint 2 carries the arm: the gear stays on one flank
    twin.move_joints(q - step)
    twin.move_joints(q)
    a = twin.true_flange()
    twin.move_joints(q + step)
    twin.move_joints(q)
    np.testing.assert_allclose(twin.true_flange(), a, atol=1e-12)


def test_the_flange_asked_again_at_rest_is_the_physics_after_every_change(truth, joints):
    """``true_flange`` remembers its last pose: asked again with nothing changed it is the
    same; after a new state, a new payload or a temperature it is the physics of the new
    state; a caller writing into the pose it got changes nothing."""
    from plugcell.sim.twin.thermal import ThermalDrift

    twin = RobotTwin(truth, seed=5)
    for k, payload in ((0, 0.0), (1, 0.0), (1, 20.0), (2, 20.0)):
        reached = joints[k] + 1e-4
        twin.set_payload(payload)
        twin.follow(joints[k], reached)
        physics = true_flange_poses(truth, reached, twin.payload)
        got = twin.true_flange()
        np.testing.assert_array_equal(got, physics)
        got[:3, 3] += 1.0  # the caller's copy
        np.testing.assert_array_equal(twin.true_flange(), physics)
    assert not np.allclose(true_flange_poses(truth, joints[1] + 1e-4, Payload(20.0)),
                           true_flange_poses(truth, joints[1] + 1e-4, Payload()))
    drift = ThermalDrift()
    twin.set_thermal_drift(drift, 25.0)
    warm = twin.true_flange()
    np.testing.assert_allclose(warm[:3, 3], physics[:3, 3] * drift.length_scale(25.0),
                               rtol=0, atol=1e-15)
    assert np.linalg.norm(warm[:3, 3] - physics[:3, 3]) > 1e-6
