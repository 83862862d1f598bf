"""Frames a campaign cannot see (issue 36, part 1), on the digital twin.

A surface scan at constant tool orientation cannot tell the PROBE position from the BASE
position.  Before the fix (``null_tol=0`` is the old code path, bit for bit) the two
wandered along that direction by decimetres to metres; now they stay at their initial
values in it, one warning says so in words, PARAMS.json records it and export, compensate
and the validity region do not use it as if it were measured.  A campaign that varies
the orientation is unchanged.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from plugcell.apps.cli import main
from plugcell.calibration import CalibrationData, Calibrator
from plugcell.calibration.determinacy import (
    analyse_determinacy,
    orientation_spread,
    required_spread,
    with_probe,
)
from plugcell.calibration.initial import (
    InitialEstimateError,
    estimate_base_probe,
    estimate_base_probe_positions,
)
from plugcell.io.export import ExportError, export_calibration
from plugcell.io.measurements import write_measurements
from plugcell.io.params import (
    ParamsError,
    params_document,
    result_from_params,
    undetermined_from_document,
)
from plugcell.kinematics.rotations import matrix_to_angles
from plugcell.kinematics.transforms import so3_exp
from plugcell.sim.twin.campaign import (
    measure_poses,
    surface_scan_joints,
    working_volume_joints,
)
from plugcell.sim.twin.robot import RobotTwin
from plugcell.sim.twin.scenario import TwinScenario
from plugcell.sim.twin.tracker import LaserTracker

N_SCAN = 150
TRUE_PROBE_MM = (0.0, 0.0, 50.0)  # the fanuc twin profile's T-MAC on the flange


def _twin():
    return RobotTwin(TwinScenario(robot="fanuc_m20ia", seed=3))


@pytest.fixture(scope="module")
def scan():
    """The surface scan measured by the twin's tracker, 6-DoF (T-MAC) and 3-DoF (SMR)."""
    robot = _twin()
    q = surface_scan_joints(robot.description, robot.reveal_truth().profile, N_SCAN,
                            np.random.default_rng(5))
    six, _ = measure_poses(robot, LaserTracker(seed=3), q)
    three, _ = measure_poses(robot, LaserTracker(seed=4), q, mode="3dof")
    return robot, {"6dof": six, "3dof": three}


@pytest.fixture(scope="module")
def varied():
    """A campaign in the working volume, orientation spread ±20° (the twin's default)."""
    robot = _twin()
    q = working_volume_joints(robot.description, robot.reveal_truth().profile, N_SCAN,
                              np.random.default_rng(9))
    six, _ = measure_poses(robot, LaserTracker(seed=3), q)
    return robot, CalibrationData.from_measurements(six)


@pytest.fixture(scope="module")
def fits(scan):
    robot, sets = scan
    out = {}
    for mode, ms in sets.items():
        data = CalibrationData.from_measurements(ms)
        out[mode] = (data, Calibrator(robot.description, "serial").fit(data),
                     Calibrator(robot.description, "serial", null_tol=0).fit(data))
    return out


def test_twin_measures_positions_only_in_3dof_mode(scan):
    robot, sets = scan
    assert sets["3dof"].angles is None and sets["6dof"].angles is not None
    assert np.allclose(sets["3dof"].joints, sets["6dof"].joints, atol=1e-5)
    with pytest.raises(ValueError, match="mode"):
        measure_poses(robot, LaserTracker(seed=1), sets["6dof"].joints[:2], mode="5dof")


def test_the_scan_holds_the_tool_orientation(fits):
    data, res, _ = fits["6dof"]
    u = res.undetermined
    # the joints move by tens of degrees, the flange orientation by a few millidegrees
    assert np.degrees(np.ptp(data.q, axis=0)).max() > 15
    assert math.degrees(u.orientation_spread_rad) < 0.01
    assert u.required_spread_rad == pytest.approx(math.sqrt(3 / N_SCAN))


