"""A twin for a robot without a profile of its own (twin/generic.py): a URDF robot, or a
user's description file — estimated from the description, deterministic, and usable
end to end (twin measure → calibrate → export) from the command line."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
from shared_data import UR_XACRO, URDF_DIR

from plugcell.apps.cli import main
from plugcell.io.robot_schema import description_to_dict
from plugcell.io.robots import description_to_toml, load_robot
from plugcell.kinematics import forward
from plugcell.kinematics.rotations import zyz_to_matrix
from plugcell.sim.twin.campaign import working_volume_joints
from plugcell.sim.twin.generic import DEFLECTION, generic_twin
from plugcell.sim.twin.physics import gravity_torques
from plugcell.sim.twin.scenario import TwinScenario, make_truth

UR_ARGS = ["--robot", str(UR_XACRO), "--robot-arg", "ur_type=ur10", "--robot-arg", "name=ur10",
           "--package-path", str(URDF_DIR)]
needs_ur = pytest.mark.skipif(not UR_XACRO.is_file(),
                              reason=f"the shared URDF data are not at {URDF_DIR}")


@pytest.fixture(scope="module")
def bare_elbow():
    """elbow6 under another name, without its working volume and stiffness: what the
    twin knows of a robot it has no profile for."""
    d = load_robot("elbow6")
    return dataclasses.replace(d, name="my_elbow", working_volume=None, stiffness=None)


def test_the_estimate_is_deterministic_and_completes_the_description(bare_elbow):
    d1, p1 = generic_twin(bare_elbow)
    d2, p2 = generic_twin(bare_elbow)
    assert p1 == p2 and d1.working_volume == d2.working_volume
    np.testing.assert_array_equal(d1.stiffness, d2.stiffness)
    assert d1.working_volume is not None and d1.stiffness is not None
    assert np.all(d1.stiffness > 0)


def test_the_stiffness_bounds_the_deflection_under_the_arms_weight(bare_elbow):
    desc, _ = generic_twin(bare_elbow)
    rng = np.random.default_rng(3)
    lo, hi = desc.joint_limits[:, 0], desc.joint_limits[:, 1]
    q = lo + rng.uniform(size=(200, desc.n_readings)) * (hi - lo)
    tau = gravity_torques(desc, desc.nominal_parameters(), q)
    # the estimate sampled other configurations: allow a little more than δ here
    assert np.abs(tau / desc.stiffness).max() < 1.5 * DEFLECTION


def test_the_tracker_faces_the_volume_and_the_tmac_faces_the_tracker(bare_elbow):
    desc, prof = generic_twin(bare_elbow)
    centre = np.asarray(desc.working_volume.center)
    tracker = np.asarray(prof.tracker_position)
    assert math.isclose(np.linalg.norm((tracker - centre)[:2]), 3.0, rel_tol=1e-12)
    to_robot = centre - tracker
    assert math.isclose(prof.tracker_yaw, math.atan2(to_robot[1], to_robot[0]), abs_tol=1e-12)
    normal = zyz_to_matrix(*prof.reference_zyz)[:, 2]  # T-MAC normal = flange z
    to_tracker = (tracker - centre) / np.linalg.norm(tracker - centre)
    # horizontal, at the tracker's bearing: within the poses' spread of the line of sight
    # (the tracker stands lower than the volume's centre)
    assert normal @ to_tracker > math.cos(prof.spread)


def test_poses_are_found_in_the_estimated_volume(bare_elbow):
    desc, prof = generic_twin(bare_elbow)
    q = working_volume_joints(desc, prof, 30, np.random.default_rng(0))
    p = forward(desc, desc.nominal_parameters(), q).flange[:, :3, 3]
    assert np.all(desc.working_volume.contains(p))


def test_a_shipped_robot_keeps_its_own_profile():
    by_name = make_truth(TwinScenario(robot="elbow6", seed=4))
    by_description = make_truth(TwinScenario(robot="elbow6", seed=4,
                                             description=description_to_dict(load_robot("elbow6"))))
    assert by_name.profile == by_description.profile
    np.testing.assert_array_equal(by_name.base, by_description.base)
    for f in ("theta", "d", "a", "alpha", "beta"):
        np.testing.assert_array_equal(getattr(by_name.params, f),
                                      getattr(by_description.params, f))


def test_a_description_file_without_a_profile_gets_the_estimate(bare_elbow, tmp_path):
    path = tmp_path / "my_elbow.toml"
    path.write_text(description_to_toml(bare_elbow))
    truth = make_truth(TwinScenario(robot=str(path), seed=1))
    assert truth.profile.robot == "my_elbow" and truth.profile.beams == ()
    assert truth.description.working_volume == generic_twin(bare_elbow)[0].working_volume
    scenario = TwinScenario(robot="my_elbow", seed=1, description=description_to_dict(bare_elbow))
    assert TwinScenario.from_json(scenario.to_json()) == scenario  # JSON round trip


@needs_ur
@pytest.mark.slow
def test_a_vendor_xacro_robot_end_to_end_from_the_command_line(tmp_path, capsys):
    """ur_description xacro: twin campaign → calibration → UR kinematics file."""
    cal, val, params = tmp_path / "cal.csv", tmp_path / "val.csv", tmp_path / "p.json"
    assert main(["twin", "measure", *UR_ARGS, "--poses", "30", "--out", str(cal),
                 "--quiet"]) == 0
    assert main(["twin", "measure", *UR_ARGS, "--poses", "20", "--pose-seed", "9",
                 "--out", str(val), "--quiet"]) == 0
    assert main(["calibrate", *UR_ARGS, "--model", "1", "--data", str(cal), "--validate",
                 str(val), "--out", str(params), "--quiet"]) == 0
    d = json.loads(params.read_text())
    assert d["robot"] == "ur10"
    before, after = d["validation"]["before"]["mean_mm"], d["validation"]["mean_mm"]
    assert before > 0.3 and after < 0.25 * before  # the hidden errors are found
    out = tmp_path / "ur10_kinematics.yaml"
    assert main(["export", "--params", str(params), "--format", "ur-kinematics",
                 "--out", str(out)]) == 0
    assert "shoulder:" in out.read_text()
    capsys.readouterr()
    assert main(["twin", "report", *UR_ARGS, "--poses", "20", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["robot"] == "ur10" and report["nominal_mean_mm"] > 0


def test_urdf_options_for_a_non_urdf_twin_are_refused(capsys):
    assert main(["twin", "report", "--robot", "elbow6", "--robot-arg", "a=b"]) == 2
    assert "applies to .urdf/.xacro robots only" in capsys.readouterr().err
