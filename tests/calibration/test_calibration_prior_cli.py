"""``plugcell calibrate --prior EARLIER.json`` (issue 36 part 2): the command around
:class:`~plugcell.calibration.prior.PriorCalibrator`, and its bad input."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from calibration_testlib import ur10_toml

from plugcell.apps.cli import main


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("prior")
    for name, n, seed in (("a", 80, 1), ("b", 25, 2), ("v", 40, 3)):
        assert main(["twin", "measure", "--poses", str(n), "--pose-seed", str(seed),
                     "--out", str(d / f"{name}.csv"), "--quiet"]) == 0
    assert main(["calibrate", "--robot", "smart_h4", "--model", "2", "--data", str(d / "a.csv"),
                 "--out", str(d / "a.json"), "--quiet"]) == 0
    return d


def _on_b(d: Path, *extra: str) -> list[str]:
    return ["calibrate", "--robot", "smart_h4", "--model", "2", "--data", str(d / "b.csv"),
            "--quiet", *extra]


def test_prior_writes_a_calibration_that_says_what_it_did(files, capsys):
    capsys.readouterr()
    assert main(_on_b(files, "--prior", str(files / "a.json"), "--prior-scale", "10",
                      "--validate", str(files / "v.csv"), "--out", str(files / "b.json"))) == 0
    out = capsys.readouterr().out
    assert "prior: the earlier calibration of smart_h4, BASE + PROBE re-identified" in out
    assert "× τ = 10 (given)" in out
    d = json.loads((files / "b.json").read_text())
    pri = d["settings"]["prior"]
    assert pri["scale"] == 10 and pri["regularised"] and not pri["layer_offset"]
    # the campaign's own stage was tried (25 poses) and its verdict printed
    assert "campaign stage: " in out and "adopted" in pri["stage"]
    assert d["validation"]["mean_mm"] < 0.5
    # what it wrote is a calibration the other commands read
    assert main(["export", "--params", str(files / "b.json"), "--format", "toml",
                 "--out", str(files / "b.toml")]) == 0


def test_prior_cv_kfold_reaches_the_choice_and_is_reported(files, capsys, monkeypatch):
    """``--prior-cv kfold``: the calibrator's choice runs with ``cv_split="kfold"`` and the
    printout names the random 10-fold CV, not the cells."""
    from plugcell.calibration.prior import PriorCalibrator

    seen = []

    def choose(self, data, offset=None):
        seen.append(self.cv_split)
        return 10.0, {"0": 2e-4, "10": 1e-4, "moved": 2e-4, "alone": 3e-4}

    monkeypatch.setattr(PriorCalibrator, "choose", choose)
    capsys.readouterr()
    assert main(_on_b(files, "--prior", str(files / "a.json"), "--prior-cv", "kfold",
                      "--prior-stage", "none", "--out", str(files / "b-kfold.json"))) == 0
    out = capsys.readouterr().out
    assert seen == ["kfold"]
    assert "× τ = 10 (random 10-fold CV)" in out
    assert "random 10-fold CV (mm): τ = 0 0.200, τ = 10 0.100, moved 0.200" in out
    pri = json.loads((files / "b-kfold.json").read_text())["settings"]["prior"]
    assert pri["scale_chosen_by"] == "random 10-fold CV"


def test_the_default_choice_is_the_random_split_with_the_one_se_rule(files, capsys,
                                                                    monkeypatch):
    """Without ``--prior-cv``/``--prior-se`` the choice runs on the random 10-fold with k = 1;
    ``--prior-se 2 --prior-cv cells`` reach the calibrator; the printout and PARAMS.json
    name the rule."""
    from plugcell.calibration.prior import PriorCalibrator

    seen = []

    def choose(self, data, offset=None):
        seen.append((self.cv_split, self.se_k))
        return 10.0, {"0": 2e-4, "10": 1e-4, "moved": 2e-4, "alone": 3e-4}

    monkeypatch.setattr(PriorCalibrator, "choose", choose)
    capsys.readouterr()
    assert main(_on_b(files, "--prior", str(files / "a.json"), "--prior-stage", "none",
                      "--out", str(files / "b-default.json"))) == 0
    out = capsys.readouterr().out
    assert "more than 1 standard error of the paired CV difference below the better" in out
    pri = json.loads((files / "b-default.json").read_text())["settings"]["prior"]
    assert pri["se_k"] == 1.0 and pri["scale_chosen_by"] == "random 10-fold CV"
    assert main(_on_b(files, "--prior", str(files / "a.json"), "--prior-stage", "none",
                      "--prior-se", "2", "--prior-cv", "cells",
                      "--out", str(files / "b-se2.json"))) == 0
    assert seen == [("kfold", 1.0), ("cells", 2.0)]


def test_the_summary_says_the_stage_rule(files):
    """The summary line of the campaign stage: adopted with its CV, its gain and the SE it
    beat; refused with the reason (what PARAMS.json's ``settings.prior.stage`` holds)."""
    from plugcell.apps.commands.calibrate import _summary

    assert main(_on_b(files, "--prior", str(files / "a.json"), "--prior-scale", "10",
                      "--prior-stage", "none", "--out", str(files / "b-summary.json"))) == 0
    d = json.loads((files / "b-summary.json").read_text())
    d["settings"]["prior"]["stage"] = {
        "adopted": True, "reason": "", "physical_mm": 0.40, "hybrid_mm": 0.35,
        "gain_mm": -0.05, "se_mm": 0.02, "se_k": 1.0, "cells": 9, "folds": 5, "params": {}}
    assert ("campaign stage: adopted (grouped CV over 9 cells: 0.400 -> 0.350 mm, gain 0.050 "
            "mm > 1 × its standard error 0.020 mm)") in _summary(d)
    d["settings"]["prior"]["stage"]["se_k"] = 0.0
    assert "gain 0.050 mm (standard error 0.020 mm))" in _summary(d)
    d["settings"]["prior"]["stage"].update(adopted=False, reason="its grouped CV gain …")
    assert "campaign stage: not used: its grouped CV gain …" in _summary(d)


def test_the_stage_k_is_its_own_option(files, capsys, monkeypatch):
    """``--prior-stage-se K`` reaches the calibrator's ``stage_se_k`` (default 0: the plain
    comparison) and leaves the choice's ``se_k`` alone."""
    from plugcell.calibration.prior import PriorCalibrator

    seen = []

    def choose(self, data, offset=None):
        seen.append((self.se_k, self.stage_se_k))
        return 10.0, {"0": 2e-4, "10": 1e-4, "moved": 2e-4, "alone": 3e-4}

    monkeypatch.setattr(PriorCalibrator, "choose", choose)
    for extra in ([], ["--prior-stage-se", "1.5"]):
        assert main(_on_b(files, "--prior", str(files / "a.json"), "--prior-stage", "none",
                          *extra, "--out", str(files / "b-stage-se.json"))) == 0
    assert seen == [(1.0, 0.0), (1.0, 1.5)]


def test_the_stage_weights_are_their_own_option(files, monkeypatch):
    """``--prior-stage-weights W,…`` reaches the calibrator's ``stage_weights`` (sorted;
    default {1}: the stage whole or not at all) and PARAMS.json's stage record holds the
    grid and the weight applied."""
    from plugcell.calibration.campaign_stage import STAGE_WEIGHTS
    from plugcell.calibration.prior import PriorCalibrator

    seen = []

    def choose(self, data, offset=None):
        seen.append(self.stage_weights)
        return 10.0, {"0": 2e-4, "10": 1e-4, "moved": 2e-4, "alone": 3e-4}

    monkeypatch.setattr(PriorCalibrator, "choose", choose)
    for extra in ([], ["--prior-stage-weights", "1, 0.5"]):
        assert main(_on_b(files, "--prior", str(files / "a.json"), *extra,
                          "--out", str(files / "b-weights.json"))) == 0
    assert seen == [STAGE_WEIGHTS, (0.5, 1.0)]
    st = json.loads((files / "b-weights.json").read_text())["settings"]["prior"]["stage"]
    assert st["weights"] == [0.5, 1.0] and st["weight"] in (0.0, 0.5, 1.0)
    assert (st["weight"] > 0) == st["adopted"]


def test_the_summary_says_the_stage_weight(files):
    """An adopted stage with a weight below 1: the summary gives the CV at that weight."""
    from plugcell.apps.commands.calibrate import _summary

    assert main(_on_b(files, "--prior", str(files / "a.json"), "--prior-scale", "10",
                      "--prior-stage", "none", "--out", str(files / "b-summary-w.json"))) == 0
    d = json.loads((files / "b-summary-w.json").read_text())
    d["settings"]["prior"]["stage"] = {
        "adopted": True, "reason": "", "physical_mm": 0.40, "hybrid_mm": 0.41,
        "cv_by_weight_mm": {"0": 0.40, "0.5": 0.37, "1": 0.41}, "weight": 0.5,
        "gain_mm": -0.03, "se_mm": 0.01, "se_k": 0.0, "cells": 9, "folds": 5, "params": {}}
    assert ("campaign stage: adopted (grouped CV over 9 cells: 0.400 -> 0.370 mm at weight "
            "0.5, gain 0.030 mm (standard error 0.010 mm))") in _summary(d)


@pytest.mark.parametrize(("extra", "message"), [
    (["--prior-scale", "3"], "--prior-scale needs --prior EARLIER.json"),
    (["--prior", "A", "--prior-scale", "0.5"],
     "--prior-scale must be 0 (BASE + PROBE only) or a number ≥ 1"),
    (["--prior-stage", "none"], "--prior-stage needs --prior EARLIER.json"),
    (["--prior-cv", "kfold"], "--prior-cv needs --prior EARLIER.json"),
    (["--prior-se", "1"], "--prior-se needs --prior EARLIER.json"),
    (["--prior", "A", "--prior-se", "-1"], "--prior-se must be a number ≥ 0 (standard errors), "
                                           "got -1.0"),
    (["--prior-stage-se", "1"], "--prior-stage-se needs --prior EARLIER.json"),
    (["--prior", "A", "--prior-stage-se", "nan"],
     "--prior-stage-se must be a number ≥ 0 (standard errors), got nan"),
    (["--prior-stage-weights", "0.5"], "--prior-stage-weights needs --prior EARLIER.json"),
    (["--prior", "A", "--prior-stage-weights", "0.5,x"],
     "--prior-stage-weights: 'x' is not a number (W[,W…], each in [0, 1])"),
    (["--prior", "A", "--prior-stage-weights", ""],
     "--prior-stage-weights: the campaign stage's weights are empty (give 0 for no stage)"),
    (["--prior", "A", "--prior-stage-weights", "0,1.5"],
     "--prior-stage-weights: each campaign stage weight must be a number in [0, 1], got 1.5"),
    (["--prior", "A", "--prior-stage-weights", "nan"],
     "--prior-stage-weights: each campaign stage weight must be a number in [0, 1], got nan"),
    (["--prior", "A", "--prior-stage-weights", "0.5,1,0.5"],
     "--prior-stage-weights: the campaign stage's weights list 0.5 twice"),
    (["--prior", "A"], "--prior needs --out PARAMS.json"),
    (["--prior", "A", "--thermal"], "--prior: --thermal cannot be combined with it"),
    (["--prior", "A", "--probe", "0,0,90,0,0,0"], "--prior: --probe cannot be combined"),
    (["--prior", "A", "--residual-model", "learned", "--out", "x.json"],
     "--residual-model learned cannot be combined"),
])
def test_options_that_mean_nothing_with_a_prior_are_refused(files, capsys, extra, message):
    extra = [str(files / "a.json") if x == "A" else x for x in extra]
    assert main(_on_b(files, *extra)) == 2
    assert message in capsys.readouterr().err


def test_a_prior_of_another_robot_or_model_or_no_calibration_is_refused(files, capsys,
                                                                         tmp_path):
    capsys.readouterr()
    # another model: names both
    other = _on_b(files, "--prior", str(files / "a.json"))
    other[other.index("--model") + 1] = "1"
    assert main(other) == 2
    err = capsys.readouterr().err
    assert "a calibration with model 2 (loop), not model 1 (serial); give --model 2" in err
    # another robot: names both
    (tmp_path / "ur.toml").write_text(ur10_toml())
    assert main(["calibrate", "--robot", str(tmp_path / "ur.toml"), "--model", "1",
                 "--data", str(files / "b.csv"), "--prior", str(files / "a.json")]) == 2
    err = capsys.readouterr().err
    assert "a.json" in err and "'smart_h4'" in err and "'ur10-test'" in err, err
    # a file that is not PARAMS.json
    assert main(_on_b(files, "--prior", str(files / "b.csv"))) == 2
    assert "b.csv: not valid JSON" in capsys.readouterr().err
    (tmp_path / "x.json").write_text('{"robot": "smart_h4"}')
    assert main(_on_b(files, "--prior", str(tmp_path / "x.json"))) == 2
    assert "not a plugcell calibration" in capsys.readouterr().err
    # a PARAMS.json without the earlier σ
    d = json.loads((files / "a.json").read_text())
    del d["sigma2"]
    (tmp_path / "nosigma.json").write_text(json.dumps(d))
    assert main(_on_b(files, "--prior", str(tmp_path / "nosigma.json"))) == 2
    assert "the earlier σ are missing" in capsys.readouterr().err
