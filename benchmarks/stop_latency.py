"""How long a serving ``plugcell`` process takes to exit after SIGTERM.

    .venv/bin/python benchmarks/stop_latency.py [--repeat 3]

Each row starts its command as its own process in a fresh cell, waits for its ready
line (or, for the "while starting" rows, for a fixed moment while it is still starting),
sends SIGTERM and measures the wall time until the process has exited; best, median and
worst of ``--repeat`` runs, and the exit codes seen (a process still there 45 s after
SIGTERM is killed: ``> 45``, exit code -9).  Rows:

* ``opcua serve`` — the cell's OPC UA gateway, idle;
* ``serve opcua-device`` — connected to the node-opcua gripper of tests/opcua/js (the row
  is skipped, with the reason, when Node.js or its modules are missing);
* ``serve opcua-device, while starting`` — its endpoint accepts TCP and never answers, so
  the process is still connecting (its log says ``connecting to``) when SIGTERM comes;
  with ``watch_s=30`` the connection would time out after 60 s, and SIGTERM must not
  wait for that.

Wall time on a loaded machine includes waiting for the CPU: run it on a quiet one.
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import shutil
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import uuid
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from plugcell.sim.ports import free_port

ROOT = Path(__file__).resolve().parents[1]
JS = ROOT / "tests" / "opcua" / "js"
MAP = ROOT / "tests" / "opcua" / "gripper.toml"
#: Seconds a process gets to exit after SIGTERM before it is killed (shown as "> 45").
STOP_LIMIT_S = 45.0


def plugcell(*args: str) -> list[str]:
    return [sys.executable, "-m", "plugcell", *args]


def stop_time(argv: list[str], env: dict[str, str], ready: Callable[[str], bool],
              start_timeout: float = 60.0) -> tuple[float, int]:
    """Start ``argv``; once a line satisfies ``ready``, SIGTERM it; the seconds until it
    exited, and its exit code."""
    proc = subprocess.Popen(argv, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True, start_new_session=True)
    lines: list[str] = []
    seen = threading.Event()

    def read() -> None:
        assert proc.stdout is not None
        for line in proc.stdout:
            lines.append(line)
            if ready(line):
                seen.set()

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    try:
        if not seen.wait(start_timeout):
            raise RuntimeError(f"{argv[3:5]} not ready: {''.join(lines)[-400:]}")
        t0 = time.perf_counter()
        proc.send_signal(signal.SIGTERM)
        try:
            code = proc.wait(STOP_LIMIT_S)
        except subprocess.TimeoutExpired:  # killed below; the row says "> limit"
            return math.inf, -9
        return time.perf_counter() - t0, code
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()


@contextmanager
def gripper_server() -> Iterator[str]:
    """The node-opcua gripper of the tests; its endpoint."""
    port = free_port()
    proc = subprocess.Popen(["node", str(JS / "gripper_server.js"), str(port)],
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        assert proc.stdout is not None
        for line in proc.stdout:
            if '"listening"' in line:
                break
        yield f"opc.tcp://127.0.0.1:{port}/gripper"
    finally:
        proc.terminate()
        proc.wait(10)


@contextmanager
def silent_server() -> Iterator[str]:
    """A TCP listener that accepts and never answers: an OPC UA client hangs connecting."""
    sock = socket.socket()
    sock.bind(("127.0.0.1", 0))
    sock.listen()
    held: list[socket.socket] = []
    stop = threading.Event()

    def accept() -> None:
        sock.settimeout(0.2)
        while not stop.is_set():
            try:
                held.append(sock.accept()[0])
            except OSError:
                continue

    thread = threading.Thread(target=accept, daemon=True)
    thread.start()
    try:
        yield f"opc.tcp://127.0.0.1:{sock.getsockname()[1]}/silent"
    finally:
        stop.set()
        thread.join()
        for conn in held:
            conn.close()
        sock.close()


def _seconds(t: float) -> str:
    return f"> {STOP_LIMIT_S:g}" if math.isinf(t) else f"{t:.2f}"


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=3, help="runs per row (default 3)")
    args = ap.parse_args(argv)
    home = Path(tempfile.mkdtemp(prefix="plugcell-stop-"))
    env = {**os.environ, "PLUGCELL_HOME": str(home), "PYTHONUNBUFFERED": "1"}
    serving = lambda line: "serving in cell" in line  # noqa: E731
    gateway = lambda line: "OPC UA gateway" in line  # noqa: E731
    connecting = lambda line: "connecting to opc.tcp" in line  # noqa: E731

    def cell() -> str:
        return f"stop-{uuid.uuid4().hex[:8]}"

    rows: list[tuple[str, Callable[[], tuple[float, int]] | str]] = [
        ("opcua serve (idle gateway)",
         lambda: stop_time(plugcell("opcua", "serve", "--cell", cell(), "--port",
                                    str(free_port()), "--allow-anonymous"), env, gateway)),
    ]
    have_node = shutil.which("node") and (JS / "node_modules").is_dir()
    if have_node:
        def device() -> tuple[float, int]:
            with gripper_server() as endpoint:
                return stop_time(plugcell("serve", "opcua-device", "--cell", cell(),
                                          "--endpoint", endpoint, "--map", str(MAP),
                                          "--insecure-accept-any"),
                                 env, serving)
        rows.append(("serve opcua-device (connected)", device))
    else:
        rows.append(("serve opcua-device (connected)",
                     "skipped: needs node and tests/opcua/js/node_modules (npm ci there)"))

    def starting() -> tuple[float, int]:
        with silent_server() as endpoint:
            return stop_time(plugcell("serve", "opcua-device", "--cell", cell(), "--endpoint",
                                      endpoint, "--map", str(MAP), "--param", "watch_s=30",
                                      "--insecure-accept-any", "--log-level", "INFO"), env,
                             connecting)
    rows.append(("serve opcua-device (while starting)", starting))

    print(f"SIGTERM → exit, {args.repeat} runs each; {platform.processor() or platform.machine()}"
          f", {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}")
    print(f"| {'process':<38} | best s | median s | worst s | exit codes |")
    print(f"|{'-' * 40}|--------|----------|---------|------------|")
    for label, run in rows:
        if isinstance(run, str):
            print(f"| {label:<38} | {run} |")
            continue
        times, codes = [], set()
        for _ in range(args.repeat):
            t, code = run()
            times.append(t)
            codes.add(code)
        best, median, worst = (_seconds(t) for t in (min(times), statistics.median(times),
                                                      max(times)))
        print(f"| {label:<38} | {best:>6} | {median:>8} | {worst:>7} | "
              f"{','.join(map(str, sorted(codes))):<10} |")
    shutil.rmtree(home, ignore_errors=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
