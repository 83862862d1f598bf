"""``plugcell path run``: a path on the twin with the tracker in the loop, and its faults.

The runs are in simulated time (the twin's controller waits for each answer), so they do
not depend on the machine's load; each takes a few tens of seconds on a loaded machine.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import plugcell
from plugcell.io.path_files import parse_path
from plugcell.sim.path_run import PathRunOptions, run_path

#: 80 mm along y at 100 mm/s from the Smart H4's home TCP; the last 30 mm untracked.
PATH = """x,y,z,a,b,c,speed,tracking
1473.3,-231.7,2488.4,-60,30,-90,,
1473.3,-181.7,2488.4,-60,30,-90,100,1
1473.3,-151.7,2488.4,-60,30,-90,100,0
"""


#: 100 mm tracked: long enough for a break, the re-acquisition and the resumption.
LONG = """x,y,z,a,b,c,speed
1473.3,-231.7,2488.4,-60,30,-90,
1473.3,-131.7,2488.4,-60,30,-90,100
"""


def _run(text=PATH, calibration=None, **kw):
    return run_path(parse_path(text, "p.csv"), PathRunOptions(**kw), calibration=calibration)


@pytest.fixture(scope="module")
def calibration():
    """Model 5 of the path's twin (seed 0, 36 kg) from its own 90-pose campaign."""
    from plugcell.sim.twin.calibrated import calibrate_twin
    from plugcell.sim.twin.robot import RobotTwin
    from plugcell.sim.twin.scenario import TwinScenario

    twin = RobotTwin(TwinScenario(robot="smart_h4", seed=0, payload_kg=36.0))
    return calibrate_twin(twin, 90, joints_seed=1, tracker_seed=0)


@pytest.fixture(scope="module")
def tracked():
    return _run()


@pytest.fixture(scope="module")
def untracked():
    return _run(tracking=False)


@pytest.mark.slow
def test_the_tracker_makes_the_tracked_segment_accurate(tracked, untracked):
    with_t = tracked.accuracy.of(0, "all")
    without = untracked.accuracy.of(0, "all")
    assert tracked.ended == "" and untracked.ended == ""
    assert without.perpendicular_max > 1e-3  # the nominal model is millimetres off
    assert with_t.perpendicular_max < 0.5 * without.perpendicular_max
    # the segment asking for no tracking is not corrected: the model alone again
    assert tracked.accuracy.of(1, "off") is not None
    assert tracked.accuracy.of(1, "all").perpendicular_max > with_t.perpendicular_max
    assert tracked.samples_ok > 100 and tracked.late == 0


@pytest.mark.slow
def test_the_corrected_path_never_jumps(tracked):
    offset = tracked.traces["corrected"] - tracked.traces["commanded"]
    step = np.abs(np.diff(offset, axis=0)).max()
    assert step <= 50e-3 * 0.004 + 1e-9  # the link's speed limit: 50 mm/s × 4 ms


@pytest.mark.slow
def test_a_beam_break_is_a_window_and_tracking_resumes_by_itself():
    run = _run(LONG, beam_breaks=((0.05, 0.1),))
    assert run.ended == ""
    [w] = run.windows
    assert w.reason == "line_of_sight" and 0.05 <= w.start_s <= 0.15
    assert w.end_s is not None and w.end_s > 0.45  # re-acquired (0.3 s), resumed
    states = set(run.traces["state"][run.traces["segment"] == 0].tolist())
    assert {"tracking", "holding"} <= states
    assert run.samples_lost > 0


@pytest.mark.slow
def test_a_tracker_gone_ends_the_run_with_the_reason_and_no_jump():
    run = _run(tracker_lost_at=0.2, silence_s=0.1)
    assert run.ended.startswith("tracker silent for")
    # the loop holds as soon as samples are late; the run ends when the silence lasts
    assert run.windows and run.windows[-1].reason in ("late, then tracker silent",
                                                      "tracker silent")
    assert run.windows[-1].end_s is None
    offset = run.traces["corrected"] - run.traces["commanded"]
    assert np.abs(np.diff(offset, axis=0)).max() <= 50e-3 * 0.004 + 1e-9


@pytest.mark.slow
def test_a_calibrated_model_compensates_the_path_without_the_tracker(untracked, calibration):
    run = _run(calibration=calibration, tracking=False)
    nominal = untracked.accuracy.of(-1, "all")
    model = run.accuracy.of(-1, "all")
    assert nominal.perpendicular_max > 1.5e-3  # the nominal model: millimetres
    assert model.perpendicular_max < 0.4 * nominal.perpendicular_max
    assert model.along_max < 0.5 * nominal.along_max
    assert set(run.traces["state"][run.traces["segment"] >= 0].tolist()) == {"model"}


@pytest.mark.slow
def test_a_3dof_reflector_corrects_the_position_with_the_models_orientation(untracked):
    run = _run(six_dof=False)
    assert run.ended == "" and run.samples_ok > 100
    with_t = run.accuracy.of(0, "all")
    assert with_t.perpendicular_max < 0.5 * untracked.accuracy.of(0, "all").perpendicular_max


def test_a_calibration_of_another_robot_is_refused():
    from types import SimpleNamespace as Ns

    other = Ns(model=Ns(structure=Ns(source=Ns(name="kr16"))), residual_model=None)
    with pytest.raises(ValueError, match="the calibration is of the robot 'kr16', the path "
                       "runs on 'smart_h4'"):
        _run(calibration=other)


def _cli(*args, cwd):
    env = {**os.environ, "PYTHONPATH": str(Path(plugcell.__file__).parents[1])}
    return subprocess.run([sys.executable, "-m", "plugcell", "path", "run", *args],
                          capture_output=True, text=True, cwd=cwd, timeout=600, env=env)


@pytest.mark.parametrize(("text", "args", "message"), [
    ("x,y,z\n1,2,3\n1,2\n", (), "p.csv: line 3: 2 cells, the header has 3"),
    ("x,y,q\n", (), "p.csv: line 1: unknown column 'q'"),
    (PATH, ("--beam-break", "1"), "--beam-break '1': expected START:DURATION"),
    (PATH, ("--rate", "2000"), "rate 2000 Hz outside 1…1000 Hz"),
    ("x,y,z\n0,0,0\n0,0,10\n", (), "p.csv: line 2: "),
])
def test_cli_errors_name_the_cause(tmp_path, text, args, message):
    (tmp_path / "p.csv").write_text(text)
    out = _cli("--path", "p.csv", *args, cwd=tmp_path)
    assert out.returncode == 2, out.stderr
    assert message in out.stderr


@pytest.mark.slow
def test_cli_prints_the_table_and_writes_the_result(tmp_path):
    (tmp_path / "p.csv").write_text(PATH)
    out = _cli("--path", "p.csv", "--out", "r.json", "--json", "--tracker-lost-at", "0.05",
               cwd=tmp_path)
    assert out.returncode == 1 and "ended early: tracker silent" in out.stderr
    result = json.loads(out.stdout)
    saved = json.loads((tmp_path / "r.json").read_text())
    assert saved["accuracy"] == result["accuracy"] and saved["ended"] == result["ended"]
    assert len(saved["traces"]["t_s"]) == result["cycles"]
    assert {r["segment"] for r in result["accuracy"]} == {0, 1, -1}
