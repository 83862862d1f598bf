"""``plugcell calibrate`` and ``plugcell reproduce 8.1`` end to end (files in, files out)."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from plugcell.apps.cli import main
from plugcell.io.measurements import read_measurements, write_measurements
from plugcell.sim.twin.campaign import measure_poses, working_volume_joints
from plugcell.sim.twin.robot import RobotTwin
from plugcell.sim.twin.scenario import TwinScenario
from plugcell.sim.twin.tracker import LaserTracker

SHARED_TABLE = Path(__file__).resolve().parents[3] / "shared" / "data" / "thesis_table_8_1.csv"


def _campaign(path: Path, n: int, pose_seed: int, payload: float = 0.0) -> None:
    robot = RobotTwin(TwinScenario(seed=2).with_payload(payload))
    q = working_volume_joints(robot.description, robot.reveal_truth().profile, n,
                              np.random.default_rng(pose_seed))
    data, _ = measure_poses(robot, LaserTracker(seed=2), q)
    write_measurements(path, data)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("cal")
    _campaign(d / "cal.csv", 60, 1)
    _campaign(d / "val.csv", 30, 2)
    return d


def test_calibrate_writes_params_and_an_offline_report(files, capsys):
    out, rep = files / "params.json", files / "report.html"
    rc = main(["calibrate", "--robot", "smart_h4", "--model", "loop+gravity",
               "--data", str(files / "cal.csv"), "--validate", str(files / "val.csv"),
               "--out", str(out), "--report", str(rep), "--json"])
    assert rc == 0
    captured = capsys.readouterr()
    printed = json.loads(captured.out)
    assert "[identify] iteration 1" in captured.err  # progress on stderr
    saved = json.loads(out.read_text())
    assert printed["parameters"] == saved["parameters"]
    assert saved["model"]["number"] == 4 and len(saved["parameters"]) == 37
    for key in ("calibration", "validation"):
        assert {"mean_mm", "std_mm", "max_mm"} <= set(saved[key])
        assert saved[key]["mean_mm"] < 0.25 * saved[key]["before"]["mean_mm"]
    assert saved["base"]["matrix"] and saved["probe"]["matrix"]
    assert isinstance(saved["iterations"], int) and saved["condition_number"] > 1
    row = next(p for p in saved["parameters"] if p["key"] == "theta2'")
    assert row["name"] == "Δθ2'" and row["stands_for"] == "Δθ2' + Δθ3" and row["unit"] == "rad"
    html = rep.read_text()
    assert html.count("data:image/png;base64,") >= 4
    assert "<script" not in html and "http://" not in html and "https://" not in html
    assert "Δa2' − Δa4'" in html


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--robot", "no_such_robot", "--model", "2"], "unknown robot 'no_such_robot'"),
        (["--robot", "smart_h4", "--model", "9"], "unknown model '9'"),
        (["--robot", "smart_h4", "--model", "5"], "carry no payload"),
    ],
)
def test_calibrate_user_errors_exit_2(files, tmp_path, capsys, argv, message):
    rc = main(["calibrate", *argv, "--data", str(files / "cal.csv"),
               "--out", str(tmp_path / "p.json"), "--quiet"])
    assert rc == 2
    assert message in capsys.readouterr().err


def test_calibrate_bad_files_too_few_poses_and_divergence(files, tmp_path, capsys):
    bad = tmp_path / "bad.csv"
    bad.write_text("j1,j2,j3,j4,j5,j6,x,y\n1,2,3,4,5,6,7,8\n")
    assert main(["calibrate", "--robot", "smart_h4", "--model", "2", "--data", str(bad),
                 "--out", str(tmp_path / "p.json")]) == 2
    assert "lacks the column 'z'" in capsys.readouterr().err
    lines = (files / "cal.csv").read_text().splitlines()
    header = next(i for i, ln in enumerate(lines) if ln.startswith("j1"))
    few = tmp_path / "few.csv"
    few.write_text("\n".join(lines[: header + 6]) + "\n")
    assert main(["calibrate", "--robot", "smart_h4", "--model", "2", "--data", str(few),
                 "--out", str(tmp_path / "p.json"), "--quiet"]) == 2
    assert "too few poses" in capsys.readouterr().err
    rows = list(csv.reader(lines[header:]))
    swapped = tmp_path / "swapped.csv"
    body = [",".join([r[0], r[2], r[1], *r[3:]]) for r in rows[1:]]  # θ2 <-> θ2'
    swapped.write_text("\n".join([",".join(rows[0]), *body]) + "\n")
    assert main(["calibrate", "--robot", "smart_h4", "--model", "2", "--data", str(swapped),
                 "--out", str(tmp_path / "p.json"), "--quiet"]) == 2
    assert "do not match robot 'smart_h4'" in capsys.readouterr().err
    assert not (tmp_path / "p.json").exists()


def test_reproduce_8_1(tmp_path, capsys):
    rc = main(["reproduce", "8.1", "--json", "--out-dir", str(tmp_path)])
    assert rc == 0
    d = json.loads(capsys.readouterr().out)
    assert d["iterations"] <= 7 and d["converged"]
    assert d["residual_mean_mm"] < 1e-4
    assert d["max_param_error"] < 1e-5
    assert d["parameters_identified"] == 34
    assert (tmp_path / "8.1.md").is_file() and (tmp_path / "8.1-convergence.png").is_file()


def test_reproduce_writes_under_out_by_default(tmp_path, monkeypatch, capsys):
    """Run from any folder, it writes out/reproduce/ there — no stray docs/ folder."""
    monkeypatch.chdir(tmp_path)
    assert main(["reproduce", "8.1", "--poses", "12"]) == 0
    assert "wrote out/reproduce/8.1.md" in capsys.readouterr().err
    assert (tmp_path / "out" / "reproduce" / "8.1.md").is_file()
    assert not (tmp_path / "docs").exists()


@pytest.mark.skipif(not SHARED_TABLE.is_file(), reason="shared data not available")
def test_embedded_table_8_1_matches_the_shared_csv():
    from plugcell.apps.reproduce.identification_8_1 import TABLE_8_1

    rows = [r for r in csv.reader(SHARED_TABLE.read_text().splitlines())
            if r and not r[0].startswith("#")][1:]
    shared = {(r[0], r[1]): (float(r[2]) if r[2] else None, float(r[3]) if r[3] else None)
              for r in rows}
    ours = {(lk, f): (inp, th) for lk, f, inp, th, _ in TABLE_8_1}
    for key, (inp, th) in ours.items():
        assert shared[key] == (inp, th), key
    assert {k for k, v in shared.items() if v[0] is not None} == set(ours)


def test_reproduce_8_2_quick(tmp_path, capsys):
    rc = main(["reproduce", "8.2", "--quick", "--json", "--out-dir", str(tmp_path)])
    assert rc == 0
    d = json.loads(capsys.readouterr().out)
    un = d["unloaded"]
    val = {m: un[m]["validation"]["mean_mm"] for m in ("nominal", "model1", "model2", "model3",
                                                       "model4")}
    assert 2.0 < val["nominal"] < 8.0  # the twin's nominal error has the thesis's size (4 mm)
    assert max(val[m] for m in ("model1", "model2", "model3", "model4")) < 0.25 * val["nominal"]
    assert val["model4"] < min(val["model1"], val["model3"])  # the loop model wins (8.2.3)
    l36 = d["loaded_36kg"]
    for m in ("nominal", "model4", "model5"):  # shape shown, not forced: no ordering asserted
        assert 0 < l36[m]["validation"]["mean_mm"] < 10.0
    assert len(d["table_8_4"]) == 50
    assert (tmp_path / "8.2.md").is_file() and (tmp_path / "8.2-models.png").is_file()


def test_calibrate_a_serial_robot_without_loop(tmp_path, capsys):
    for name, n, seed in (("cal.csv", 50, 1), ("val.csv", 30, 2)):
        assert main(["twin", "measure", "--robot", "elbow6", "--poses", str(n), "--pose-seed",
                     str(seed), "--out", str(tmp_path / name), "--quiet"]) == 0
    out = tmp_path / "p.json"
    assert main(["calibrate", "--robot", "elbow6", "--model", "serial+gravity", "--data",
                 str(tmp_path / "cal.csv"), "--validate", str(tmp_path / "val.csv"),
                 "--out", str(out), "--quiet"]) == 0
    d = json.loads(out.read_text())
    assert d["model"]["family"] == "serial"
    assert any(p["kind"] == "gravity" for p in d["parameters"])  # compliance from its masses
    assert d["validation"]["mean_mm"] < 0.5 * d["validation"]["before"]["mean_mm"]


def test_calibrate_exports_every_poses_residual(files, tmp_path, capsys):
    out, res = tmp_path / "p.json", tmp_path / "out" / "residuals.json"
    assert main(["calibrate", "--robot", "smart_h4", "--model", "loop",
                 "--data", str(files / "cal.csv"), "--validate", str(files / "val.csv"),
                 "--out", str(out), "--residuals", str(res), "--quiet"]) == 0
    assert capsys.readouterr().out.rstrip().endswith(f"wrote {out} and {res}")
    params, doc = json.loads(out.read_text()), json.loads(res.read_text())
    assert doc["format"] == "plugcell-residuals" and doc["robot"] == "smart_h4"
    poses = doc["poses"]
    assert [p["set"] for p in poses] == ["calibration"] * 60 + ["validation"] * 30
    measured = read_measurements(files / "cal.csv").positions * 1e3
    np.testing.assert_allclose([p["measured_mm"] for p in poses[:60]], measured, atol=1e-9)
    for name in ("calibration", "validation"):
        mine = [p for p in poses if p["set"] == name]
        after = np.linalg.norm([p["after_mm"] for p in mine], axis=1)
        before = np.linalg.norm([p["before_mm"] for p in mine], axis=1)
        assert after.mean() == pytest.approx(params[name]["mean_mm"], rel=1e-9)
        assert before.mean() == pytest.approx(params[name]["before"]["mean_mm"], rel=1e-9)
        assert after.max() == pytest.approx(params[name]["max_mm"], rel=1e-9)
    assert main(["calibrate", "--robot", "smart_h4", "--model", "loop", "--data",
                 str(files / "cal.csv"), "--out", str(out), "--residuals", str(tmp_path),
                 "--quiet"]) == 2
    assert "cannot write" in capsys.readouterr().err


def _validation(argv: list[str], capsys) -> dict:
    assert main(["calibrate", *argv, "--quiet", "--json"]) == 0
    return json.loads(capsys.readouterr().out)["validation"]


def test_validate_refit_honours_the_rotation_weight_or_positions_only(files, tmp_path, capsys):
    """6-DOF files; the refit of BASE on the validation poses weighs their orientations by
    --rotation-weight (it used 1 whatever the option said), or ignores them."""
    common = ["--robot", "smart_h4", "--model", "loop", "--data", str(files / "cal.csv"),
              "--validate", str(files / "val.csv"), "--out", str(tmp_path / "p.json"),
              "--validate-refit", "base"]
    assert read_measurements(files / "val.csv").angles is not None
    # --rotation-weight sets the weight of the fit and of the refit, so compare at one weight
    light = _validation([*common, "--rotation-weight", "0.01"], capsys)
    light_positions = _validation([*common, "--rotation-weight", "0.01",
                                   "--refit-positions-only"], capsys)
    heavy = _validation([*common, "--rotation-weight", "100"], capsys)
    positions = _validation([*common, "--rotation-weight", "100", "--refit-positions-only"],
                            capsys)
    # a light orientation weight is nearly the positions-only registration ...
    assert light["mean_mm"] == pytest.approx(light_positions["mean_mm"], rel=1e-4)
    # ... a heavy one is not (the twin's measured orientations have their own noise)
    assert heavy["mean_mm"] > positions["mean_mm"] * (1 + 1e-3)
    assert "orientation" in positions  # orientations still evaluated


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--refit-positions-only"], "--refit-positions-only needs --validate-refit"),
        (["--validate-refit", "base"], "--validate-refit needs a --validate file"),
        (["--rotation-weight", "0"], "--rotation-weight must be a finite number > 0"),
        (["--rotation-weight", "inf"], "--rotation-weight must be a finite number > 0"),
    ],
)
def test_calibrate_refit_option_errors(files, tmp_path, capsys, extra, message):
    assert main(["calibrate", "--robot", "smart_h4", "--model", "loop", "--data",
                 str(files / "cal.csv"), "--out", str(tmp_path / "p.json"), "--quiet",
                 *extra]) == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "p.json").exists()


def test_refit_positions_only_refuses_position_files(tmp_path, capsys):
    pos = tmp_path / "pos.csv"
    lines = ["j1,j2,j3,j4,j5,j6,x,y,z"]
    lines += ["0,-90,-187,0,90,0,1,2,3"] * 3
    pos.write_text("\n".join(lines) + "\n")
    assert main(["calibrate", "--robot", "smart_h4", "--model", "loop", "--data", str(pos),
                 "--validate", str(pos), "--validate-refit", "base", "--refit-positions-only",
                 "--out", str(tmp_path / "p.json"), "--quiet"]) == 2
    assert "measures positions only" in capsys.readouterr().err


def test_loss_scale_sets_the_robust_threshold(files, tmp_path, capsys):
    """One pose 3 mm off: with --loss huber the pose is down-weighted when the threshold
    --loss-scale × median residual is below its residual, not when it is far above."""
    from plugcell.calibration.identify import DEFAULT_LOSS_SCALE

    lines = (files / "cal.csv").read_text().splitlines()
    header = next(i for i, ln in enumerate(lines) if ln.startswith("j1"))
    cells = lines[header + 5].split(",")
    cells[6] = f"{float(cells[6]) + 3.0:.6f}"  # x of pose #5, mm
    lines[header + 5] = ",".join(cells)
    bad = tmp_path / "outlier.csv"
    bad.write_text("\n".join(lines) + "\n")

    def weight_of_pose_5(*scale: str) -> tuple[float, dict]:
        res = tmp_path / "res.json"
        assert main(["calibrate", "--robot", "smart_h4", "--model", "loop", "--data", str(bad),
                     "--out", str(tmp_path / "p.json"), "--residuals", str(res), "--quiet",
                     "--loss", "huber", *scale]) == 0
        capsys.readouterr()
        poses = json.loads(res.read_text())["poses"]
        return poses[4]["weight"], json.loads((tmp_path / "p.json").read_text())["settings"]

    tight, settings = weight_of_pose_5("--loss-scale", "2")
    assert tight < 0.2 and settings["loss_scale"] == 2.0
    loose, settings = weight_of_pose_5("--loss-scale", "1000")
    assert loose == 1.0 and settings["loss_scale"] == 1000.0
    default, settings = weight_of_pose_5()
    assert tight < default < loose and settings["loss_scale"] == DEFAULT_LOSS_SCALE
    with pytest.raises(SystemExit):
        main(["calibrate", "--help"])
    assert f"(default {DEFAULT_LOSS_SCALE:g})" in " ".join(capsys.readouterr().out.split())


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--loss", "huber", "--loss-scale", "0"], "--loss-scale must be a finite number > 0"),
        (["--loss", "cauchy", "--loss-scale", "-1"], "--loss-scale must be a finite number > 0"),
        (["--loss", "huber", "--loss-scale", "nan"], "--loss-scale must be a finite number > 0"),
        (["--loss", "huber", "--loss-scale", "inf"], "--loss-scale must be a finite number > 0"),
        (["--loss-scale", "2"], "the linear loss has none"),
    ],
)
def test_loss_scale_errors(files, tmp_path, capsys, extra, message):
    assert main(["calibrate", "--robot", "smart_h4", "--model", "loop", "--data",
                 str(files / "cal.csv"), "--out", str(tmp_path / "p.json"), "--quiet",
                 *extra]) == 2
    assert message in capsys.readouterr().err


def test_calibrate_json_needs_no_out(files, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    argv = ["calibrate", "--robot", "smart_h4", "--model", "loop", "--data",
            str(files / "cal.csv"), "--quiet"]
    assert main([*argv, "--json"]) == 0
    captured = capsys.readouterr()
    d = json.loads(captured.out)
    assert d["model"]["number"] == 2 and d["calibration"]["mean_mm"] > 0
    assert captured.err == ""
    assert main(argv) == 0  # neither: the summary, and a word that nothing was saved
    captured = capsys.readouterr()
    assert captured.out.startswith("robot smart_h4, model 2 (loop)")
    assert "wrote" not in captured.out
    assert "parameters not saved: give --out PARAMS.json" in captured.err
    assert list(tmp_path.iterdir()) == []
