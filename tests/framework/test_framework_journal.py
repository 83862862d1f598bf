"""The journal on its own: recovery of a previous incarnation, both schema versions,
and readers that scan the index-less ``updates`` table once, not per process."""

from __future__ import annotations

import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from plugcell.devices.cell import journal_tail as controller_journal
from plugcell.devices.cell.journal_tail import JournalTail
from plugcell.framework.journal import (
    SCHEMA_VERSION,
    Journal,
    JournalInUseError,
    journal_dir,
    read_journal,
)

#: The version-1 schema (``updates`` keyed by (recipient, sender, identifier, seq)),
#: as journals written before version 2 still have it.
V1_UPDATES = """CREATE TABLE updates (
    recipient TEXT NOT NULL, sender TEXT NOT NULL, identifier INTEGER NOT NULL,
    seq INTEGER NOT NULL, t_ns INTEGER NOT NULL, state TEXT NOT NULL,
    reason TEXT NOT NULL DEFAULT '', data TEXT NOT NULL DEFAULT '',
    PRIMARY KEY (recipient, sender, identifier, seq));
CREATE TABLE meta (key TEXT PRIMARY KEY, value TEXT);
INSERT INTO meta VALUES ('schema_version', '1');"""


def _process(journal: Journal, identifier: int, state: str = "Queued", sender: str = "A") -> None:
    journal.record_process(
        sender=sender, identifier=identifier, sender_instance="s", recipient_instance="r",
        command="Measure", option="", command_type="SingleData", input_summary="",
        received_ns=time.time_ns(), state=state, reason="refused" if state == "Failed" else "",
    )


def _history(journal: Journal) -> None:
    """1 Completed; 2 Running (interrupted); 3 Queued, never started (interrupted);
    4 refused at acceptance; 5 Failed while running; 6 from another sender, Running."""
    for identifier in (1, 2, 3, 5):
        _process(journal, identifier)
    _process(journal, 4, "Failed")
    _process(journal, 6, sender="B")
    journal.record_update("A", 1, 1, "Running", "", "")
    journal.record_update("A", 1, 2, "Completed", "OK", "")
    journal.record_update("A", 2, 1, "Running", "", "")
    journal.record_update("A", 2, 2, "Running", "", "Double[1] [1.0]")
    journal.record_update("A", 5, 1, "Running", "", "")
    journal.record_update("A", 5, 2, "Failed", "E42", "")
    journal.record_update("B", 6, 1, "Running", "", "")
    journal.commit()


def _final_states(path: Path) -> dict[tuple[str, int], tuple[str, int, str]]:
    return {
        (p["sender"], p["identifier"]): (
            p["state"], p["updates"][-1]["seq"] if p["updates"] else 0, p["reason"]
        )
        for p in read_journal([path])
    }


@pytest.mark.parametrize("version", [1, SCHEMA_VERSION])
def test_recover_fails_exactly_the_unfinished_processes(tmp_path: Path, version: int) -> None:
    path = tmp_path / "DEV.sqlite"
    if version == 1:
        with sqlite3.connect(path) as db:
            db.executescript(V1_UPDATES)
    journal = Journal(path, "DEV")
    _history(journal)
    journal.close()

    again = Journal(path, "DEV")
    assert again.recover("interrupted") == 3
    assert again.recover("interrupted") == 0  # idempotent: nothing is left unfinished
    _process(again, 9)  # this incarnation is interrupted too, while 9 runs
    again.record_update("A", 9, 1, "Running", "", "")
    again.commit()
    again.close()
    third = Journal(path, "DEV")
    assert third.recover("interrupted again") == 1  # 9 only: 1–6 end before the mark
    third.close()
    assert _final_states(path) == {
        ("A", 1): ("Completed", 2, "OK"),
        ("A", 2): ("Failed", 3, "interrupted"),  # after its last update
        ("A", 3): ("Failed", 1, "interrupted"),
        ("A", 4): ("Failed", 0, "refused"),
        ("A", 5): ("Failed", 2, "E42"),
        ("B", 6): ("Failed", 2, "interrupted"),
        ("A", 9): ("Failed", 2, "interrupted again"),
    }
    with sqlite3.connect(path) as db:  # an old journal keeps its version and its key
        assert db.execute("SELECT value FROM meta WHERE key='schema_version'").fetchone() == (
            str(version),
        )
        keyed = db.execute("PRAGMA index_list(updates)").fetchall()
        assert bool(keyed) == (version == 1)


