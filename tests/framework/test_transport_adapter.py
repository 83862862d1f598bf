"""The transport adapter (framework/bus.py): the one holder of a Zenoh session.

Two buses on loopback in peer mode exercise each door by purpose; a static check (ast,
no import) keeps every module outside ``plugcell/framework`` off Zenoh and sessions.
"""

from __future__ import annotations

import ast
import threading
import time
import uuid
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from childproc import until
from hypothesis import given, settings
from hypothesis import strategies as st
from source_trees import parsed

from plugcell.framework.bus import Bus
from plugcell.framework.keys import KeySpace, Presence
from plugcell.framework.transport import TransportConfig

SRC = Path(__file__).resolve().parents[2] / "src" / "plugcell"

#: Modules outside the framework allowed to touch Zenoh or sessions, and why.
RAW_ZENOH = {
    "apps/bench/peer.py": "both ends of the raw-Zenoh floor plugcell is compared with (thesis "
                          "5.3; `plugcell bench transport`, round_trip_trace)",
}
OPENS_A_BARE_SESSION = {
    "apps/commands/router.py": "a router declares nothing: it only routes, for every cell",
}


Handed = list[tuple[Callable[[Any], None], Any]]


@pytest.fixture
def owner_and_other() -> Iterator[tuple[Bus, Bus, Handed]]:
    """Two buses of one cell; the first hands its callbacks to a list (as a
    participant hands them to its loop), the second runs them on Zenoh's threads."""
    handed: Handed = []
    cell = f"bus{uuid.uuid4().hex[:10]}"
    cfg = TransportConfig.from_env()
    owner = Bus.connect(cfg, KeySpace(cell), hand_off=handed.append)
    other = Bus.connect(cfg, KeySpace(cell))
    yield owner, other, handed
    for bus in (owner, other):
        if bus.is_open:
            bus.close()


@pytest.fixture
def buses() -> Iterator[tuple[Bus, Bus]]:
    cell = f"bus{uuid.uuid4().hex[:10]}"
    cfg = TransportConfig.from_env()
    a, b = Bus.connect(cfg, KeySpace(cell)), Bus.connect(cfg, KeySpace(cell))
    yield a, b
    a.close()
    b.close()


def test_a_service_door_answers_a_query_by_name(buses: tuple[Bus, Bus]) -> None:
    a, b = buses
    served = a.serve("get", "CAMERA", lambda q: q.reply(q.key_expr, b"state of CAMERA"))
    replies: list[bytes] = []
    done = threading.Event()

    def ask() -> bool:
        replies.clear()
        done.clear()
        b.query("get", "CAMERA", None, lambda r: replies.append(r.ok.payload.to_bytes()),
                lambda _: done.set(), timeout=1.0)
        return done.wait(3.0) and replies == [b"state of CAMERA"]

    assert until(ask)
    # another name, another door: nobody answers
    done.clear()
    b.query("subscribe", "CAMERA", None, replies.append, lambda _: done.set(), timeout=0.3)
    assert done.wait(3.0)
    served.undeclare()


def test_published_requests_arrive_with_their_sender(buses: tuple[Bus, Bus]) -> None:
    a, b = buses
    got: list[tuple[str, bytes]] = []
    a.take_requests("DRILL", lambda sender, s: got.append((sender, s.payload.to_bytes())))
    door = b.request_door("DRILL", "ROBOT")
    assert until(lambda: door.matching_status.matching)
    door.put(b"create")
    assert until(lambda: got == [("ROBOT", b"create")])
    door.undeclare()


def test_presence_is_seen_coming_and_going(buses: tuple[Bus, Bus]) -> None:
    a, b = buses
    seen: list[tuple[Presence, bool]] = []
    b.watch_presence(lambda p, joined: seen.append((p, joined)))
    token = a.announce("service", "TRACKER", "0001abc")
    me = Presence("service", "TRACKER", "0001abc")
    assert until(lambda: (me, True) in seen)
    found: list[Presence] = []
    done = threading.Event()
    b.find_service("TRACKER", found.append, lambda _: done.set())
    assert done.wait(3.0) and found == [me]
    token.undeclare()
    assert until(lambda: (me, False) in seen)


