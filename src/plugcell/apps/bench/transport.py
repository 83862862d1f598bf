"""``plugcell bench transport``: the message throughput and latency of thesis 5.3.

Reproduces the experiment of 5.3.1 between two services in two OS processes on
one host (Table 5-5): a *publisher* (a :class:`BenchService` in a child process)
and a *consumer* (a service in this process).

* throughput: the publisher pushes 10 000 ProcessUpdate notifications, each
  carrying the payload, as fast as possible; r = 10 000 / t_total (eq. 5.1), with
  t_total from sending the CreateProcess to receiving the last update.  Run
  ``--repeat`` times (3; 1 with ``--quick`` or ``--networked``), interleaved with the
  floor's runs; r is the best run (other programs on the machine only ever slow a
  run down, as with ``timeit``) and every run is kept in the report;
* latency: the consumer sends CreateProcess with the payload, the publisher
  answers with a ProcessUpdate carrying the same data; t_l is half the round trip,
  over 2 000 cycles (avg, max, min, std);
* payloads 4 B, 32 B, 1 KiB, 4 KiB, 64 KiB, 0.3 MB (640×480) and 0.9 MB (640×480×3)
  (Table 5-4), as Byte arrays of those shapes;
* the floor: plain Zenoh pub/sub between two Python processes (ping-pong for
  latency, a burst of puts for throughput), measured in the same run, payload by
  payload, interleaved with ours; its callbacks hand each sample to a thread, as
  plugcell's must.  Both of its ends are processes of their own
  (:class:`RawRequester`), plain Zenoh as a program using it alone gets it.  For
  reference, the same ping-pong answered inside Zenoh's callbacks themselves
  (``raw_zenoh_in_callback_latency_ms``): what Zenoh alone costs on the machine; and
  the same ping-pong with each sample handed to an event loop on each side
  (``raw_zenoh_event_loop_latency_ms``): the floor of any asyncio service, plugcell's
  design, before plugcell does any work.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import math
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import AsyncIterator, Sequence
from dataclasses import dataclass
from importlib import metadata
from typing import Any

import numpy as np

from plugcell.apps.bench.peer import stats_ms
from plugcell.apps.commands.deprecated import DeprecatedName
from plugcell.framework import eventloop
from plugcell.framework.messages import ProcessStates
from plugcell.framework.participant import Participant
from plugcell.framework.transport import TransportConfig


@dataclass(frozen=True)
class Payload:
    """One row of Table 5-4."""

    label: str
    shape: tuple[int, ...]

    @property
    def nbytes(self) -> int:
        return math.prod(self.shape)


PAYLOADS = (
    Payload("4 B", (4,)),
    Payload("32 B", (32,)),
    Payload("1 KiB", (1024,)),
    Payload("4 KiB", (4096,)),
    Payload("64 KiB", (65536,)),
    Payload("0.3 MB (640x480)", (480, 640)),
    Payload("0.9 MB (640x480x3)", (480, 640, 3)),
)

#: Table 5-5 (two local services): throughput r (msg/s), latency avg/max/min/std (ms).
THESIS_LOCAL: dict[int, tuple[str, float, tuple[float, float, float, float]]] = {
    4: (">10000", 10000, (0.23, 3.09, 0.21, 0.05)),
    32: (">10000", 10000, (0.30, 3.33, 0.22, 0.06)),
    1024: ("8333", 8333, (0.32, 3.45, 0.26, 0.31)),
    4096: ("6250", 6250, (2.01, 5.51, 1.26, 0.91)),
    65536: ("725", 725, (4.23, 8.82, 3.00, 1.34)),
    307200: ("80", 80, (8.80, 11.39, 5.38, 1.57)),
    921600: ("46", 46, (23.69, 28.31, 18.33, 1.90)),
}
#: Table 5-6 (two networked services, 100 Mbit/s), for reference.
THESIS_NETWORKED: dict[int, tuple[str, float, tuple[float, float, float, float]]] = {
    4: (">5000", 5000, (0.62, 6.46, 0.42, 0.60)),
    32: (">5000", 5000, (0.54, 1.75, 0.42, 0.14)),
    1024: ("3500", 3500, (0.84, 2.24, 0.67, 0.15)),
    4096: ("1385", 1385, (1.36, 4.36, 1.21, 0.42)),
    65536: ("90", 90, (13.53, 17.18, 12.67, 1.32)),
    307200: ("19", 19, (60.62, 63.07, 57.26, 1.33)),
    921600: ("6", 6, (178.34, 184.12, 174.07, 2.10)),
}


class Child:
    """A benchmark peer process (``python -m plugcell.apps.bench.peer``)."""

    def __init__(
        self, role: str, cell: str, env: dict[str, str], journal: bool, prefix: list[str],
        *, commands: bool = False,
    ) -> None:
        argv = [*prefix, sys.executable, "-m", "plugcell.apps.bench.peer", role, "--cell", cell]
        if not journal:
            argv.append("--no-journal")
        self.popen = subprocess.Popen(argv, stdout=subprocess.PIPE, text=True, env=env,
                                      stdin=subprocess.PIPE if commands else None)
        assert self.popen.stdout is not None
        line = self.popen.stdout.readline()
        if line.strip() != "ready":
            self.stop()
            raise RuntimeError(f"benchmark peer {role} did not start: {line!r}")

    def stop(self) -> None:
        if self.popen.stdin is not None:  # a command pipe: its end is the peer's signal
            with contextlib.suppress(OSError):
                self.popen.stdin.close()
            with contextlib.suppress(subprocess.TimeoutExpired):
                self.popen.wait(15)
        if self.popen.poll() is None:
            self.popen.terminate()
            try:
                self.popen.wait(15)
            except subprocess.TimeoutExpired:
                self.popen.kill()
                self.popen.wait(5)
        if self.popen.stdout is not None:
            self.popen.stdout.close()


class RawRequester(Child):
    """The raw-Zenoh floor's requester (:class:`~plugcell.apps.bench.peer.RawFloor`) in a
    process of its own, driven over its standard input and output one JSON line at a
    time: the floor is plain Zenoh between two Python processes, as a program using
    Zenoh alone gets it — not sharing this process's Zenoh threads, whose Python thread
    states plugcell keeps (framework/threadstate.py), which would speed the floor up too.
    """

    def __init__(self, cell: str, env: dict[str, str], prefix: list[str]) -> None:
        super().__init__("raw-requester", cell, env, False, prefix, commands=True)

    def _ask(self, op: str, *args: int) -> Any:
        assert self.popen.stdin is not None and self.popen.stdout is not None
        self.popen.stdin.write(json.dumps([op, *args]) + "\n")
        self.popen.stdin.flush()
        line = self.popen.stdout.readline()
        if not line:
            raise RuntimeError(f"the raw requester ended during {op} (exit {self.popen.poll()})")
        answer = json.loads(line)
        if "error" in answer:
            raise RuntimeError(f"the raw requester failed in {op}: {answer['error']}")
        return answer["result"]

    def latency(self, nbytes: int, cycles: int, warmup: int) -> dict[str, float]:
        """:meth:`RawFloor.latency <plugcell.apps.bench.peer.RawFloor.latency>`."""
        return dict(self._ask("latency", nbytes, cycles, warmup))

    def latency_in_callback(self, nbytes: int, cycles: int, warmup: int) -> dict[str, float]:
        """:meth:`RawFloor.latency_in_callback
        <plugcell.apps.bench.peer.RawFloor.latency_in_callback>`."""
        return dict(self._ask("latency_in_callback", nbytes, cycles, warmup))

    def latency_in_loop(self, nbytes: int, cycles: int, warmup: int) -> dict[str, float]:
        """:meth:`RawFloor.latency_in_loop <plugcell.apps.bench.peer.RawFloor.latency_in_loop>`."""
        return dict(self._ask("latency_in_loop", nbytes, cycles, warmup))

    def throughput(self, nbytes: int, messages: int) -> float:
        """:meth:`RawFloor.throughput <plugcell.apps.bench.peer.RawFloor.throughput>`."""
        return float(self._ask("throughput", nbytes, messages))

    def close(self) -> None:
        self.stop()


async def our_latency(consumer: Participant, payload: Payload, cycles: int, warmup: int) -> dict:
    """CreateProcess(Echo, data) → the ProcessUpdate with the same data; half the round trip
    (``consumer``: the consumer service's participant)."""
    data = np.full(payload.shape, 7, np.uint8)
    data.flags.writeable = False  # never changes: sent without a copy
    trips = []
    for i in range(warmup + cycles):
        t0 = time.perf_counter_ns()
        call = await consumer.create_process("PUBLISHER", "Echo", data=data, timeout=30)
        async for update in call:
            if update.data is not None or update.state.final:
                break
        t1 = time.perf_counter_ns()
        if update.state is not ProcessStates.Completed or update.data is None:
            raise RuntimeError(f"Echo failed: {update.reason}")
        if i >= warmup:
            trips.append((t1 - t0) // 2)
    return stats_ms(trips)


async def our_throughput(consumer: Participant, payload: Payload, messages: int) -> float:
    """Push ``messages`` ProcessUpdates with the payload; r = messages / t_total (eq. 5.1)."""
    t0 = time.perf_counter()
    call = await consumer.create_process(
        "PUBLISHER", "Push", data=[messages, *payload.shape], timeout=60
    )
    received = 0
    if received < messages:
        async for update in call:
            if update.state.final:
                raise RuntimeError(f"Push ended early: {update.reason}")
            if update.data is not None:
                received += 1
                if received == messages:
                    break
    rate = messages / (time.perf_counter() - t0)
    stop = await consumer.stop_process(call)
    await stop.result()
    await call.result()
    return rate


def machine() -> dict[str, Any]:
    cpu = platform.processor() or platform.machine()
    with contextlib.suppress(OSError), open("/proc/cpuinfo", encoding="utf-8") as f:
        for line in f:
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    return {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "system": f"{platform.system()} {platform.release()}",
        "python": platform.python_version(),
        "zenoh": metadata.version("eclipse-zenoh"),
        "msgspec": metadata.version("msgspec"),
        "event_loop": eventloop.name(),
        "load_avg_1min": os.getloadavg()[0] if hasattr(os, "getloadavg") else None,
    }


@dataclass
class Parties:
    """Who takes part in a run of the benchmark (:func:`parties`)."""

    consumer: Any
    """The requester and consumer: a :class:`~plugcell.apps.bench.device.BenchService`
    in this process, subscribed to the publisher."""
    publisher: Child
    """The :class:`~plugcell.apps.bench.device.BenchService` it measures, its own process."""
    raw_peer: Child
    """The far end of the raw-Zenoh floor (:func:`~plugcell.apps.bench.peer.serve_raw`)."""
    raw: RawRequester
    """The near end of that floor, a process of its own beside this one."""


@contextlib.asynccontextmanager
async def parties(cell: str, env: dict[str, str], transport: TransportConfig, journal: bool,
                  peer_env: dict[str, str] | None = None,
                  prefix: Sequence[str] = ()) -> AsyncIterator[Parties]:
    """Start everyone a run needs, in cell ``cell``, and stop them all afterwards.

    Parameters
    ----------
    cell, env, transport
        The cell, the environment of the processes beside this one, and this process's
        transport.
    journal
        Whether the two services keep their journals.
    peer_env, prefix
        The environment of the far ends (default ``env``) and the command prefix that
        starts them (``--networked``: in the other network namespace).
    """
    from plugcell.apps.bench.device import bench_service

    far_env = env if peer_env is None else peer_env
    publisher = Child("service", cell, far_env, journal, list(prefix))
    raw_peer = Child("raw", cell, far_env, False, list(prefix))
    consumer = bench_service("CONSUMER", cell=cell, transport=transport, journal=journal)
    raw = None
    try:
        await consumer.start()
        if not await consumer.participant.wait_for("PUBLISHER", 15):
            raise RuntimeError("the publisher service did not appear")
        await consumer.participant.subscribe("PUBLISHER")
        raw = await asyncio.to_thread(RawRequester, cell, env, [])  # here, beside us
        yield Parties(consumer, publisher, raw_peer, raw)
    finally:
        if raw is not None:
            raw.close()
        await consumer.close()
        publisher.stop()
        raw_peer.stop()


async def _measure(
    args: argparse.Namespace, cell: str, env: dict[str, str], payloads: list[Payload], progress: Any
) -> list[dict[str, Any]]:
    os.environ["PLUGCELL_HOME"] = env["PLUGCELL_HOME"]
    transport = TransportConfig.from_env()
    prefix: list[str] = []
    peer_env = env
    if args.peer_netns:  # --networked, inside namespace A: the peers run in namespace B
        prefix = ["ip", "netns", "exec", args.peer_netns]
        peer_env = {**env, "PLUGCELL_LISTEN": args.peer_listen}
    rows = []
    async with parties(cell, env, transport, not args.no_journal, peer_env, prefix) as who:
        consumer, raw = who.consumer, who.raw
        repeat = _repeat(args)
        for p in payloads:
            cycles, messages = _counts(args, p)
            warmup = min(50, cycles)
            progress(f"{p.label}: raw latency")
            raw_lat = raw.latency(p.nbytes, cycles, warmup)
            progress(f"{p.label}: raw latency inside Zenoh's callbacks")
            raw_cb = raw.latency_in_callback(p.nbytes, cycles, warmup)
            progress(f"{p.label}: raw latency through event loops")
            raw_loop = raw.latency_in_loop(p.nbytes, cycles, warmup)
            progress(f"{p.label}: latency ({cycles} cycles)")
            lat = await our_latency(consumer.participant, p, cycles, warmup)
            raw_runs, runs = [], []
            for i in range(repeat):
                run_no = f", run {i + 1} of {repeat}" if repeat > 1 else ""
                progress(f"{p.label}: raw throughput{run_no}")
                raw_runs.append(raw.throughput(p.nbytes, messages))
                progress(f"{p.label}: throughput ({messages} messages{run_no})")
                runs.append(await our_throughput(consumer.participant, p, messages))
            thr, raw_thr = max(runs), max(raw_runs)
            table = THESIS_NETWORKED if args.peer_netns else THESIS_LOCAL
            thesis_r, thesis_r_num, thesis_lat = table[p.nbytes]
            rows.append(
                {
                    "payload": p.label,
                    "payload_bytes": p.nbytes,
                    "shape": list(p.shape),
                    "cycles": cycles,
                    "messages": messages,
                    "throughput_msg_s": thr,
                    "throughput_runs_msg_s": runs,
                    "latency_ms": lat,
                    "raw_zenoh_throughput_msg_s": raw_thr,
                    "raw_zenoh_throughput_runs_msg_s": raw_runs,
                    "raw_zenoh_latency_ms": raw_lat,
                    "raw_zenoh_in_callback_latency_ms": raw_cb,
                    "raw_zenoh_event_loop_latency_ms": raw_loop,
                    "latency_vs_raw": lat["avg"] / raw_lat["avg"],
                    "throughput_vs_thesis": thr / thesis_r_num,
                    "thesis": {
                        "throughput_msg_s": thesis_r,
                        "latency_ms": dict(
                            zip(("avg", "max", "min", "std"), thesis_lat, strict=True)
                        ),
                    },
                }
            )
    return rows


#: The shaped link of ``--networked`` (thesis 5.3.1: 100 Mbit Ethernet through a switch).
LINK_MBIT = 100.0


def _counts(args: argparse.Namespace, p: Payload) -> tuple[int, int]:
    """Latency cycles and throughput messages for one payload.

    Local: 2 000 cycles and 10 000 messages as in 5.3.1 (``--quick``: 200, and
    1 000 or 200 messages).  Networked: the same, capped so that each payload
    moves at most ~300 MB (~24 s at 100 Mbit/s; 30 MB with ``--quick``) — the
    thesis's 10 000 × 0.9 MB at 6 msg/s took half an hour.
    """
    big = p.nbytes >= 300_000
    cycles = args.cycles or (200 if args.quick else 2000)
    messages = args.messages or ((200 if big else 1000) if args.quick else 10000)
    if args.peer_netns:
        budget = 30e6 if args.quick else 300e6
        if not args.messages:
            messages = min(messages, max(50, int(budget / p.nbytes)))
        if not args.cycles:
            cycles = min(cycles, max(30, int(budget / 4 / p.nbytes)))
    return cycles, messages


def _repeat(args: argparse.Namespace) -> int:
    """Throughput runs per payload: ``--repeat``, else 3 (1 quick or networked, where
    the shaped link, not the machine, sets the rate)."""
    if args.repeat is not None:
        return int(args.repeat)
    return 1 if args.quick or args.peer_netns else 3


def _at_least_one(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {value}")
    return value


def targets(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """The issue's targets, evaluated (not tuned for)."""
    out: dict[str, Any] = {
        "throughput_10x_thesis_every_payload": all(r["throughput_vs_thesis"] >= 10 for r in rows),
        "latency_within_1.5x_raw_every_payload": all(r["latency_vs_raw"] <= 1.5 for r in rows),
    }
    four = next((r for r in rows if r["payload_bytes"] == 4), None)
    if four is not None:
        out["4B_avg_latency_le_0.05ms"] = four["latency_ms"]["avg"] <= 0.05
        out["4B_max_latency_le_1ms"] = four["latency_ms"]["max"] <= 1.0
    return out


def run(args: argparse.Namespace) -> dict[str, Any]:
    """Run the benchmark; return the JSON-able report."""
    payloads = list(PAYLOADS)
    if args.payloads:
        wanted = {int(x) for x in args.payloads.split(",")}
        payloads = [p for p in PAYLOADS if p.nbytes in wanted]
    home = tempfile.mkdtemp(prefix="plugcell-bench-")
    env = {**os.environ, "PLUGCELL_HOME": home, "PYTHONUNBUFFERED": "1"}
    cell = args.cell or f"bench{os.getpid()}"
    started = time.time()

    def progress(text: str) -> None:
        if not args.json:
            print(f"  … {text}", file=sys.stderr, flush=True)

    if args.networked:
        return _run_networked(args)
    try:
        rows = eventloop.run(_measure(args, cell, env, payloads, progress))
    finally:
        shutil.rmtree(home, ignore_errors=True)
    networked = bool(args.peer_netns)
    return {
        "benchmark": "transport",
        "thesis": "Table 5-6 (two networked services, 100 Mbit)"
        if networked
        else "Table 5-5 (two services on one computer)",
        "mode": _mode(networked),
        "quick": bool(args.quick),
        "throughput_runs": _repeat(args),
        "journal": not args.no_journal,
        "machine": machine(),
        "seconds": time.time() - started,
        "rows": rows,
        "targets": targets(rows),
    }


def _mode(networked: bool) -> str:
    if networked:
        return (
            f"networked (two network namespaces, veth shaped to {LINK_MBIT:g} Mbit/s, "
            "via plugcell router, no shared memory)"
        )
    transport = TransportConfig.from_env()
    joined = ("Zenoh clients of a router (PLUGCELL_MODE=client)" if transport.mode == "client"
              else "Zenoh peers on loopback")
    if transport.shared_memory:
        return (
            f"local (two OS processes, {joined}; Zenoh's shared-memory "
            "transport carries messages of 3 KiB and more)"
        )
    return f"local (two OS processes, {joined}, no shared memory)"


def _run_networked(args: argparse.Namespace) -> dict[str, Any]:
    """Namespaces A (consumer, router) and B (publisher) joined by a shaped veth pair."""
    from plugcell.apps.bench.netns import VethPair, netns_available

    why = netns_available()
    if why:
        raise RuntimeError(f"--networked needs Linux network namespaces: {why}")
    with VethPair.create(rate_mbit=LINK_MBIT) as pair, tempfile.TemporaryDirectory() as tmp:
        router_ep = f"tcp/{pair.addr_a}:7447"
        env = {
            **os.environ,
            "PYTHONUNBUFFERED": "1",
            "PLUGCELL_MULTICAST": "0",
            "PLUGCELL_SHM": "0",  # every byte through the shaped link
            "PLUGCELL_CONNECT": router_ep,
            "PLUGCELL_LISTEN": f"tcp/{pair.addr_a}:0",
        }
        router = subprocess.Popen(
            pair.argv(pair.a, [sys.executable, "-m", "plugcell", "router", "--listen", router_ep]),
            stdout=subprocess.PIPE,
            text=True,
            env=env,
        )
        try:
            assert router.stdout is not None
            router.stdout.readline()
            out = os.path.join(tmp, "report.json")
            argv = [
                sys.executable,
                "-m",
                "plugcell.apps.bench.transport",
                "--json",
                "--output",
                out,
                "--peer-netns",
                pair.b,
                "--peer-listen",
                f"tcp/{pair.addr_b}:0",
            ]
            for flag in ("quick", "no_journal"):
                if getattr(args, flag):
                    argv.append("--" + flag.replace("_", "-"))
            for opt, flag in (("payloads", "--payload-bytes"), ("cycles", "--cycles"),
                              ("messages", "--messages"), ("repeat", "--repeat"),
                              ("cell", "--cell")):
                if getattr(args, opt):
                    argv += [flag, str(getattr(args, opt))]
            subprocess.run(pair.argv(pair.a, argv), check=True, env=env, stdout=subprocess.DEVNULL)
            with open(out, encoding="utf-8") as f:
                return json.load(f)
        finally:
            router.terminate()
            router.wait(15)


def format_table(report: dict[str, Any]) -> str:
    """Our table beside Table 5-5."""
    m = report["machine"]
    lines = [
        f"plugcell transport benchmark — thesis 5.3, beside {report['thesis']}",
        f"mode: {report['mode']}",
        f"machine: {m['cpu']}, {m['cores']} cores, {m['system']}, Python {m['python']}, "
        f"eclipse-zenoh {m['zenoh']}, {m.get('event_loop', 'asyncio')} loop; "
        f"journal {'on' if report['journal'] else 'off'}; "
        f"{'quick' if report['quick'] else 'full'} run, {report['seconds']:.0f} s"
        + (f"; r is the best of {report['throughput_runs']} runs"
           if report.get("throughput_runs", 1) > 1 else ""),
        "",
        f"{'payload':<19}| {'throughput r (msg/s)':^32} | "
        f"{'latency t_l (ms): avg / max / min / std':^79}",
        f"{'':<19}| {'thesis':>8} {'plugcell':>11} {'raw zenoh':>11} | "
        f"{'thesis':^27} {'plugcell':^33} {'raw zenoh avg':>15}",
        "-" * 136,
    ]
    for r in report["rows"]:
        t = r["thesis"]["latency_ms"]
        o = r["latency_ms"]
        lines.append(
            f"{r['payload']:<19}| {r['thesis']['throughput_msg_s']:>8} "
            f"{r['throughput_msg_s']:>11,.0f} {r['raw_zenoh_throughput_msg_s']:>11,.0f} | "
            f"{t['avg']:>5.2f} /{t['max']:>6.2f} /{t['min']:>5.2f} /{t['std']:>5.2f}   "
            f"{o['avg']:>6.3f} /{o['max']:>7.3f} /{o['min']:>6.3f} /{o['std']:>6.3f}   "
            f"{r['raw_zenoh_latency_ms']['avg']:>10.3f} ({r['latency_vs_raw']:.2f}x)"
        )
    lines.append("")
    lines.append(
        "targets: "
        + ", ".join(f"{k} {'PASS' if v else 'FAIL'}" for k, v in report["targets"].items())
    )
    four = next((r for r in report["rows"] if r["payload_bytes"] == 4), None)
    if four is not None:  # what the floor itself does against the absolute targets
        raw = four["raw_zenoh_latency_ms"]
        lines.append(
            f"raw Zenoh's own 4 B latency (the floor): avg {raw['avg']:.3f} ms "
            f"(target for plugcell 0.05), max {raw['max']:.3f} ms (target 1)"
        )
        bare = four.get("raw_zenoh_in_callback_latency_ms")
        if bare is not None:
            lines.append(
                f"  answered inside Zenoh's callbacks, with no hop to a thread: avg "
                f"{bare['avg']:.3f} ms, max {bare['max']:.3f} ms"
            )
        looped = four.get("raw_zenoh_event_loop_latency_ms")
        if looped is not None:
            lines.append(
                f"  answered from an event loop on each side ({m.get('event_loop', 'asyncio')}, "
                f"call_soon_threadsafe): avg {looped['avg']:.3f} ms, max {looped['max']:.3f} ms"
            )
    return "\n".join(lines)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.add_argument(
        "--quick",
        action="store_true",
        help="fewer cycles/messages (200 cycles; 1000 messages, 200 for big payloads)",
    )
    p.add_argument("--payload-bytes", "--payloads", dest="payloads", action=DeprecatedName,
                   old=("--payloads",), metavar="B,B,…",
                   help="comma-separated message payload sizes, bytes (default: all; "
                        "--payloads is its old name)")
    p.add_argument("--cycles", type=int, help="latency cycles per payload (default 2000)")
    p.add_argument("--messages", type=int, help="throughput messages per payload (default 10000)")
    p.add_argument(
        "--repeat",
        type=_at_least_one,
        help="throughput runs per payload, the best reported (default 3; 1 quick or networked)",
    )
    p.add_argument("--no-journal", action="store_true", help="run both services without journal")
    p.add_argument("--cell", help="cell name to use (default: bench<pid>)")
    p.add_argument("--output", help="also write the JSON report to this file")
    p.add_argument(
        "--networked",
        action="store_true",
        help="publisher in another network namespace behind a veth pair shaped to "
        "100 Mbit/s, via plugcell router (Table 5-6; needs root)",
    )
    p.add_argument("--peer-netns", help=argparse.SUPPRESS)
    p.add_argument("--peer-listen", help=argparse.SUPPRESS)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="benchmarks/transport.py", description=__doc__)
    add_arguments(parser)
    return report_and_exit(parser.parse_args(argv))


def report_and_exit(args: argparse.Namespace) -> int:
    report = run(args)
    text = json.dumps(report, indent=2)
    if args.output:
        with open(args.output, "w", encoding="utf-8") as f:
            f.write(text + "\n")
    print(text if args.json else format_table(report))
    return 0


if __name__ == "__main__":
    sys.exit(main())