@pytest.mark.parametrize("mode", ["6dof", "3dof"])
def test_before_the_fix_the_frames_wander(fits, mode):
    """The old code path (null_tol=0): PROBE wanders by decimetres along the direction
    the poses do not see, BASE with it, and nothing warns."""
    _, _, old = fits[mode]
    assert np.linalg.norm(old.model.probe()[:3, 3]) > 0.2
    assert old.undetermined is None
    assert not any("PROBE position" in w for w in old.warnings)


@pytest.mark.parametrize("mode", ["6dof", "3dof"])
def test_undetermined_frames_stay_at_their_initial_values(fits, scan, mode):
    robot, _ = scan
    data, res, old = fits[mode]
    desc = robot.description
    # PROBE stays at its initial value — the description's tool point — in what the
    # poses do not see (here: all of its position)
    assert np.allclose(res.model.probe()[:3, 3], desc.tool[:3, 3], atol=1e-6)
    # BASE stays within the true PROBE offset (50 mm) of the truth; the old one did not
    true_base = robot.true_base()
    err = np.linalg.norm(res.model.base()[:3, 3] - true_base[:3, 3])
    assert err < 0.06
    assert np.linalg.norm(old.model.base()[:3, 3] - true_base[:3, 3]) > 0.2
    # the fit itself is as good as the old one
    assert res.calibration.position.norm.mean < 0.3e-3
    assert res.calibration.position.norm.mean < 1.2 * old.calibration.position.norm.mean
    # one warning, in words, with the remedy derived from the poses
    msgs = [w for w in res.warnings if "PROBE position" in w]
    assert len(msgs) == 1
    need = f"{math.degrees(required_spread(len(data))):.1f}°"
    assert msgs[0].startswith("PROBE position not determined: the tool orientation")
    assert f"at least {need}" in msgs[0] and "give --probe" in msgs[0]
    assert "BASE position" in msgs[0]
    # the column warnings of the frame parameters it explains are not repeated
    assert not any(w.startswith("parameter Δd7 ") or w.startswith("parameter Δd6 ")
                   for w in res.warnings)
    u = res.undetermined
    assert "probe_position" in u.components and set(u.probe_axes) == {"x", "y", "z"}
    assert u.unknown("probe_position") and u.messages[0] == msgs[0]


def test_a_given_probe_is_kept_and_counts_as_known(scan, fits):
    robot, _ = scan
    data = fits["6dof"][0]
    P = np.eye(4)
    P[:3, 3] = np.array(TRUE_PROBE_MM) / 1e3
    res = Calibrator(robot.description, "serial", probe=P).fit(data)
    # (within 0.1 mm: the PROBE's determined rotation turns its offset a little)
    assert np.allclose(res.model.probe()[:3, 3], P[:3, 3], atol=1e-4)
    assert np.linalg.norm(res.model.base()[:3, 3] - robot.true_base()[:3, 3]) < 0.01
    u = res.undetermined
    assert "probe_position" in u.components and not u.unknown("probe_position")
    assert "kept at the --probe given" in u.messages[0]


@pytest.mark.parametrize("positions_only", [False, True])
@pytest.mark.parametrize("method", ["gauss-newton", "lm"])
def test_a_varied_campaign_is_unchanged(varied, positions_only, method):
    """Orientation spread: nothing undetermined, parameters and warnings exactly those
    of the old code path."""
    robot, data = varied
    if positions_only:
        data = data.positions_only()
    new = Calibrator(robot.description, "serial", method=method).fit(data)
    old = Calibrator(robot.description, "serial", method=method, null_tol=0).fit(data)
    assert new.undetermined is None
    np.testing.assert_allclose(new.model.values, old.model.values, rtol=0, atol=1e-12)
    np.testing.assert_allclose(new.model.base(), old.model.base(), rtol=0, atol=1e-12)
    np.testing.assert_allclose(new.model.probe(), old.model.probe(), rtol=0, atol=1e-12)
    assert new.warnings == old.warnings
    np.testing.assert_allclose(new.validity.lever_m, old.validity.lever_m, rtol=1e-12)