def test_process_updates_reach_their_sender_and_the_cells_monitor(
        buses: tuple[Bus, Bus]) -> None:
    a, b = buses
    to_robot: list[bytes] = []
    monitored: list[tuple[str, bytes]] = []
    b.follow_processes("ROBOT", lambda s: to_robot.append(s.payload.to_bytes()))
    b.watch_processes(lambda service, s: monitored.append((service, s.payload.to_bytes())))
    publisher = a.process_publisher("CAMERA", "ROBOT", express=True)
    other = a.process_publisher("CAMERA", "UI", express=False)
    both = {("CAMERA", b"update for ROBOT"), ("CAMERA", b"update for UI")}

    def delivered() -> bool:
        # put again until both subscribers are known to the publishers (a matching
        # status cannot tell which of b's two subscribers has been declared to a)
        publisher.put(b"update for ROBOT")
        other.put(b"update for UI")
        time.sleep(0.05)
        return bool(to_robot) and set(monitored) >= both

    assert until(delivered)
    assert set(to_robot) == {b"update for ROBOT"}  # the UI's updates are not ROBOT's
    assert set(monitored) == both


def test_notifications_reach_the_partners_that_follow_them(buses: tuple[Bus, Bus]) -> None:
    a, b = buses
    heard: list[bytes] = []
    b.follow_notifications("CAMERA", lambda s: heard.append(s.payload.to_bytes()))

    def published() -> bool:
        a.notify("state", "CAMERA", b"Busy")
        return b"Busy" in heard
    assert until(published)
    a.notify("shutdown", "CAMERA", b"bye")
    a.notify("state", "DRILL", b"not CAMERA's")
    assert until(lambda: b"bye" in heard)
    assert b"not CAMERA's" not in heard


def test_the_reflector_channel_keeps_the_latest_pose(buses: tuple[Bus, Bus]) -> None:
    a, b = buses
    latest: list[bytes] = []
    publisher, queryable = a.reflector("TMAC", lambda: latest[-1] if latest else None)
    assert b.query_reflectors(0.3) == []  # nothing published yet: the queryable is silent
    seen: list[bytes] = []
    b.watch_reflectors(seen.append)
    latest.append(b"pose 1")
    assert until(lambda: b.query_reflectors(0.5) == [b"pose 1"])
    publisher.put(b"pose 2")
    assert until(lambda: seen == [b"pose 2"])
    other = Bus(b.session, KeySpace("another-cell"))  # same session, other cell's keys
    assert other.query_reflectors(0.3) == []
    publisher.undeclare()
    queryable.undeclare()


def test_with_a_hand_off_handlers_run_where_the_owner_runs_them(
        owner_and_other: tuple[Bus, Bus, Handed]) -> None:
    owner, other, handed = owner_and_other
    ran: list[tuple[str, bytes]] = []
    owner.take_requests("DRILL", lambda sender, s: ran.append((sender, bytes(s.payload))))
    door = other.request_door("DRILL", "ROBOT")
    assert until(lambda: door.matching_status.matching)
    door.put(b"create")
    assert until(lambda: len(handed) == 1)
    assert ran == []  # not on Zenoh's thread: the owner runs it
    handler, item = handed[0]
    handler(item)
    assert ran == [("ROBOT", b"create")]


def test_a_direct_view_runs_handlers_on_zenohs_threads_and_closes_nothing(
        owner_and_other: tuple[Bus, Bus, Handed]) -> None:
    owner, other, handed = owner_and_other
    view = owner.direct()
    assert view.session is owner.session and view.keys == owner.keys
    threads: list[str] = []

    def latest() -> bytes:
        threads.append(threading.current_thread().name)
        return b"pose"

    publisher, queryable = view.reflector("SMR", latest)
    assert until(lambda: other.query_reflectors(0.5) == [b"pose"])
    assert handed == []  # answered at once, not handed to the owner's loop
    assert threads and threading.main_thread().name not in threads
    publisher.undeclare()
    queryable.undeclare()
    view.close()
    assert owner.is_open  # the view closed nothing: the session is the owner's
    owner.close()
    assert not owner.is_open


# -- only the framework holds a session ---------------------------------------------------


def transport_offences(source: str, where: str) -> list[str]:
    """What ``source`` (a module outside the framework) does that only the transport
    adapter may: import Zenoh, open a session, reach for a participant's session."""
    found = []
    for node in ast.walk(parsed(source)):
        if isinstance(node, ast.Import):
            found += [f"{where}:{node.lineno}: imports zenoh" for a in node.names
                      if a.name.split(".")[0] == "zenoh"]
        elif isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == "zenoh":
            found.append(f"{where}:{node.lineno}: imports zenoh")
        elif isinstance(node, ast.ImportFrom) and any(a.name == "open_session"
                                                      for a in node.names):
            found.append(f"{where}:{node.lineno}: opens a session")
        elif (isinstance(node, ast.Attribute) and node.attr == "session"
              and not (isinstance(node.value, ast.Name) and node.value.id == "self")):
            found.append(f"{where}:{node.lineno}: reaches for a session")
    return found


