"""benchmarks/learning_residual.py's split of a learned path's error: the tracker's
systematic error in F0 (against the streaming tracker's own samples), the perpendicular
distance, and the decomposition's bookkeeping (true = −s + r)."""

from __future__ import annotations

import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

import learning_residual as lr
from dynamic_correction import _three_sigma, perpendicular
from plugcell.kinematics.transforms import invert
from plugcell.sim.twin.tracker import LaserTracker
from plugcell.sim.twin.tracker_stream import TrackerStream


def _base() -> np.ndarray:
    """The Smart H4 cell's BASE: the tracker at (4.6, 1.1, 0.35) m in the robot's frame,
    turned 197° about z (sim/twin/profiles/smart_h4.toml)."""
    c, s = np.cos(np.radians(197.0)), np.sin(np.radians(197.0))
    tracker_in_robot = np.eye(4)
    tracker_in_robot[:3, :3] = [[c, -s, 0], [s, c, 0], [0, 0, 1]]
    tracker_in_robot[:3, 3] = [4.6, 1.1, 0.35]
    return invert(tracker_in_robot)


@pytest.mark.parametrize("tracker_seed", [4, 5])
def test_the_systematic_error_in_f0_is_what_the_streams_samples_average_to(tracker_seed):
    """A static reflector at the paths' start streamed for 5 s at 20 Hz: the mean of the
    samples mapped to F0 (``B⁻¹``) minus the truth is the tracker's fixed error there,
    ``R_Bᵀ s(B p)`` — to the noise's ≈ 2 µm, against a field of ≈ 40 µm at these seeds
    (a wrong sign or frame fails)."""
    B = _base()
    tracker = LaserTracker(seed=tracker_seed)
    p_f0 = np.array([1.6, -0.4, 1.1])
    p_tr = B[:3, :3] @ p_f0 + B[:3, 3]
    T = np.eye(4)
    T[:3, 3] = p_tr
    tracker.point_at(p_tr)
    stream = TrackerStream(tracker, lambda t: T, 20.0, six_dof=False, seed=3)
    got = np.array([s.pose[:3, 3] for s in stream.advance(5.0) if s.status == "ok"])
    assert len(got) > 90
    measured_f0 = (got.mean(0) - B[:3, 3]) @ B[:3, :3]
    cell = SimpleNamespace(model=SimpleNamespace(base=B), tracker=tracker)
    s = lr.tracker_error_f0(cell, p_f0[None])[0]
    assert np.linalg.norm(s) > 30e-6
    np.testing.assert_allclose(measured_f0 - p_f0, s, atol=6e-6)


def test_the_perpendicular_distance_of_a_shifted_line_and_circle():
    y = np.linspace(0, 1, 101)
    line = np.c_[np.full_like(y, 1.6), y - 0.5, np.full_like(y, 1.1)]
    # along the line: no distance; across it: the shift's size, constant (3σ = it)
    assert np.abs(perpendicular(line + np.array([0, 5e-6, 0]), line[0], "line")).max() < 1e-15
    shifted = line + np.array([3e-6, 0, 4e-6])
    np.testing.assert_allclose(perpendicular(shifted, line[0], "line"), 5e-6)
    th = np.linspace(0, 2 * np.pi, 20001)
    centre = np.array([1.6, -0.35, 1.1])
    circ = centre + 0.15 * np.c_[np.sin(th), -np.cos(th), 0 * th]
    assert perpendicular(circ, circ[0], "circle").max() < 1e-12
    # a circle shifted by m in its plane is |m cos θ| off: mean 2m/π, 3σ ≈ 1.56 m;
    # out of its plane by h: h everywhere
    m = 10e-6
    d = perpendicular(circ + np.array([m, 0, 0]), circ[0], "circle")
    assert d.mean() == pytest.approx(2 * m / np.pi, rel=1e-3)
    assert _three_sigma(d) == pytest.approx(m * (2 / np.pi + 3 * np.sqrt(0.5 - 4 / np.pi ** 2)),
                                            rel=1e-3)
    lifted = circ + np.array([0, 0, m])
    np.testing.assert_allclose(perpendicular(lifted, circ[0], "circle"), m, rtol=1e-6)


