"""One iteration of the tracking loop, part by part, on a recorded run (issue 38 §4).

    .venv/bin/python benchmarks/tracking_loop_cost.py [--save run.npz] [--compare run.npz]
        [--speed 100] [--poses 60] [--seed 0]

Records what a tracked path gives the loop (:class:`plugcell.sim.tracked_path.TrackedCell`,
the Smart H4 twin with 36 kg and its model-5 calibration, a 0.2 m line, simulated time:
the same inputs on any machine), then replays them through a fresh
:class:`~plugcell.compensation.tracking.TrackingLoop` and times every cycle — its wall
time and its thread's CPU time (``time.thread_time``: what the loop costs whatever else
the machine runs) — and each part of it:

* ``estimator`` — the samples' residuals: the joint history at their times, the
  calibrated model's poses there, the pose errors, the Kalman updates
  (``TrackingLoop._take_samples``); of it, ``model poses`` alone;
* ``feed-forward`` — the model's inverse at the anchors, the extrapolation between them;
* ``lead``, ``limiter`` — the lead's differences and its bound, the tracker term's bound;
* ``rest`` — the state machine, the fade, the output filter, the offset's composition;

and, beside the loop, what the robot service adds to each cycle: the planned pose and the
controller's Jacobian looked up and ``Δq = J⁻¹ o`` (``tracked_moves``), and the crossing
of the shared memory between the link's process and the service (``stream.adjusting``:
the cycle written, read, the adjustment written, read — the four seqlocked copies).

``--save`` writes the loop's outputs of the replay, ``--compare`` checks them against a
file saved before (e.g. by another version of the loop: the recorded run is the same)
and prints the largest difference.  Machine: say which and its load (printed).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections import defaultdict
from multiprocessing import RawArray
from pathlib import Path

import numpy as np

from plugcell.compensation.tracking import TrackingLoop, TrackingSettings

FIELDS = ("offset", "feedforward", "lead", "tracker", "residual")


def record(speed_mm_s: float, poses: int, seed: int) -> tuple[object, list[tuple]]:
    """The cell and the loop's calls of a simulated tracked run: ``("add", samples)`` and
    ``("cycle", (t, q, T_path))``."""
    import plugcell.sim.tracked_path as tp

    calls: list[tuple] = []

    class Recorded(TrackingLoop):
        def add(self, ms):  # type: ignore[override]
            ms = list(ms)
            calls.append(("add", ms))
            super().add(ms)

        def cycle(self, t, q, T_path):  # type: ignore[override]
            calls.append(("cycle", (t, np.array(q, float), np.array(T_path, float))))
            return super().cycle(t, q, T_path)

    cell = tp.TrackedCell(seed=seed, calibration_poses=poses)
    real, tp.TrackingLoop = tp.TrackingLoop, Recorded
    try:
        cell.run(cell.plan("line", speed_mm_s, size_m=0.2), "tracking",
                 settings=TrackingSettings(lead_s=0.008))
    finally:
        tp.TrackingLoop = real
    return cell, calls


class _Clock:
    """Wall and thread CPU time spent in wrapped calls, per part (µs), per cycle."""

    def __init__(self) -> None:
        self.now: dict[str, float] = defaultdict(float)

    def wrap(self, obj: object, name: str, part: str) -> None:
        f = getattr(obj, name)

        def timed(*args, **kwargs):
            c0 = time.thread_time_ns()
            try:
                return f(*args, **kwargs)
            finally:
                self.now[part] += (time.thread_time_ns() - c0) / 1e3

        object.__setattr__(obj, name, timed)  # a frozen dataclass's too (the model)


def replay(cell, calls: list[tuple]) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Each cycle's outputs and its costs (µs): ``wall``, ``cpu`` and the parts' CPU."""
    loop = TrackingLoop(cell.model, TrackingSettings(lead_s=0.008), payload_kg=cell.payload_kg)
    clock = _Clock()
    clock.wrap(loop, "_take_samples", "estimator")
    clock.wrap(loop.model, "pose", "model poses")
    clock.wrap(loop, "_feedforward", "feed-forward")
    clock.wrap(loop, "_lead", "lead")
    clock.wrap(loop._limiter, "apply", "limiter")
    outs: dict[str, list] = defaultdict(list)
    cost: dict[str, list] = defaultdict(list)
    for kind, payload in calls:
        if kind == "add":
            loop.add(payload)
            continue
        clock.now.clear()
        w0, c0 = time.perf_counter_ns(), time.thread_time_ns()
        out = loop.cycle(*payload)
        cpu = (time.thread_time_ns() - c0) / 1e3
        cost["wall"].append((time.perf_counter_ns() - w0) / 1e3)
        cost["cpu"].append(cpu)
        parts = ("estimator", "model poses", "feed-forward", "lead", "limiter")
        for part in parts:
            cost[part].append(clock.now.get(part, 0.0))
        cost["rest"].append(cpu - sum(clock.now.get(p, 0.0) for p in parts
                                      if p != "model poses"))
        for f in FIELDS:
            outs[f].append(np.asarray(getattr(out, f), dtype=float))
        outs["weight"].append(np.array([out.weight]))
    return ({k: np.array(v) for k, v in outs.items()},
            {k: np.array(v) for k, v in cost.items()})


