"""``plugcell kin``: fk/ik through plugcell.apps.cli.main, and its error paths."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from plugcell.apps.cli import main
from plugcell.io.robots import load_robot
from plugcell.kinematics import forward, matrix_to_zyz


def _run(capsys, *argv: str) -> tuple[int, dict | None, str]:
    rc = main(["kin", *argv])
    out, err = capsys.readouterr()
    return rc, (json.loads(out) if rc == 0 and out.strip().startswith("{") else None), err


def test_fk_prints_the_flange_pose(capsys):
    rc, out, _ = _run(capsys, "fk", "--robot", "smart_h4", "--joints", "0,-90,-187,0,90,0")
    assert rc == 0
    T = np.array(out["T"])
    desc = load_robot("smart_h4")
    np.testing.assert_allclose(
        T, forward(desc, None, np.radians([0, -90, -187, 0, 90, 0])).flange, atol=1e-11
    )
    assert out["warnings"] == []
    assert out["passive_deg"] == pytest.approx({"3'": 97.0, "4'": 83.0})
    np.testing.assert_allclose(out["pose_mm_zyz"][:3], T[:3, 3] * 1e3, atol=1e-5)
    np.testing.assert_allclose(
        np.radians(out["pose_mm_zyz"][3:]), matrix_to_zyz(T[:3, :3]), atol=1e-7
    )


def test_fk_reports_limits_but_evaluates(capsys):
    rc, out, _ = _run(capsys, "fk", "--robot", "elbow6", "--joints", "-200,-90,0,0,90,0")
    assert rc == 0
    assert out["warnings"] == ["joint 1 = -200.0000° outside [-185°, 185°]"]
    assert "passive_deg" not in out


def test_ik_round_trip_with_seed(capsys):
    q = [12.0, -75.0, -180.0, 20.0, 70.0, -30.0]
    desc = load_robot("smart_h4")
    T = forward(desc, None, np.radians(q)).flange
    a, b, c = np.degrees(matrix_to_zyz(T[:3, :3]))
    x, y, z = T[:3, 3] * 1e3
    pose = ",".join(f"{v:.12f}" for v in (x, y, z, a, b, c))
    rc, out, _ = _run(
        capsys, "ik", "--robot", "smart_h4", "--pose", pose, "--start", "10,-70,-175,15,65,-25"
    )
    assert rc == 0
    np.testing.assert_allclose(out["joints"], q, atol=1e-6)
    rc, old, err = _run(  # --start's old name still works, and says it is old
        capsys, "ik", "--robot", "smart_h4", "--pose", pose, "--seed", "10,-70,-175,15,65,-25"
    )
    assert rc == 0 and old == out
    assert "plugcell: warning: --seed is deprecated: use --start" in err
    rc2, out2, _ = _run(capsys, "ik", "--robot", "smart_h4", "--pose", pose)  # default seed
    assert rc2 == 0
    T2 = forward(desc, None, np.radians(out2["joints"])).flange
    np.testing.assert_allclose(T2, T, atol=1e-8)


def test_robot_file_path_and_listing(capsys, tmp_path: Path):
    f = tmp_path / "mine.toml"
    f.write_text((Path(__file__).parents[2] / "src/plugcell/robots/elbow6.toml").read_text())
    rc, out, _ = _run(capsys, "fk", "--robot", str(f), "--joints", "0,-90,0,0,90,0")
    assert rc == 0 and out["robot"] == "elbow6"
    assert main(["kin", "robots"]) == 0
    assert {"smart_h4", "elbow6"} <= set(capsys.readouterr().out.split())
    assert main(["kin", "describe", "--robot", "smart_h4"]) == 0
    assert json.loads(capsys.readouterr().out)["actuated"] == ["1", "2", "2'", "4", "5", "6"]


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (
            ["fk", "--robot", "smart_h4", "--joints", "0,0,0"],
            "--joints: expected 6 comma-separated numbers",
        ),
        (
            ["fk", "--robot", "smart_h4", "--joints", "0,a,0,0,0,0"],
            "--joints: value 2 ('a') is not a number",
        ),
        (
            ["fk", "--robot", "smart_h4", "--joints", "0,nan,0,0,0,0"],
            "--joints: value 2 ('nan') is not finite",
        ),
        (
            ["fk", "--robot", "kuka", "--joints", "0"],
            "unknown robot 'kuka'; available robots: elbow6, fanuc_m20ia, smart_h4",
        ),
        (
            ["fk", "--robot", "/no/such/robot.toml", "--joints", "0"],
            "robot description file not found",
        ),
        (
            ["fk", "--robot", "smart_h4", "--joints", "0,-90,-90,0,0,0"],
            "smart_h4: the four-bar loop collapses",
        ),
        (
            ["ik", "--robot", "smart_h4", "--pose", "1,2,3"],
            "--pose: expected 6 comma-separated numbers",
        ),
        (
            ["ik", "--robot", "smart_h4", "--pose", "5000,0,0,0,0,0"],
            "smart_h4: pose is out of reach",
        ),
        (
            ["ik", "--robot", "smart_h4", "--pose", "1500,0,1000,0,90,0", "--start", "1,2"],
            "--start: expected 6",
        ),
        (
            [
                "ik",
                "--robot",
                "smart_h4",
                "--pose",
                "1524.8389,-150.1484,3125.8548,-9.0909,21.5409,-157.032",
            ],
            "no solution inside the joint limits",
        ),
    ],
)
def test_user_errors_exit_2(capsys, argv, message):
    rc = main(["kin", *argv])
    err = capsys.readouterr().err
    assert rc == 2
    assert err.startswith("plugcell: error: ")
    assert message in err


def test_bad_description_file_names_file_and_key(capsys, tmp_path: Path):
    text = (Path(__file__).parents[2] / "src/plugcell/robots/smart_h4.toml").read_text()
    f = tmp_path / "broken_h4.toml"
    f.write_text(text.replace('parent = "3\'"', 'parent = "9"', 1))
    assert main(["kin", "fk", "--robot", str(f), "--joints", "0,0,0,0,0,0"]) == 2
    assert "broken_h4.toml: links[4].parent: unknown parent link '9'" in capsys.readouterr().err
