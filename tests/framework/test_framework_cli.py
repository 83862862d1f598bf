"""The framework commands of the CLI, run as subprocesses against served services."""

from __future__ import annotations

import json
import subprocess

import pytest
from framework_testlib import plugcell_argv, unique_cell

from plugcell.apps.bench.transport import format_table

pytestmark = [pytest.mark.slow, pytest.mark.timeout(90)]


def cli(procs, *args: str, check: bool = True) -> subprocess.CompletedProcess[str]:
    result = subprocess.run(
        plugcell_argv(*args), capture_output=True, text=True, timeout=60, env=procs.env
    )
    if check:
        assert result.returncode == 0, result.stderr
    return result


def lines(result: subprocess.CompletedProcess[str]) -> list[dict]:
    return [json.loads(line) for line in result.stdout.splitlines()]


def test_services_call_wire_journal(procs, cell):
    for proc in (procs.serve("camera", cell, "--param", "time_scale=0.01", wait=False),
                 procs.serve("drill", cell, "--param", "time_scale=0.001", name="TOOL",
                             wait=False)):
        proc.wait_serving()  # started side by side

    listed = json.loads(cli(procs, "services", "--json", "--cell", cell).stdout)
    assert listed["cell"] == cell and listed["wires"] == []
    by_name = {s["name"]: s for s in listed["services"]}
    assert set(by_name) == {"CAMERA", "TOOL"}
    assert by_name["TOOL"]["kind"] == "drill"
    assert [c["name"] for c in by_name["CAMERA"]["commands"]] == [
        "Connect",
        "Disconnect",
        "SnapShot",
        "MovieShot",
        "StopMovie",
    ]
    snap = next(c for c in by_name["CAMERA"]["commands"] if c["name"] == "SnapShot")
    assert (snap["type"], snap["output"]["type"], snap["output"]["size"]) == (
        "SingleData",
        "Byte",
        [480, 640],
    )
    # `services` is `cell ls`: the same JSON, the same text
    assert json.loads(cli(procs, "cell", "ls", "--json", "--cell", cell).stdout) == listed
    text = cli(procs, "services", "--commands", "--cell", cell).stdout
    assert "CAMERA" in text and "camera" in text and "Drill" in text

    out = lines(cli(procs, "call", "CAMERA", "SnapShot", "--data", "5", "--cell", cell))
    assert [o["event"] for o in out] == ["ack", "update", "update"]
    assert [o["state"] for o in out] == ["Queued", "Running", "Completed"]
    assert out[-1]["data"]["size"] == [480, 640] and out[-1]["data"]["type"] == "Byte"

    out = lines(
        cli(
            procs,
            "call",
            "TOOL",
            "Drill",
            "--option",
            "Air",
            "--data",
            "[550, 1100]",
            "--cell",
            cell,
            "--name",
            "PDL",
        )
    )
    assert out[-1]["state"] == "Completed" and out[0]["sender"] == "PDL"

    movie = lines(
        cli(procs, "call", "CAMERA", "MovieShot", "--data", "40", "--frames", "2", "--cell", cell)
    )
    stop = next(o for o in movie if o["event"] == "stop")
    assert stop["command"] == "StopMovie" and stop["state"] == "Completed"
    assert movie[-1]["state"] == "Completed"
    assert sum(1 for o in movie if o.get("data")) >= 2

    bad = cli(procs, "call", "CAMERA", "SnapShot", "--data", "[1, 2]", "--cell", cell, check=False)
    assert bad.returncode == 1
    assert lines(bad)[-1]["reason"] == "SnapShot input: size [2] does not match the declared [1]"
    unknown = cli(procs, "call", "CAMERA", "Zoom", "--cell", cell, check=False)
    assert unknown.returncode == 1 and "unknown command 'Zoom'" in lines(unknown)[-1]["reason"]
    nobody = cli(procs, "call", "NOBODY", "X", "--timeout", "1", "--cell", cell, check=False)
    assert nobody.returncode == 1 and "unknown device 'NOBODY'" in lines(nobody)[-1]["reason"]

    assert (
        "TOOL subscribed to CAMERA" in cli(procs, "wire", "TOOL", "CAMERA", "--cell", cell).stdout
    )
    listed = json.loads(cli(procs, "services", "--json", "--cell", cell).stdout)
    tool = next(s for s in listed["services"] if s["name"] == "TOOL")
    assert tool["partners"] == ["CAMERA"]
    assert listed["wires"] == [{"service": "TOOL", "partner": "CAMERA"}]
    cli(procs, "unwire", "TOOL", "CAMERA", "--cell", cell)
    again = cli(procs, "unwire", "TOOL", "CAMERA", "--cell", cell, check=False)
    assert again.returncode == 1 and "was not a partner" in again.stderr

    journal = json.loads(cli(procs, "journal", "--json", "--cell", cell).stdout)
    commands = [(r["recipient"], r["command"], r["state"]) for r in journal]
    assert ("CAMERA", "SnapShot", "Completed") in commands
    assert ("TOOL", "Drill", "Completed") in commands
    assert ("CAMERA", "MovieShot", "Completed") in commands
    assert ("CAMERA", "StopMovie", "Completed") in commands
    assert all(r["updates"] or r["state"] == "Failed" for r in journal)
    assert "PDL -> TOOL  Drill#Air" in cli(procs, "journal", "--cell", cell).stdout

    # another cell on the same network sees none of it
    assert json.loads(cli(procs, "services", "--json", "--cell", unique_cell()).stdout)[
        "services"] == []