def test_the_check_sees_each_offence() -> None:
    bad = ("import zenoh\nfrom zenoh.handlers import Callback\n"
           "from plugcell.framework.transport import open_session\n"
           "def f(client):\n    return client.participant.session\n")
    assert [o.split(": ", 1)[1] for o in transport_offences(bad, "bad.py")] == [
        "imports zenoh", "imports zenoh", "opens a session", "reaches for a session"]
    assert transport_offences("from plugcell.framework.bus import Bus\n", "ok.py") == []


def test_only_the_framework_touches_zenoh_and_sessions() -> None:
    offences = []
    for path in SRC.rglob("*.py"):
        where = path.relative_to(SRC).as_posix()
        if where.startswith("framework/") or where in RAW_ZENOH:
            continue
        found = transport_offences(path.read_text(encoding="utf-8"), where)
        if where in OPENS_A_BARE_SESSION:
            found = [f for f in found if not f.endswith("opens a session")]
        offences += found
    assert offences == []


def test_the_exceptions_still_exist() -> None:
    for where in [*RAW_ZENOH, *OPENS_A_BARE_SESSION]:
        assert (SRC / where).is_file(), f"stale exception: {where}"


# -- the settings an idle cell's cost depends on -------------------------------------------


def test_lease_and_shared_memory_come_from_the_environment(
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("PLUGCELL_LEASE", raising=False)
    monkeypatch.delenv("PLUGCELL_SHM", raising=False)
    default = TransportConfig.from_env()
    assert default.lease_s == 10.0 and default.shared_memory
    conf = default.zenoh_config()  # Zenoh's own defaults
    assert conf.get_json("transport/link/tx/lease") == "10000"
    assert conf.get_json("transport/shared_memory/enabled") == "true"
    monkeypatch.setenv("PLUGCELL_LEASE", "60")
    monkeypatch.setenv("PLUGCELL_SHM", "0")
    lean = TransportConfig.from_env()
    assert lean.lease_s == 60.0 and not lean.shared_memory
    conf = lean.zenoh_config()
    assert conf.get_json("transport/link/tx/lease") == "60000"
    assert conf.get_json("transport/shared_memory/enabled") == "false"


@pytest.mark.parametrize(("text", "reason"), [
    ("soon", "PLUGCELL_LEASE must be a number of seconds, got 'soon'"),
    ("0.5", "PLUGCELL_LEASE must be between 1 and 3600 s, got 0.5"),
    ("1e9", "PLUGCELL_LEASE must be between 1 and 3600 s, got 1e9"),
])
def test_a_bad_lease_is_refused_with_the_reason(
        monkeypatch: pytest.MonkeyPatch, text: str, reason: str) -> None:
    monkeypatch.setenv("PLUGCELL_LEASE", text)
    with pytest.raises(ValueError) as caught:
        TransportConfig.from_env()
    assert str(caught.value) == reason


def test_the_mode_comes_from_the_environment_and_a_client_listens_on_nothing(
        monkeypatch: pytest.MonkeyPatch) -> None:
    for name in ("PLUGCELL_MODE", "PLUGCELL_LISTEN", "PLUGCELL_CONNECT", "PLUGCELL_MULTICAST"):
        monkeypatch.delenv(name, raising=False)
    assert TransportConfig.from_env().mode == "peer"
    monkeypatch.setenv("PLUGCELL_MODE", "client")
    client = TransportConfig.from_env()  # finds a router on the host by scouting
    assert client.mode == "client" and client.listen == () and client.multicast
    conf = client.zenoh_config()
    assert conf.get_json("mode") == '"client"' and conf.get_json("listen/endpoints") == "[]"
    routed = TransportConfig.from_env(connect=["tcp/10.0.0.1:7447"])
    assert routed.connect == ("tcp/10.0.0.1:7447",)
    assert TransportConfig.from_env(mode="router").mode == "router"  # the router's own
    assert TransportConfig.from_env(mode="router").listen == ("tcp/0.0.0.0:7447",)


@pytest.mark.parametrize(("env", "listen", "reason"), [
    ({"PLUGCELL_MODE": "router"}, None, "PLUGCELL_MODE must be peer or client, got 'router'"),
    ({"PLUGCELL_MODE": "Client"}, None, "PLUGCELL_MODE must be peer or client, got 'Client'"),
    ({"PLUGCELL_MODE": "client", "PLUGCELL_MULTICAST": "0"}, None,
     "a client needs a router to reach: PLUGCELL_CONNECT (or --connect) or multicast scouting"),
    ({"PLUGCELL_MODE": "client", "PLUGCELL_LISTEN": "tcp/127.0.0.1:0"}, None,
     "a client listens on nothing: it reaches the cell through a router "
     "(unset PLUGCELL_LISTEN and --listen)"),
    ({"PLUGCELL_MODE": "client"}, ["tcp/127.0.0.1:0"],
     "a client listens on nothing: it reaches the cell through a router "
     "(unset PLUGCELL_LISTEN and --listen)"),
])
def test_a_bad_mode_is_refused_with_the_reason(
        monkeypatch: pytest.MonkeyPatch, env: dict[str, str], listen: list[str] | None,
        reason: str) -> None:
    for name in ("PLUGCELL_MODE", "PLUGCELL_LISTEN", "PLUGCELL_CONNECT", "PLUGCELL_MULTICAST"):
        monkeypatch.delenv(name, raising=False)
    for name, value in env.items():
        monkeypatch.setenv(name, value)
    with pytest.raises(ValueError) as caught:
        TransportConfig.from_env(listen=listen)
    assert str(caught.value) == reason


@settings(max_examples=200, deadline=None, derandomize=True)
@given(text=st.text(st.characters(blacklist_categories=("Cs",), blacklist_characters="\x00")))
def test_any_mode_text_is_a_mode_or_refused_with_the_reason(text: str) -> None:
    import os

    saved = {name: os.environ.pop(name, None)
             for name in ("PLUGCELL_MODE", "PLUGCELL_LISTEN", "PLUGCELL_CONNECT")}
    os.environ["PLUGCELL_MODE"] = text
    try:
        cfg = TransportConfig.from_env()
    except ValueError as exc:
        assert str(exc) == f"PLUGCELL_MODE must be peer or client, got {text.strip()!r}"
    else:
        assert cfg.mode == (text.strip() or "peer") and cfg.mode in ("peer", "client")
    finally:
        for name, value in saved.items():
            os.environ.pop(name, None)
            if value is not None:
                os.environ[name] = value


def test_a_lean_cell_still_sees_a_killed_peer_leave_at_once(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """With a long lease and no shared memory, a peer that dies still leaves at once:
    its links close with its process (the lease only bounds a hung peer)."""
    import subprocess
    import sys

    monkeypatch.setenv("PLUGCELL_LEASE", "120")
    monkeypatch.setenv("PLUGCELL_SHM", "0")
    cell = f"bus{uuid.uuid4().hex[:10]}"
    watcher = Bus.connect(TransportConfig.from_env(), KeySpace(cell))
    seen: list[tuple[Presence, bool]] = []
    watcher.watch_presence(lambda p, joined: seen.append((p, joined)))
    child = subprocess.Popen(
        [sys.executable, "-c",
         "import sys, time\n"
         "from plugcell.framework.bus import Bus\n"
         "from plugcell.framework.keys import KeySpace\n"
         "from plugcell.framework.transport import TransportConfig\n"
         f"bus = Bus.connect(TransportConfig.from_env(), KeySpace({cell!r}))\n"
         "token = bus.announce('service', 'DOOMED', '0001')\n"
         "print('up', flush=True)\n"
         "time.sleep(600)\n"],
        stdout=subprocess.PIPE, text=True)
    try:
        assert child.stdout is not None and child.stdout.readline().strip() == "up"
        doomed = Presence("service", "DOOMED", "0001")
        assert until(lambda: (doomed, True) in seen, 10.0)
        child.kill()
        killed = time.monotonic()
        assert until(lambda: (doomed, False) in seen, 10.0)
        assert time.monotonic() - killed < 10.0  # far below the 120 s lease
    finally:
        child.kill()
        child.wait()
        watcher.close()


def test_the_transport_benchmark_names_how_its_processes_joined(
        monkeypatch: pytest.MonkeyPatch) -> None:
    from plugcell.apps.bench.transport import _mode

    for name in ("PLUGCELL_MODE", "PLUGCELL_SHM", "PLUGCELL_LISTEN", "PLUGCELL_CONNECT"):
        monkeypatch.delenv(name, raising=False)
    assert "Zenoh peers on loopback; Zenoh's shared-memory" in _mode(False)
    monkeypatch.setenv("PLUGCELL_MODE", "client")
    monkeypatch.setenv("PLUGCELL_SHM", "0")
    assert _mode(False) == ("local (two OS processes, Zenoh clients of a router "
                            "(PLUGCELL_MODE=client), no shared memory)")
