"""The runs of a repeated path (plugcell.compensation.tracking.repeat): judged by the
tracker's samples only, learned from when measured enough, stopped when converged or
diverging (the offset rolled back to the best run's), the windows never measured."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.signal import cont2discrete, lfilter

from plugcell.compensation.tracking.learning import (
    InverseSettings,
    IterativeLearning,
    LearningSettings,
)
from plugcell.compensation.tracking.repeat import RepeatedLearning, StopRule

T = 0.004
START = 10.0  # robot time the motion starts (s)
DURATION = 2.0


def _servo(u: np.ndarray, sign: float = 1.0) -> np.ndarray:
    """The arm's response to the target offset: an 8 Hz servo, two cycles dead time."""
    w = 2 * np.pi * 8.0
    b, a, _ = cont2discrete(([w * w], [1.0, 1.4 * w, w * w]), T, method="zoh")
    y = lfilter(np.ravel(b), np.ravel(a), u, axis=0)
    return sign * np.vstack([np.zeros((2, 3)), y[:-2]])


def _repeat(grid: np.ndarray) -> np.ndarray:
    d = np.zeros((grid.size, 3))
    d[:, 0] = 0.3e-3 * np.sin(np.pi * np.clip(grid / DURATION, 0, 1)) ** 2
    d[:, 1] = -0.1e-3 * np.sin(2 * np.pi * np.clip(grid / DURATION, 0, 1))
    return d


def _session(**rule) -> RepeatedLearning:
    s = LearningSettings(gain=0.8, lead_s=0.008, cutoff_hz=4.0, max_offset_m=5e-3)
    return RepeatedLearning(IterativeLearning(DURATION, s), StopRule(**rule))


def _run(rep: RepeatedLearning, k: int, sign: float = 1.0,
         hole: tuple[float, float] | None = None, noise: float = 20e-6):
    """One run: the tracker's samples (4 a cycle, fresh noise) of the error the arm makes
    with the session's offset; the commanded path is the origin."""
    lr = rep.learning
    g = lr.grid
    e = _repeat(g) + _servo(lr.u, sign)
    ts = (START + g[:, None] + T * np.array([-0.375, -0.125, 0.125, 0.375])).ravel()
    ps = np.repeat(e, 4, axis=0) + noise * np.random.default_rng(k).standard_normal((ts.size, 3))
    if hole is not None:
        keep = ~((ts >= START + hole[0]) & (ts < START + hole[1]))
        ts, ps = ts[keep], ps[keep]
    path_t = START + np.array([g[0] - 1.0, g[-1] + 1.0])
    return rep.learn(ts, ps, path_t, np.zeros((2, 3)), START), e


def test_the_runs_converge_and_stop_when_a_run_no_longer_pays():
    rep = _session()
    errors, used = [], []
    for k in range(12):
        used.append(rep.learning.u.copy())
        rec, _ = _run(rep, k)
        errors.append(rec.rms_m)
        if rec.stop:
            break
    assert [r.verdict for r in rep.records[:-1]] == ["learned"] * (len(rep.records) - 1)
    assert rep.records[-1].verdict == "converged" and "less than 5 % below" in \
        rep.records[-1].reason
    assert 3 <= len(rep.records) <= 10
    assert errors[-1] < 0.2 * errors[0]          # the repeatable error learned away
    assert all(r.measured == 1.0 for r in rep.records)
    assert rep.records[0].change_m > rep.records[1].change_m > 0
    assert rep.never_measured() == []
    # the offset kept is the one the best run used (measured), not the last update's
    best = int(np.argmin(errors))
    assert np.array_equal(rep.learning.u, used[best])


def test_a_growing_error_stops_the_runs_and_rolls_the_offset_back():
    rep = _session()
    # an arm that answers the wrong way (a sign error in the frames): the law diverges
    used = []
    for k in range(10):
        used.append(rep.learning.u.copy())
        rec, _ = _run(rep, k, sign=-1.0)
        if rec.stop:
            break
    last = rep.records[-1]
    assert last.verdict == "diverged" and math.isnan(last.change_m)
    assert "rolled back" in last.reason
    best = int(np.argmin([r.rms_m for r in rep.records]))
    np.testing.assert_array_equal(rep.learning.u, used[best])
    assert last.rms_m > 1.25 * rep.records[best].rms_m


