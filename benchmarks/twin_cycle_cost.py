"""What the twin that moves in time costs a cycle (the simulated controllers' ``--dynamics``,
``plugcell twin rsi``).

    .venv/bin/python benchmarks/twin_cycle_cost.py [--cycles 1000] [--moves 3]

Times, on the Smart H4 twin with 36 kg:

* ``DynamicTwin.step`` — one 4 ms cycle of the servos, backlash and modes (median, p99);
* ``RobotTwin.true_reflector_in_tracker`` — the static physics of one pose (gravity
  through the closed loop, link bending): what the reflector feed and every look at the
  world pay;
* a ``DynamicArm`` move at speed inf (no pacing): the simulated seconds moved per real
  second — the largest ``--speed`` at which the dynamic arm keeps its pace.

Prints one table.  Timings are of one Python thread on whatever machine runs it (say
which, and how loaded).
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import time

import numpy as np

from plugcell.pdl import SimClock
from plugcell.sim.controller.arm import DynamicArm
from plugcell.sim.twin.dynamics import DynamicTwin
from plugcell.sim.twin.scenario import TwinScenario

SCENARIO = TwinScenario(robot="smart_h4", seed=0, payload_kg=36.0)
TARGETS = ([20.0, -80.0, -180.0, 10.0, 80.0, 10.0], [-10.0, -95.0, -195.0, -20.0, 95.0, -30.0],
           [0.0, -90.0, -187.0, 0.0, 90.0, 0.0])


def _times(call, n: int) -> np.ndarray:
    out = np.empty(n)
    for i in range(n):
        t0 = time.perf_counter()
        call(i)
        out[i] = time.perf_counter() - t0
    return out * 1e3


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--cycles", type=int, default=1000)
    p.add_argument("--moves", type=int, default=3)
    args = p.parse_args()
    arm = DynamicTwin(SCENARIO)
    q0 = arm.measured.copy()
    ramp = q0 + np.outer(np.linspace(0, 0.2, args.cycles), [1, 0, 0, 0, 0, 0])
    step = _times(lambda i: arm.step(ramp[i]), args.cycles)
    pose = _times(lambda i: arm.twin.true_reflector_in_tracker(), max(50, args.cycles // 10))
    clock = SimClock(speed=math.inf)
    motion = DynamicArm(DynamicTwin(SCENARIO), clock)
    t0 = time.perf_counter()
    for k in range(args.moves):
        motion.move_joints(TARGETS[k % len(TARGETS)])
    real = time.perf_counter() - t0
    print(f"Smart H4 twin, 36 kg; {platform.processor() or platform.machine()}, "
          f"{os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f}")
    print("| what | mean ms | median ms | p99 ms | mean's share of a 4 ms cycle |")
    print("|---|---:|---:|---:|---:|")
    for name, t in (("DynamicTwin.step (one cycle)", step),
                    ("true_reflector_in_tracker (one pose)", pose)):
        print(f"| {name} | {np.mean(t):.3f} | {np.median(t):.3f} | "
              f"{np.percentile(t, 99):.3f} | {np.mean(t) / 4.0:.1%} |")
    print(f"DynamicArm, {args.moves} PTPs at 40°/s: {clock.now():.2f} s moved in {real:.2f} s "
          f"real: {clock.now() / real:.1f}× real time at most")


if __name__ == "__main__":
    main()
