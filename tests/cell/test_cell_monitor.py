"""The process monitor: who asked whom, state, duration, queues (thesis 7.6, Figure 7-11)."""

from __future__ import annotations

from plugcell.devices.cell.monitor import MonitorFeed, ProcessMonitor
from plugcell.framework.messages import (
    Data,
    DataTypes,
    ProcessStates,
    ProcessUpdateNotification,
    Tag,
)


def update(sender: str, recipient: str, identifier: int, state: str, seq: int,
           data: Data | None = None, reason: str = "") -> ProcessUpdateNotification:
    return ProcessUpdateNotification(tag=Tag(sender, recipient), identifier=identifier,
                                     state=ProcessStates(state), data=data, reason=reason, seq=seq)


def test_sources_merge_into_one_record_per_process() -> None:
    m = ProcessMonitor()
    m.created("TRACKER", "R1", 7, command="Single Measurement", option="tr2rpy",
              type="SingleData", t_ns=1_000_000_000, source="journal")
    m.created("TRACKER", "R2", 8, command="Single Measurement", t_ns=1_100_000_000)
    assert m.queues()["TRACKER"]["length"] == 2
    m.updated("TRACKER", update("R1", "TRACKER", 7, "Running", 1), t_ns=1_200_000_000)
    pose = Data(DataTypes.Double, (6,), bytes(48))
    m.updated("TRACKER", update("R1", "TRACKER", 7, "Completed", 2, pose), t_ns=1_700_000_000)
    m.updated("TRACKER", update("R1", "TRACKER", 7, "Running", 1), t_ns=1_800_000_000)  # late
    r = m.records[("TRACKER", "R1", 7)]
    assert (r.state, r.command, r.frames) == ("Completed", "Single Measurement", 1)
    assert r.duration() == 0.7
    assert r.to_json()["data"] == {"type": "Double", "size": [6], "value": [0.0] * 6}
    assert r.sources == {"journal", "live"}
    q = m.queues()["TRACKER"]
    assert q["length"] == 1 and q["queued"][0]["sender"] == "R2" and not q["running"]


def test_an_update_without_its_creation_is_kept_and_named_later() -> None:
    m = ProcessMonitor()
    m.updated("TOOL", update("R1", "TOOL", 3, "Running", 1), t_ns=5)
    assert m.records[("TOOL", "R1", 3)].command == ""
    m.created("TOOL", "R1", 3, command="Drill", t_ns=4, source="journal")
    r = m.records[("TOOL", "R1", 3)]
    assert (r.command, r.state, r.received_ns, r.started_ns) == ("Drill", "Running", 4, 5)
    assert m.journal_update("TOOL", "R1", 3, 2, "Completed", "", "", 9) is r
    assert m.journal_update("TOOL", "X", 1, 1, "Running", "", "", 9) is None
    assert r.state == "Completed" and r.ended_ns == 9


def test_a_lost_service_fails_what_it_had_not_finished() -> None:
    m = ProcessMonitor()
    m.created("CAMERA", "R1", 1, command="MovieShot")
    m.updated("CAMERA", update("R1", "CAMERA", 1, "Running", 1))
    m.created("CAMERA", "R2", 2, command="SnapShot")
    lost = m.service_lost("CAMERA")
    assert {r.identifier for r in lost} == {1, 2}
    assert all(r.state == "Failed" and "lost" in r.reason for r in lost)
    assert m.queues() == {}
    assert m.counts()["Failed"] == 2


def test_memory_is_bounded_and_keeps_what_is_going_on() -> None:
    m = ProcessMonitor(max_records=10)
    m.created("S", "R", 0, command="Hold")
    for i in range(1, 50):
        m.created("S", "R", i, command="Work")
        m.updated("S", update("R", "S", i, "Completed", 1))
    assert len(m.records) == 10
    assert ("S", "R", 0) in m.records  # still queued: kept
    assert len(m.snapshot(limit=5)) == 5


class Clock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def test_the_feed_holds_an_unnamed_process_for_its_journal_row_and_counts_each_end_once() -> None:
    m, clock = ProcessMonitor(), Clock()
    feed = MonitorFeed(hold_s=1.0, clock=clock)
    r = m.updated("TOOL", update("R1", "TOOL", 3, "Completed", 2), t_ns=5)
    assert not feed.offer(r) and feed.held() == [r.key] and feed.ended == 0
    m.created("TOOL", "R1", 3, command="Drill", t_ns=4, source="journal")  # the row names it
    assert feed.offer(r) and feed.held() == [] and feed.ended == 1
    assert not feed.offer(r)  # nothing new

    late = m.updated("CAMERA", update("R1", "CAMERA", 4, "Completed", 1), t_ns=6)
    assert not feed.offer(late)
    clock.t += 1.0  # no row came in time: shown without its command …
    assert feed.offer(late) and feed.ended == 2
    m.created("CAMERA", "R1", 4, command="SnapShot", t_ns=5, source="journal")
    assert feed.offer(late) and (late.command, feed.ended) == ("SnapShot", 2)  # … then named


def test_the_feed_skips_history_and_other_services_and_shows_state_changes() -> None:
    m = ProcessMonitor()
    old = m.created("TOOL", "R1", 1, command="Drill", state="Completed", t_ns=1)
    feed = MonitorFeed(service="TOOL", hold_s=0.0)
    feed.history(m.records.values())
    assert not feed.offer(old) and feed.ended == 0
    other = m.created("CAMERA", "R1", 2, command="SnapShot", t_ns=2)
    assert not feed.offer(other)
    r = m.created("TOOL", "R2", 3, command="Drill", t_ns=3)
    assert feed.offer(r)  # Queued
    for state, seq in (("Running", 1), ("Completed", 2)):
        m.updated("TOOL", update("R2", "TOOL", 3, state, seq), t_ns=4 + seq)
        assert feed.offer(r) and r.state == state
    assert feed.ended == 1 and not feed.offer(r)
    unnamed = m.updated("TOOL", update("R3", "TOOL", 9, "Failed", 1, reason="x"), t_ns=9)
    assert feed.offer(unnamed) and feed.ended == 2  # nothing to wait for without journals


def test_journal_rows_become_records_as_the_tail_reads_them() -> None:
    """The rows of a journal tail's poll, as the controller and ``cell monitor`` apply them."""
    m = ProcessMonitor()
    processes = [{"recipient": "TOOL", "sender": "R1", "identifier": 3, "command": "Drill",
                  "option": None, "command_type": "SingleData", "state": "Queued",
                  "reason": None, "received_ns": 5}]
    updates = [
        {"recipient": "TOOL", "sender": "R1", "identifier": 3, "seq": 2, "state": "Failed",
         "reason": "bit broke", "data": None, "t_ns": 9},
        {"recipient": "TOOL", "sender": "X", "identifier": 1, "seq": 1, "state": "Running",
         "reason": None, "data": None, "t_ns": 9},  # a process the journal never named
    ]
    touched = m.from_journal(processes, updates)
    r = m.records[("TOOL", "R1", 3)]
    assert touched == [r, r]
    assert (r.command, r.option, r.state, r.reason, r.sources) == (
        "Drill", "", "Failed", "bit broke", {"journal"})
    assert m.from_journal([], []) == []