def _synthetic(shape: str, s_vec, r_amp: float, runs: int = 3) -> dict:
    """A recorded learning as :func:`learning_residual.record` saves it, on the taught
    geometry: the tracker's error ``s`` constant, the arm's residual a 10 Hz ripple
    across the path (changing sign run to run)."""
    t = np.arange(-0.2, 3.6, 0.004)
    u = np.clip(t / 3.2, 0, 1)  # the window (the motion + 0.2 s) one whole circle
    if shape == "line":
        cmd = np.c_[np.full_like(u, 1.6), u - 0.5, np.full_like(u, 1.1)]
        across = np.array([1.0, 0, 0])
    else:
        th = 2 * np.pi * u
        cmd = np.c_[1.6 + 0.15 * np.sin(th), -0.35 - 0.15 * np.cos(th), np.full_like(u, 1.1)]
        across = np.array([0, 0, 1.0])
    s = np.broadcast_to(np.asarray(s_vec, float), cmd.shape).copy()
    true, syss = [], []
    for k in range(runs):
        r = (-1) ** k * r_amp * np.sin(2 * np.pi * 10 * t)[:, None] * across
        true.append(r - s)
        syss.append(s)
    return {"t": np.array([t] * runs), "true": np.array(true), "sys": np.array(syss),
            "cmd": np.array([cmd] * runs), "duration": 3.0, "shape": shape}


def _rows(out: str) -> dict[str, float]:
    """The decomposition's perp 3σ (µm) by its part's label."""
    rows = {}
    for line in out.splitlines():
        cells = [c.strip() for c in line.strip("|").split("|")]
        if len(cells) == 4 and cells[0][:2] in ("th", "(a", "(b", "(c"):
            rows[cells[0]] = float(cells[1])
    return rows


TRUE, A, R = "the true error (−s + r)", "(a) −s alone", \
    "(b)+(c) r alone: a tracker without systematic error"


def test_the_decomposition_of_a_circle_puts_the_trackers_error_in_a_and_the_ripple_in_c(
        capsys):
    s = np.array([12e-6, -9e-6, 0.0])  # 15 µm in the circle's plane
    lr.decompose(_synthetic("circle", s, 0.0))
    rows = _rows(capsys.readouterr().out)
    # no residual: the true error is (a), and (a) is 1.56 × 15 µm
    assert rows[TRUE] == pytest.approx(rows[A])
    assert rows[A] == pytest.approx(15 * 1.5623, rel=0.02)
    assert rows[R] < 0.01
    # a ripple out of the plane that changes sign from run to run: all of it is (c)
    lr.decompose(_synthetic("circle", s, 8e-6))
    rows = _rows(capsys.readouterr().out)
    assert rows["(c) changing r alone"] == pytest.approx(rows[R])
    assert rows[R] > 8.0
    assert rows["(b) repeatable r alone"] < 0.01
    assert rows["(a) + (b) −s + repeatable r"] == pytest.approx(rows[A])


def test_a_constant_tracker_error_along_the_line_leaves_no_floor(capsys):
    """The line's perpendicular distance ignores a shift along it: the tracker's error in
    y is no floor there (the circle's answer to the same shift is 1.56 ×)."""
    lr.decompose(_synthetic("line", [0.0, 20e-6, 0.0], 0.0))
    line = _rows(capsys.readouterr().out)
    lr.decompose(_synthetic("circle", [0.0, 20e-6, 0.0], 0.0))
    circle = _rows(capsys.readouterr().out)
    assert line[A] < 0.01
    assert circle[A] == pytest.approx(20 * 1.5623, rel=0.02)


@pytest.mark.slow
def test_the_floor_of_a_cell_is_its_own_trackers_error_moved_onto_the_circle():
    """``TrackedCell(tracker_seed=…)`` measures with that tracker; on the circle its error
    is nearly constant (5° of azimuth), so the floor is the perpendicular 3σ of the
    circle moved by the mean of ``s`` — 1.56 × its in-plane size when it lies in the
    plane."""
    from plugcell.sim.tracked_path import TrackedCell

    cell = TrackedCell(seed=0, calibration_poses=60, tracker_seed=4)
    p = np.array([3.3, 0.5, 0.7])
    np.testing.assert_array_equal(cell.tracker.systematic_error(p),
                                  LaserTracker(seed=4).systematic_error(p))
    assert np.abs(cell.tracker.systematic_error(p)
                  - LaserTracker(seed=0).systematic_error(p)).max() > 1e-6
    f = lr.tracker_floor(cell, "circle", 100.0)
    assert f["spread"] < 0.1 * np.linalg.norm(f["mean"])
    assert 3.0 < f["range"][0] < f["range"][1] < 3.7
    th = np.linspace(0, 2 * np.pi, 4001)[:, None]
    circ = np.array([1.6, -0.35, 1.1]) + 0.15 * np.c_[np.sin(th), -np.cos(th), 0 * th]
    constant = _three_sigma(perpendicular(circ - f["mean"], circ[0], "circle"))
    assert f["floor"] == pytest.approx(constant, rel=0.1)
    assert np.all(np.abs(f["beam"]) < 4 * f["sigma"])