@settings(max_examples=60, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(mark=st.one_of(st.text(max_size=30), st.integers(-(2**63), 2**63 - 1),
                      st.binary(max_size=8), st.floats(allow_nan=True),
                      st.just("99999999999999999999 3"), st.just(f"{2**63 - 1} 3")))
def test_a_damaged_recovery_mark_only_makes_recovery_read_everything(
    tmp_path_factory: pytest.TempPathFactory, mark: object
) -> None:
    """Whatever ``meta.recovered_through`` holds, recovery fails exactly the unfinished
    processes (reading everything if the mark cannot be read) and writes a good mark."""
    path = tmp_path_factory.mktemp("mark") / "DEV.sqlite"
    journal = Journal(path, "DEV")
    _history(journal)
    journal._db.execute("INSERT OR REPLACE INTO meta VALUES ('recovered_through', ?)", (mark,))
    journal.commit()
    readable = mark == f"{2**63 - 1} 3"  # a mark past every process: nothing to recover
    assert journal.recover("interrupted") == (0 if readable else 3)
    good = journal._db.execute(
        "SELECT value FROM meta WHERE key = 'recovered_through'").fetchone()[0]
    journal.close()
    # 6 processes; 7 updates, and the 3 Failed ones unless the mark was past them all
    assert [int(v) for v in good.split()] == [6, 7 if readable else 10]


def _plan(db: sqlite3.Connection, sql: str) -> list[str]:
    return [row[3] for row in db.execute(f"EXPLAIN QUERY PLAN {sql}")]


def _assert_one_pass(plan: list[str]) -> None:
    visits = [step for step in plan if " updates" in step]
    one_pass = ("SCAN updates", "SEARCH updates",  # all of it, or from a rowid on
                "SEARCH updates USING INTEGER PRIMARY KEY (rowid>?)")
    assert len(visits) == 1 and visits[0] in one_pass, plan
    assert not any("CORRELATED" in step for step in plan), plan


def test_journal_readers_visit_updates_in_one_pass(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """No lookup of ``updates`` per process (the table has no index from version 2):
    in SQLite's plans of the statements that recovery and the tail's start really
    run, ``updates`` is visited once, by no index and by no correlated subquery."""
    path = journal_dir("C", tmp_path) / "DEV.sqlite"
    journal = Journal(path, "DEV")
    _history(journal)
    ran: list[str] = []
    journal._db.set_trace_callback(ran.append)
    journal.recover("interrupted")
    journal._db.set_trace_callback(None)
    recovery = [sql for sql in ran if "INSERT INTO updates SELECT" in sql]
    assert len(recovery) == 1
    plan = _plan(journal._db, recovery[0])
    _assert_one_pass(plan)
    assert "SEARCH updates USING INTEGER PRIMARY KEY (rowid>?)" in plan  # from the mark on

    connect = sqlite3.connect

    def traced(*args: object, **kwargs: object) -> sqlite3.Connection:
        db = connect(*args, **kwargs)  # type: ignore[arg-type]
        db.set_trace_callback(ran.append)
        return db

    monkeypatch.setattr(sqlite3, "connect", traced)
    ran.clear()
    tail = JournalTail("C", tmp_path)
    tail.poll()
    tail.close()
    start = [sql for sql in ran if "MIN(" in sql and "updates" in sql]
    assert len(start) == 1
    _assert_one_pass(_plan(journal._db, start[0]))
    journal.close()


def test_tail_starts_at_the_first_update_of_its_history(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The controller's tail shows the last ``HISTORY`` processes with all their updates,
    found without an index on ``updates``."""
    monkeypatch.setattr(controller_journal, "HISTORY", 2)
    journal = Journal(journal_dir("C", tmp_path) / "DEV.sqlite", "DEV")
    _history(journal)
    for identifier in (7, 8):
        _process(journal, identifier)
        journal.record_update("A", identifier, 1, "Running", "", "")
    journal.record_update("A", 2, 3, "Completed", "OK", "")  # an old process ends late
    journal.commit()
    tail = JournalTail("C", tmp_path)
    try:
        processes, updates = tail.poll()
    finally:
        tail.close()
        journal.close()
    assert [p["identifier"] for p in processes] == [7, 8]
    # from the first update of process 7 on: its own, 8's, and the late one of 2
    assert [(u["identifier"], u["seq"]) for u in updates] == [(7, 1), (8, 1), (2, 3)]


def test_one_process_at_a_time_holds_a_journal(tmp_path: Path) -> None:
    """A second opener — another service of the same name on this host — is refused
    while the first holds the journal, and admitted once it closes or dies (kill -9)."""
    path = tmp_path / "DEV.sqlite"
    first = Journal(path, "DEV")
    with pytest.raises(JournalInUseError, match="is in use by another process"):
        Journal(path, "DEV")
    first.close()
    Journal(path, "DEV").close()

    holder = subprocess.Popen(
        [sys.executable, "-c",
         "import sys, time; from pathlib import Path; from plugcell.framework.journal import "
         "Journal; Journal(Path(sys.argv[1]), 'DEV'); print('open', flush=True); time.sleep(60)",
         str(path)],
        stdout=subprocess.PIPE, text=True,
    )
    try:
        assert holder.stdout is not None and holder.stdout.readline().strip() == "open"
        with pytest.raises(JournalInUseError):
            Journal(path, "DEV")
    finally:
        holder.kill()
        holder.wait(10)
    Journal(path, "DEV").close()  # the kernel released the dead holder's lock
    assert [p.name for p in sorted(tmp_path.glob("*.sqlite"))] == ["DEV.sqlite"]
