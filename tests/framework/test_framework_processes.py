"""Services as real OS processes: discovery, wiring, processes, kill -9, journal, router."""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

import numpy as np
import pytest
from childproc import until
from framework_testlib import plugcell_argv

from plugcell.framework import BlockingClient, ProcessStates, TransportConfig
from plugcell.framework.journal import journal_files, read_journal
from plugcell.sim.ports import free_port

pytestmark = [pytest.mark.slow, pytest.mark.timeout(90)]

C, F, R = ProcessStates.Completed, ProcessStates.Failed, ProcessStates.Running


def partners_of(client: BlockingClient, name: str) -> list[str]:
    return [p.name for p in client.get(name).partners]


def test_two_services_in_two_processes_kill_and_restart(procs, cell, home):
    camera = procs.serve("camera", cell, "--param", "time_scale=0.01", wait=False)
    procs.serve("drill", cell, "--param", "time_scale=0.001", wait=False).wait_serving()
    camera.wait_serving()  # the two started side by side
    with BlockingClient("ROBOT", cell=cell) as robot:
        # discovery without any router: liveliness tokens over loopback
        assert robot.wait_for("CAMERA") and robot.wait_for("TOOL")
        assert {"CAMERA", "TOOL"} <= set(robot.services())
        # TOOL (one process) subscribes to CAMERA (another process) at run time
        assert robot.ask_subscribe("TOOL", "CAMERA").ok
        assert partners_of(robot, "TOOL") == ["CAMERA"]

        snap = robot.create_process("CAMERA", "SnapShot", "", 5)
        assert snap.ack.state is ProcessStates.Queued
        updates = list(snap)
        assert [u.state for u in updates] == [R, C]
        image = snap.array(updates[-1])
        assert image.shape == (480, 640) and image.dtype == np.uint8
        drill = robot.create_process("TOOL", "Drill", "Air", [550, 1100])
        assert drill.result().state is C

        movie = robot.create_process("CAMERA", "MovieShot", "", 20)
        frames = iter(movie)
        assert next(frames).state is R  # Running
        assert next(frames).data is not None  # first image
        camera.kill9()  # no Shutdown: only its liveliness token disappears
        final = next(f for f in frames if f.state.final)
        assert final.state is F and "CAMERA lost" in final.reason
        until(lambda: "CAMERA" not in partners_of(robot, "TOOL"))  # removed from Partners

        # the killed service lost nothing it had acknowledged
        rows = read_journal(journal_files(cell, home))
        movie_row = next(r for r in rows if r.get("command") == "MovieShot")
        assert movie_row["sender"] == "ROBOT" and movie_row["state"] == "Running"
        assert any(u["data"].startswith("Byte[480, 640]") for u in movie_row["updates"])
        assert next(r for r in rows if r.get("command") == "SnapShot")["state"] == "Completed"

        # restart: the unfinished process is closed in the journal, partners re-wire
        procs.serve("camera", cell, "--param", "time_scale=0.01")
        assert robot.wait_for("CAMERA")
        rows = read_journal(journal_files(cell, home))
        movie_row = next(r for r in rows if r.get("command") == "MovieShot")
        assert movie_row["state"] == "Failed" and "interrupted" in movie_row["reason"]
        assert robot.ask_subscribe("TOOL", "CAMERA").ok
        again = robot.create_process("CAMERA", "SnapShot", "", 1)
        assert again.result().state is C


def test_killed_sender_frees_the_device_for_the_next_in_queue(procs, cell, home):
    procs.serve("camera", cell, "--param", "time_scale=0.01")
    streamer = procs.start(plugcell_argv("call", "CAMERA", "MovieShot", "--data", "20",
                                         "--name", "STREAMER", "--cell", cell))
    streamer.wait_line(lambda line: '"seq": 2' in line)  # streaming: the device is held
    with BlockingClient("WAITER", cell=cell) as waiter:
        snap = waiter.create_process("CAMERA", "SnapShot", "", 1, timeout=30)
        assert snap.ack.state is ProcessStates.Queued
        streamer.kill9()
        assert snap.result().state is C
    movie = next(r for r in read_journal(journal_files(cell, home)) if r["command"] == "MovieShot")
    assert movie["state"] == "Failed" and "sender STREAMER lost" in movie["reason"]


