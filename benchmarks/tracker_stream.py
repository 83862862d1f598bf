"""The tracker's stream at up to 1 kHz: sample → subscriber latency and the share delivered.

    .venv/bin/python benchmarks/tracker_stream.py [--seconds 10]

A simulated tracker service runs as its own process (``plugcell serve tracker``); this
process publishes a T-MAC on the simulated world, Moves the beam onto it and subscribes
to Stream Measurement at 1000 Hz with 1, 8 and 25 samples per message (and 125 Hz for
comparison).  For every sample it records ``arrival − pc_time_s`` (both ``time.time()``
on this machine: from the driver having the sample to the subscriber having it) and
counts the samples delivered against those the tracker's clock says were due (``seq``).
The instrument's own latency (model: window/2 + 2 ms) comes before that and is not
in the figure.  Speed is measured here, never asserted in tests.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import os
import platform
import subprocess
import sys
import time
import uuid

import numpy as np

from plugcell.devices.tracker.service import STREAM_COLUMNS
from plugcell.framework import Client, ProcessCall, ProcessStates
from plugcell.framework.bus import Bus
from plugcell.framework.keys import KeySpace
from plugcell.framework.transport import TransportConfig, open_session
from plugcell.io.units import pose_from_robot
from plugcell.sim.world import ReflectorPublisher

SEQ, PC = STREAM_COLUMNS.index("seq"), STREAM_COLUMNS.index("pc_time_s")
TARGET = [2000.0, 300.0, 400.0, 0.0, 0.0, 0.0]  # mm, deg: 2 m in front of the tracker


async def run_one(client: Client, rate: int, per_message: int, seconds: float) -> dict:
    call = await client.create_process("TRACKER", "Stream Measurement", "", [rate, per_message],
                                       timeout=30)
    latencies: list[np.ndarray] = []
    seqs: list[np.ndarray] = []

    async def collect() -> None:
        async for update in call:
            if update.data is not None:
                now = time.time()
                rows = ProcessCall.array(update)
                latencies.append(now - rows[:, PC])
                seqs.append(rows[:, SEQ])

    with contextlib.suppress(TimeoutError):
        await asyncio.wait_for(collect(), seconds)
    stop = await (await client.create_process("TRACKER", "Stop Measurement", "")).result()
    assert stop.state is ProcessStates.Completed, stop.reason
    lat = np.concatenate(latencies) * 1e3 if latencies else np.array([np.nan])
    seq = np.concatenate(seqs) if seqs else np.array([0.0])
    due = seq.max() - seq.min() + 1
    return {"rate": rate, "per": per_message, "n": len(seq), "share": len(np.unique(seq)) / due,
            "p50": np.percentile(lat, 50), "p99": np.percentile(lat, 99), "max": lat.max()}


async def main_async(seconds: float) -> list[dict]:
    cell = f"bench{uuid.uuid4().hex[:10]}"
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen([sys.executable, "-m", "plugcell", "serve", "tracker", "--cell", cell,
                             "--no-journal", "--log-level", "WARNING"], env=env)
    session = open_session(TransportConfig.from_env())
    tmac = ReflectorPublisher(Bus(session, KeySpace(cell)), "TMAC", "tmac")
    tmac.publish(pose_from_robot(TARGET, "zyz"))
    try:
        async with Client("BENCH", cell=cell) as client:
            assert await client.wait_for("TRACKER", 30), "the tracker service did not start"
            move = await (await client.create_process("TRACKER", "Move", "", TARGET)).result()
            assert move.state is ProcessStates.Completed, move.reason
            return [await run_one(client, rate, per, seconds)
                    for rate, per in ((1000, 1), (1000, 8), (1000, 25), (125, 1))]
    finally:
        tmac.close()
        session.close()
        proc.terminate()
        proc.wait(10)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="per configuration")
    args = parser.parse_args()
    rows = asyncio.run(main_async(args.seconds))
    print(f"Tracker Stream Measurement, simulated tracker in its own process, {args.seconds:g} s "
          f"each ({platform.processor() or platform.machine()}, {os.cpu_count()} cores)")
    print("| rate Hz | samples/message | samples | delivered | driver → subscriber p50 ms "
          "| p99 ms | max ms |")
    print("|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        print(f"| {r['rate']} | {r['per']} | {r['n']} | {100 * r['share']:.2f} % | "
              f"{r['p50']:.2f} | {r['p99']:.2f} | {r['max']:.2f} |")


if __name__ == "__main__":
    main()