def test_scipy_path_keeps_the_undetermined_frames(fits, scan):
    robot, _ = scan
    data = fits["6dof"][0]
    res = Calibrator(robot.description, "serial", method="least-squares").fit(data)
    assert np.allclose(res.model.probe()[:3, 3], robot.description.tool[:3, 3], atol=1e-6)
    assert res.calibration.position.norm.mean < 0.3e-3


def test_validity_region_does_not_take_levers_from_an_undetermined_probe(fits):
    _, res, old = fits["6dof"]
    # the old region: lever arms and threshold from a PROBE decimetres to metres away
    assert old.validity.lever_m.max() > 1.5 * res.validity.lever_m.max()
    assert res.validity.lever_m.max() < 2.5  # m/rad: a 1.8 m reach robot at its flange
    assert res.validity.threshold_m < 0.5


def test_params_json_records_what_is_undetermined(fits, fanuc):
    _, res, _ = fits["3dof"]
    doc = json.loads(json.dumps(params_document(res)))
    u = doc["undetermined"]
    assert "probe_position" in u["components"] and u["messages"]
    back = result_from_params(doc, fanuc).undetermined
    assert back.components == res.undetermined.components
    assert back.parameters == res.undetermined.parameters
    np.testing.assert_allclose(back.flange_orientation, res.undetermined.flange_orientation)
    assert back.required_spread_rad == pytest.approx(res.undetermined.required_spread_rad)
    # a file written before the record loads as before
    del doc["undetermined"]
    assert result_from_params(doc, fanuc).undetermined is None
    bad = json.loads(json.dumps(params_document(res)))
    bad["undetermined"]["components"] = ["probe"]
    with pytest.raises(ParamsError, match=r"undetermined\.components: unknown 'probe'"):
        result_from_params(bad, fanuc)
    bad["undetermined"] = {**u, "flange_orientation": [[1, 0], [0, 1]]}
    with pytest.raises(ParamsError, match=r"undetermined\.flange_orientation"):
        result_from_params(bad, fanuc)


_VALUES = st.one_of(st.none(), st.booleans(), st.integers(-3, 3), st.floats(allow_nan=True),
                    st.text(max_size=4), st.lists(st.text(max_size=3), max_size=3),
                    st.lists(st.lists(st.floats(-2, 2), min_size=3, max_size=3), max_size=4))


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(key=st.sampled_from(["components", "probe_axes", "parameters", "given",
                            "orientation_spread_deg", "required_spread_deg",
                            "flange_orientation", "poses", "directions", "tolerance",
                            "messages"]),
       value=_VALUES)
def test_a_bad_undetermined_entry_is_named(key, value):
    good = {"components": ["probe_position"], "probe_axes": ["x"], "parameters": [],
            "given": [], "orientation_spread_deg": 0.001, "required_spread_deg": 8.1,
            "flange_orientation": np.eye(3).tolist(), "poses": 150, "directions": 3,
            "tolerance": 1e-3, "messages": ["m"]}
    try:
        u = undetermined_from_document({**good, key: value})
    except ParamsError as exc:
        assert f"undetermined.{key}" in str(exc)
    else:
        assert isinstance(u.components, tuple)


