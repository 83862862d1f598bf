"""What an idle cell costs: N services, each its own process, doing nothing.

    .venv/bin/python benchmarks/idle_cost.py [--services 20] [--seconds 30]
        [--settings default,no-shm,lean] [--topology mesh,star] [--threads]

Starts ``--services`` services (cameras, drills, benchmark publishers and compute
services in turn, simulated, Zenoh on loopback — peers, or clients of a router with
``--topology star`` —, journals on) as
``plugcell serve KIND`` processes in a fresh cell, waits until every one says it is
serving and has settled, then reads the CPU time (user + system, from
``/proc/PID/stat``) of all of them over ``--seconds`` of idleness: presence, the
queued-process heartbeat and Zenoh's own keep-alive are all that runs.  Then the same
for as many bare Zenoh sessions (``zenoh.open`` with plugcell's transport
configuration, nothing declared): the floor Zenoh's peer mesh sets.  Prints each total
as a share of one core and per process.  Linux only (reads /proc).

Each of ``--settings`` runs both, with the transport settings an idle cell's cost
depends on (framework/transport.py): ``default`` (Zenoh's shared memory on, its 10 s
lease), ``no-shm`` (``PLUGCELL_SHM=0``: no shared-memory hand-off task waking every
process ten times a second) and ``lean`` (``PLUGCELL_SHM=0 PLUGCELL_LEASE=60``: keep-alives on
each link every 15 s instead of 2.5 s).

``--topology``: ``mesh`` (the default: every process a peer, linked to every other,
N(N−1)/2 links) and ``star`` (every process a client of one ``plugcell router`` on
loopback, ``PLUGCELL_MODE=client``: N links; the router's CPU counts, and is shown apart).

``--threads`` also lists where that CPU time goes, summed over the processes by thread
name (``/proc/PID/task/TID/stat``): Zenoh's runtime threads (``net-0``, ``tx-0``,
``rx-0``…), the journal's mover, the interpreter's main thread (``python``).
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path

from plugcell.sim.ports import free_port

KINDS = ("camera", "drill", "bench", "compute")
#: A bare Zenoh session with plugcell's transport configuration, announcing itself.
BARE = ("import time\n"
        "from plugcell.framework.transport import TransportConfig, open_session\n"
        "s = open_session(TransportConfig.from_env())\n"
        "print('serving in cell (bare zenoh session)', flush=True)\n"
        "time.sleep(1e6)\n")
TICK = os.sysconf("SC_CLK_TCK")
SETTINGS: dict[str, dict[str, str]] = {
    "default": {},
    "no-shm": {"PLUGCELL_SHM": "0"},
    "lean": {"PLUGCELL_SHM": "0", "PLUGCELL_LEASE": "60"},
}


def _stat_cpu(stat: str) -> float:
    """User + system CPU time (s) from a ``/proc/.../stat`` line."""
    fields = stat.rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICK  # utime, stime (fields 14, 15)


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of process ``pid`` (s)."""
    return _stat_cpu(Path(f"/proc/{pid}/stat").read_text())


def thread_seconds(pid: int) -> dict[tuple[int, str], float]:
    """CPU time (s) of each live thread of process ``pid``, keyed by (thread id, name)."""
    out: dict[tuple[int, str], float] = {}
    for task in Path(f"/proc/{pid}/task").iterdir():
        try:
            stat = (task / "stat").read_text()
        except OSError:  # the thread ended meanwhile
            continue
        out[(int(task.name), stat[stat.index("(") + 1:stat.rindex(")")])] = _stat_cpu(stat)
    return out


def by_thread_name(before: list[dict[tuple[int, str], float]],
                   after: list[dict[tuple[int, str], float]]) -> dict[str, float]:
    """CPU seconds between the two readings, summed over processes by thread name
    (a thread started in between counts from zero)."""
    total: dict[str, float] = {}
    for b, a in zip(before, after, strict=True):
        for key, seconds in a.items():
            total[key[1]] = total.get(key[1], 0.0) + seconds - b.get(key, 0.0)
    return total


def _wait_for(process: subprocess.Popen[str], marker: str) -> None:
    """Read ``process``'s output until a line holds ``marker`` (SystemExit if it ends
    first)."""
    assert process.stdout is not None
    for line in process.stdout:
        if marker in line:
            return
    raise SystemExit(f"{process.args[:4]} ended before {marker!r} (exit {process.wait()})")


