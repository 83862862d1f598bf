"""What one interpolation cycle of a planned trajectory costs (plugcell.motion).

    .venv/bin/python benchmarks/motion_sampling.py [--cycles 500] [--robots elbow6,smart_h4]

A real-time link to a robot controller (KUKA RSI, ABB EGM) must deliver the next joint
setpoint every 4 ms.  For each robot this plans a joint PTP move and a Cartesian LIN
(whose every sample runs the inverse kinematics, Newton steps on the robot's own model,
loops included) and times:

* one cycle at a time — ``trajectory.at_cycle(k, 0.004)``, positions only (what the
  stream needs) and with velocities and accelerations — median and 99th percentile;
* the whole move at once — ``trajectory.sample(trajectory.cycle_times(0.004))``,
  vectorised, per cycle (what a link can precompute before the move starts);
* the planning with its checks.

Prints one table; the last column is the median's share of the 4 ms cycle.  Timings
are of a single Python thread on whatever machine runs it (say which).
"""

from __future__ import annotations

import argparse
import platform
import sys
import time

import numpy as np

from plugcell.io.robots import load_robot
from plugcell.kinematics import forward
from plugcell.motion import LIN, PTP, CartesianLimits, JointLimits, Trajectory, plan

CYCLE = 0.004
START = {"elbow6": [10.0, -80.0, 20.0, 30.0, 60.0, -20.0],
         "smart_h4": [10.0, -80.0, -190.0, 30.0, 60.0, -20.0],
         "fanuc_m20ia": [10.0, 10.0, -10.0, 30.0, -60.0, -20.0]}
JOINTS = JointLimits(np.radians([120, 115, 120, 190, 180, 260]),
                     np.radians([400, 350, 400, 600, 600, 800]),
                     np.radians([3000, 2500, 3000, 5000, 5000, 7000]))
CART = CartesianLimits(1.0, 4.0, 40.0, 2.0, 8.0, 80.0)


def _moves(name: str) -> tuple[np.ndarray, dict[str, list]]:
    desc = load_robot(name)
    q0 = np.radians(START[name])
    T0 = forward(desc, None, q0, "nominal").tcp
    T1 = T0.copy()
    T1[:3, 3] += [0.3, -0.2, -0.2]
    q1 = q0 + np.radians([40.0, 15.0, -20.0, 60.0, 30.0, 90.0])
    return q0, {"PTP (joints)": [PTP(target=q1)], "LIN (IK per sample)": [LIN(target=T1)]}


def _time_cycles(tr: Trajectory, cycles: int, order: int) -> np.ndarray:
    n = len(tr.cycle_times(CYCLE))
    ks = np.linspace(0, n - 1, cycles).astype(int)
    out = np.empty(cycles)
    for i, k in enumerate(ks):
        t0 = time.perf_counter()
        tr.at_cycle(int(k), CYCLE, order)
        out[i] = time.perf_counter() - t0
    return out


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cycles", type=int, default=500, help="cycles timed one at a time")
    ap.add_argument("--robots", default="elbow6,smart_h4")
    args = ap.parse_args(argv)
    print(f"machine: {platform.machine()}, {platform.processor() or 'cpu'}, Python "
          f"{platform.python_version()}; cycle {CYCLE * 1e3:g} ms")
    head = (f"{'robot':<12} {'move':<20} {'what':<34} {'median µs':>10} {'p99 µs':>10} "
            f"{'of 4 ms':>8}")
    print(head)
    print("-" * len(head))
    for name in args.robots.split(","):
        desc = load_robot(name)
        q0, cases = _moves(name)
        for label, moves in cases.items():
            t0 = time.perf_counter()
            tr = plan(desc, q0, moves, JOINTS, CART)
            t_plan = time.perf_counter() - t0
            rows = []
            for order, what in ((0, "one cycle, positions"), (2, "one cycle, + vel. and acc.")):
                x = _time_cycles(tr, args.cycles, order) * 1e6
                rows.append((what, float(np.median(x)), float(np.percentile(x, 99))))
            times = tr.cycle_times(CYCLE)
            t0 = time.perf_counter()
            tr.sample(times, 0)
            per = (time.perf_counter() - t0) / times.size * 1e6
            rows.append((f"whole move at once ({times.size} cycles)", per, float("nan")))
            rows.append((f"plan + checks ({tr.duration:.2f} s of motion)", t_plan * 1e6,
                         float("nan")))
            for what, med, p99 in rows:
                share = f"{med / (CYCLE * 1e6) * 100:7.1f}%" if "plan" not in what else ""
                p99s = f"{p99:10.0f}" if np.isfinite(p99) else f"{'':>10}"
                print(f"{name:<12} {label:<20} {what:<34} {med:10.0f} {p99s} {share:>8}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
