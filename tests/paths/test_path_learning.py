"""``plugcell path run --learn N`` / ``--learned FILE`` / ``--learned-out FILE`` on the twin:
the learned offset reaches the robot through the RSI seam, the runs learn from the
tracker's samples and get better, the correction is saved, reused and refused for another
path or speed, and the faults (bad N, corrupt file, beam broken in every run, a tracker
gone) end with the reason.  Simulated time: the results do not depend on the machine."""

from __future__ import annotations

import contextlib
import io
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import plugcell
from plugcell.apps.cli import main
from plugcell.compensation.tracking.learning import DEFAULT_WEIGHTING, IterativeLearning
from plugcell.io.learned_paths import LearnedFile, save_learned
from plugcell.io.path_files import parse_path
from plugcell.sim.path_learning import learned_context, learning_settings
from plugcell.sim.path_run import PathRunOptions, run_path

#: 80 mm along y at 100 mm/s from the Smart H4's home TCP.
PATH = """x,y,z,a,b,c,speed
1473.3,-231.7,2488.4,-60,30,-90,
1473.3,-151.7,2488.4,-60,30,-90,100
"""


def _cli(*args, cwd):
    """``plugcell path run ARGS`` as a process of its own (the real exit code)."""
    env = {**os.environ, "PYTHONPATH": str(Path(plugcell.__file__).parents[1])}
    return subprocess.run([sys.executable, "-m", "plugcell", "path", "run", *args],
                          capture_output=True, text=True, cwd=cwd, timeout=900, env=env)


def _main(*args, cwd):
    """``plugcell path run ARGS`` in ``cwd`` in this process (``plugcell.apps.cli.main``,
    what ``python -m plugcell`` runs; the exit code of the real process is
    :func:`_cli`'s): its exit code, stdout and stderr.  The learning's modules (SciPy's
    signal, the calibration) are loaded once, not again by a process a run."""
    out, err = io.StringIO(), io.StringIO()
    here = os.getcwd()
    os.chdir(cwd)
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                code = main(["path", "run", *args])
            except SystemExit as exc:  # argparse's own refusals
                code = exc.code
    finally:
        os.chdir(here)
    return subprocess.CompletedProcess(args, code, out.getvalue(), err.getvalue())


def _other_file(tmp_path: Path, text: str, name: str) -> Path:
    """A learned correction for the path ``text`` (nothing learned yet), as the command
    writes it."""
    path = parse_path(text, name)
    o = PathRunOptions()
    ctx = learned_context(path, name, o, "nominal", False)
    f = tmp_path / f"{name}.learned.json"
    save_learned(f, LearnedFile(ctx, IterativeLearning(ctx.duration_s, learning_settings(o)),
                                []))
    return f


def test_a_continued_learning_judges_its_runs_against_the_files_best_run(tmp_path):
    """``--learned FILE --learn N``: the stop rule starts from the file's best run (as the
    robot service's tracked moves do), so a continued learning stops and rolls back as an
    uninterrupted one would; fed forward only (no ``--learn``), nothing is judged."""
    import argparse

    from plugcell.apps.commands.path import configure  # the command's own options
    from plugcell.apps.commands.path_learn import _session

    path = parse_path(PATH, "p.csv")
    o = PathRunOptions()
    ctx = learned_context(path, "p.csv", o, "nominal", False)
    learning = IterativeLearning(ctx.duration_s, learning_settings(o))
    u = np.full_like(learning.u, 0.1e-3)
    f = tmp_path / "l.json"
    save_learned(f, LearnedFile(ctx, learning, [], best=(0.05e-3, u, 2)))
    parser = argparse.ArgumentParser()
    configure(parser)
    for extra, judged in ((["--learn", "1"], True), ([], False)):
        args = parser.parse_args(["run", "--path", "p.csv", "--learned", str(f), *extra])
        _, repeated, _ = _session(args, path, "p.csv", o, None)
        if judged:
            rms, best_u, steps = repeated.best
            assert rms == pytest.approx(0.05e-3, rel=1e-9) and steps == 2
            np.testing.assert_allclose(best_u, u, rtol=0, atol=1e-12)
        else:
            assert repeated.best is None


