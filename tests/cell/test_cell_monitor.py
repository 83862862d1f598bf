"""The process monitor: who asked whom, state, duration, queues (thesis 7.6, Figure 7-11)."""

from __future__ import annotations

from plugcell.framework.model import Data, DataTypes, ProcessStates, ProcessUpdateNotification, Tag
from plugcell.services.controller_monitor import ProcessMonitor


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
