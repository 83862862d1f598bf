"""What the kinematics of one configuration cost a call (a real-time cycle's share).

    .venv/bin/python benchmarks/kinematics_cycle.py [--calls 3000] [--repeat 5]
                                                    [--robots smart_h4,elbow6,fanuc_m20ia]

A 4 ms correction or tracking cycle calls the forward kinematics and Jacobians of *one*
configuration a dozen times (a compensation's Newton steps, the nominal model of the
controller, the twin's physics); the calibration calls them for thousands at once.  Per
robot this prints the CPU time (``time.process_time``, µs per configuration: the best
of ``--repeat`` rounds of ``--calls`` calls, so another process's load does not count)
of

* ``forward`` of one configuration, and per configuration of a batch of 1 000;
* ``manipulator_jacobian`` of one configuration;
* ``fourbar_closure`` of one configuration (robots with a parallelogram loop);
* ``so3_log`` of one rotation (the TCP's: every pose error takes one).

To compare two versions, run the script of one under ``PYTHONPATH`` of the other's
``src``.  Timings are of one Python thread on whatever machine runs it (say which).
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from collections.abc import Callable

import numpy as np

from plugcell.io.robots import RobotNotFoundError, load_robot
from plugcell.kinematics import forward, fourbar_closure
from plugcell.kinematics.jacobian import manipulator_jacobian
from plugcell.kinematics.transforms import so3_log

BATCH = 1000


def _us(call: Callable[[], object], calls: int, repeat: int, per: int = 1) -> float:
    """The best round's CPU µs per configuration."""
    call()
    best = float("inf")
    for _ in range(repeat):
        t0 = time.process_time()
        for _ in range(calls):
            call()
        best = min(best, time.process_time() - t0)
    return best / calls / per * 1e6


def _row(name: str, calls: int, repeat: int) -> list[str]:
    desc = load_robot(name)
    q = np.asarray(desc.home, dtype=float)
    batch = np.random.default_rng(0).uniform(*desc.joint_limits.T, (BATCH, desc.n_readings))
    batch = batch[forward(desc, None, batch, raise_errors=False).valid]
    in_batch = _us(lambda: forward(desc, None, batch), max(calls // 100, 3), repeat, len(batch))
    cells = [f"{_us(lambda: forward(desc, None, q), calls, repeat):.0f}", f"{in_batch:.1f}",
             f"{_us(lambda: manipulator_jacobian(desc, None, q), calls, repeat):.0f}"]
    if desc.loops:
        p = desc.nominal_parameters()
        ia, ic, i3, i4, _, _ = desc.loop_indices[0]
        theta = forward(desc, None, q).theta
        args = (theta[ia], theta[ic], p.a[ia], p.a[ic], p.a[i3], p.a[i4])
        cells.append(f"{_us(lambda: fourbar_closure(*args), calls, repeat):.0f}")
    else:
        cells.append("–")
    R = forward(desc, None, q).tcp[:3, :3].copy()
    cells.append(f"{_us(lambda: so3_log(R), calls, repeat):.0f}")
    return [name, *cells]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--calls", type=int, default=3000, help="calls a round (default 3000)")
    ap.add_argument("--repeat", type=int, default=5, help="rounds, the best kept (default 5)")
    ap.add_argument("--robots", default="smart_h4,elbow6,fanuc_m20ia",
                    help="comma-separated robot names (default: the three shipped)")
    args = ap.parse_args(argv)
    if args.calls < 1 or args.repeat < 1:
        ap.error("--calls and --repeat must be at least 1")
    names = [n.strip() for n in args.robots.split(",")]
    for name in names:
        try:
            load_robot(name)
        except RobotNotFoundError as exc:
            ap.error(f"--robots: {exc}")
    print(f"{platform.machine()}, Python {platform.python_version()}, "
          f"load average {os.getloadavg()[0]:.1f}; CPU µs per configuration, best of "
          f"{args.repeat} rounds of {args.calls} calls\n")
    print(f"| robot | forward, one | forward, in a batch of {BATCH} | Jacobian, one "
          "| four-bar closure, one | so3_log, one |")
    print("|---|---:|---:|---:|---:|---:|")
    for name in names:
        print("| " + " | ".join(_row(name, args.calls, args.repeat)) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