@pytest.mark.parametrize(("args", "message"), [
    (("--learn", "0"), "--learn must be ≥ 1 run, got 0"),
    (("--learn", "-2"), "--learn must be ≥ 1 run, got -2"),
    (("--learned-out", "l.json"), "--learned-out needs --learn N: nothing is learned without it"),
    (("--learned", "none.json"), "none.json: cannot read: no such file"),
    (("--learned", "p.csv"), "p.csv: not a JSON document"),
    (("--learn", "2", "--learn-diverged", "0"), "--learn-converged/--learn-diverged: "
     "StopRule.diverged_rel must be a finite number > 0"),
    (("--learn", "2", "--learn-gain", "2.5"), "--learn-gain/--learn-cutoff: LearningSettings."
     "gain (L) must lie in (0, 2)"),
    (("--learn-gain", "1"), "--learn-gain/--learn-cutoff set up a new learning"),
    (("--learn-law", "inverse"), "--learn-law needs --learn N: it is the law of a learning"),
    (("--learn", "1", "--learn-law", "inverse"), "--learn-law inverse needs --learn N ≥ 2, "
     "got 1: the first run's update adds a known excitation, the second run identifies the "
     "plant from it (or keep the learning with --learned-out FILE and go on with --learned "
     "FILE --learn N)"),
    (("--learn", "2", "--learn-law", "q"), "--learn-law: invalid choice: 'q'"),
    (("--learn", "2", "--weighting", "none"), "--inverse-reidentify/--weighting set up the "
     "inverse law of a new learning (--learn N --learn-law inverse without --learned"),
    (("--learn", "2", "--learn-law", "p", "--inverse-reidentify", "0"),
     "--inverse-reidentify/--weighting set up the inverse law of a new learning"),
    (("--learned", "p.csv", "--learn", "2", "--learn-law", "inverse", "--weighting", "none"),
     "--inverse-reidentify/--weighting set up the inverse law of a new learning"),
    (("--learn", "2", "--learn-law", "inverse", "--inverse-reidentify", "2"),
     "--inverse-reidentify: invalid choice: 2"),
    (("--learn", "2", "--learn-law", "inverse", "--weighting", "wiener"),
     "--weighting: invalid choice: 'wiener'"),
    (("--learn", "2", "--weighting-detect", "3"),
     "--inverse-reidentify/--weighting set up the inverse law of a new learning"),
    (("--learn", "2", "--learn-law", "inverse", "--weighting", "none", "--weighting-window-s",
      "1"), "--weighting-detect/--weighting-window-s/--weighting-detect-fell set up the Kalman "
     "weighting: not with --weighting none"),
    (("--learn", "2", "--learn-law", "inverse", "--weighting", "none",
      "--weighting-detect-fell", "1"), "not with --weighting none"),
    (("--learn", "2", "--learn-law", "inverse", "--weighting-detect-fell", "2"),
     "--weighting-detect-fell: invalid choice: 2"),
    (("--learn", "2", "--learn-law", "p", "--weighting-detect-fell", "1"),
     "--inverse-reidentify/--weighting set up the inverse law of a new learning"),
    (("--learn", "2", "--learn-law", "inverse", "--weighting-detect", "-1"),
     "--weighting-detect/--weighting-window-s: WeightingSettings: smooth_hz must be > 0, "
     "detect and window_s ≥ 0, got 0.5, -1.0 and 1.0"),
    (("--learn", "2", "--learn-law", "inverse", "--weighting-window-s", "nan"),
     "--weighting-detect/--weighting-window-s: WeightingSettings.window_s"),
])
def test_bad_learning_options_are_refused_before_anything_runs(tmp_path, monkeypatch, capsys,
                                                            args, message):
    """In this process (``plugcell.apps.cli.main``, what ``python -m plugcell`` runs): the
    refusals are the parser's and the command's checks; the exit code 2 of the real
    process is the next test's."""
    (tmp_path / "p.csv").write_text(PATH)
    monkeypatch.chdir(tmp_path)
    try:
        code = main(["path", "run", "--path", "p.csv", *args])
    except SystemExit as exc:  # argparse's own refusals (an invalid choice)
        code = exc.code
    out = capsys.readouterr()
    assert code == 2, out.err
    assert message in out.err
    assert "segment" not in out.out and "run " not in out.out


@pytest.mark.slow
def test_a_correction_of_another_path_or_speed_is_refused_with_the_reason(tmp_path):
    (tmp_path / "p.csv").write_text(PATH)
    other = _other_file(tmp_path, PATH.replace("-151.7", "-141.7"), "other.csv")
    out = _cli("--path", "p.csv", "--learned", str(other), cwd=tmp_path)
    assert out.returncode == 2
    assert f"{other}: cannot be used for this run: it was learned on the path 'other.csv' " \
           "(sha256 " in out.stderr and "this run's path 'p.csv' is another" in out.stderr
    slow = _other_file(tmp_path, PATH, "p.csv")
    out = _cli("--path", "p.csv", "--learned", str(slow), "--speed", "100", "--payload", "20",
               cwd=tmp_path)
    assert out.returncode == 2
    assert "it was learned with a payload of 36 kg, this run carries 20 kg" in out.stderr
    (tmp_path / "q.csv").write_text(PATH.replace(",100\n", ",250\n"))
    out = _cli("--path", "q.csv", "--learned", str(slow), cwd=tmp_path)
    assert "segment 1 was learned at 100 mm/s, this run goes 250 mm/s" in out.stderr


