"""The robot service's answers over RSI or EGM while it runs a program (issue 37 §7):
``rsi_latency.py --in-service`` and ``egm_latency.py --in-service``.

    python benchmarks/rsi_latency.py --in-service [--link-thread] [--seconds 60] [--cell N]
    python benchmarks/egm_latency.py --in-service [--link-thread] [--seconds 60] [--cell N]

``--link-thread`` runs the link in a thread of the service's process
(``--param stream_process=false``) instead of its own process: the before of the move.

Four processes: the twin's robot side (``plugcell twin rsi`` or ``plugcell twin egm``:
the dynamic twin behind a KUKA controller's RSI or an ABB controller's
EGM, which owns the clock, sends a packet every 4 ms, times each answer from its send to
its arrival and counts the late ones as the controller does — RSI's ``<Delay>``, EGM's
samples left unanswered); ``plugcell serve robot --rsi/--egm`` (the controller's timeout
left at its default: RSI ``Timeout`` 100 cycles, EGM ``\\CommTimeout`` 1 s — 250 cycles),
running a program that swings two axes back and forth (a PTP a second, each planned on
the PC), its joints published at 25 Hz; a bare UDP echo (``recvfrom`` → ``sendto``) pinged
by this process every 4 ms, the floor of Python and the kernel in the same run.  The
first two seconds are warm-up.  CPU is the service's process and its children's (the
link's process) user + system time over the measured seconds, % of one core.

The table says how late the service answers the robot (round trip p50 / p99 / p99.9 /
max, late cycles as the controller counts them, the longest run of late cycles in a row —
the controller breaks off at its timeout) and whether the program still ran at the end
(the stream survived the controller's default timeout).  Nothing is asserted.
"""

from __future__ import annotations

import json
import os
import select
import shutil
import socket
import subprocess
import sys
import tempfile
import threading
import time
import uuid
from pathlib import Path

import numpy as np

from plugcell.sim.ports import free_port

WARMUP_S = 2.0
#: the program the service runs: it swings two axes, a PTP a second, until stopped
SWING = Path(__file__).resolve().parents[1] / "tests" / "robot" / "programs" / "swing.pdl"
#: vendor → the twin's command (``plugcell twin …``), the service's flag of the stream,
#: the twin's timeout option and the service's (both far out: the run measures on whatever
#: happens), and the controller's default timeout in cycles (RSI Timeout 100; EGM
#: \CommTimeout 1 s)
TWINS = {"RSI": ("rsi", "--rsi", "10000", "10000", 100),
         "EGM": ("egm", "--egm", "3600", "60", 250)}


def _tree_cpu_s(pid: int) -> float:
    """User + system seconds of ``pid`` and its descendants now (Linux /proc)."""
    tick = os.sysconf("SC_CLK_TCK")
    total, todo = 0.0, [pid]
    while todo:
        p = todo.pop()
        try:
            fields = Path(f"/proc/{p}/stat").read_text().rsplit(")", 1)[1].split()
            total += (int(fields[11]) + int(fields[12])) / tick
            for task in Path(f"/proc/{p}/task").iterdir():
                todo += [int(c) for c in (task / "children").read_text().split()]
        except (OSError, IndexError, ValueError):
            continue
    return total