def tcp_sockets(pid: int) -> dict[str, int]:
    """How many TCP sockets process ``pid`` has listening and established (from /proc)."""
    inodes = set()
    for fd in Path(f"/proc/{pid}/fd").iterdir():
        with contextlib.suppress(OSError):  # closed meanwhile
            target = os.readlink(fd)
            if target.startswith("socket:["):
                inodes.add(target[len("socket:["):-1])
    count = {"listening": 0, "established": 0}
    for table in ("tcp", "tcp6"):
        for line in Path(f"/proc/{pid}/net/{table}").read_text().splitlines()[1:]:
            fields = line.split()
            if fields[9] in inodes and fields[3] in ("0A", "01"):
                count["listening" if fields[3] == "0A" else "established"] += 1
    return count


def test_router_joins_participants_without_multicast(procs, cell):
    port = free_port()
    router = procs.start(plugcell_argv("router", "--listen", f"tcp/127.0.0.1:{port}"))
    router.wait_line(lambda line: "listening on" in line)
    env = {"PLUGCELL_MULTICAST": "0", "PLUGCELL_CONNECT": f"tcp/127.0.0.1:{port}"}
    procs.serve("drill", cell, "--param", "time_scale=0.001", env=env)
    transport = TransportConfig(connect=(f"tcp/127.0.0.1:{port}",), multicast=False)
    with BlockingClient("ROBOT", cell=cell, transport=transport) as robot:
        assert robot.wait_for("TOOL")
        call = robot.create_process("TOOL", "Drill", "", [550, 1100])
        assert [u.state for u in call] == [R, C]


def test_clients_reach_each_other_through_the_router_alone(procs, cell):
    """``PLUGCELL_MODE=client``: a client has one link, to the router (a star, not a
    mesh), and the cell works as in peer mode, clients and peers together: discovery, a
    service subscribing to another, processes, and a killed client seen leaving."""
    port = free_port()
    router = procs.start(plugcell_argv("router", "--listen", f"tcp/127.0.0.1:{port}"))
    router.wait_line(lambda line: "listening on" in line)
    routed = {"PLUGCELL_MULTICAST": "0", "PLUGCELL_CONNECT": f"tcp/127.0.0.1:{port}"}
    drill = procs.serve("drill", cell, "--param", "time_scale=0.001",
                        env={**routed, "PLUGCELL_MODE": "client"})
    camera = procs.serve("camera", cell, "--param", "time_scale=0.01",
                         env={**routed, "PLUGCELL_MODE": "peer"})
    transport = TransportConfig(mode="client", listen=(), connect=(f"tcp/127.0.0.1:{port}",),
                                multicast=False)
    with BlockingClient("ROBOT", cell=cell, transport=transport) as robot:
        assert robot.wait_for("TOOL") and robot.wait_for("CAMERA")
        assert robot.ask_subscribe("TOOL", "CAMERA").ok  # the client subscribes to a peer
        assert partners_of(robot, "TOOL") == ["CAMERA"]
        call = robot.create_process("TOOL", "Drill", "", [550, 1100])
        assert [u.state for u in call] == [R, C]
        snap = robot.create_process("CAMERA", "SnapShot", "", 1)
        final = snap.result()
        assert final.state is C and snap.array(final).shape == (480, 640)

        assert tcp_sockets(drill.pid) == {"listening": 0, "established": 1}  # the router
        assert tcp_sockets(camera.pid)["listening"] == 1  # a peer listens

        drill.kill9()
        until(lambda: "TOOL" not in robot.services())


def test_a_bad_mode_or_a_listening_client_is_refused_with_the_reason(procs, cell):
    for env, reason in (
        ({"PLUGCELL_MODE": "mesh"}, "PLUGCELL_MODE must be peer or client, got 'mesh'"),
        ({"PLUGCELL_MODE": "client", "PLUGCELL_MULTICAST": "0"},
         "a client needs a router to reach: PLUGCELL_CONNECT (or --connect) or multicast "
         "scouting"),
        ({"PLUGCELL_MODE": "client", "PLUGCELL_LISTEN": "tcp/127.0.0.1:0"},
         "a client listens on nothing"),
    ):
        proc = procs.start(plugcell_argv("serve", "drill", "--cell", cell), env)
        assert proc.popen.wait(30) == 2
        assert any(reason in line for line in proc.errors), proc.errors
