"""``plugcell cell …`` and ``plugcell controller`` as OS processes against real services."""

from __future__ import annotations

import json
import os
import subprocess
import urllib.request
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from cell_testlib import PROGRAMS, plugcell_argv

pytestmark = pytest.mark.slow  # starts services and a controller as processes


def cli(home: Path, *args: str, timeout: float = 30.0) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PLUGCELL_HOME": str(home)}
    return subprocess.run(plugcell_argv(*args), capture_output=True, text=True, env=env,
                          timeout=timeout, check=False)


def lines(out: str) -> list[dict[str, Any]]:
    return [json.loads(x) for x in out.splitlines() if x.strip()]


def test_cell_cli_discovers_wires_saves_loads_runs_and_monitors(
        cell: str, home: Path, procs: Any, tmp_path: Path) -> None:
    for proc in (procs.serve("camera", cell, "--param", "time_scale=0.001", wait=False),
                 procs.serve("drill", cell, "--param", "time_scale=0.001", wait=False),
                 procs.serve("robot", cell, "--param", "sim=true", name="R1", wait=False)):
        proc.wait_serving()  # started side by side

    ls = cli(home, "cell", "ls", "--json", "--cell", cell)
    assert ls.returncode == 0, ls.stderr
    doc = json.loads(ls.stdout)
    assert {s["name"] for s in doc["services"]} == {"CAMERA", "TOOL", "R1"}
    assert "ACTIVATE" in {c["name"] for s in doc["services"] for c in s["commands"]}

    for partner in ("TOOL", "CAMERA"):
        r = cli(home, "cell", "wire", "R1", partner, "--cell", cell)
        assert r.returncode == 0 and f"R1 subscribed to {partner}" in r.stdout, r.stderr
    bad = cli(home, "cell", "wire", "R1", "GHOST", "--cell", cell, "--timeout", "2")
    assert bad.returncode == 1 and "GHOST" in bad.stderr
    text = cli(home, "cell", "ls", "--cell", cell).stdout
    assert "R1 → CAMERA, R1 → TOOL" in text

    wiring = tmp_path / "cell.json"
    r = cli(home, "cell", "save", str(wiring), "--cell", cell)
    assert r.returncode == 0 and "saved 2 wires" in r.stdout
    assert cli(home, "cell", "unwire", "R1", "CAMERA", "--cell", cell).returncode == 0
    r = cli(home, "cell", "load", str(wiring), "--json", "--cell", cell, "--wait", "3")
    assert r.returncode == 0, r.stderr
    assert {(x["service"], x["partner"], x["ok"]) for x in lines(r.stdout)} == {
        ("R1", "CAMERA", True), ("R1", "TOOL", True)}
    broken = tmp_path / "broken.json"
    broken.write_text('{"wires": [{"service": "R1"}]}')
    r = cli(home, "cell", "load", str(broken), "--cell", cell)
    assert r.returncode == 2 and "broken.json: wire 1" in r.stderr

    # every process of the cell, and only TOOL's until one has ended; both watch before the run
    everything = procs.start(plugcell_argv("cell", "monitor", "--json", "--duration", "25",
                                           "--cell", cell))
    tool = procs.start(plugcell_argv("cell", "monitor", "--json", "--service", "TOOL",
                                     "--count", "1", "--duration", "25", "--cell", cell))
    for monitor in (everything, tool):
        ready = json.loads(monitor.wait_line(lambda x: '"monitoring"' in x, 30.0))
        assert ready == {"event": "monitoring", "cell": cell}
    program = str(PROGRAMS / "cellcheck.pdl")
    r = cli(home, "cell", "run", "R1", program, "--cell", cell)
    assert r.returncode == 0, r.stdout + r.stderr
    assert lines(r.stdout)[-1]["state"] == "Completed"

    def ended(sender: str, recipient: str, command: str) -> Callable[[str], bool]:
        def match(line: str) -> bool:
            x = json.loads(line)
            return x["event"] == "process" and x["state"] == "Completed" and (
                x["sender"], x["recipient"], x["command"]) == (sender, recipient, command)
        return match

    everything.wait_line(ended("R1", "TOOL", "Drill"), 20.0)
    everything.wait_line(ended("R1", "CAMERA", "SnapShot"), 20.0)
    assert tool.popen.wait(20) == 0  # --count 1: it stops by itself
    seen = [x for x in map(json.loads, tool.lines) if x["event"] == "process"]
    assert all("TOOL" in (x["sender"], x["recipient"]) for x in seen)
    assert (seen[-1]["sender"], seen[-1]["command"], seen[-1]["state"]) == (
        "R1", "Drill", "Completed")

    # the thesis EXAMPLE needs its taught points: given as program values
    r = cli(home, "cell", "run", "R1", "example", "--cell", cell)
    assert r.returncode == 1 and "pnt0001 is uninitialized" in lines(r.stdout)[-2]["reason"]
    r = cli(home, "cell", "run", "R1", "example", "--value", "pnt0001=1500,0,1300,0,90,0",
            "--value", "R1:pnt0002=1500,200,1000,0,90,0", "--cell", cell)
    assert r.returncode == 0 and lines(r.stdout)[-1]["state"] == "Completed", r.stdout
    r = cli(home, "cell", "run", "R1", "example", "--value", "pnt0001", "--cell", cell)
    assert r.returncode == 2 and "expected [ROBOT:]NAME=VALUE" in r.stderr
    r = cli(home, "cell", "run", "R1", "no_such_program", "--cell", cell)
    assert r.returncode == 1 and "no_such_program" in lines(r.stdout)[-2]["reason"]
    r = cli(home, "cell", "run", "R1", "--cell", cell)
    assert r.returncode == 2 and "ROBOT PROGRAM pairs" in r.stderr


def test_cell_serve_serves_the_ui_and_joins_the_cell(
        cell: str, home: Path, procs: Any, tmp_path: Path) -> None:
    procs.serve("drill", cell, "--param", "time_scale=0.001")
    ui = procs.start(plugcell_argv("cell", "serve", "--port", "0", "--cell", cell,
                                   "--docs", str(tmp_path)))
    line = ui.wait_line(lambda x: "controller UI on" in x, 30.0)
    url = line.split(" on ", 1)[1].split(" ", 1)[0]
    with urllib.request.urlopen(url, timeout=5) as page:
        assert b"cell controller" in page.read()
    ls = cli(home, "cell", "ls", "--json", "--cell", cell)
    names = {s["name"]: s for s in json.loads(ls.stdout)["services"]}
    assert names["CONTROLLER"]["kind"] == "cell-controller"
    assert "TOOL" in names["CONTROLLER"]["partners"]  # it subscribed to everyone
    r = cli(home, "cell", "wire", "CONTROLLER", "TOOL", "--via", "CONTROLLER", "--cell", cell)
    assert r.returncode == 1 and "wire other services" in r.stderr
    # the old name of `cell serve` still works, with a warning
    taken = cli(home, "controller", "--port", url.rsplit(":", 1)[1].strip("/"), "--cell", cell,
                "--name", "CTL2", timeout=30)
    assert taken.returncode == 2 and "cannot serve" in taken.stderr
    assert ("plugcell: warning: plugcell controller is deprecated: use plugcell cell serve"
            in taken.stderr)
