"""What the compute service's worker costs and buys: ``worker=thread`` against ``process``.

    .venv/bin/python benchmarks/compute_worker.py [--poses 60] [--model 4] [--evaluates 20]

For each worker a compute service runs as ``plugcell serve compute --param worker=W`` (an
OS process of its own, as served); a requester (this process) puts a calibration
campaign of the digital twin (``--poses`` poses, seed 0, 36 kg) into its workspace and
measures:

* first Evaluate: ``n = size(mT)`` the first time (the process worker starts there);
* Evaluate round trip: the median of ``--evaluates`` more — the service's path plus, for
  the process worker, the workspace pickled to the worker and back;
* calibrate: ``params = calibrate(mJ, mT, model=M, payload=36)``, wall time, the first
  and the second time (the first imports what the functions need, in the worker
  process anew);
* Get during calibrate: the service's Get (its GenericDeviceState, answered beside the
  process queue) round trips, median, 95th percentile and max, asked every 10 ms while
  the second calibration runs — what the service's own computing costs its answers —
  beside the same when idle.  (Get Matrix waits in the queue behind the Evaluate
  either way: one process at a time.)

Figures vary with the machine's load; the table says what was measured.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import platform
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path

import numpy as np

from plugcell.framework import Client, ProcessStates


def campaign(poses: int) -> tuple[np.ndarray, np.ndarray]:
    """Joint readings (deg) and tracker poses (mm, deg ZYZ) of the twin, as a robot
    program sends them."""
    from plugcell.sim.twin.campaign import measure_poses, working_volume_joints
    from plugcell.sim.twin.robot import RobotTwin
    from plugcell.sim.twin.scenario import TwinScenario
    from plugcell.sim.twin.tracker import LaserTracker

    robot = RobotTwin(TwinScenario(seed=0, payload_kg=36.0))
    profile = robot.reveal_truth().profile
    q = working_volume_joints(robot.description, profile, poses, np.random.default_rng(1))
    m, _ = measure_poses(robot, LaserTracker(seed=0), q, rotation="zyz")
    return np.rad2deg(m.joints), np.hstack([m.positions * 1e3, np.rad2deg(m.angles)])


def serve(worker: str, cell: str, home: Path) -> subprocess.Popen[str]:
    proc = subprocess.Popen(
        [sys.executable, "-m", "plugcell", "serve", "compute", "--cell", cell, "--no-journal",
         "--param", f"worker={worker}", "--param", f"data_dir={home / worker}"],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        env={**os.environ, "PLUGCELL_HOME": str(home)})
    assert proc.stdout is not None
    for line in proc.stdout:
        if "serving in cell" in line:
            return proc
    raise RuntimeError(f"the compute service ({worker}) did not start: exit {proc.wait()}")


async def _round_trip(client: Client, command: str, option: str = "", data=None) -> float:
    start = time.perf_counter()
    final = await (await client.create_process("COMPUTE", command, option, data,
                                               timeout=600)).result()
    if final.state is not ProcessStates.Completed:
        raise RuntimeError(f"{command} {option}: {final.reason}")
    return time.perf_counter() - start


async def _get(client: Client) -> float:
    start = time.perf_counter()
    await client.get("COMPUTE")
    return time.perf_counter() - start


async def _gets_while(client: Client, running: asyncio.Task) -> list[float]:
    times = []
    while not running.done():
        times.append(await _get(client))
        await asyncio.sleep(0.01)
    return times


async def measure(cell: str, mJ: np.ndarray, mT: np.ndarray, model: int, evaluates: int
                  ) -> dict[str, float]:
    async with Client("BENCH", cell=cell) as client, Client("BENCH_GET", cell=cell) as getter:
        assert await client.wait_for("COMPUTE", 30) and await getter.wait_for("COMPUTE", 30)
        await _round_trip(client, "Set Matrix", "mJ", mJ)
        await _round_trip(client, "Set Matrix", "mT", mT)
        first = await _round_trip(client, "Evaluate", "", "n = size(mT)")
        evals = [await _round_trip(client, "Evaluate", "", "n = size(mT)")
                 for _ in range(evaluates)]
        idle = [await _get(getter) for _ in range(50)]
        text = f"params = calibrate(mJ, mT, model={model}, payload=36)"
        calibrate1 = await _round_trip(client, "Evaluate", "", text)
        calibrate = asyncio.create_task(_round_trip(client, "Evaluate", "", text))
        busy = await _gets_while(getter, calibrate)
        return {"first": first, "evaluate": float(np.median(evals)),
                "calibrate1": calibrate1,
                "calibrate": calibrate.result(), "busy50": float(np.median(busy)),
                "busy95": float(np.percentile(busy, 95)), "busymax": max(busy),
                "idle50": float(np.median(idle)), "gets": len(busy)}


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--poses", type=int, default=60)
    p.add_argument("--model", type=int, default=4)
    p.add_argument("--evaluates", type=int, default=20)
    p.add_argument("--workers", default="thread,process")
    args = p.parse_args()
    mJ, mT = campaign(args.poses)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for worker in args.workers.split(","):
            cell = f"cw{uuid.uuid4().hex[:8]}"
            proc = serve(worker, cell, Path(tmp))
            try:
                rows.append((worker, asyncio.run(measure(cell, mJ, mT, args.model,
                                                         args.evaluates))))
            finally:
                proc.terminate()
                proc.wait(30)
    print(f"compute service workers: {args.poses} poses, model {args.model}; "
          f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"Python {platform.python_version()}")
    print("| worker | first Evaluate s | Evaluate ms | calibrate s: first | second "
          "| Get idle ms | Get during calibrate ms: median | p95 | max | Gets |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for worker, r in rows:
        print(f"| {worker} | {r['first']:.2f} | {r['evaluate'] * 1e3:.1f} | "
              f"{r['calibrate1']:.2f} | {r['calibrate']:.2f} | {r['idle50'] * 1e3:.2f} | "
              f"{r['busy50'] * 1e3:.2f} | "
              f"{r['busy95'] * 1e3:.2f} | {r['busymax'] * 1e3:.1f} | {r['gets']} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
