"""The OPC UA gateway's cost: a method call through it beside the same process sent with
plugcell's own client and with ``plugcell call``, and subscription updates per second.

    .venv/bin/python benchmarks/opcua_gateway.py [--calls 200] [--frames 2000] [--json OUT]

One run starts ``plugcell serve bench`` (the transport benchmark's publisher: ``Echo``
returns its input, ``Push`` streams N frames) and ``plugcell opcua serve`` as their
own processes, then from this process measures, for a 4-byte ``Echo``:

* **OPC UA, warm**: ``Cell/PUBLISHER/Echo`` called through the gateway over an open
  asyncua session (the OPC UA client's request → gateway → CreateProcess → service →
  ProcessUpdate → gateway → response);
* **plugcell client, warm**: the same process created with :class:`Client` directly
  (what ``plugcell call`` does once it is connected);
* **cold**: one OPC UA session opened, the call, closed; and one ``plugcell call``
  process (interpreter start, Zenoh session, discovery, the call);

and for a stream, ``Push`` of N 8-byte frames: updates per second received by an OPC UA
subscription to the process's ``Data`` variable (trigger StatusValueTimestamp — the
frames are all equal —, queue 10 000, publishing every 10 ms)
against frames per second received by the plugcell client.  Medians and percentiles of
the calls; the machine is a shared VM, so figures vary ±50 % with its load.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
import uuid

from asyncua import Client as UaClient
from asyncua import ua

from plugcell.framework import Client
from plugcell.sim.ports import free_port

PLUGCELL = [sys.executable, "-m", "plugcell"]


def _start(argv: list[str], ready: str, env: dict[str, str]) -> subprocess.Popen[str]:
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                            env=env, start_new_session=True)
    assert proc.stdout is not None
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if ready in line:
            return proc
        if not line and proc.poll() is not None:
            break
    proc.kill()
    raise RuntimeError(f"{argv[3:5]} did not start")


def _stats(seconds: list[float]) -> dict[str, float]:
    ms = sorted(s * 1e3 for s in seconds)
    return {"n": len(ms), "median_ms": statistics.median(ms),
            "p95_ms": ms[min(len(ms) - 1, int(0.95 * len(ms)))], "min_ms": ms[0]}


async def _warm(url: str, cell: str, calls: int) -> dict[str, dict[str, float]]:
    payload = [1, 2, 3, 4]
    out: dict[str, dict[str, float]] = {}
    async with UaClient(url) as ua_client:
        idx = await ua_client.get_namespace_index(f"urn:plugcell:cell:{cell}")
        obj = ua_client.get_node(ua.NodeId("Cell/PUBLISHER", idx))
        method = ua.NodeId("Cell/PUBLISHER/Echo", idx)
        data = ua.Variant(payload, ua.VariantType.Byte, is_array=True)
        for _ in range(20):
            await obj.call_method(method, "", data)
        times = []
        for _ in range(calls):
            t0 = time.perf_counter()
            await obj.call_method(method, "", data)
            times.append(time.perf_counter() - t0)
        out["opcua_warm"] = _stats(times)
    async with Client("bench-opcua", cell=cell) as client:
        await client.wait_for("PUBLISHER")
        for _ in range(20):
            await (await client.create_process("PUBLISHER", "Echo", "", payload)).result()
        times = []
        for _ in range(calls):
            t0 = time.perf_counter()
            await (await client.create_process("PUBLISHER", "Echo", "", payload)).result()
            times.append(time.perf_counter() - t0)
        out["plugcell_warm"] = _stats(times)
    return out


async def _cold_opcua(url: str, cell: str, runs: int) -> dict[str, float]:
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        async with UaClient(url) as ua_client:
            idx = await ua_client.get_namespace_index(f"urn:plugcell:cell:{cell}")
            await ua_client.get_node(ua.NodeId("Cell/PUBLISHER", idx)).call_method(
                ua.NodeId("Cell/PUBLISHER/Echo", idx), "",
                ua.Variant([1, 2, 3, 4], ua.VariantType.Byte, is_array=True))
        times.append(time.perf_counter() - t0)
    return _stats(times)


def _cold_cli(cell: str, env: dict[str, str], runs: int) -> dict[str, float]:
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        subprocess.run([*PLUGCELL, "call", "PUBLISHER", "Echo", "--data", "[1,2,3,4]",
                        "--cell", cell], env=env, check=True, capture_output=True, timeout=60)
        times.append(time.perf_counter() - t0)
    return _stats(times)


class _Counter:
    def __init__(self) -> None:
        self.count = 0
        self.first = 0.0
        self.last = 0.0
        self.status: object = None

    def status_change_notification(self, status: object) -> None:
        self.status = status

    def datachange_notification(self, node: object, value: object, data: object) -> None:
        now = time.perf_counter()
        if self.count == 0:
            self.first = now
        self.count += 1
        self.last = now


async def _stream(url: str, cell: str, frames: int) -> dict[str, float]:
    out: dict[str, float] = {}
    async with UaClient(url) as ua_client:
        idx = await ua_client.get_namespace_index(f"urn:plugcell:cell:{cell}")
        obj = ua_client.get_node(ua.NodeId("Cell/PUBLISHER", idx))
        # the process object exists from the call's return; Push frames flow right away,
        # so the first ~ms of frames may pass before the monitored item: count what came
        counter = _Counter()
        sub = await ua_client.create_subscription(ua.CreateSubscriptionParameters(
            RequestedPublishingInterval=10, RequestedLifetimeCount=10_000,
            RequestedMaxKeepAliveCount=100, MaxNotificationsPerPublish=1000,
            PublishingEnabled=True), counter)
        process, _ = await obj.call_method(ua.NodeId("Cell/PUBLISHER/Push", idx), "",
                                           ua.Variant([frames, 8], ua.VariantType.Int32))
        data = ua_client.get_node(ua.NodeId(process.Identifier + "/Data", idx))
        frames_node = ua_client.get_node(ua.NodeId(process.Identifier + "/Frames", idx))
        item = ua.MonitoredItemCreateRequest()  # every frame, equal values too
        item.ItemToMonitor = ua.ReadValueId(NodeId=data.nodeid, AttributeId=ua.AttributeIds.Value)
        item.MonitoringMode = ua.MonitoringMode.Reporting
        params = ua.MonitoringParameters(ClientHandle=4242, SamplingInterval=0.0,
                                         QueueSize=10_000, DiscardOldest=True)
        params.Filter = ua.DataChangeFilter(Trigger=ua.DataChangeTrigger.StatusValueTimestamp)
        item.RequestedParameters = params
        await sub.create_monitored_items([item])
        t0 = time.perf_counter()
        while await frames_node.read_value() < frames and time.perf_counter() - t0 < 120:
            await asyncio.sleep(0.05)
        gateway_s = time.perf_counter() - t0
        await asyncio.sleep(0.5)  # the last publish
        await ua_client.get_node(process).call_method(ua.NodeId(process.Identifier + "/Stop",
                                                                idx))
        await sub.delete()
        span = max(counter.last - counter.first, 1e-9)
        out.update(opcua_updates=counter.count, opcua_updates_per_s=counter.count / span,
                   gateway_frames_per_s=frames / gateway_s)
    async with Client("bench-opcua-stream", cell=cell) as client:
        await client.wait_for("PUBLISHER")
        call = await client.create_process("PUBLISHER", "Push", "", [frames, 8])
        got, first, last = 0, 0.0, 0.0
        async for update in call:
            if update.data is not None:
                now = time.perf_counter()
                first = first or now
                last = now
                got += 1
                if got == frames:
                    await client.stop_process(call)
        out.update(plugcell_frames=got,
                   plugcell_frames_per_s=got / max(last - first, 1e-9))
    return out


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--calls", type=int, default=200, help="warm calls per path")
    parser.add_argument("--cold", type=int, default=5, help="cold calls per path")
    parser.add_argument("--frames", type=int, default=20000, help="frames of the stream")
    parser.add_argument("--json", help="write the results to this file")
    args = parser.parse_args(argv)
    cell = f"bench-ua-{uuid.uuid4().hex[:8]}"
    port = free_port()
    url = f"opc.tcp://127.0.0.1:{port}/plugcell"
    with tempfile.TemporaryDirectory() as home:
        env = {**os.environ, "PLUGCELL_HOME": home, "PYTHONUNBUFFERED": "1"}
        service = _start([*PLUGCELL, "serve", "bench", "--cell", cell, "--no-journal"],
                         "serving in cell", env)
        gateway = _start([*PLUGCELL, "opcua", "serve", "--cell", cell, "--port", str(port),
                          "--allow-anonymous"], "OPC UA gateway", env)
        try:
            time.sleep(1.5)  # the gateway discovers PUBLISHER
            results: dict[str, object] = asyncio.run(_warm(url, cell, args.calls))
            results["opcua_cold"] = asyncio.run(_cold_opcua(url, cell, args.cold))
            results["cli_cold"] = _cold_cli(cell, env, args.cold)
            results["stream"] = asyncio.run(_stream(url, cell, args.frames))
        finally:
            for proc in (gateway, service):
                proc.terminate()
                proc.wait(15)
    results["machine"] = (f"{platform.machine()} {platform.processor() or ''} "
                          f"Python {platform.python_version()}").strip()
    print(f"Echo of 4 bytes, {args.calls} warm calls, {args.cold} cold ({results['machine']})")
    print("| path | median ms | p95 ms | min ms |")
    print("|---|---|---|---|")
    for key, title in (("opcua_warm", "OPC UA method call through the gateway (open session)"),
                       ("plugcell_warm", "plugcell Client.create_process (connected)"),
                       ("opcua_cold", "OPC UA: connect, call, disconnect"),
                       ("cli_cold", "`plugcell call` (a new process)")):
        s = results[key]
        assert isinstance(s, dict)
        print(f"| {title} | {s['median_ms']:.2f} | {s['p95_ms']:.2f} | {s['min_ms']:.2f} |")
    stream = results["stream"]
    assert isinstance(stream, dict)
    print(f"\nPush of {args.frames} frames of 8 bytes")
    print("| receiver | updates | updates/s |")
    print("|---|---|---|")
    print(f"| OPC UA subscription to the process's Data (10 ms publishing) | "
          f"{stream['opcua_updates']} | {stream['opcua_updates_per_s']:.0f} |")
    print(f"| (gateway writing Data: frames/s) | {args.frames} | "
          f"{stream['gateway_frames_per_s']:.0f} |")
    print(f"| plugcell client | {stream['plugcell_frames']} | "
          f"{stream['plugcell_frames_per_s']:.0f} |")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(results, f, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