def measure(commands: list[list[str]], env: dict[str, str], seconds: float,
            settle: float, router: list[str] | None = None,
            ) -> tuple[float, float, list[float], dict[str, float]]:
    """Start the processes (after ``router``, when given, until it listens), wait until
    each says it is serving, settle, then their CPU time over ``seconds``: (start-up s,
    measured wall s, CPU s of each process — the router's last —, CPU s summed by thread
    name)."""
    procs: list[subprocess.Popen[str]] = []  # every one started, stopped at the end

    def start(argv: list[str]) -> subprocess.Popen[str]:
        procs.append(subprocess.Popen(argv, env=env, stdout=subprocess.PIPE,
                                      stderr=subprocess.STDOUT, text=True))
        return procs[-1]

    t0 = time.monotonic()
    try:
        hub = [start(router)] if router is not None else []
        for p in hub:
            _wait_for(p, "listening on")
        services = [start(argv) for argv in commands]
        for p in services:
            _wait_for(p, "serving in cell")
        measured = services + hub  # the router's last, as the caller reads it
        started = time.monotonic() - t0
        time.sleep(settle)
        before = [cpu_seconds(p.pid) for p in measured]
        threads_before = [thread_seconds(p.pid) for p in measured]
        t1 = time.monotonic()
        time.sleep(seconds)
        after = [cpu_seconds(p.pid) for p in measured]
        threads_after = [thread_seconds(p.pid) for p in measured]
        wall = time.monotonic() - t1
    finally:
        for p in procs:
            p.terminate()
        for p in procs:
            try:
                p.wait(10)
            except subprocess.TimeoutExpired:
                p.kill()
    return (started, wall, [a - b for a, b in zip(after, before, strict=True)],
            by_thread_name(threads_before, threads_after))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--services", type=int, default=20)
    ap.add_argument("--seconds", type=float, default=30.0)
    ap.add_argument("--settle", type=float, default=5.0,
                    help="seconds to wait after the last process is serving")
    ap.add_argument("--settings", default="default,no-shm,lean",
                    help=f"comma-separated, of {', '.join(SETTINGS)}")
    ap.add_argument("--topology", default="mesh",
                    help="comma-separated, of mesh, star (module doc)")
    ap.add_argument("--threads", action="store_true",
                    help="also list the CPU by thread name (Zenoh's runtime threads, ...)")
    args = ap.parse_args()
    chosen = [x.strip() for x in args.settings.split(",") if x.strip()]
    unknown = [x for x in chosen if x not in SETTINGS]
    if unknown:
        ap.error(f"unknown settings {', '.join(unknown)} (known: {', '.join(SETTINGS)})")
    topologies = [x.strip() for x in args.topology.split(",") if x.strip()]
    if not topologies or set(topologies) - {"mesh", "star"}:
        ap.error(f"--topology takes mesh and/or star, got {args.topology!r}")
    cell = f"idle{uuid.uuid4().hex[:8]}"
    base_env = {k: v for k, v in os.environ.items()
                if k not in ("PLUGCELL_SHM", "PLUGCELL_LEASE", "PLUGCELL_MODE", "PLUGCELL_CONNECT",
                             "PLUGCELL_LISTEN", "PLUGCELL_MULTICAST")}
    services = [[sys.executable, "-m", "plugcell", "serve", KINDS[i % len(KINDS)], "--cell",
                 cell, "--name", f"{KINDS[i % len(KINDS)].upper()}{i}"]
                for i in range(args.services)]
    bare = [[sys.executable, "-c", BARE]] * args.services
    print(f"idle cell: {args.services} processes, Zenoh on loopback; "
          f"{platform.machine()}, Python {platform.python_version()}, {os.cpu_count()} cores, "
          f"load {os.getloadavg()[0]:.1f}")
    print(f"{'settings':9s} {'':5s} {'':34s} {'started in s':>13} {'measured s':>11} "
          f"{'CPU of one core':>16} {'per process':>12} {'busiest':>9}")
    for topology in topologies:
        star = topology == "star"
        for setting in chosen:
            for label, commands in ((f"plugcell services ({', '.join(KINDS)})", services),
                                    ("bare Zenoh sessions (the floor)", bare)):
                home = Path(tempfile.mkdtemp(prefix="plugcell-idle-"))
                env = {**base_env, **SETTINGS[setting], "PLUGCELL_HOME": str(home),
                       "PYTHONUNBUFFERED": "1"}
                router = ([sys.executable, "-m", "plugcell", "router", "--listen",
                           f"tcp/127.0.0.1:{free_port()}"] if star else None)
                if router is not None:
                    env.update(PLUGCELL_MODE="client", PLUGCELL_MULTICAST="0",
                               PLUGCELL_CONNECT=router[-1])
                started, wall, used, threads = measure(commands, env, args.seconds,
                                                       args.settle, router)
                total = sum(used) / wall
                hub = f" (router {100 * used[-1] / wall:.2f}%)" if star else ""
                print(f"{setting:9s} {topology:5s} {label:34s} {started:13.1f} {wall:11.1f} "
                      f"{100 * total:15.2f}% {100 * total / len(used):11.3f}% "
                      f"{100 * max(used) / wall:8.3f}%{hub}", flush=True)
                if args.threads:
                    busy = sorted(threads.items(), key=lambda kv: -kv[1])
                    print("    by thread: " + ", ".join(
                        f"{name} {100 * cpu / wall:.2f}%" for name, cpu in busy if cpu > 0),
                        flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
