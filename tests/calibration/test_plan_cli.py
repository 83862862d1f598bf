"""``plugcell plan`` end to end: plan file → twin campaign → calibration; bad input.

The module's fixtures make the plan (``planned``) and the twin's campaign of it
(``measured``) once; every test reads them and writes only in a folder of its own
(``tmp_path``), so that each test passes alone, in any order and after any other."""

from __future__ import annotations

import json

import numpy as np
import pytest

from plugcell.apps.cli import main
from plugcell.devices.robot.value_text import value_from_text
from plugcell.io.measurements import read_measurements
from plugcell.io.plans import read_plan
from plugcell.io.robots import load_robot
from plugcell.pdl.types import JOINTPOS, ArrayType


@pytest.fixture(scope="module")
def planned(tmp_path_factory):
    d = tmp_path_factory.mktemp("plan")
    rc = main(["plan", "--robot", "smart_h4", "--poses", "30", "--candidates", "600",
               "--out", str(d / "plan.csv"), "--program", str(d / "prog.json"), "--json",
               "--quiet"])
    assert rc == 0
    return d


@pytest.fixture(scope="module")
def measured(planned):
    """The twin's campaign of the plan: ``cal.csv`` beside it."""
    rc = main(["twin", "measure", "--plan", str(planned / "plan.csv"), "--out",
               str(planned / "cal.csv"), "--quiet"])
    assert rc == 0
    return planned / "cal.csv"


def test_plan_file_is_measured_by_the_twin_with_its_payloads(planned, measured):
    plan = read_plan(planned / "plan.csv", n_joints=6)
    assert len(plan) == 30
    assert set(np.unique(plan.payload_kg)) <= {0.0, 18.0, 36.0}
    assert len(np.unique(plan.payload_kg)) >= 2
    assert np.all(np.diff(plan.payload_kg) >= 0)
    assert np.all(load_robot("smart_h4").within_limits(plan.joints))
    m = read_measurements(measured)
    np.testing.assert_allclose(m.payload_kg, plan.payload_kg)
    # the readings are the planned joints plus the twin's encoder/repeatability noise
    assert np.max(np.abs(m.joints - plan.joints)) < np.radians(0.05)


def test_plan_summary_json_and_program_values(planned, capsys, tmp_path):
    rc = main(["plan", "--robot", "smart_h4", "--poses", "30", "--candidates", "600",
               "--out", str(tmp_path / "again.csv"), "--json", "--quiet"])
    assert rc == 0
    d = json.loads(capsys.readouterr().out)
    assert d["poses"] == 30 and d["criterion"] == "I" and d["model"]["number"] == 5
    assert d["condition_number"] > 1 and len(d["predicted_sigma"]) == 51
    assert (tmp_path / "again.csv").read_text().split("\n", 4)[4] == \
        (planned / "plan.csv").read_text().split("\n", 4)[4], "deterministic"
    files = sorted(planned.glob("prog*.json"))
    assert len(files) == len(d["payload_groups"])
    total = 0
    for f in files:
        values = json.loads(f.read_text())
        assert values[0] == "calibration"
        kv = dict(v.split("=", 1) for v in values[1:])
        rows = value_from_text(kv["configs"], ArrayType(JOINTPOS, (200,)))
        assert len(rows) == int(kv["n_configs"])
        total += len(rows)
    assert total == 30


def test_plan_from_measured_poses(measured, capsys, tmp_path):
    rc = main(["plan", "--robot", "smart_h4", "--model", "4", "--poses", "12",
               "--from", str(measured), "--out", str(tmp_path / "sub.csv"),
               "--criterion", "D"])
    assert rc == 0
    sub = read_plan(tmp_path / "sub.csv", n_joints=6)
    cal = read_measurements(measured)
    # every planned row is one of the measured poses, with its measurement and payload
    d = np.abs(sub.joints[:, None, :] - cal.joints[None]).max(axis=2)
    assert np.all(d.min(axis=1) < 1e-9)
    rows = d.argmin(axis=1)
    assert len(set(rows.tolist())) == 12
    got = read_measurements(tmp_path / "sub.csv")
    np.testing.assert_allclose(got.positions, cal.positions[rows], atol=1e-9)
    np.testing.assert_allclose(got.payload_kg, cal.payload_kg[rows])
    assert "estimated from 30 measured poses" in capsys.readouterr().err
    # measured poses keep their payloads
    assert main(["plan", "--robot", "smart_h4", "--poses", "12", "--from",
                 str(measured), "--out", str(tmp_path / "x.csv"),
                 "--payloads-kg", "0,36", "--quiet"]) == 2
    assert "measured with their own payloads" in capsys.readouterr().err