def test_the_inverse_laws_identifying_run_is_learned_from_but_not_judged():
    """The run carrying the excitation errs by more than the divergence guard allows
    (its error holds the excitation): it neither stops the runs nor becomes the best;
    the plant is identified from it and the next updates are the inverse law's."""
    inv = InverseSettings(excitation_m=0.3e-3, band_high_hz=20.0)
    s = LearningSettings(gain=0.8, lead_s=0.008, cutoff_hz=4.0, max_offset_m=5e-3, inverse=inv)
    rep = RepeatedLearning(IterativeLearning(DURATION, s), StopRule())
    used = []
    for k in range(3):
        used.append(rep.learning.u.copy())
        _run(rep, k)
    first, excited, third = rep.records
    assert (first.verdict, first.law) == ("learned", "p")
    assert excited.rms_m > 1.25 * first.rms_m  # the guard would have fired on it
    assert (excited.verdict, excited.law, excited.stop) == \
        ("learned", "inverse", False)
    assert excited.reason == "the identifying run (excitation): not judged"
    assert rep.learning.plant is not None and third.law == "inverse"
    assert third.verdict != "diverged" and third.rms_m < first.rms_m


def test_a_run_the_tracker_hardly_saw_is_not_learned_from():
    rep = _session()
    before = rep.learning.u.copy()
    rec, _ = _run(rep, 0, hole=(-1.0, 1.5))  # the beam broken over 75 % of the motion
    assert rec.verdict == "not learned" and not rec.stop
    assert "measured 25 % of the motion" in rec.reason
    np.testing.assert_array_equal(rep.learning.u, before)
    assert rep.never_measured() == []  # nothing learned: no holes to speak of


def test_a_beam_break_at_the_same_place_in_every_run_is_a_window_never_measured():
    rep = _session()
    for k in range(3):
        _run(rep, k, hole=(0.5, 0.8))
    (a, b), = rep.never_measured()
    assert a == pytest.approx(0.5, abs=T) and b == pytest.approx(0.8, abs=T)
    assert [r.measured for r in rep.records] == [pytest.approx(1 - 0.3 / 2.0, abs=0.01)] * 3
    rep = _session()
    _run(rep, 0)  # the beam clear once: every cycle was measured in some learned run
    for k in range(1, 3):
        _run(rep, k, hole=(0.5, 0.8))
    assert [r.verdict for r in rep.records] == ["learned"] * 3
    assert rep.never_measured() == []


def test_no_sample_at_all_is_a_run_not_learned_with_nan_errors():
    rep = _session()
    rec = rep.learn(np.zeros(0), np.zeros((0, 3)), [0.0, 100.0], np.zeros((2, 3)), START)
    assert rec.verdict == "not learned" and math.isnan(rec.rms_m) and rec.measured == 0.0


@pytest.mark.parametrize(("kw", "message"), [
    ({"converged_rel": 1.0}, "converged_rel must be a finite number in [0, 1)"),
    ({"diverged_rel": 0.0}, "diverged_rel must be a finite number > 0"),
    ({"min_measured": math.nan}, "min_measured must be a finite number in [0, 1]"),
    ({"min_change_m": -1.0}, "min_change_m must be a finite number ≥ 0"),
])
def test_stop_rule_refuses_bad_values(kw, message):
    with pytest.raises(ValueError, match=message.replace("[", r"\[").replace(")", r"\)")):
        StopRule(**kw)


def test_a_learning_resumed_from_its_best_run_judges_against_it():
    """A learning run once a session (a robot program's tracked move) goes on from the
    earlier session's best run: a run that does not improve on it ends the runs as
    converged and keeps the offset that best run used."""
    lr = IterativeLearning(1.0, LearningSettings())
    u_best = np.full_like(lr.u, 1e-5)
    rep = RepeatedLearning(lr)
    rep.resume((1e-4, u_best, 3))
    assert rep.best[0] == 1e-4 and rep.best[2] == 3
    t = np.linspace(0.0, 1.0, 1001)
    path = np.zeros((t.size, 3))
    worse = path + np.array([2e-4, 0.0, 0.0])  # 0.2 mm: twice the best run's
    rec = rep.learn(t, worse, t, path, 0.0)
    assert rec.verdict == "diverged" and "the best run's 0.1000 mm" in rec.reason
    np.testing.assert_array_equal(lr.u, u_best)
    assert lr.steps == 3
    with pytest.raises(ValueError, match=r"RepeatedLearning\.resume"):
        rep.resume((1e-4, np.zeros((3, 3)), 1))
