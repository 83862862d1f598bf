"""Dynamic path correction on the twin: nominal, model-based, model + tracker (issue 38 §4).

    .venv/bin/python benchmarks/dynamic_correction.py [--shapes line,circle]
        [--speeds 50,100,250] [--learn 6] [--learn-on model] [--learn-law inverse]
        [--inverse-cutoff 20] [--inverse-reg 0.05] [--inverse-gain 1] [--inverse-decay 1]
        [--inverse-modes 4] [--inverse-reidentify 1] [--weighting kalman]
        [--weighting-adapt 1] [--weighting-adapt-step 2] [--weighting-adapt-margin 0]
        [--weighting-detect-fell 0]
        [--excitation-um 20] [--jobs 2]
        [--faults] [--udp]
        [--lead-ms MS] [--seed 0] [--plot docs/results/dynamic-correction.png]
        [--plan-speeds]

``--shapes ''`` skips the main table (``--faults``/``--udp`` alone; their lead ``τ`` is
then ``--lead-ms``, default the 8.0 ms the line at 100 mm/s measures).  ``--plan-speeds``
prints only the planned TCP speed of each path (the lowest in the middle of the motion:
the circle's tangent junction) and runs nothing.

The Smart H4 twin with 36 kg is calibrated from its own campaign (model 5,
:class:`plugcell.sim.tracked_path.TrackedCell`); each path (a 1 m line along y, a circle
of 300 mm diameter) runs on the dynamic twin under a simulated KUKA controller (RSI mode
(b): the controller runs its path, plugcell superimposes absolute Cartesian corrections)
three times: ``nominal`` (no correction), ``model`` (the lead and the model-based
feed-forward of :class:`plugcell.compensation.tracking.TrackingLoop`, no tracker) and
``tracking`` (+ the tracker term from a 1 kHz T-MAC stream).  The lead ``τ`` is estimated
from the nominal run (the path's pose from RSol against the nominal TCP of AIPos,
:func:`plugcell.metrology.timing.estimate_delay`), as a cell would.

``--learn N`` adds iterative learning (:mod:`plugcell.compensation.tracking.learning`):
the ``model`` run (or with ``--learn-on tracking`` the ``tracking`` run) is the first
run of the repeated path; from its tracker samples the learning computes the offset of
the next run, which runs with it (and the tracker's noise fresh: a seed per run), and so
on ``N`` times — the rows ``learning 1 … N``; the learning sees only the tracker's
samples, never the twin's truth.  With ``--learn-law inverse`` (the default) run 1 also
carries a seeded excitation, from which (against run 0) the learning identifies the arm's
plant — the few-mode model of :mod:`plugcell.compensation.tracking.plant` — and runs 2 …
N learn with its norm-optimal inverse (``learning.py`` (3)), above the arm's modes, the
plant identified again after each of them, from the excited run against every other
(the default ``--inverse-reidentify 1``; ``0``: once, from the first pair), each
frequency learned by its Kalman gain against the tracker's noise (the default
``--weighting kalman``; ``none``: all of the error, ``γ/(1 + λ_I j)``);
``--learn-law p`` is the P-type law alone, below them.  ``--jobs`` runs the paths in
parallel processes.

Errors, over the motion (path start to end + 0.2 s), of the *true* reflector (the T-MAC,
the controller's TCP) against the path commanded at the same time ``T_p(t)``:

* ``perp``: distance from the programmed (taught) geometry — the line, or the circle
  (radial and out-of-plane) — ``3σ`` = mean + 3 std of the distance, and max;
* ``along``: position along the path minus the commanded one at the same time (the
  following error; with the lead it is fed forward), 3σ of its magnitude and max;
* ``orient``: angle of ``R_p R_trueᵀ`` (6-DoF), 3σ and max.

Deterministic (simulated time): any machine prints the same figures; the wall time
depends on the machine.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
import sys
import threading
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

# one BLAS thread per process: the machine is shared, and the learning's small solves
# run many times slower when a BLAS spreads each of them over busy cores
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np

from plugcell.compensation.tracking import (
    DEFAULT_WEIGHTING,
    InverseSettings,
    IterativeLearning,
    LearningSettings,
    TrackingSettings,
    WeightingSettings,
)
from plugcell.devices.robot.stream.source import Correction, CycleState
from plugcell.kinematics import forward
from plugcell.kinematics.transforms import so3_log
from plugcell.metrology.timing import estimate_delay
from plugcell.sim.tracked_path import CYCLE, Fault, LogFeed, PathRun, TrackedCell, learn
from plugcell.sim.tracked_udp import run_over_udp

PUBLISHED = [
    ("Nikon Adaptive Robot Control (commercial), robot accuracy", "0.1 mm"),
    ("Gharaaty et al. 2018, FANUC + optical CMM in the loop, end pose", "±0.05 mm / ±0.05°"),
    ("Shu et al. 2018, along paths", "±0.20 mm"),
    ("MAPS, ABB IRB 120 + photogrammetry, path error", "0.114 → 0.015 mm"),
]
GOALS = {100.0: 0.05e-3, 250.0: 0.10e-3}
#: The learning on the twin (δ = the estimated lead τ): Q at 6 Hz, order 4 (zero phase:
#: |Q| = 0.04 at the first mode, 9 Hz; 8 Hz diverged on the line at 250 mm/s), L = 0.8
#: falling as 1/(1 + 0.5 k) to average the tracker's noise (docs/dynamic-correction.md)
#: (its weighting is set by main() from --weighting; None here keeps what other scripts
#: build on it, benchmarks/learning_residual.py, the unweighted law they were measured with)
LEARNING = LearningSettings(gain=0.8, cutoff_hz=6.0, order=4, gain_decay=0.5, weighting=None)
#: The model-inverting law (learning.py (3)) after one identifying run: Q_I above the
#: modes (9–14 Hz on the twin), γ_j = 1/(1 + j) (the running mean of the runs' estimates)
INVERSE = InverseSettings()


def _three_sigma(x: np.ndarray) -> float:
    return float(x.mean() + 3 * x.std())


def perpendicular(p: np.ndarray, p0: np.ndarray, shape: str) -> np.ndarray:
    """Distance (m) of the points ``p`` (N, 3; F0) from the taught geometry through the
    path's start ``p0``: the 1 m line along y, or the 300 mm circle in the plane z =
    ``p0[2]`` with its centre ``p0 + (0, 0.15, 0)`` — radial and out-of-plane together,
    ``√((|ρ_xy| − R)² + ρ_z²)``, ``ρ = p − centre``."""
    if shape == "line":
        rel = p - p0
        return np.hypot(rel[:, 0], rel[:, 2])
    centre, R = p0 + np.array([0.0, 0.15, 0.0]), 0.15
    rp = p - centre
    return np.hypot(np.hypot(rp[:, 0], rp[:, 1]) - R, rp[:, 2])


def errors(run: PathRun, shape: str, mask: np.ndarray | None = None) -> dict[str, float]:
    """The run's error statistics (module docstring), metres and radians (over the cycles
    of ``mask`` too, if given)."""
    w = (run.t >= run.motion[0]) & (run.t <= run.motion[1] + 0.2)
    if mask is not None:
        w &= mask
    p, c = run.true_pose[w, :3, 3], run.path_pose[w, :3, 3]
    p0 = run.path_pose[0, :3, 3]  # the path's start (before the mask)
    perp = perpendicular(p, p0, shape)
    if shape == "line":
        along = (p - c) @ np.array([0.0, 1.0, 0.0])
    else:
        centre, R = p0 + np.array([0.0, 0.15, 0.0]), 0.15
        rp, rc = p - centre, c - centre
        ang = np.arctan2(rp[:, 1], rp[:, 0]) - np.arctan2(rc[:, 1], rc[:, 0])
        along = R * ((ang + np.pi) % (2 * np.pi) - np.pi)
    rot = np.array([np.linalg.norm(so3_log(a[:3, :3] @ b[:3, :3].T))
                    for a, b in zip(run.path_pose[w], run.true_pose[w], strict=True)])
    return {"perp_3s": _three_sigma(perp), "perp_max": float(perp.max()),
            "along_3s": _three_sigma(np.abs(along)), "along_max": float(np.abs(along).max()),
            "along_mean": float(along.mean()),
            "rot_3s": _three_sigma(rot), "rot_max": float(rot.max())}


def lead_from(cell: TrackedCell, run: PathRun) -> float:
    """``τ``: delay of the nominal TCP of the joint feedback behind the path (RSol)."""
    fb = forward(cell.desc_tool, None, run.joint_feedback, "nominal").tcp[:, :3, 3]
    t_fb = run.t - CYCLE  # AIPos was read at the start of the cycle
    est = estimate_delay(run.t, run.path_pose[:, :3, 3], t_fb, fb, max_delay_s=0.05)
    return float(est.delay_s)


def rates(run: PathRun) -> tuple[float, float]:
    """Largest speed (m/s) and acceleration (m/s²) of the position offset sent."""
    o = run.offset[:, :3]
    return (float(np.abs(np.diff(o, axis=0)).max() / CYCLE),
            float(np.abs(np.diff(o, 2, axis=0)).max() / CYCLE ** 2))


def case(cell: TrackedCell, shape: str, speed: float, learn_runs: int = 0,
         learn_on: str = "model", learning_settings: LearningSettings = LEARNING,
         tracking: bool = True, observe=None) -> dict:
    """One path: its runs and their errors (module docstring).  ``observe(k, learning,
    run)``, if given, is called after each run ``k`` of the learning (0: the first, before
    the learning's update from it; ``learning.u`` is then the offset that run used)."""
    print(f"running {shape} at {speed:g} mm/s …", file=sys.stderr, flush=True)
    t0 = time.time()
    traj = cell.plan(shape, speed)
    nominal = cell.run(traj, "nominal")
    tau = lead_from(cell, nominal)
    s = TrackingSettings(lead_s=tau)
    model = cell.run(traj, "model", settings=s)
    runs = {"nominal": nominal, "model": model}
    if tracking or learn_on == "tracking":
        runs["tracking"] = cell.run(traj, "tracking", settings=s)
    learning = IterativeLearning(traj.duration,
                                 dataclasses.replace(learning_settings, lead_s=tau))
    last = runs[learn_on]
    for k in range(1, learn_runs + 1):
        if observe is not None:
            observe(k - 1, learning, last)
        learn(learning, last)
        print(f"  {shape} {speed:g} mm/s: learning run {k}/{learn_runs} …", file=sys.stderr,
              flush=True)
        last = runs[f"learning {k}"] = cell.run(traj, learn_on, settings=s, learning=learning,
                                                stream_seed=cell.seed + 1000 * k)
        e = errors(last, shape)
        print(f"  … perp 3σ {e['perp_3s'] * 1e3:.4f} mm, along 3σ {e['along_3s'] * 1e3:.4f} mm "
              f"(model {errors(model, shape)['perp_3s'] * 1e3:.4f} mm)", file=sys.stderr,
              flush=True)
    if learn_runs:
        if observe is not None:
            observe(learn_runs, learning, last)
        learn(learning, last)  # the last run's error as the tracker saw it
    st = runs["tracking"].stats if "tracking" in runs else None
    ages = np.array(st.ages_s if st else [math.nan]) * 1e3
    final = f"learning {learn_runs}" if learn_runs else "tracking" if st else "model"
    return {"shape": shape, "speed": speed, "tau": tau, "duration": traj.duration,
            "rows": {m: errors(r, shape) for m, r in runs.items()},
            "runs": runs, "final": final, "learn_on": learn_on,
            "learned_rms": [h["rms_m"] for h in learning.history],
            "plant": learning.plant,
            "fresh": st.fresh_cycles / max(st.cycles, 1) if st else math.nan,
            "age_ms": (np.percentile(ages, 50), np.percentile(ages, 99), ages.max()),
            "rates": rates(runs[final]), "traj": traj, "wall_s": time.time() - t0}


_CELL: TrackedCell | None = None


def _init_worker(seed: int, poses: int) -> None:
    global _CELL
    _CELL = TrackedCell(seed=seed, calibration_poses=poses)


def _case_in_worker(args: tuple[str, float, int, str, LearningSettings, bool]) -> dict:
    assert _CELL is not None
    return case(_CELL, *args)


def faults(cell: TrackedCell, traj, tau: float) -> list[tuple[str, PathRun]]:
    s = TrackingSettings(lead_s=tau)
    cases = [("beam break 0.5 s at 4 s", Fault("beam_break", 4.0, 0.5)),
             ("late tracker (+80 ms for 0.5 s at 3 s)", Fault("late", 3.0, 0.5, 0.08)),
             ("tracker killed at 6 s", Fault("killed", 6.0, delay_s=0.1))]
    return [(name, cell.run(traj, "tracking", settings=s, faults=(f,))) for name, f in cases]


class Beside:
    """The loop beside the link, as the robot service runs it (``tracked_moves._Worker``,
    the link process's pump): each answer offers its cycle to the loop's thread and
    carries, at once, the newest correction that thread has made (none before the first:
    hold).  Records, per correction, the time from its samples' hand-over to the first
    answer that carried it (``wire_s``), and per answer whether it carried a new one.

    Parameters
    ----------
    feed : LogFeed
        The samples' hand-over and the loop (``feed(state)``), run in the thread.
    """

    def __init__(self, feed: LogFeed) -> None:
        self.feed = feed
        self._cond = threading.Condition()
        self._job: CycleState | None = None
        self._made: tuple[Correction, int, float] | None = None  # (it, version, handed)
        self._sent = 0
        self.wire_s: list[float] = []
        self.fresh: list[bool] = []
        self._stop = False
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def __call__(self, state: CycleState) -> Correction:
        with self._cond:
            self._job = state
            self._cond.notify()
            made = self._made
        now = time.perf_counter()
        if made is None:
            self.fresh.append(False)
            return Correction(offset=state.offset)  # hold where the stream stands
        corr, version, handed = made
        self.fresh.append(version != self._sent)
        if version != self._sent:
            self._sent = version
            self.wire_s.append(now - handed)
        return corr

    def _run(self) -> None:
        version = 0
        while True:
            with self._cond:
                while self._job is None and not self._stop:
                    self._cond.wait()
                if self._stop:
                    return
                job, self._job = self._job, None
            handed = time.perf_counter()
            corr = self.feed(job)
            version += 1
            with self._cond:
                self._made = (corr, version, handed)

    def close(self) -> None:
        with self._cond:
            self._stop = True
            self._cond.notify()
        self._thread.join(5.0)


def udp_timing(cell: TrackedCell, tau: float, beside: bool = False) -> dict:
    """The loop through the real seam: RsiRobot in its thread, RsiLink over UDP on
    loopback, the TrackingSource fed the twin's reflector each cycle (``LogFeed``); a
    0.2 m line at 100 mm/s in real time.  ``beside``: the loop in a thread beside the
    link (:class:`Beside`), else in the answer.  The tracker sample's hand-over → the
    answer carrying its correction on the wire (in the answer: the link's own packet in
    → answer out), the loop's compute time, the share of cycles the controller got its
    answer in time, and the share of answers that carried a new correction."""
    traj = cell.plan("line", 100.0, size_m=0.2)
    beside_feed: list[Beside] = []
    wall_us: list[float] = []
    cpu_us: list[float] = []

    def answer(feed: LogFeed) -> Beside | LogFeed:
        loop = feed.source.loop
        cycle = loop.cycle

        def timed(*args):  # one iteration of the loop: its wall and its thread's CPU time
            w0, c0 = time.perf_counter_ns(), time.thread_time_ns()
            out = cycle(*args)
            cpu_us.append((time.thread_time_ns() - c0) / 1e3)
            wall_us.append((time.perf_counter_ns() - w0) / 1e3)
            return out

        loop.cycle = timed
        if not beside:
            return feed
        beside_feed.append(Beside(feed))
        return beside_feed[0]

    udp = run_over_udp(cell, traj, tau, record_latency=True, path_slack_s=120.0,
                       end_timeout_s=60.0, answer=answer)
    link, feed, loop, robot = udp.link, udp.feed, udp.loop, udp.robot
    for b in beside_feed:
        b.close()
    out = np.array(link.latencies) * 1e-6
    comp = np.array(feed.compute_s) * 1e3
    st = robot.stats()
    if beside_feed:
        wire = np.array(beside_feed[0].wire_s) * 1e3
        fresh_answers = float(np.mean(beside_feed[0].fresh))
    else:
        wire, fresh_answers = out, 1.0
    in_time = st.answered / max(st.cycles, 1)
    return {"wire_ms": np.percentile(wire, [50, 99, 100]), "out_ms":
            np.percentile(out, [50, 99, 100]), "compute_ms": np.percentile(comp, [50, 99, 100]),
            "in_time": in_time, "fresh_robot": in_time * fresh_answers,
            "fresh": loop.stats.fresh_cycles / max(loop.stats.cycles, 1), "cycles": st.cycles,
            "iter_wall_us": np.percentile(wall_us, [50, 99]),
            "iter_cpu_us": np.percentile(cpu_us, [50, 99])}


def print_udp(runs: list[tuple[str, dict]]) -> None:
    print("\nthrough UDP on loopback, real time (a 0.2 m line at 100 mm/s):")
    print("| loop | cycles | sample → correction on the wire p50/p99/max ms | packet in → "
          "answer out p50/p99/max ms | loop p50/p99/max ms | loop iteration p50/p99 µs "
          "(wall; CPU) | answers in time | robot cycles with a fresh correction | loop "
          "cycles with a fresh estimate |")
    print("|---|---:|---|---|---|---|---:|---:|---:|")
    for name, u in runs:
        w, o, c = (" / ".join(f"{x:.2f}" for x in u[k]) for k in ("wire_ms", "out_ms",
                                                                   "compute_ms"))
        it = (f"{u['iter_wall_us'][0]:.0f} / {u['iter_wall_us'][1]:.0f}; "
              f"{u['iter_cpu_us'][0]:.0f} / {u['iter_cpu_us'][1]:.0f}")
        print(f"| {name} | {u['cycles']} | {w} | {o} | {c} | {it} | "
              f"{u['in_time'] * 100:.1f} % | {u['fresh_robot'] * 100:.1f} % | "
              f"{u['fresh'] * 100:.1f} % |")


def print_table(results: list[dict]) -> None:
    print("| path | speed mm/s | correction | perp 3σ mm | perp max mm | along 3σ mm | "
          "along max mm | orient 3σ ° | orient max ° |")
    print("|---|---:|---|---:|---:|---:|---:|---:|---:|")
    for r in results:
        for m, e in r["rows"].items():
            if m.startswith("learning") and m != r["final"]:
                continue  # the iterations: print_learning
            print(f"| {r['shape']} | {r['speed']:g} | {m} | {e['perp_3s'] * 1e3:.3f} | "
                  f"{e['perp_max'] * 1e3:.3f} | {e['along_3s'] * 1e3:.3f} | "
                  f"{e['along_max'] * 1e3:.3f} | {math.degrees(e['rot_3s']):.4f} | "
                  f"{math.degrees(e['rot_max']):.4f} |")
    print("\n| path | speed mm/s | lead τ ms | perp 3σ model / tracking / final | goal "
          "(final) | fresh cycles | sample age at use p50/p99/max ms | offset speed max mm/s "
          "(final) | accel max m/s² |")
    print("|---|---:|---:|---|---|---:|---|---:|---:|")
    for r in results:
        m = r["rows"]["model"]["perp_3s"]
        t = r["rows"].get("tracking", {"perp_3s": math.nan})["perp_3s"]
        f = r["rows"][r["final"]]["perp_3s"]
        goal = GOALS.get(r["speed"])
        ok = ("met" if f <= goal and m / f >= 5 else "not met") + \
            f" (≤ {goal * 1e3:.2f} mm, ≥ 5×)" if goal is not None else \
            ("met" if m / f >= 5 else "not met") + " (≥ 5×)"
        a = r["age_ms"]
        print(f"| {r['shape']} | {r['speed']:g} | {r['tau'] * 1e3:.2f} | {m / t:.1f}× / "
              f"{m / f:.1f}× ({r['final']}) | {ok} | "
              f"{r['fresh'] * 100:.1f} % | {a[0]:.1f} / {a[1]:.1f} / {a[2]:.1f} | "
              f"{r['rates'][0] * 1e3:.2f} | {r['rates'][1]:.3f} |")


def plan_speeds(cell: TrackedCell, shape: str, speed: float, step_s: float = 0.001) -> dict:
    """The planned TCP speed of one path (the controller's program, :meth:`TrackedCell.plan`,
    its first section sampled every ``step_s``): the programmed speed, the highest
    planned one, and the lowest in the middle half of the motion (``t`` from ``D/4`` to
    ``3D/4``, ``D`` the section's duration) with where it is — on the circle the tangent
    junction of its two CIRCs, half-way."""
    path = cell.plan(shape, speed).sections[0].path
    t = np.arange(0.0, path.duration, step_s)
    v = np.linalg.norm(path.sample(t).v, axis=1)
    mid = (t >= path.duration / 4) & (t <= 3 * path.duration / 4)
    k = int(np.flatnonzero(mid)[np.argmin(v[mid])])
    return {"shape": shape, "speed": speed, "duration": path.duration,
            "max": float(v.max()), "mid_min": float(v[k]), "at": t[k] / path.duration}


def print_plan_speeds(rows: list[dict]) -> None:
    print("\nplanned TCP speed (the controller's program, sections[0].path; middle: t from "
          "D/4 to 3D/4 of the motion's duration D):")
    print("| path | speed mm/s | duration s | max planned mm/s | middle's min mm/s | "
          "where (t/D) |")
    print("|---|---:|---:|---:|---:|---:|")
    for r in rows:
        print(f"| {r['shape']} | {r['speed']:g} | {r['duration']:.3f} | {r['max'] * 1e3:.1f} | "
              f"{r['mid_min'] * 1e3:.1f} | {r['at']:.3f} |")


def _perp_3s_where(run: PathRun, shape: str, held: bool) -> float:
    """Perpendicular 3σ (m) over the motion's cycles in which the loop held (model alone,
    ``held``) or tracked (NaN if none)."""
    w = (run.t >= run.motion[0]) & (run.t <= run.motion[1] + 0.2)
    states = np.array(run.state)
    pick = (states == "holding") if held else (states == "tracking")
    if not (w & pick).any():
        return math.nan
    return errors(run, shape, pick)["perp_3s"]


def print_learning(results: list[dict], ls: LearningSettings) -> None:
    """Per learning run: the true error (perp and along 3σ) and what the tracker saw."""
    runs = [r for r in results if r["final"].startswith("learning")]
    if not runs:
        return
    n = max(int(r["final"].split()[1]) for r in runs)
    law = f"L = {ls.gain:g}/(1 + {ls.gain_decay:g} k), Q {ls.cutoff_hz:g} Hz order {ls.order} " \
        "zero phase, δ = τ"
    if ls.inverse is not None:
        iv = ls.inverse
        law = (f"run 1: P-type ({law}) + excitation {iv.excitation_m * 1e6:g} µm rms "
               f"{iv.excitation_low_hz:g}–{iv.excitation_high_hz:g} Hz, identifies the plant "
               f"({iv.modes} modes{', re-identified after each run' if iv.reidentify else ''}"
               f"); runs 2…: model-inverting, γ_j = "
               + (f"{iv.gain:g}" if ls.weighting is not None else
                  f"{iv.gain:g}/(1 + {iv.gain_decay:g} j)")
               + f", β = {iv.regularisation:g}, Q_I {iv.cutoff_hz:g} Hz order {iv.order}")
        if ls.weighting is not None:
            law += (f", each frequency by its Kalman gain K_j = S_j/(S_j + N), which holds "
                    f"the decay γ_j has without it (N from {ls.weighting.noise_low_hz:g}–"
                    f"{ls.weighting.noise_high_hz:g} Hz, S averaged over "
                    f"±{ls.weighting.smooth_hz:g} Hz, covariance matching "
                    + (f"κ {ls.weighting.detect:g}" if math.isfinite(ls.weighting.detect)
                       else "off")
                    + (" only where the error fell" if ls.weighting.detect_fell else "")
                    + (f", per tile of {ls.weighting.window_s:g} s" if ls.weighting.window_s
                       else "")
                    + (f", prior inflated up to {ls.weighting.adapt_max:g}× (× or ÷ "
                       f"{ls.weighting.adapt_step:g} as the error fell by "
                       f"{ls.weighting.adapt_margin:g} σ or not)"
                       if ls.weighting.adapt_max > 1 else "") + ")")
    print(f"\niterative learning ({law}; run 0 = {runs[0]['learn_on']}; perp 3σ / "
          "along 3σ mm, true; in brackets the rms the tracker measured):")
    print("| path | speed mm/s | " + " | ".join(f"run {k}" for k in range(n + 1)) + " |")
    print("|---|---:|" + "---:|" * (n + 1))
    for r in runs:
        keys = [r["learn_on"]] + [f"learning {k}" for k in range(1, n + 1)]
        cells = [f"{r['rows'][k]['perp_3s'] * 1e3:.3f} / {r['rows'][k]['along_3s'] * 1e3:.3f}"
                 f" ({rms * 1e3:.3f})" for k, rms in zip(keys, r["learned_rms"], strict=True)]
        print(f"| {r['shape']} | {r['speed']:g} | " + " | ".join(cells) + " |")
    for r in runs:
        p = r.get("plant")
        if p is not None:
            print(f"identified on the {r['shape']} at {r['speed']:g} mm/s: modes "
                  + ", ".join(f"{f:.2f} Hz (ζ {z:.3f})" for f, z in
                              zip(p.frequency_hz, p.damping, strict=True))
                  + f"; R² {p.fit:.3f}")


def print_faults(shape: str, runs: list[tuple[str, PathRun]]) -> None:
    print(f"\nfaults ({shape}, 100 mm/s, tracking):")
    print("| fault | windows (start–end s, reason) | model alone s | perp 3σ mm all / "
          "held / tracked | offset step max µm | offset speed max mm/s | accel max m/s² |")
    print("|---|---|---:|---|---:|---:|---:|")
    for name, run in runs:
        end = run.motion[1] + 0.2
        wins = "; ".join(f"{w.start_s - run.motion[0]:.2f}–"
                         f"{'end' if w.end_s is None else f'{w.end_s - run.motion[0]:.2f}'} "
                         f"{w.reason}" for w in run.windows) or "none"
        alone = sum(min(end if w.end_s is None else w.end_s, end) - w.start_s
                    for w in run.windows)
        v, a = rates(run)
        step = float(np.abs(np.diff(run.offset[:, :3], axis=0)).max())
        parts = " / ".join(f"{x * 1e3:.3f}" for x in (
            errors(run, shape)["perp_3s"], _perp_3s_where(run, shape, True),
            _perp_3s_where(run, shape, False)))
        print(f"| {name} | {wins} | {alone:.2f} | {parts} | {step * 1e6:.1f} | "
              f"{v * 1e3:.2f} | {a:.3f} |")


def plot(result: dict, results: list[dict], path: Path) -> bool:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return False
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(11.0, 4.0),
                                  gridspec_kw={"width_ratios": [2.2, 1]})
    show = ("nominal", "model", "tracking", result["final"])
    for m, run in result["runs"].items():
        if m not in show:
            continue
        w = (run.t >= run.motion[0]) & (run.t <= run.motion[1] + 0.2)
        d = np.linalg.norm(run.true_pose[w, :3, 3] - run.path_pose[w, :3, 3], axis=1)
        ax.plot(run.t[w] - run.motion[0], d * 1e3, label=m, lw=0.8)
    ax.set_yscale("log")
    ax.set_xlabel("time on the path (s)")
    ax.set_ylabel("|true − commanded| (mm)")
    ax.set_title(f"Smart H4 twin, 36 kg, {result['shape']} at {result['speed']:g} mm/s",
                 fontsize=10)
    ax.legend(fontsize=8)
    for r in results:
        keys = [r["learn_on"], *sorted((k for k in r["rows"] if k.startswith("learning")),
                                       key=lambda k: int(k.split()[1]))]
        if len(keys) > 1:
            ax2.plot(range(len(keys)), [r["rows"][k]["perp_3s"] * 1e3 for k in keys],
                     marker="o", lw=0.8, label=f"{r['shape']} {r['speed']:g} mm/s")
    ax2.set_yscale("log")
    ax2.set_xlabel("run of the learning (0: no learned offset)")
    ax2.set_ylabel("perp 3σ, true (mm)")
    ax2.set_title("iterative learning", fontsize=10)
    ax2.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return True


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--shapes", default="line,circle")
    ap.add_argument("--speeds", default="50,100,250", help="mm/s")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--calibration-poses", type=int, default=150)
    ap.add_argument("--learn", type=int, default=0, metavar="N",
                    help="runs of iterative learning after the first (default 0: none)")
    ap.add_argument("--learn-on", choices=("model", "tracking"), default="model",
                    help="the learning's runs with the model alone or with the tracker term")
    ap.add_argument("--learn-gain", type=float, default=LEARNING.gain, help="L")
    ap.add_argument("--learn-decay", type=float, default=LEARNING.gain_decay,
                    help="λ of L/(1 + λk)")
    ap.add_argument("--learn-cutoff", type=float, default=LEARNING.cutoff_hz,
                    help="Q's cut-off (Hz)")
    ap.add_argument("--learn-order", type=int, default=LEARNING.order, help="Q's order")
    ap.add_argument("--learn-law", choices=("inverse", "p"), default="inverse",
                    help="inverse: the first update is P-type and excites the next run, "
                    "which identifies the plant; then the model-inverting law (default); "
                    "p: the P-type law alone")
    ap.add_argument("--inverse-gain", type=float, default=INVERSE.gain, help="γ")
    ap.add_argument("--inverse-decay", type=float, default=INVERSE.gain_decay,
                    help="λ_I of γ/(1 + λ_I j)")
    ap.add_argument("--inverse-reg", type=float, default=INVERSE.regularisation, help="β")
    ap.add_argument("--inverse-cutoff", type=float, default=INVERSE.cutoff_hz,
                    help="Q_I's cut-off (Hz)")
    ap.add_argument("--inverse-modes", type=int, default=INVERSE.modes,
                    help="modes of the identified plant")
    ap.add_argument("--inverse-reidentify", type=int, choices=(0, 1),
                    default=INVERSE.reidentify,
                    help="1 (default): identify the plant again after each run by the "
                    "inverse, from the excited run against every run before and after it; "
                    "0: once, from the first pair")
    ap.add_argument("--excitation-um", type=float, default=INVERSE.excitation_m * 1e6,
                    help="the identifying run's excitation, rms per axis (µm)")
    ap.add_argument("--weighting", choices=("kalman", "none"), default="kalman",
                    help="kalman (default): the inverse law learns each frequency by its "
                    "Kalman gain against the tracker's noise "
                    "(compensation/tracking/smoothing.py); none: all of the error, "
                    "γ/(1 + λ_I j)")
    ap.add_argument("--weighting-smooth-hz", type=float,
                    default=DEFAULT_WEIGHTING.smooth_hz,
                    help="half width of the power's average over frequency (Hz)")
    ap.add_argument("--weighting-detect", type=float, default=DEFAULT_WEIGHTING.detect,
                    help="κ of the covariance matching (standard deviations; default 3; inf: "
                    "off)")
    ap.add_argument("--weighting-window-s", type=float, default=DEFAULT_WEIGHTING.window_s,
                    help="0: a gain per frequency over the run; > 0 (default 1): per tile of a "
                    "short-time FFT with windows this long (s)")
    ap.add_argument("--weighting-adapt", type=float, default=DEFAULT_WEIGHTING.adapt_max,
                    help="c_max of the weighting's inflation where the last update made the "
                    "error fall (smoothing.py (5); 1, the default: off)")
    ap.add_argument("--weighting-adapt-step", type=float,
                    default=DEFAULT_WEIGHTING.adapt_step,
                    help="a of (5): the inflation's factor per update")
    ap.add_argument("--weighting-detect-fell", type=int, choices=(0, 1),
                    default=DEFAULT_WEIGHTING.detect_fell,
                    help="1: the covariance matching only where the error fell after the "
                    "last update (smoothing.py (6); the default); 0: wherever it exceeds the "
                    "prediction")
    ap.add_argument("--weighting-adapt-margin", type=float,
                    default=DEFAULT_WEIGHTING.adapt_margin,
                    help="κ_a of (5): the fall that counts, in standard deviations of the "
                    "power's average (0: any)")
    ap.add_argument("--no-tracking", action="store_true",
                    help="skip the run with the real-time tracker term (the slowest)")
    ap.add_argument("--jobs", type=int, default=1, help="paths run in parallel processes")
    ap.add_argument("--faults", action="store_true", help="the fault runs (line, 100 mm/s)")
    ap.add_argument("--udp", action="store_true",
                    help="also time the loop through the real RSI link over UDP")
    ap.add_argument("--lead-ms", type=float, default=8.0,
                    help="the lead τ of --faults/--udp without the main table (ms)")
    ap.add_argument("--plot", type=Path)
    ap.add_argument("--plan-speeds", action="store_true",
                    help="only the planned TCP speed of --shapes at --speeds (the middle's "
                    "minimum: the circle's tangent junction), no runs")
    args = ap.parse_args(argv)
    if not (math.isfinite(args.lead_ms) and 0 <= args.lead_ms <= 100):
        ap.error(f"--lead-ms must be 0…100 ms, got {args.lead_ms}")
    if args.learn < 0 or args.jobs < 1:
        ap.error(f"--learn must be ≥ 0 and --jobs ≥ 1, got {args.learn} and {args.jobs}")
    try:
        inverse = dataclasses.replace(
            INVERSE, gain=args.inverse_gain, gain_decay=args.inverse_decay,
            regularisation=args.inverse_reg, cutoff_hz=args.inverse_cutoff,
            modes=args.inverse_modes, excitation_m=args.excitation_um * 1e-6,
            reidentify=args.inverse_reidentify) \
            if args.learn_law == "inverse" else None
        learning = dataclasses.replace(LEARNING, gain=args.learn_gain,
                                       gain_decay=args.learn_decay,
                                       cutoff_hz=args.learn_cutoff, order=args.learn_order,
                                       inverse=inverse,
                                       weighting=WeightingSettings(
                                           smooth_hz=args.weighting_smooth_hz,
                                           detect=args.weighting_detect,
                                           window_s=args.weighting_window_s,
                                           adapt_max=args.weighting_adapt,
                                           adapt_step=args.weighting_adapt_step,
                                           adapt_margin=args.weighting_adapt_margin,
                                           detect_fell=args.weighting_detect_fell)
                                       if args.weighting == "kalman" and inverse else None)
    except ValueError as exc:
        ap.error(str(exc))
    t0 = time.time()
    cell = TrackedCell(seed=args.seed, calibration_poses=args.calibration_poses)
    if args.plan_speeds:
        print_plan_speeds([plan_speeds(cell, shape, float(v))
                           for shape in filter(None, args.shapes.split(","))
                           for v in args.speeds.split(",")])
        print(f"wall time {time.time() - t0:.0f} s")
        return 0
    cases = [(shape, float(v), args.learn, args.learn_on, learning, not args.no_tracking)
             for shape in filter(None, args.shapes.split(",")) for v in args.speeds.split(",")]
    if args.jobs > 1 and cases:
        with ProcessPoolExecutor(args.jobs, initializer=_init_worker,
                                 initargs=(args.seed, args.calibration_poses)) as pool:
            results = list(pool.map(_case_in_worker, cases))
    else:
        results = [case(cell, *c) for c in cases]
    print(f"Smart H4 twin (seed {args.seed}, 36 kg), model 5 from {args.calibration_poses} "
          f"poses, RSI mode (b) at {CYCLE * 1e3:g} ms, T-MAC stream 1 kHz")
    if results:
        print_table(results)
        print_learning(results, learning)
    if args.faults:
        traj = cell.plan("line", 100.0)
        tau = next((r["tau"] for r in results if r["shape"] == "line" and r["speed"] == 100),
                   args.lead_ms * 1e-3)
        print_faults("line", faults(cell, traj, tau))
    if args.udp:
        tau = results[0]["tau"] if results else args.lead_ms * 1e-3
        print_udp([("in the answer", udp_timing(cell, tau)),
                   ("beside the link (the service's)", udp_timing(cell, tau, beside=True))])
    print("\npublished:")
    for what, value in PUBLISHED:
        print(f"  {what}: {value}")
    if args.plot and results:
        pick = next((r for r in results if r["speed"] == 100.0), results[0])
        print(f"plot: {args.plot}" if plot(pick, results, args.plot) else "plot: no matplotlib")
    print(f"wall time {time.time() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
