"""Fault benchmark: how fast a requester learns that its service died (issue 10 §2).

``python benchmarks/faults.py [ROUNDS]`` — each round starts a camera service as an
OS process (``plugcell serve camera``), streams ``MovieShot`` to an in-process
requester, kills the service with SIGKILL and measures, on the requester:

* kill → liveliness loss (Zenoh notices the closed link and withdraws the token);
* liveliness loss → the process ``Failed`` (the framework's part; target < 50 ms);
* kill → ``Failed`` (what a robot program sees).

Prints a table (ms: min / median / max) and one JSON line.
"""

from __future__ import annotations

import asyncio
import json
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
import uuid

from plugcell.framework import Client, ProcessStates

TARGET_MS = 50.0


def _serve(cell: str, env: dict[str, str]) -> subprocess.Popen[str]:
    proc = subprocess.Popen(
        [sys.executable, "-m", "plugcell", "serve", "camera", "--cell", cell],
        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, env=env,
        start_new_session=True,
    )
    assert proc.stdout is not None
    deadline = time.monotonic() + 30
    for line in proc.stdout:  # bounded by the service's own start-up
        if "serving in cell" in line or time.monotonic() > deadline:
            break
    return proc


async def _round(cell: str, proc: subprocess.Popen[str]) -> tuple[float, float, float]:
    async with Client("REQUESTER", cell=cell) as client:
        assert await client.wait_for("CAMERA", 15)
        call = await client.create_process("CAMERA", "MovieShot", data=20, timeout=10)
        async for update in call:
            if update.data is not None:
                break
        loop = asyncio.get_running_loop()
        left: asyncio.Future[float] = loop.create_future()

        async def watch() -> None:
            async for event in client.events():
                if event.kind == "leave" and event.presence.name == "CAMERA":
                    left.set_result(time.perf_counter())
                    return

        watcher = asyncio.create_task(watch())
        await asyncio.sleep(0.05)
        t_kill = time.perf_counter()
        os.killpg(proc.pid, signal.SIGKILL)
        final = await asyncio.wait_for(call.result(), 5)
        t_fail = time.perf_counter()
        t_left = await asyncio.wait_for(left, 5)
        watcher.cancel()
        assert final.state is ProcessStates.Failed, final
        return (t_left - t_kill) * 1e3, (t_fail - t_left) * 1e3, (t_fail - t_kill) * 1e3


def main() -> int:
    rounds = int(sys.argv[1]) if len(sys.argv) > 1 else 10
    rows: list[tuple[float, float, float]] = []
    with tempfile.TemporaryDirectory() as home:
        env = {**os.environ, "PLUGCELL_HOME": home}
        for _ in range(rounds):
            cell = f"bf{uuid.uuid4().hex[:10]}"
            proc = _serve(cell, env)
            try:
                rows.append(asyncio.run(asyncio.wait_for(_round(cell, proc), 60)))
            finally:
                if proc.poll() is None:
                    os.killpg(proc.pid, signal.SIGKILL)
                proc.wait(10)
                if proc.stdout is not None:
                    proc.stdout.close()
    names = ("kill → liveliness loss", "liveliness loss → Failed", "kill → Failed")
    print(f"{'ms':<26} {'min':>8} {'median':>8} {'max':>8}   ({rounds} rounds)")
    summary = {}
    for i, name in enumerate(names):
        col = [r[i] for r in rows]
        summary[name] = [min(col), statistics.median(col), max(col)]
        print(f"{name:<26} {min(col):8.2f} {statistics.median(col):8.2f} {max(col):8.2f}")
    worst = max(r[1] for r in rows)
    print(f"target: Failed within {TARGET_MS:g} ms of the liveliness loss — "
          f"{'met' if worst < TARGET_MS else 'MISSED'} (worst {worst:.2f} ms)")
    print(json.dumps({"rounds": rounds, "ms": summary}))
    return 0 if worst < TARGET_MS else 1


if __name__ == "__main__":
    sys.exit(main())
