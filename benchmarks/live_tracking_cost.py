"""What showing a tracked move live costs (devices/robot/live_tracking.py, issue 38 §2).

    PYTHONPATH=src .venv/bin/python benchmarks/live_tracking_cost.py [--cycles 2000]

The tracking loop's cycle (the real-time path: ``TrackedMoves``'s ``offset``) only
appends ``(k, newest good sample)`` for the live view; everything else — reading the
cycles, the deviations, decimation, msgpack — runs in the robot service's event loop
(:class:`LiveTracking`, ≤ 10 times a second).  Measured on this machine, median of 7
repeats, µs:

* the loop's own cycle for scale: ``TrackingLoop.add`` + ``cycle`` (Smart H4, nominal
  model, a 1 kHz tracker's 4 samples a 4 ms cycle);
* what the live view adds to a cycle: ``_newest_good`` + the append;
* one batch of the service's event loop: 25 cycles (0.1 s at 4 ms), and 250 (a batch
  decimated to 25 points), with its size in bytes.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from plugcell.compensation.pose_model import NominalModel
from plugcell.compensation.tracking import TrackerMeasurement, TrackingLoop, TrackingSettings
from plugcell.devices.robot.live_tracking import LiveTracking, identity_now
from plugcell.devices.robot.tracked_moves import _newest_good
from plugcell.io.robots import load_robot

T = 0.004


def _median_us(fn, n: int, repeats: int = 7) -> float:
    runs = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn(n)
        runs.append((time.perf_counter() - t0) / n * 1e6)
    return statistics.median(runs)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cycles", type=int, default=2000)
    n = ap.parse_args().cycles
    desc = load_robot("smart_h4")
    model = NominalModel(desc, np.eye(4))
    q0 = np.radians([0.0, -20.0, -100.0, 0.0, 30.0, 0.0])
    Tp = model.evaluate(q0)[0][0]
    rng = np.random.default_rng(0)

    def samples(k: int) -> list[TrackerMeasurement]:
        out = []
        for j in range(4):
            P = Tp.copy()
            P[:3, 3] += 60e-6 * rng.standard_normal(3)
            out.append(TrackerMeasurement(k * T - 0.003 + j * 1e-3, P, True, "ok"))
        return out

    batches = [samples(k) for k in range(n)]

    def loop_cycles(m: int) -> None:
        loop = TrackingLoop(model, TrackingSettings(cycle_s=T))
        for k in range(m):
            loop.add(batches[k])
            loop.cycle(k * T, q0, Tp)

    def live_adds(m: int) -> None:
        cycles: list = []
        for k in range(m):
            cycles.append((k, _newest_good(batches[k])))

    plan_p = np.tile(Tp[:3, 3], (n + 1, 1))
    record = [(k * T, np.r_[0.0, 5e-4, 0.0, 0.0, 0.0, 0.0], "tracking", None, 1.0)
              for k in range(n)]
    cycles = [(k, _newest_good(batches[k])) for k in range(n)]
    sizes: dict[int, int] = {}

    def flushes(per_batch: int):
        def run(m: int) -> None:
            sent: list[bytes] = []
            live = LiveTracking("H4", sent.append)
            shown_r: list = []
            shown_c: list = []
            live.begin(identity_now(("line.pdl", 1), 1, "TRACKER"), T, 0.5, plan_p, shown_r,
                       shown_c)
            for i in range(m):
                a = (i * per_batch) % (n - per_batch)
                shown_r.extend(record[a:a + per_batch])
                shown_c.extend(cycles[a:a + per_batch])
                live.flush()
            sizes[per_batch] = len(sent[-1])
        return run

    loop_us = _median_us(loop_cycles, n)
    add_us = _median_us(live_adds, n)
    f25 = _median_us(flushes(25), 200)
    f250 = _median_us(flushes(250), 50)
    print("| what | where | µs | note |")
    print("|---|---|---:|---|")
    print(f"| tracking loop, one cycle (add + cycle) | loop thread | {loop_us:.1f} | "
          "4 samples a 4 ms cycle |")
    print(f"| live view's addition to a cycle | loop thread | {add_us:.2f} | "
          f"{100 * add_us / loop_us:.2f} % of the cycle |")
    print(f"| one batch, 25 cycles | service event loop | {f25:.0f} | {sizes[25]} bytes, "
          f"{100 * f25 / 1e5:.2f} % of a core at 10 batches/s |")
    print(f"| one batch, 250 cycles → 25 points | service event loop | {f250:.0f} | "
          f"{sizes[250]} bytes |")


if __name__ == "__main__":
    main()