class EchoPinger:
    """A bare UDP echo (``rsi_latency.py --role echo``: it sends back a datagram's last 64
    bytes) pinged every cycle from a thread."""

    def __init__(self, cycle_ms: float) -> None:
        script = str(Path(__file__).with_name("rsi_latency.py"))
        self.proc = subprocess.Popen([sys.executable, script, "--role", "echo"],
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        line = self.proc.stdout.readline()  # type: ignore[union-attr]
        if not line.startswith("READY "):
            raise RuntimeError(f"the echo did not start: {line!r}")
        self.port = int(line.split()[1])
        self.cycle_ns = int(cycle_ms * 1e6)
        self.rtts: list[int] = []
        self.sent = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.connect(("127.0.0.1", self.port))
        sock.setblocking(False)
        poller = select.poll()
        poller.register(sock, select.POLLIN)
        seq, next_t, pending = 0, time.monotonic_ns(), {}
        while not self._stop.is_set():
            now = time.monotonic_ns()
            if now >= next_t:
                seq += 1
                pending[seq] = time.monotonic_ns()
                sock.send(seq.to_bytes(8, "big"))
                self.sent += 1
                next_t += self.cycle_ns
                if next_t < now:
                    next_t = now + self.cycle_ns
            for _ in poller.poll(max(0, (next_t - time.monotonic_ns()) // 1_000_000)):
                while True:
                    try:
                        data = sock.recv(64)
                    except BlockingIOError:
                        break
                    t0 = pending.pop(int.from_bytes(data[:8], "big"), None)
                    if t0 is not None:
                        self.rtts.append(time.monotonic_ns() - t0)
        sock.close()

    def reset(self) -> None:
        self.rtts, self.sent = [], 0

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2)
        self.proc.kill()
        self.proc.wait(10)


def _wait_line(proc: subprocess.Popen, needle: str, timeout: float) -> list[str]:
    """Wait for a line holding ``needle``; the process's output is read (and kept) on."""
    got: list[str] = []
    found = threading.Event()

    def read() -> None:
        for line in proc.stdout:  # type: ignore[union-attr]
            got.append(line)
            if needle in line:
                found.set()

    threading.Thread(target=read, daemon=True).start()
    if not found.wait(timeout):
        raise RuntimeError(f"no {needle!r} within {timeout} s: {''.join(got)[-2000:]}")
    return got


def _plugcell(env: dict, *args: str, timeout: float = 60) -> str:
    out = subprocess.run([sys.executable, "-m", "plugcell", *args], env=env, text=True,
                         capture_output=True, timeout=timeout)
    return out.stdout + out.stderr


def measure(vendor: str, seconds: float, cycle_ms: float = 4.0, thread: bool = False,
            params: tuple[str, ...] = ()) -> dict:
    """One in-service run (module docstring); the figures.  ``thread``: the link in a
    thread of the service's process (``--param stream_process=false``), not its own;
    ``params``: more ``KEY=VALUE`` of the service (the link's scheduling:
    ``stream_rt_priority=20``, ``stream_cpu=1``, ``stream_mlock=true``)."""
    side, flag, twin_timeout, service_timeout, _ = TWINS[vendor]
    home = Path(tempfile.mkdtemp(prefix="plugcell-in-service-"))
    (home / "programs").mkdir()
    shutil.copy(SWING, home / "programs")
    env = {**os.environ, "PLUGCELL_HOME": str(home), "PYTHONUNBUFFERED": "1"}
    cell = f"ins{uuid.uuid4().hex[:8]}"
    port = free_port("udp")
    stats_file = home / "twin.json"
    echo = EchoPinger(cycle_ms)
    twin = subprocess.Popen([sys.executable, "-m", "plugcell", "twin", side, "--ip",
                             "127.0.0.1", "--port", str(port), "--timeout", twin_timeout,
                             "--stats", str(stats_file)], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    service = subprocess.Popen(
        [sys.executable, "-m", "plugcell", "serve", "robot", flag, f"127.0.0.1:{port}",
         f"{flag}-timeout", service_timeout,
         "--param", f"library={home / 'programs'}", "--cell", cell,
         *(["--param", "stream_process=false"] if thread else []),
         *(a for kv in params for a in ("--param", kv))], env=env,
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        _wait_line(twin, "streaming", 60)
        _wait_line(service, "serving in cell", 60)
        started = _plugcell(env, "call", "ROBOT", "ACTIVATE", "--data", '["swing"]',
                            "--cell", cell)
        if '"Completed"' not in started:
            raise RuntimeError(f"the program did not start: {started}")
        time.sleep(WARMUP_S)
        echo.reset()
        cpu0, t0 = _tree_cpu_s(service.pid), time.monotonic_ns()
        time.sleep(seconds)
        cpu = _tree_cpu_s(service.pid) - cpu0
        t1 = time.monotonic_ns()
        wall = (t1 - t0) / 1e9
        echo_rtts, echo_sent = list(echo.rtts), echo.sent
        status = _plugcell(env, "call", "ROBOT", "PROGRAM_STATUS", "--cell", cell)
    finally:
        twin.terminate()
        twin.wait(30)
        service.terminate()
        try:
            service.wait(30)
        except subprocess.TimeoutExpired:
            service.kill()
        echo.close()
    stats = json.loads(stats_file.read_text())
    shutil.rmtree(home, ignore_errors=True)
    window = [rtt for sent, rtt in stats["rtt_ns"] if t0 <= sent < t1]
    late_flags = np.array([rtt < 0 or rtt > cycle_ms * 1e6 for rtt in window])
    rtts = np.array([rtt for rtt in window if rtt >= 0], dtype=float) / 1e3
    return {
        "service": {
            "cycles": len(window), "late": int(stats["late"]),
            "twin_cycles": int(stats["cycles"]),
            "late_measured": int(late_flags.sum()),
            "late_100_after_s": _nth_late_s(late_flags, 100, cycle_ms),
            "longest_late_run": _longest_run(late_flags),
            "rtt_us": _percentiles(rtts),
            "cpu_pct": 100 * cpu / wall,
            "program_running": "RUNNING" in status,
            "twin_stopped": stats.get("stopped"),
        },
        "echo": {
            "cycles": echo_sent, "late": int(sum(r > cycle_ms * 1e6 for r in echo_rtts))
            + echo_sent - len(echo_rtts),
            "rtt_us": _percentiles(np.array(echo_rtts, dtype=float) / 1e3),
        },
        "status": _final(status),
    }


def _final(output: str) -> str:
    """The final update's state and reason (or data) of ``plugcell call``'s output."""
    for line in reversed(output.strip().splitlines()):
        try:
            event = json.loads(line)
        except ValueError:
            continue
        return f"{event.get('state')}: {event.get('reason') or event.get('data')}"
    return output.strip()[-300:]


def _nth_late_s(flags: np.ndarray, n: int, cycle_ms: float) -> float | None:
    """Seconds into the window when the ``n``-th late cycle came (``None``: fewer)."""
    late = np.flatnonzero(flags)
    return float(late[n - 1] * cycle_ms / 1000) if len(late) >= n else None


def _longest_run(flags: np.ndarray) -> int:
    best = run = 0
    for f in flags:
        run = run + 1 if f else 0
        best = max(best, run)
    return best


def _percentiles(x: np.ndarray) -> dict:
    if not len(x):
        return {"p50": float("nan"), "p99": float("nan"), "p99.9": float("nan"),
                "max": float("nan")}
    return {q: float(np.percentile(x, p)) for q, p in
            (("p50", 50), ("p99", 99), ("p99.9", 99.9))} | {"max": float(x.max())}


def table(vendor: str, r: dict, seconds: float, thread: bool = False) -> str:
    s, e = r["service"], r["echo"]
    where = "a thread of the service's process" if thread else "its own process"
    lines = [f"plugcell serve robot --{vendor.lower()} running a program, the link in {where}, "
             f"{seconds:.0f} s measured (+{WARMUP_S:.0f} s warm-up); round trips timed by the "
             f"twin's {vendor} robot side", "",
             "| answered by | cycles | round trip p50 / p99 / p99.9 / max (µs) | late "
             "(controller's count) | longest late run | CPU % of a core |",
             "|---|---:|---|---:|---:|---:|"]
    for name, x, run, cpu in ((f"robot service over {vendor}", s, s["longest_late_run"],
                               f"{s['cpu_pct']:.1f}"),
                              ("bare UDP echo", e, "", "")):
        rt = x["rtt_us"]
        late = x.get("late_measured", x["late"])
        lines.append(f"| {name} | {x['cycles']} | {rt['p50']:.0f} / {rt['p99']:.0f} / "
                     f"{rt['p99.9']:.0f} / {rt['max']:.0f} | {late} | {run} | {cpu} |")
    default = TWINS[vendor][4]
    after = s["late_100_after_s"]
    lines += ["", f"the program still running at the end: "
              f"{'yes' if s['program_running'] else 'NO'} (PROGRAM_STATUS {r['status'][:300]})",
              f"the twin counted {s['late']} late answers over its whole run "
              f"({s['twin_cycles']} cycles)",
              "a controller counting every late answer of a session (rsipi, the twin's RSI "
              "side) with Timeout 100 would have stopped "
              + (f"{after:.1f} s into the window" if after is not None else "never"),
              f"a controller counting them in a row with the default ({default} cycles) would "
              f"have stopped: {'yes' if s['longest_late_run'] >= default else 'no'} "
              f"(longest run {s['longest_late_run']})"]
    return "\n".join(lines)


def main(vendor: str, seconds: float, json_path: Path | None, thread: bool = False,
         params: tuple[str, ...] = ()) -> int:
    """Run :func:`measure` and print the table (``rsi_latency.py --in-service``; its
    ``--rt-priority``, ``--cpu`` and ``--mlock`` become the service's ``params``)."""
    print(f"machine: {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f} at start",
          flush=True)
    result = measure(vendor, seconds, thread=thread, params=params)
    print(table(vendor, result, seconds, thread))
    if params:
        print("the service's link: " + " ".join(f"--param {kv}" for kv in params))
    print(f"load average {os.getloadavg()[0]:.2f} at the end")
    if json_path:
        json_path.write_text(json.dumps(result, indent=1), encoding="utf-8")
    return 0
