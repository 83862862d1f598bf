"""``plugcell demo --fast``: the thesis end to end over service processes (issue 9).

What CI runs.  The figures must be those of a working cell, not the thesis's numbers
copied: the checks are orderings and bounds the physics implies.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = [pytest.mark.slow, pytest.mark.timeout(420)]


def test_demo_fast_runs_the_three_steps_over_services(tmp_path: Path) -> None:
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    proc = subprocess.run(
        [sys.executable, "-m", "plugcell", "demo", "--fast", "--json", "--out", str(tmp_path)],
        capture_output=True, text=True, timeout=400, env=env, start_new_session=True)
    assert proc.returncode == 0, proc.stderr[-3000:]
    r = json.loads(proc.stdout)
    assert "1. Calibration" in proc.stderr  # progress goes to stderr with --json
    c, k, d = r["calibration"], r["compensation"], r["demonstration"]
    print(json.dumps({"calibration": c, "compensation": k, "demonstration": d}, indent=1,
                     default=float)[:4000])  # shown when an assertion below fails
    # 8.2: model 5 identified from the program's measurements, checked on other poses
    assert c["validation"]["before_mean_mm"] > 1.0
    assert c["validation"]["mean_mm"] < 0.3
    # 8.3: the sensor stage beats the model stage, which is sub-millimetre
    assert k["sigma3_position_mm"]["model"] < 1.0
    assert k["sigma3_position_mm"]["sensor"] < k["sigma3_position_mm"]["model"]
    assert k["not_corrected"] == 0
    # 8.4: nominal (mm) → model → sensor (≤ 0.1 mm), one tracker serving both robots
    m = d["mean_position_mm"]
    assert m["initial"] > 1.0 > m["model"] > m["sensor"] and m["sensor"] < 0.1
    assert d["initial_measured"] == d["targets"]
    assert d["tracker_served"]["robot1"] > d["targets"] and d["tracker_served"]["robot2"] >= 3
    assert d["kuka_smr_spread_mm"] < 0.05  # a fixed SMR, measured again and again
    # the files: the JSON, the report, every service's journal
    assert json.loads((tmp_path / "demo.json").read_text())["cell"] == r["cell"]
    page = (tmp_path / "report.html").read_text()
    assert "8.3: 3σ position after sensor" in page and "<img src='errors.png'" in page
    assert (tmp_path / "errors.png").read_bytes()[:4] == b"\x89PNG"
    assert len(k["errors_mm"]["sensor"]) == k["targets"]
    assert len(d["errors_mm"]["nominal"]) == d["targets"]
    names = {Path(p).stem for p in r["journal"]}
    assert {"TRACKER", "COMPUTE", "H4", "KUKA", "CONTROLLER"} <= names


def test_demo_refuses_a_speed_that_is_not_one(tmp_path: Path, capsys) -> None:
    from plugcell.apps.cli import main

    assert main(["demo", "--fast", "--speed", "0", "--out", str(tmp_path)]) == 2
    assert "--speed must be positive, not 0.0" in capsys.readouterr().err
    assert not (tmp_path / "demo.json").exists()  # refused before anything started


def test_demo_fast_over_rsi_calibrates_with_the_program_on_the_pc(tmp_path: Path) -> None:
    """``plugcell demo --fast --link rsi``: H4's calibration program runs on the PC, every
    move streams over KUKA RSI to the twin's RSI side (its own process, the dynamic twin),
    the tracker measures the T-MAC the twin publishes as it moves, COMPUTE identifies."""
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    proc = subprocess.run(
        [sys.executable, "-m", "plugcell", "demo", "--fast", "--link", "rsi", "--json",
         "--out", str(tmp_path)],
        capture_output=True, text=True, timeout=400, env=env, start_new_session=True)
    assert proc.returncode == 0, proc.stderr[-3000:]
    r = json.loads(proc.stdout)
    assert "over RSI" in proc.stderr and "the twin's RSI side" in proc.stderr
    c = r["calibration"]
    print(json.dumps({"calibration": c, "rsi": r["rsi"]}, indent=1, default=float))
    assert r["config"]["link"] == "rsi" and c["poses"] == r["config"]["calibration_poses"]
    # model 5 from measurements of the moving twin, checked on other poses: 15 poses for
    # 50 parameters and the arm's ringing make the fast run's figure vary (0.24–0.56 mm
    # measured, docs/demo.md) around the thesis's 0.363 mm
    assert c["validation"]["before_mean_mm"] > 1.0
    assert c["validation"]["mean_mm"] < 0.7
    assert c["validation"]["poses"] == r["config"]["validation_poses"]
    # the moves went over RSI: thousands of 4 ms cycles, answered (lockstep); on a loaded
    # machine a few answers come late and are counted, not answered (CI run 17: 18 of
    # 8 059 at load 21) — the stream must not have broken off
    rsi = r["rsi"]
    assert rsi["cycles"] > 2000 and rsi["answered"] >= 0.99 * rsi["cycles"]
    assert "compensation" not in r and "demonstration" not in r  # step 1 only
    names = {Path(p).stem for p in r["journal"]}
    assert {"TRACKER", "COMPUTE", "H4", "CONTROLLER"} <= names and "KUKA" not in names
    assert "calibration: campaign wall time" in (tmp_path / "report.html").read_text()


def test_demo_over_rsi_refuses_a_simulated_speed(tmp_path: Path, capsys) -> None:
    from plugcell.apps.cli import main

    assert main(["demo", "--fast", "--link", "rsi", "--speed", "20", "--out",
                 str(tmp_path)]) == 2
    assert "over RSI the twin moves in real time: speed must be 1, not 20" in \
        capsys.readouterr().err
    assert not (tmp_path / "demo.json").exists()