def test_export_refuses_an_undetermined_probe_unless_given(fits, scan):
    robot, _ = scan
    data, res, _ = fits["6dof"]
    desc = robot.description
    with pytest.raises(ExportError, match="did not determine the PROBE position"):
        export_calibration(res, desc, "toml")
    P = np.eye(4)
    P[:3, 3] = np.array(TRUE_PROBE_MM) / 1e3
    out = export_calibration(res, desc, "toml", probe=P)
    assert "xyz = [0.0, 0.0, 0.05]" in out.text
    # the given PROBE re-expresses BASE: the campaign's points stay where they were measured
    m = with_probe(res.model, P, res.undetermined)
    moved = m.predict(data.q)[:, :3, 3] - res.model.predict(data.q)[:, :3, 3]
    # up to |Δt_P| × the calibrated flange's own orientation spread (~0.02°): 50 mm × 3e-4
    assert np.abs(moved).max() < 5e-5
    assert np.linalg.norm(m.base()[:3, 3] - robot.true_base()[:3, 3]) < 0.01


def test_the_commands_on_a_surface_scan(scan, tmp_path, capsys):
    """calibrate warns once; export refuses without --probe; compensate refuses targets
    at another tool orientation without --tool and accepts them with it."""
    robot, sets = scan
    meas, params = tmp_path / "scan.csv", tmp_path / "params.json"
    write_measurements(meas, sets["6dof"], joint_scale=robot.description.reading_scale())
    assert main(["calibrate", "--robot", "fanuc_m20ia", "--model", "serial", "--data",
                 str(meas), "--out", str(params), "--quiet"]) == 0
    assert capsys.readouterr().out.count("PROBE position not determined") == 1
    assert main(["export", "--params", str(params), "--format", "toml", "--out",
                 str(tmp_path / "r.toml")]) != 0
    assert "did not determine the PROBE position" in capsys.readouterr().err
    assert main(["export", "--params", str(params), "--format", "toml", "--out",
                 str(tmp_path / "r.toml"), "--probe", "0,0,50,0,0,0"]) == 0
    capsys.readouterr()
    # targets: two scan poses as they are, one turned by 20° about the flange's x axis
    res = result_from_params(json.loads(params.read_text()), robot.description)
    m = res.model
    T = np.linalg.inv(m.base()) @ m.predict(sets["6dof"].joints[:2])
    turned = T[0].copy()
    turned[:3, :3] = T[0, :3, :3] @ so3_exp([math.radians(20), 0, 0])
    rows = ["name,x,y,z,rx,ry,rz"]
    for name, P in (("A", T[0]), ("B", T[1]), ("C", turned)):
        a = np.degrees(matrix_to_angles(P[:3, :3], "zyz"))
        rows.append(f"{name}," + ",".join(f"{v:.6f}" for v in (*P[:3, 3] * 1e3, *a)))
    targets = tmp_path / "targets.csv"
    targets.write_text("\n".join(rows) + "\n")
    rc = main(["compensate", "--params", str(params), "--targets", str(targets), "--out",
               str(tmp_path / "j.csv")])
    err = capsys.readouterr().err
    assert rc != 0 and "did not determine the PROBE position" in err
    assert "(C): tool turned 20.0" in err and "--tool" in err
    targets.write_text("\n".join(rows[:3]) + "\n")  # the campaign's orientation only
    assert main(["compensate", "--params", str(params), "--targets", str(targets), "--out",
                 str(tmp_path / "j.csv")]) == 0
    assert "the PROBE position was not determined" in capsys.readouterr().err
    targets.write_text("\n".join(rows) + "\n")
    assert main(["compensate", "--params", str(params), "--targets", str(targets), "--out",
                 str(tmp_path / "j.csv"), "--tool", "0,0,50,0,0,0"]) == 0