@pytest.mark.parametrize("argv, message", [
    (["--tracker", "-4000,0,1000", "--line-of-sight-deg", "1"], "line of sight"),
    (["--poses", "5000"], "only"),
    (["--criterion", "X"], "unknown criterion 'X'"),
    (["--poses", "2"], "equations for"),
    (["--payloads-kg", "0,-3"], "--payloads-kg"),
    (["--payloads-kg", "0"], "model 5 identifies payload"),
    (["--volume", "1,2,3"], "--volume"),
    (["--tracker", "a,b,c"], "--tracker"),
    (["--line-of-sight-deg", "0"], "--line-of-sight-deg"),
    (["--model", "9"], "--model"),
    (["--from", "/nonexistent/q.csv"], "cannot read"),
    (["--program-value", "base_est=1,2,3,4,5,6"], "give --program FILE too"),
])
def test_bad_input_is_a_clear_error(capsys, tmp_path, argv, message):
    base = {"--poses": "20", "--candidates": "300"}
    for i in range(0, len(argv), 2):
        base[argv[i]] = argv[i + 1]
    if "--from" in base:
        base.pop("--candidates")
    args = ["plan", "--robot", "smart_h4", "--out", str(tmp_path / "bad.csv"), "--quiet"]
    args += [f"{k}={v}" for k, v in base.items()]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.startswith("plugcell: error:") and message in err, err


def test_program_values_are_appended_to_the_activate_data(capsys, tmp_path):
    """--program-value: what the program needs beyond the poses (BASE and PROBE estimates,
    the identification) in the file, so that `call … ACTIVATE --data "$(cat FILE)"` runs
    it (docs/robot-programs.md; issue 39)."""
    out = tmp_path / "values.json"
    identify = "identify=params = calibrate(mJ, mT, model=5, payload=36); s = summary(params)"
    assert main(["plan", "--robot", "smart_h4", "--poses", "20", "--candidates", "300",
                 "--payloads-kg", "36", "--model", "4", "--out", str(tmp_path / "v.csv"),
                 "--program", str(out), "--program-value", "base_est=4720.6,-293,-350,163,0,0",
                 "--program-value", identify, "--quiet"]) == 0
    values = json.loads(out.read_text())
    assert values[0] == "calibration" and values[-2:] == ["base_est=4720.6,-293,-350,163,0,0",
                                                           identify]
    assert main(["plan", "--robot", "smart_h4", "--poses", "20", "--out", str(out),
                 "--program", str(out), "--program-value", "=3", "--quiet"]) == 2
    assert "--program-value must be NAME=VALUE" in capsys.readouterr().err


def test_bad_plan_file_for_the_twin(capsys, tmp_path):
    bad = tmp_path / "bad_plan.csv"
    bad.write_text("j1,j2,j3,j4,j5,j6\n0,0,0,0,0,0\n")
    assert main(["twin", "measure", "--plan", str(bad), "--out", str(tmp_path / "x.csv")]) == 2
    assert "outside the joint or coupled limits" in capsys.readouterr().err
    bad.write_text("j1,j2,j3\n0,0,0\n")
    assert main(["twin", "measure", "--plan", str(bad), "--out", str(tmp_path / "x.csv")]) == 2
    assert "3 joint columns, the robot has 6" in capsys.readouterr().err


def test_another_robots_data_are_refused_and_dropped_poses_reported(planned, measured, capsys,
                                                                   tmp_path):
    """Issue 39 §7: the Smart H4's measurements planned as another robot are refused with
    the misfit named; configurations left out are counted with the reason; a file mostly
    outside the robot's joint limits is refused."""
    out = ["--out", str(tmp_path / "x.csv"), "--poses", "12", "--model", "1"]
    assert main(["plan", "--robot", "fanuc_m20ia", "--from", str(measured),
                 *out]) == 2
    err = capsys.readouterr().err
    assert "the measurements do not fit robot 'fanuc_m20ia'" in err, err
    assert "measured on another robot? give its --robot" in err
    assert not (tmp_path / "x.csv").exists()
    # a file of configurations: those outside the limits or the volume are counted
    plan = read_plan(planned / "plan.csv", n_joints=6)
    q = np.degrees(plan.joints)
    bad = q.copy()
    bad[:4, 1] = -170.0  # joint 2 outside [-165°, -15°]
    rows = "\n".join(",".join(f"{v:.6f}" for v in r) for r in bad)
    (tmp_path / "some.csv").write_text("j1,j2,j3,j4,j5,j6\n" + rows + "\n")
    assert main(["plan", "--robot", "smart_h4", "--from", str(tmp_path / "some.csv"),
                 *out]) == 0
    err = capsys.readouterr().err
    assert f"warning: 4 of the {len(q)} configurations of {tmp_path / 'some.csv'} left out " \
           "(4 outside the limits)" in err, err
    bad[:, 1] = -170.0
    rows = "\n".join(",".join(f"{v:.6f}" for v in r) for r in bad)
    (tmp_path / "all.csv").write_text("j1,j2,j3,j4,j5,j6\n" + rows + "\n")
    assert main(["plan", "--robot", "smart_h4", "--from", str(tmp_path / "all.csv"),
                 *out, "--quiet"]) == 2
    assert "none of the" in capsys.readouterr().err
    bad[: len(q) // 2 + 1, 1] = -170.0
    bad[len(q) // 2 + 1:, 1] = q[len(q) // 2 + 1:, 1]
    rows = "\n".join(",".join(f"{v:.6f}" for v in r) for r in bad)
    (tmp_path / "most.csv").write_text("j1,j2,j3,j4,j5,j6\n" + rows + "\n")
    assert main(["plan", "--robot", "smart_h4", "--from", str(tmp_path / "most.csv"),
                 *out, "--quiet"]) == 2
    err = capsys.readouterr().err
    assert f"{len(q) // 2 + 1} of its {len(q)} configurations are outside the joint limits " \
           "of robot 'smart_h4' — a file of another robot? give its --robot" in err, err
