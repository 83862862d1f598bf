"""Outputs say what their figures are (issue 39 §8): the parameter counts of a model
(identified of its parameters, and why the rest are not), a speed target met or not,
and the thesis's figures only beside the robot the thesis measured."""

from __future__ import annotations

import argparse
import json

import pytest

from plugcell.apps.bench import calibration as bench_calibration
from plugcell.apps.cli import main
from plugcell.apps.commands.calibrate import _counted


def test_calibrate_counts_identified_of_the_models_parameters():
    d = {"parameters": [{}] * 50, "dependent": [{}] * 13, "unidentifiable": ["A1"] * 9}
    assert _counted(d) == ("50 of its 72 parameters identified (13 stand for others, 9 not "
                           "identifiable from these data)")
    assert _counted({"parameters": [{}] * 30, "dependent": [], "unidentifiable": []}) == (
        "30 parameters identified")
    assert _counted({"parameters": [{}] * 37, "dependent": [{}] * 11}) == (
        "37 of its 48 parameters identified (11 stand for others)")


@pytest.mark.parametrize(("median_s", "said"), [(0.3069, "target < 50 ms: NOT met"),
                                                (0.0301, "target < 50 ms: met")])
def test_bench_calibration_says_whether_the_target_is_met(monkeypatch, capsys, median_s, said):
    monkeypatch.setattr(bench_calibration, "measure", lambda *a: {
        "parameters": 50, "model_parameters": 72, "t150_s": median_s,
        "t150_all_s": [median_s], "iterations_150": 4, "target_t150_s": 0.05,
        "scaling": []})
    assert bench_calibration.run(argparse.Namespace(repeat=1, max_poses=0, seed=0,
                                                    json=False)) == 0
    out = capsys.readouterr().out
    assert said in out and "model 5 (50 identified of its 72 parameters, one payload)" in out
    assert f"150 poses: median {median_s * 1e3:.1f} ms over 1 runs, 4 iterations" in out, out


def test_plan_says_identifiable_of_the_models_parameters(tmp_path, capsys):
    assert main(["plan", "--robot", "smart_h4", "--model", "5", "--poses", "60",
                 "--candidates", "400", "--out", str(tmp_path / "p.csv"), "--json"]) == 0
    captured = capsys.readouterr()
    d = json.loads(captured.out)
    assert d["model"]["parameters"] == 72 and d["model"]["identifiable"] == 51, d["model"]
    assert "for the 51 identifiable of the 72 parameters of model 5" in captured.err


def test_twin_report_shows_the_thesis_figures_only_for_the_smart_h4(capsys):
    assert main(["twin", "report", "--robot", "elbow6", "--poses", "10"]) == 0
    out = capsys.readouterr().out
    assert "thesis" not in out.splitlines()[1] and "4.03" not in out
    assert "(the thesis's figures are of the smart_h4: not shown for elbow6)" in out
    assert main(["twin", "report", "--poses", "10"]) == 0
    out = capsys.readouterr().out
    assert "thesis" in out.splitlines()[1] and "4.03" in out