@pytest.mark.slow
def test_the_learned_offset_reaches_the_robot_through_the_rsi_seam():
    """A constant learned offset of 0.2 mm in x moves the twin's true TCP by that much
    over the path (the model alone: no tracker term to mix in)."""
    path = parse_path(PATH, "p.csv")
    o = PathRunOptions(tracking=False)
    plain = run_path(path, o)
    shifted = run_path(path, o, learned=lambda t: np.array([0.2e-3, 0.0, 0.0]))
    # both traces start at cycle 0 (t = k·T − settle); a run may record a cycle more after
    # its program ended (the link's last answer races the robot's stop), so compare the
    # cycles both have
    n = min(plain.traces["t"].size, shifted.traces["t"].size)
    on = plain.traces["segment"][:n] >= 0
    d = shifted.traces["actual"][:n][on] - plain.traces["actual"][:n][on]
    np.testing.assert_allclose(d.mean(axis=0), [0.2e-3, 0.0, 0.0], atol=0.01e-3)
    assert np.abs(d[:, 0] - 0.2e-3).max() < 0.03e-3


@pytest.mark.slow
def test_learning_runs_get_better_save_and_reuse_the_correction(tmp_path):
    (tmp_path / "p.csv").write_text(PATH)
    out = _main("--path", "p.csv", "--learn", "3", "--learned-out", "l.json", "--json",
               "--out", "r.json", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    doc = json.loads(out.stdout)
    result = json.loads((tmp_path / "r.json").read_text())
    assert result["format"] == "plugcell-tracked-path" and result["learning"] == doc
    runs = doc["runs"]
    assert 2 <= len(runs) <= 3 and runs[0]["verdict"] == "learned"
    # the tracker's view improves, and so does the truth it never saw
    assert runs[1]["tracker_rms_mm"] < 0.6 * runs[0]["tracker_rms_mm"]
    assert runs[1]["perpendicular_3sigma_mm"] < runs[0]["perpendicular_3sigma_mm"]
    assert runs[1]["along_max_mm"] < runs[0]["along_max_mm"]
    assert "run 1/3 p.csv" not in out.stderr  # --json: no progress lines
    saved = json.loads((tmp_path / "l.json").read_text())
    assert saved["context"]["path"] == "p.csv" and saved["context"]["speeds_mm_s"] == [100.0]
    assert len(saved["runs"]) == len(runs) and saved["steps"] == len(runs)
    assert 0.1 < np.abs(saved["offset"]["u_mm"]).max() < 5.0

    again = _main("--path", "p.csv", "--learned", "l.json", cwd=tmp_path)
    assert again.returncode == 0, again.stderr
    assert f"learned correction: l.json ({len(runs)} updates, largest offset" in again.stdout
    assert "fed forward, not learning" in again.stdout and "   path  all" in again.stdout

    more = _main("--path", "p.csv", "--learned", "l.json", "--learn", "1", "--learned-out",
                "l2.json", cwd=tmp_path)
    assert more.returncode == 0, more.stderr
    assert more.stdout.startswith("run  perp 3σ mm")
    assert "run 1/1 p.csv" in more.stderr  # progress
    cont = json.loads((tmp_path / "l2.json").read_text())
    assert len(cont["runs"]) == len(runs) + 1
    # the new run is judged against the file's best run, as in an uninterrupted learning:
    # converged or diverged, the offset is the one the best run used — the file's best, or
    # the new run itself when it beat that by less than the converged share (it ran with
    # the file's offset: its steps; CI of 2026-11-28); else one step more
    if cont["runs"][-1]["verdict"] in ("converged", "diverged"):
        new_is_best = cont["best"]["measured_rms_mm"] < saved["best"]["measured_rms_mm"]
        if new_is_best:
            assert cont["runs"][-1]["verdict"] == "converged"
            assert cont["steps"] == cont["best"]["steps"] == saved["steps"]
            expected = saved["offset"]["u_mm"]
        else:
            assert cont["steps"] == saved["best"]["steps"] < len(runs) + 1
            expected = saved["best"]["u_mm"]
        np.testing.assert_allclose(cont["offset"]["u_mm"], expected, rtol=0, atol=1e-9)
    else:
        assert cont["steps"] == len(runs) + 1


@pytest.mark.slow
@pytest.mark.timeout(1200)  # ten runs of the path, two laws
def test_the_inverse_law_learns_and_its_file_is_continued_as_inverse(tmp_path):
    (tmp_path / "p.csv").write_text(PATH)
    out = _main("--path", "p.csv", "--learn", "3", "--learn-law", "inverse", "--learned-out",
               "l.json", "--json", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    runs = json.loads(out.stdout)["runs"]
    # the first update is the P-type law's (and adds the excitation), then the inverse's
    assert [r["law"] for r in runs] == ["p", "inverse", "inverse"]
    assert runs[1]["reason"] == "the identifying run (excitation): not judged"
    saved = json.loads((tmp_path / "l.json").read_text())
    assert saved["law"] == "inverse" and [r["law"] for r in saved["runs"]] == \
        ["p", "inverse", "inverse"]
    assert saved["format_version"] == 3 and saved["inverse"]["plant"]["frequency_hz"]
    # the defaults: re-identified after each run (the excited run and its pairs kept), the
    # input weighted (its settings and S_j kept)
    assert saved["inverse"]["settings"]["reidentify"] == 1 and saved["inverse"]["weighting"]
    state = saved["inverse"]["state"]
    assert state["excited"] and len(state["pairs"]) == 2 and state["weighting"]["prior"]
    # the file keeps the identified plant and the runs: the learning goes on by the
    # inverse law, the plant identified again from the saved pairs and the new run's
    more = _main("--path", "p.csv", "--learned", "l.json", "--learn", "1", "--learned-out",
                "m.json", "--json", cwd=tmp_path)
    assert more.returncode == 0, more.stderr
    assert [r["law"] for r in json.loads(more.stdout)["runs"]] == ["inverse"]
    again = json.loads((tmp_path / "m.json").read_text())
    assert again["inverse"]["plant"] != saved["inverse"]["plant"]
    assert again["inverse"]["state"]["pairs"][:2] == state["pairs"]
    assert len(again["inverse"]["state"]["pairs"]) == 3
    assert again["inverse"]["steps"] == saved["inverse"]["steps"] + 1
    # the old law on request: identified once, all of the error learned; one run a
    # session: the file saved before its identifying run keeps the run before it, the
    # next session identifies the plant, and a continued file keeps its plant
    old = _main("--path", "p.csv", "--learn", "1", "--learn-law", "inverse",
               "--inverse-reidentify", "0", "--weighting", "none", "--learned-out",
               "o.json", "--json", cwd=tmp_path)
    assert old.returncode == 0, old.stderr
    zeroth = json.loads((tmp_path / "o.json").read_text())
    assert zeroth["inverse"]["weighting"] is None and zeroth["inverse"]["plant"] is None
    assert zeroth["inverse"]["state"]["identifying"] is not None
    ident = _main("--path", "p.csv", "--learned", "o.json", "--learn", "1", "--learned-out",
                 "o1.json", "--json", cwd=tmp_path)
    assert ident.returncode == 0, ident.stderr
    assert json.loads(ident.stdout)["runs"][0]["reason"] == \
        "the identifying run (excitation): not judged"
    first = json.loads((tmp_path / "o1.json").read_text())
    assert first["inverse"]["plant"]["frequency_hz"]
    assert first["inverse"]["state"]["identifying"] is None
    assert _main("--path", "p.csv", "--learned", "o1.json", "--learn", "1", "--learned-out",
                "o2.json", cwd=tmp_path).returncode == 0
    second = json.loads((tmp_path / "o2.json").read_text())
    assert second["inverse"]["plant"] == first["inverse"]["plant"]
    assert second["inverse"]["state"]["pairs"] == first["inverse"]["state"]["pairs"]
    # by the P-type law on request; a P-type file is not continued by the inverse law
    p = _main("--path", "p.csv", "--learned", "l.json", "--learn", "1", "--learn-law", "p",
             "--learned-out", "p.json", "--json", cwd=tmp_path)
    assert p.returncode == 0 and [r["law"] for r in json.loads(p.stdout)["runs"]] == ["p"]
    assert json.loads((tmp_path / "p.json").read_text())["law"] == "p"
    refused = _main("--path", "p.csv", "--learned", "p.json", "--learn", "1", "--learn-law",
                   "inverse", cwd=tmp_path)
    assert refused.returncode == 2 and "p.json: cannot be continued by the law inverse: it " \
        "was learned with the P-type law" in refused.stderr
    assert "run " not in refused.stdout


@pytest.mark.slow
def test_a_beam_broken_in_every_run_is_reported(tmp_path):
    (tmp_path / "p.csv").write_text(PATH)
    whole = _main("--path", "p.csv", "--learn", "2", "--beam-break", "0:5", "--learned-out",
                 "l.json", cwd=tmp_path)
    assert whole.returncode == 1
    assert "no run could be learned from (beam broken in every run?): the tracker measured " \
           "0 % of the motion" in whole.stderr
    assert "nothing learned: l.json not written" in whole.stdout
    assert not (tmp_path / "l.json").exists()
    part = _main("--path", "p.csv", "--learn", "2", "--beam-break", "0.05:0.05", cwd=tmp_path)
    assert part.returncode == 0, part.stderr
    assert "never measured in any learned run: 0.0" in part.stdout
    rows = [line for line in part.stdout.splitlines() if line.startswith("  ")]
    assert len(rows) == 2  # and the window without tracking in each run
    assert all(re.search(r" 0\.\d\d–0\.\d\d s$", line) for line in rows), rows


@pytest.mark.slow
def test_a_run_that_ends_early_is_not_learned_from(tmp_path):
    (tmp_path / "p.csv").write_text(PATH)
    out = _main("--path", "p.csv", "--learn", "3", "--tracker-lost-at", "0.05", "--learned-out",
               "l.json", cwd=tmp_path)
    assert out.returncode == 1
    assert "run 1 ended early: tracker silent for" in out.stderr
    assert out.stdout.count("\n  ") == 1 and not (tmp_path / "l.json").exists()


@pytest.mark.slow
def test_a_diverging_learning_stops_and_keeps_the_best_runs_offset(tmp_path):
    """A learning filter far above the arm's first mode (25 Hz, L = 1.5): the second run's
    measured error grows, the runs stop and the saved offset is the first run's (none)."""
    (tmp_path / "p.csv").write_text(PATH)
    out = _main("--path", "p.csv", "--learn", "4", "--learn-gain", "1.5", "--learn-cutoff",
               "25", "--learned-out", "l.json", cwd=tmp_path)
    assert out.returncode == 1
    assert "diverged at run 2: the measured error grew to " in out.stderr
    assert "the learned offset is rolled back to the one that run used" in out.stderr
    rows = [line for line in out.stdout.splitlines() if line.startswith("  ")]
    assert len(rows) == 2
    saved = json.loads((tmp_path / "l.json").read_text())
    assert saved["steps"] == 0 and np.abs(saved["offset"]["u_mm"]).max() == 0.0
    assert [r["verdict"] for r in saved["runs"]] == ["learned", "diverged"]


def test_the_kalman_weightings_options_reach_a_new_learning():
    """``--weighting-detect``/``--weighting-window-s``: the weighting's settings of a new
    inverse-law learning; the defaults otherwise; refused beside ``--weighting none``."""
    from plugcell.compensation.tracking.smoothing import WeightingSettings

    o = PathRunOptions()
    s = learning_settings(o, law="inverse", kalman=WeightingSettings(detect=3.0, window_s=1.0))
    assert (s.weighting.detect, s.weighting.window_s) == (3.0, 1.0)
    assert learning_settings(o, law="inverse").weighting == DEFAULT_WEIGHTING
    with pytest.raises(ValueError, match="the Kalman weighting's settings with the weighting"):
        learning_settings(o, law="inverse", weighting="none", kalman=WeightingSettings())


@pytest.mark.slow  # one run of the path
def test_the_kalman_weightings_options_are_kept_in_the_learned_file(tmp_path, monkeypatch,
                                                                    capsys):
    (tmp_path / "p.csv").write_text(PATH)
    monkeypatch.chdir(tmp_path)
    code = main(["path", "run", "--path", "p.csv", "--learn", "1", "--learn-law", "inverse",
                 "--weighting-detect", "3", "--weighting-window-s", "1",
                 "--weighting-detect-fell", "1", "--learned-out", "f.json"])
    assert code == 0, capsys.readouterr().err
    saved = json.loads((tmp_path / "f.json").read_text())
    assert saved["inverse"]["weighting"]["detect"] == 3.0
    assert saved["inverse"]["weighting"]["window_s"] == 1.0
    assert saved["inverse"]["weighting"]["detect_fell"] == 1
    assert saved["inverse"]["state"]["identifying"] is not None  # goes on with --learned