def test_the_goal_scale_is_where_the_3_sigma_crosses_the_goal(capsys):
    def p3(v):
        return float(np.abs(v).max())

    lr._goal_scale(p3, np.array([-20.0]), np.array([60.0]))  # 20 + 60 α = 50
    assert "r scaled by 0.50 (r alone then 30.0 µm)" in capsys.readouterr().out
    lr._goal_scale(p3, np.array([-60.0]), np.array([10.0]))  # s alone above the goal
    lr._goal_scale(p3, np.array([-10.0]), np.array([10.0]))  # all of it below
    assert capsys.readouterr().out == ""


def _recorded_learning(runs: int = 4) -> dict:
    """A learning recorded as :func:`learning_residual.record` saves it (``e``, ``m``,
    ``u`` per run, the weighting on), on a linear arm: the offset through two cycles of
    dead time and a 10 Hz mode (damping 0.04) on every axis, a repeating error rung at
    the mode, and 45 µm of seeded tracker noise per cycle."""
    import dataclasses

    from scipy.signal import cont2discrete, lfilter

    from dynamic_correction import INVERSE, LEARNING
    from plugcell.compensation.tracking import IterativeLearning, WeightingSettings

    w = 2 * np.pi * 10.0
    b, a, _ = cont2discrete(([0.08 * w, w * w], [1, 0.08 * w, w * w]), 0.004, method="zoh")
    settings = dataclasses.replace(LEARNING, lead_s=0.008, inverse=INVERSE,
                                   weighting=WeightingSettings())
    learning = IterativeLearning(2.0, settings)
    t = learning.grid
    d = np.zeros((t.size, 3))
    after = np.clip(t - 0.5, 0, None)
    d[:, 0] = 60e-6 * np.exp(-2.0 * after) * np.sin(w * after) * (t >= 0.5)
    d[:, 1] = 80e-6 * np.sin(np.pi * np.clip(t / 2.0, 0, 1)) ** 2
    rec: dict[str, list] = {"u": [], "e": [], "m": []}
    for k in range(runs):
        y = lfilter(np.ravel(b), np.ravel(a), learning.u, axis=0)
        e = d + np.vstack([np.zeros((2, 3)), y[:-2]]) \
            + 45e-6 * np.random.default_rng(k).standard_normal(d.shape)
        m = np.ones(t.size, bool)
        rec["u"].append(learning.u.copy())
        rec["e"].append(e)
        rec["m"].append(m)
        learning.learn_error(e, m)
    return {**{k: np.array(v) for k, v in rec.items()}, "tau": 0.008, "duration": 2.0,
            "weighting": True}


@pytest.mark.slow  # three plant identifications: ≈ 10 s of CPU
def test_the_gains_replay_is_the_recorded_learning_and_its_gains_fall_run_by_run(capsys):
    d = _recorded_learning()
    gains, f, diff = lr.replay_gains(d)
    assert diff == 0.0                       # the replay reproduces the recorded offsets
    # runs 0 (P-type), 1 (excited: identifies; the first update by (3) from run 0), 2, 3
    assert len(gains) == 3
    for K in gains:
        assert K.shape == f.shape and np.all((K >= 0) & (K <= 1))
    # K_j = S_j/(S_j + N): large where the repeating error is (the mode), small where the
    # record is noise, and falling with the updates (the matching off)
    mode = (f > 8) & (f < 12)
    assert gains[0][mode].mean() > 2 * gains[0][(f > 30) & (f < 45)].mean()
    assert gains[-1][mode].mean() < 0.8 * gains[0][mode].mean()
    # the learning replayed with other settings is not the recorded one: the check sees it
    assert lr.replay_gains(d, reidentify=0)[2] > 0
    lr.gain_table(d)
    out = capsys.readouterr().out
    assert "differ from the recorded ones by 0 µm" in out
    assert "| 2 |" in out and "arm's residual" not in out   # no truth recorded: no r table