def test_initial_registration_keeps_the_prior_offset():
    """Positions of a flange that turns about its z axis only, with noise: plain least
    squares lets the target offset along z wander; truncated it stays at the prior there,
    BASE taking up the rest, and the hand-eye estimate refuses."""
    rng = np.random.default_rng(1)
    n = 200
    F = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
    w = rng.normal(0, 1e-7, (n, 3))  # encoder-level wobble
    w[:, 2] += rng.uniform(-0.3, 0.3, n)
    F[:, :3, :3] = so3_exp(w)
    F[:, :3, 3] = rng.uniform(-0.5, 0.5, (n, 3)) * [1, 1, 0] + [1.0, 0, 0.5]
    base = np.eye(4)
    base[:3, 3] = [2.0, -1.0, 0.3]
    t = np.array([0.01, -0.02, 0.12])
    P = (base[:3, :3] @ (F[:, :3, 3] + F[:, :3, :3] @ t).T).T + base[:3, 3]
    P += rng.normal(0, 2e-5, P.shape)
    plain = estimate_base_probe_positions(F, P)
    assert abs(plain.probe[2, 3] - t[2]) > 0.5  # wanders along z
    prior = np.array([0.0, 0.0, 0.1])
    kept = estimate_base_probe_positions(F, P, prior_offset=prior, rel_tol=1e-3)
    np.testing.assert_allclose(kept.probe[:3, 3], [t[0], t[1], prior[2]], atol=5e-5)
    assert kept.rms < 1e-4  # BASE took up R_F (t − offset) along z
    T = F.copy()
    T[:, :3, 3] = P
    with pytest.raises(InitialEstimateError, match="PROBE position"):
        estimate_base_probe(F, T, rel_tol=1e-3)


def test_required_spread_determines_the_probe_to_the_noise():
    """The remedy's N: with the flange turning uniformly up to N = √(3/n) rad, the PROBE
    offset's standard deviation from n noisy positions is about the noise σ."""
    rng = np.random.default_rng(7)
    n, sigma = 300, 1e-4
    phi = required_spread(n)
    errs = []
    for _ in range(60):
        axis = rng.normal(size=(n, 3))
        axis /= np.linalg.norm(axis, axis=1, keepdims=True)
        R = so3_exp(axis * phi * rng.uniform(0, 1, (n, 1)) ** (1 / 3))
        # p_i = R_i t + t_B + noise: linear least squares for (t, t_B)
        M = np.concatenate([R, np.broadcast_to(np.eye(3), (n, 3, 3))], axis=2).reshape(-1, 6)
        t = np.array([0.0, 0.0, 0.1])
        y = (R @ t).reshape(-1) + rng.normal(0, sigma, 3 * n)
        errs.append(np.linalg.lstsq(M, y, rcond=None)[0][:3] - t)
    std = np.sqrt(np.mean(np.square(errs)))  # per coordinate
    assert 0.4 * sigma < std < 2.5 * sigma


def test_analysis_of_a_varied_campaign_finds_nothing(varied):
    robot, data = varied
    res = Calibrator(robot.description, "serial").fit(data)
    from plugcell.calibration.jacobian import identification_jacobian

    keys = list(res.identifiability.kept)
    jac = identification_jacobian(res.nominal, res.nominal.batch(data.q), keys)
    F = np.linalg.inv(res.nominal.base()) @ jac.poses @ np.linalg.inv(res.nominal.probe())
    assert analyse_determinacy(res.nominal, jac.H.reshape(-1, len(keys)), keys,
                               F[:, :3, :3]) is None
    _, spread = orientation_spread(F[:, :3, :3])
    assert math.degrees(spread) > 10


def test_twin_measure_scan_command(tmp_path):
    """``plugcell twin measure --scan N --mode 3dof``: N poses at one tool orientation,
    positions only; a bad count is refused."""
    from plugcell.io.measurements import read_measurements

    out = tmp_path / "scan.csv"
    assert main(["twin", "measure", "--robot", "fanuc_m20ia", "--seed", "3", "--scan", "12",
                 "--mode", "3dof", "--out", str(out), "--quiet"]) == 0
    ms = read_measurements(out, joint_scale=_twin().description.reading_scale())
    assert len(ms) == 12 and ms.angles is None
    assert "12 scan poses" in out.read_text().splitlines()[0]
    assert main(["twin", "measure", "--robot", "fanuc_m20ia", "--scan", "0", "--out",
                 str(out), "--quiet"]) != 0
