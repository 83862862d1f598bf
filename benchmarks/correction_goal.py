"""What one cycle's goal ``g`` of a mode-(b) correction costs (issue 37 §1).

The robot service's ``CORRECT`` (devices/robot/stream/correcting.py) computes ``g`` for
every controller cycle: a constant offset in the stream's own space (nothing to compute),
a Cartesian offset on a joint stream (the nominal model's forward kinematics and Jacobian
at the path's joints, ``Δq = J⁺·o``), or a calibration's compensation (one Newton step of
eq. 4.11 on the identified model; over RSI's Cartesian corrections and EGM's path
correction also the nominal inverse kinematics of the path's pose and the step turned into
the stream's correction).  Whatever costs more than a fraction of the 4 ms cycle
is computed in a thread beside the link (``_Beside``): this table is why.

    python benchmarks/correction_goal.py [--cycles 1000]

Prints, per source, the time of one ``g`` (µs: p50, p99, max) over ``--cycles`` cycles of
a path turning A1 at 10 °/s, and the share of a 4 ms cycle the median takes.  The
calibration is the 36 kg twin (seed 3) identified with model 5 from 60 simulated poses.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
import types

import numpy as np

from plugcell.calibration.identify import Calibrator
from plugcell.devices.robot.egm import EgmConfig
from plugcell.devices.robot.rsi import RsiConfig
from plugcell.devices.robot.stream.correcting import CorrectionSpec, make_source
from plugcell.devices.robot.stream.source import CycleState
from plugcell.io.params import params_json
from plugcell.sim.twin.campaign import measure_poses, working_volume_joints
from plugcell.sim.twin.robot import RobotTwin
from plugcell.sim.twin.scenario import TwinScenario
from plugcell.sim.twin.tracker import LaserTracker

Q = np.radians([-15.0, -75.0, -190.0, 0.0, 75.0, 0.0])
CYCLE_S = 0.004


def _calibration(folder: str) -> str:
    robot = RobotTwin(TwinScenario(seed=3, payload_kg=36.0))
    q = working_volume_joints(robot.description, robot.reveal_truth().profile, 60,
                              np.random.default_rng(4))
    ms, _ = measure_poses(robot, LaserTracker(seed=3), q)
    path = os.path.join(folder, "params.json")
    with open(path, "w", encoding="utf-8") as f:
        f.write(params_json(Calibrator(robot.description, 5).fit(ms)))
    return path


JOINTS = RsiConfig(robot_host="127.0.0.1", correction="joint", mode="absolute")
RKORR = RsiConfig(robot_host="127.0.0.1", correction="cartesian", mode="absolute")
PATHCORR = EgmConfig(robot_host="127.0.0.1", mode="pathcorr")


def _time(spec: CorrectionSpec, cycles: int, config=JOINTS) -> np.ndarray:
    running = make_source(spec, config)
    running.close()  # g computed here, in this thread, cycle by cycle
    offset = np.zeros(6)
    times = []
    for k in range(cycles):
        q = Q + np.radians([10.0 * CYCLE_S * k, 0, 0, 0, 0, 0])
        # the set-point joints: the path's plus the offset (a joint stream), or the path's
        # (a Cartesian one: what its inverse kinematics costs does not depend on them)
        q_set = q + offset if config is JOINTS else q
        robot = types.SimpleNamespace(joints=q_set, joints_setpoint=q_set)
        state = CycleState(robot, offset, 1, k, CYCLE_S * k)
        t0 = time.perf_counter_ns()
        offset = running.goal_now(state)
        times.append(time.perf_counter_ns() - t0)
    return np.asarray(times) / 1e3


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cycles", type=int, default=1000)
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as folder:
        params = _calibration(folder)
        rows = [("offset, joints on a joint stream",
                 CorrectionSpec("offset", (0, 0, 0, 0, 0, 1e-4), frame="joints")),
                ("offset, base frame on a joint stream",
                 CorrectionSpec("offset", (0, 0, 5e-4, 0, 0, 0), frame="base")),
                ("compensation (model 5)",
                 CorrectionSpec("compensation", calibration=params)),
                ("compensation over RKorr (base frame)",
                 CorrectionSpec("compensation", calibration=params), RKORR),
                ("compensation over EGM path corrections",
                 CorrectionSpec("compensation", calibration=params), PATHCORR)]
        print(f"one cycle's g, {args.cycles} cycles (µs); load average "
              f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
        print(f"{'source':40s} {'p50':>9s} {'p99':>9s} {'max':>9s} {'p50 / 4 ms':>11s}")
        for name, spec, *config in rows:
            t = _time(spec, args.cycles, *config)
            p50 = np.percentile(t, 50)
            print(f"{name:40s} {p50:9.1f} {np.percentile(t, 99):9.1f} {t.max():9.1f} "
                  f"{p50 / 4000 * 100:10.1f}%")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