def test_user_errors(procs, cell):
    bad_kind = cli(procs, "serve", "toaster", "--cell", cell, check=False)
    assert bad_kind.returncode == 2 and "unknown service kind 'toaster'" in bad_kind.stderr
    bad_cell = cli(procs, "services", "--cell", "no/slash", check=False)
    assert bad_cell.returncode == 2 and "invalid cell name" in bad_cell.stderr
    bad_param = cli(procs, "serve", "camera", "--param", "zoom=2", "--cell", cell, check=False)
    assert bad_param.returncode == 2 and "time_scale" in bad_param.stderr
    procs.serve("drill", cell)
    twice = cli(procs, "serve", "drill", "--cell", cell, check=False)
    assert twice.returncode == 2 and "already running" in twice.stderr


def test_bench_transport_smoke(procs):
    """The benchmark runs end to end and reports the documented JSON keys (speed: not here)."""
    result = cli(
        procs,
        "bench",
        "transport",
        "--json",
        "--payload-bytes",
        "4,65536",
        "--cycles",
        "20",
        "--messages",
        "100",
        "--repeat",
        "2",
    )
    report = json.loads(result.stdout)
    assert [r["payload_bytes"] for r in report["rows"]] == [4, 65536]
    assert report["throughput_runs"] == 2
    for row in report["rows"]:
        assert row["throughput_msg_s"] > 0 and row["raw_zenoh_latency_ms"]["avg"] > 0
        assert row["raw_zenoh_in_callback_latency_ms"]["avg"] > 0
        assert row["raw_zenoh_event_loop_latency_ms"]["avg"] > 0
        # the best of the runs, every run kept
        for best, runs in ((row["throughput_msg_s"], row["throughput_runs_msg_s"]),
                           (row["raw_zenoh_throughput_msg_s"],
                            row["raw_zenoh_throughput_runs_msg_s"])):
            assert len(runs) == 2 and best == max(runs)
        assert set(row["latency_ms"]) >= {"avg", "max", "min", "std"}
        assert row["thesis"]["latency_ms"]["avg"] in (0.23, 4.23)
    assert set(report["targets"]) >= {"throughput_10x_thesis_every_payload"}
    table = format_table(report).splitlines()  # what the command prints without --json
    assert "r is the best of 2 runs" in table[2]
    assert [line.split("|")[0].strip() for line in table[7:9]] == ["4 B", "64 KiB"]
    assert table[-3].startswith("raw Zenoh's own 4 B latency (the floor): avg ")
    assert table[-2].startswith("  answered inside Zenoh's callbacks, with no hop to a thread")
    assert table[-1].startswith("  answered from an event loop on each side (")
    refused = cli(procs, "bench", "transport", "--repeat", "0", check=False)
    assert refused.returncode == 2 and "--repeat: must be at least 1" in refused.stderr


def test_wire_waits_for_services_still_starting(procs, cell):
    """`serve … &` then `wire` at once: wire waits (up to --timeout) for both ends to be
    in the cell, as `call` waits for its service (issue 39: docs/robot-programs.md's
    `serve robot … &` then `wire H4 TRACKER` failed with 'no such service')."""
    wire = subprocess.Popen(plugcell_argv("wire", "TOOL", "CAMERA", "--cell", cell,
                                          "--timeout", "40"),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=procs.env)
    try:
        procs.serve("drill", cell, name="TOOL")
        procs.serve("camera", cell)
        out, err = wire.communicate(timeout=60)
    finally:
        wire.kill()
    assert wire.returncode == 0, err
    assert "TOOL subscribed to CAMERA" in out
    nobody = cli(procs, "wire", "TOOL", "NOBODY", "--timeout", "1", "--cell", cell,
                 check=False)
    assert nobody.returncode == 1  # the wire failed (2 is for bad usage)
    assert "unknown device 'NOBODY': no such service in cell" in nobody.stderr