def service_extras(cell, n: int = 2000) -> dict[str, np.ndarray]:
    """What the robot service adds to a cycle (µs, CPU): the planned pose and Jacobian
    looked up and the joint step, and the shared memory's four copies."""
    from plugcell.devices.robot.stream.adjusting import CYCLE_SLOTS, OFFSET_SLOTS, SeqVector
    from plugcell.kinematics import forward
    from plugcell.kinematics.jacobian import jacobian_from_fk

    desc = cell.desc_tool
    rng = np.random.default_rng(0)
    Q = cell.q0 + 0.01 * np.cumsum(rng.standard_normal((n, 6)) * 1e-2, axis=0)
    fk = forward(desc, None, Q, "nominal")
    J = jacobian_from_fk(desc, fk, "tcp")
    cyc, off = SeqVector(RawArray("d", CYCLE_SLOTS)), SeqVector(RawArray("d", OFFSET_SLOTS))
    step, shm = [], []
    o = np.array([1e-4, -2e-4, 5e-5, 0.0, 0.0, 0.0])
    for k in range(n):
        c0 = time.thread_time_ns()
        T_path = fk.tcp[k]
        dq = np.linalg.lstsq(J[k], o, rcond=None)[0]
        step.append((time.thread_time_ns() - c0) / 1e3)
        assert T_path.shape == (4, 4)
        c0 = time.thread_time_ns()
        cyc.write(np.array([1.0, k, k * 0.004, time.time(), *Q[k]]))
        seen = cyc.read()
        off.write(np.array([1.0, seen[1], *dq]))
        off.read()
        shm.append((time.thread_time_ns() - c0) / 1e3)
    return {"service: T_p, J_n looked up, Δq = J⁻¹o": np.array(step),
            "shared memory: cycle + adjustment, written and read": np.array(shm)}


def _row(name: str, x: np.ndarray) -> str:
    p50, p99 = np.percentile(x, [50, 99])
    return f"| {name} | {p50:.0f} | {p99:.0f} | {x.max():.0f} | {x.mean():.0f} |"


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--speed", type=float, default=100.0, help="mm/s")
    ap.add_argument("--poses", type=int, default=60, help="the calibration's poses")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--save", type=Path, help="write the replay's outputs (npz)")
    ap.add_argument("--compare", type=Path, help="check the outputs against a saved file")
    args = ap.parse_args(argv)
    if not (np.isfinite(args.speed) and args.speed > 0) or args.poses < 30:
        ap.error("--speed must be > 0 mm/s and --poses ≥ 30")
    t0 = time.time()
    cell, calls = record(args.speed, args.poses, args.seed)
    outs, cost = replay(cell, calls)
    extras = service_extras(cell)
    load = os.getloadavg()
    print(f"the tracking loop, one iteration: a 0.2 m line at {args.speed:g} mm/s on the "
          f"Smart H4 twin (model 5, {args.poses} poses), {len(cost['cpu'])} cycles replayed; "
          f"load average {load[0]:.1f} / {load[1]:.1f} on {os.cpu_count()} cores")
    print("| part | p50 µs | p99 µs | max µs | mean µs |")
    print("|---|---:|---:|---:|---:|")
    print(_row("loop iteration, wall", cost["wall"]))
    print(_row("loop iteration, CPU", cost["cpu"]))
    for part in ("estimator", "model poses", "feed-forward", "lead", "limiter", "rest"):
        print(_row(f"  {part} (CPU)", cost[part]))
    for name, x in extras.items():
        print(_row(f"{name} (CPU)", x))
    if args.save:
        np.savez(args.save, **outs)
        print(f"saved: {args.save}")
    if args.compare:
        ref = np.load(args.compare)
        worst = 0.0
        for k, v in outs.items():
            r = ref[k]
            if r.shape != v.shape or not np.array_equal(np.isnan(r), np.isnan(v)):
                print(f"{k}: differs in shape or in where it is undefined")
                return 1
            worst = max(worst, float(np.nan_to_num(np.abs(r - v)).max()))
        print(f"largest difference to {args.compare}: {worst:.3g} (m, rad)")
        if worst > 1e-9:
            return 1
    print(f"wall time {time.time() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
