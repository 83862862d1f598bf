"""Load: N robots × M processes each against one tracker service (issue 10 §3).

``python benchmarks/load.py [ROBOTS] [PER_ROBOT] [WINDOW]`` (default 10 × 1000, 8
outstanding per robot).  The tracker runs as an OS process (``plugcell serve
tracker``); the robots are requesters in this process (one Zenoh session each),
each keeping WINDOW processes in flight (``Set Base``, a NoData command with six
doubles, so the figure is the framework's, not the simulated instrument's).

Checked from the requesters and from the tracker's journal: no process lost (every
one acknowledged, Completed, journaled), per-sender order kept (each robot's
processes started in the order sent), no deadlock (the whole run is bounded).
Reported: tracker utilisation (time running processes / wall time) and, per robot,
its waiting time in the tracker's queue (start − received, from the journal) and
its round trip (result − send).  Exit 1 if a check fails.
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
from collections import deque
from pathlib import Path
from typing import Any

from plugcell.framework import Client, ProcessStates
from plugcell.framework.journal import journal_files, read_journal

BASE = [2500.0, -800.0, -600.0, 30.0, 2.0, -20.0]


def start_tracker(cell: str, home: str) -> subprocess.Popen[str]:
    """``plugcell serve tracker`` in ``cell``, returned once it serves (≤ 30 s)."""
    env = {**os.environ, "PLUGCELL_HOME": home, "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen(
        [sys.executable, "-m", "plugcell", "serve", "tracker", "--cell", cell],
        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, env=env,
        start_new_session=True,
    )
    assert proc.stdout is not None
    deadline = time.monotonic() + 30
    for line in proc.stdout:
        if "serving in cell" in line:
            break
        if time.monotonic() > deadline:
            raise TimeoutError("tracker did not start")
    return proc


def stop(proc: subprocess.Popen[str]) -> None:
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGTERM)
        try:
            proc.wait(15)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(10)
    if proc.stdout is not None:
        proc.stdout.close()


async def _robot(client: Client, n: int, window: int) -> dict[str, Any]:
    sent: list[int] = []
    trips: list[float] = []
    states: list[str] = []
    pending: deque[tuple[Any, float]] = deque()

    async def settle_one() -> None:
        call, t0 = pending.popleft()
        final = await call.result()
        trips.append(time.perf_counter() - t0)
        states.append(final.state.value)

    for _ in range(n):
        t0 = time.perf_counter()
        call = await client.create_process("TRACKER", "Set Base", "euler2tr", BASE, timeout=60)
        sent.append(call.identifier)
        if call.ack.state is not ProcessStates.Queued:
            states.append(f"refused: {call.ack.reason}")
            continue
        pending.append((call, t0))
        if len(pending) >= window:
            await settle_one()
    while pending:
        await settle_one()
    return {"name": client.name, "sent": sent, "trips": trips, "states": states}


async def _load(cell: str, robots: int, per_robot: int, window: int) -> list[dict[str, Any]]:
    clients = [Client(f"ROBOT{i + 1:02d}", cell=cell) for i in range(robots)]
    for c in clients:
        await c.start()
    try:
        for c in clients:
            assert await c.wait_for("TRACKER", 15), "no tracker"
            await c.subscribe("TRACKER")
        return list(await asyncio.gather(*(_robot(c, per_robot, window) for c in clients)))
    finally:
        for c in clients:
            await c.close()


def run_load(
    robots: int = 10, per_robot: int = 1000, window: int = 8, timeout: float = 600.0,
    home: str | None = None,
) -> dict[str, Any]:
    """Run the load and return the report (``ok`` False with ``problems`` if a check fails)."""
    cell = f"load{uuid.uuid4().hex[:10]}"
    with tempfile.TemporaryDirectory() as tmp:
        home = home or tmp
        tracker = start_tracker(cell, home)
        t0 = time.perf_counter()
        try:
            results = asyncio.run(asyncio.wait_for(_load(cell, robots, per_robot, window),
                                                   timeout))
        finally:
            wall = time.perf_counter() - t0
            stop(tracker)
        journal = read_journal(journal_files(cell, Path(home)))
    return report(results, journal, wall, per_robot)


def report(results: list[dict[str, Any]], journal: list[dict[str, Any]], wall: float,
           per_robot: int) -> dict[str, Any]:
    problems: list[str] = []
    by_sender: dict[str, list[dict[str, Any]]] = {}
    for p in journal:
        by_sender.setdefault(p["sender"], []).append(p)
    busy_ns = 0
    first, last = None, None
    rows = []
    for r in results:
        name = r["name"]
        done = r["states"].count("Completed")
        if done != per_robot:
            problems.append(f"{name}: {done}/{per_robot} Completed ({set(r['states'])})")
        procs = {p["identifier"]: p for p in by_sender.get(name, [])}
        missing = [i for i in r["sent"] if i not in procs]
        if missing:
            problems.append(f"{name}: {len(missing)} processes missing from the journal")
        waits = []
        starts = []
        for ident in r["sent"]:
            p = procs.get(ident)
            if p is None or not p["updates"]:
                continue
            start = p["updates"][0]["t_ns"]
            end = p.get("finished_ns") or start
            starts.append(start)
            waits.append((start - p["received_ns"]) / 1e6)
            busy_ns += end - start
            first = min(first or p["received_ns"], p["received_ns"])
            last = max(last or end, end)
        if starts != sorted(starts):
            problems.append(f"{name}: processes started out of the order sent")
        trips = [t * 1e3 for t in r["trips"]]
        rows.append({
            "robot": name, "completed": done,
            "wait_mean_ms": statistics.fmean(waits) if waits else 0.0,
            "wait_p95_ms": _pct(waits, 95), "wait_max_ms": max(waits, default=0.0),
            "trip_mean_ms": statistics.fmean(trips) if trips else 0.0,
            "trip_p95_ms": _pct(trips, 95),
        })
    span = ((last or 0) - (first or 0)) / 1e9
    total = sum(r["completed"] for r in rows)
    return {
        "ok": not problems, "problems": problems, "robots": rows, "wall_s": wall,
        "processes": total, "span_s": span, "throughput_per_s": total / span if span else 0.0,
        "tracker_utilisation": (busy_ns / 1e9) / span if span > 0 else 0.0,
    }


def _pct(values: list[float], q: float) -> float:
    if not values:
        return 0.0
    s = sorted(values)
    return s[min(len(s) - 1, round(q / 100 * (len(s) - 1)))]


def print_report(rep: dict[str, Any]) -> None:
    print(f"{'robot':<8} {'done':>6} {'wait mean':>10} {'wait p95':>9} {'wait max':>9} "
          f"{'trip mean':>10} {'trip p95':>9}   (ms)")
    for r in rep["robots"]:
        print(f"{r['robot']:<8} {r['completed']:>6} {r['wait_mean_ms']:10.2f} "
              f"{r['wait_p95_ms']:9.2f} {r['wait_max_ms']:9.2f} {r['trip_mean_ms']:10.2f} "
              f"{r['trip_p95_ms']:9.2f}")
    print(f"{rep['processes']} processes in {rep['span_s']:.2f} s at the tracker "
          f"({rep['throughput_per_s']:.0f}/s); tracker utilisation "
          f"{rep['tracker_utilisation'] * 100:.1f} %; "
          + ("no process lost, per-sender order kept" if rep["ok"]
             else "PROBLEMS: " + "; ".join(rep["problems"])))


def main() -> int:
    robots = int(sys.argv[1]) if len(sys.argv) > 1 else 10
    per_robot = int(sys.argv[2]) if len(sys.argv) > 2 else 1000
    window = int(sys.argv[3]) if len(sys.argv) > 3 else 8
    rep = run_load(robots, per_robot, window)
    print_report(rep)
    print(json.dumps({k: v for k, v in rep.items() if k != "robots"}))
    return 0 if rep["ok"] else 1


if __name__ == "__main__":
    sys.exit(main())
