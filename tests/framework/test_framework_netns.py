"""Deployment across "machines": services in two Linux network namespaces (own addresses,
a veth pair) joined through ``plugcell router`` — issue section 8.

Skipped unless run as root with ``ip netns``.  Traffic stays on the addresses the
test creates; the namespaces are removed afterwards.
"""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from plugcell.apps.bench.netns import VethPair, netns_available

pytestmark = [pytest.mark.slow, pytest.mark.netns, pytest.mark.timeout(120)]

_why_not = netns_available() if sys.platform == "linux" else "Linux only"


@pytest.fixture
def pair():
    if _why_not:
        pytest.skip(f"network namespaces unavailable: {_why_not}")
    with VethPair.create() as created:
        yield created


def test_cell_across_two_namespaces_through_a_router(pair, procs, cell):
    py = sys.executable
    router = f"tcp/{pair.addr_a}:7447"
    env = {"PLUGCELL_MULTICAST": "0"}

    def plugcell(ns: str, addr: str, *args: str) -> list[str]:
        return pair.argv(
            ns,
            [
                py,
                "-m",
                "plugcell",
                *args,
                "--cell",
                cell,
                "--connect",
                router,
                "--listen",
                f"tcp/{addr}:0",
            ],
        )

    r = procs.start(pair.argv(pair.a, [py, "-m", "plugcell", "router", "--listen", router]))
    r.wait_line(lambda line: "listening on" in line)
    tool = procs.start(
        plugcell(pair.a, pair.addr_a, "serve", "drill", "--param", "time_scale=0.001"), env
    )
    camera = procs.start(
        plugcell(pair.b, pair.addr_b, "serve", "camera", "--param", "time_scale=0.01"), env
    )
    for proc in (tool, camera):
        proc.wait_line(lambda line: "serving in cell" in line)

    def run(ns: str, addr: str, *args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            plugcell(ns, addr, *args),
            capture_output=True,
            text=True,
            timeout=60,
            env={**procs.env, **env},
        )

    # a client in namespace B drives the tool in namespace A
    drill = run(
        pair.b, pair.addr_b, "call", "TOOL", "Drill", "--option", "Air", "--data", "[550, 1100]"
    )
    assert drill.returncode == 0, drill.stderr
    assert [json.loads(x)["state"] for x in drill.stdout.splitlines()] == [
        "Queued",
        "Running",
        "Completed",
    ]
    # a client in namespace A takes a picture with the camera in namespace B
    snap = run(pair.a, pair.addr_a, "call", "CAMERA", "SnapShot", "--data", "5")
    assert snap.returncode == 0, snap.stderr
    assert json.loads(snap.stdout.splitlines()[-1])["data"]["size"] == [480, 640]
    # and the tool (A) subscribes to the camera (B) at run time
    wired = run(pair.b, pair.addr_b, "wire", "TOOL", "CAMERA")
    assert wired.returncode == 0 and "TOOL subscribed to CAMERA" in wired.stdout
