"""The journal's log: commits are appends, rows move into SQLite in the background, and
nothing committed is lost or shown twice — across a kill, a torn write, a full disk, a
restart of the log, and to every reader (``read_journal``, the cell controller's tail)."""

from __future__ import annotations

import errno
import os
import signal
import sqlite3
import subprocess
import sys
import threading
import time
from pathlib import Path

import msgspec
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from plugcell.devices.cell import journal_tail as tail_module
from plugcell.devices.cell.journal_tail import JournalTail
from plugcell.framework import journal as journal_module
from plugcell.framework import journal_log
from plugcell.framework.journal import (
    DuplicateProcessError,
    Journal,
    journal_dir,
    read_journal,
)
from plugcell.framework.journal_log import HEADER, MAGIC, encode, log_path, read_log


@pytest.fixture(autouse=True)
def _no_background_moves(monkeypatch: pytest.MonkeyPatch) -> None:
    """Rows move only when a test says so (``settle``, ``close``, opening)."""
    monkeypatch.setattr(journal_module, "MOVE_PERIOD_S", 3600.0)


def _process(journal: Journal, identifier: int, sender: str = "A") -> None:
    journal.record_process(
        sender=sender, identifier=identifier, sender_instance="s", recipient_instance="r",
        command="Measure", option="", command_type="SingleData", input_summary="",
        received_ns=identifier, state="Queued",
    )


def _commit_completed(journal: Journal, identifier: int) -> None:
    """Commit process ``identifier`` of A with its Completed update."""
    _process(journal, identifier)
    journal.record_update("A", identifier, 1, "Completed", "", "")
    journal.commit()


def _churning(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
              restart_bytes: int) -> tuple[Journal, JournalTail]:
    """A journal whose rows move every millisecond and whose log restarts past
    ``restart_bytes``, and a cell controller's tail of it."""
    monkeypatch.setattr(journal_module, "MOVE_PERIOD_S", 0.001)
    monkeypatch.setattr(journal_module, "LOG_RESTART_BYTES", restart_bytes)
    return (Journal(journal_dir("C", tmp_path) / "DEV.sqlite", "DEV"),
            JournalTail("C", tmp_path))


def _in_database(path: Path, table: str) -> int:
    with sqlite3.connect(path) as db:
        return db.execute(f"SELECT COUNT(*) FROM {table}").fetchone()[0]


def _poll(tail: JournalTail) -> list[tuple[int, ...]]:
    """What one poll of the tail shows: (identifier,) per process, (identifier, seq) per
    update."""
    processes, updates = tail.poll()
    return [(p["identifier"],) for p in processes] + [
        (u["identifier"], u["seq"]) for u in updates]


def _summary(path: Path) -> list[tuple[str, int, list[int]]]:
    return [(p["sender"], p["identifier"], [u["seq"] for u in p["updates"]])
            for p in read_journal([path])]


def test_a_commit_is_one_append_and_readers_see_it_before_it_moves(tmp_path: Path) -> None:
    path = journal_dir("C", tmp_path) / "DEV.sqlite"
    journal = Journal(path, "DEV")
    tail = JournalTail("C", tmp_path)
    try:
        _process(journal, 1)
        journal.record_update("A", 1, 1, "Running", "", "")
        journal.commit()
        found = read_log(log_path(path))
        assert found is not None and len(found.records) == 1  # one write
        assert _in_database(path, "processes") == 0  # not moved yet
        assert _summary(path) == [("A", 1, [1])]  # read from the log
        processes, updates = tail.poll()
        assert [p["identifier"] for p in processes] == [1]
        assert [(u["identifier"], u["seq"]) for u in updates] == [(1, 1)]

        journal.record_update("A", 1, 2, "Completed", "", "")
        journal.settle()
        assert _in_database(path, "processes") == 1
        assert _in_database(path, "updates") == 2
        assert _summary(path) == [("A", 1, [1, 2])]  # once, though read from both
        processes, updates = tail.poll()  # 1 and its first update were shown already
        assert processes == []
        assert [(u["identifier"], u["seq"]) for u in updates] == [(1, 2)]
        assert tail.poll() == ([], [])
    finally:
        tail.close()
        journal.close()
    assert not log_path(path).exists()  # all moved: the log goes with the journal


def _killed_writer(path: Path, processes: int) -> None:
    """A process that commits ``processes`` processes and dies (kill -9) before any
    moves into the database."""
    script = (
        "import sys, time; from pathlib import Path; "
        "from plugcell.framework import journal as m; m.MOVE_PERIOD_S = 3600.0; "
        "j = m.Journal(Path(sys.argv[1]), 'DEV'); n = int(sys.argv[2])\n"
        "for i in range(1, n + 1):\n"
        "    j.record_process(sender='A', identifier=i, sender_instance='s', "
        "recipient_instance='r', command='Measure', option='', command_type='SingleData', "
        "input_summary='', received_ns=i, state='Queued')\n"
        "    j.record_update('A', i, 1, 'Running', '', '')\n"
        "    if i % 2: j.record_update('A', i, 2, 'Completed', '', '')\n"
        "    j.commit()\n"
        "print('committed', flush=True); time.sleep(60)"
    )
    writer = subprocess.Popen([sys.executable, "-c", script, str(path), str(processes)],
                              stdout=subprocess.PIPE, text=True)
    try:
        assert writer.stdout is not None and writer.stdout.readline().strip() == "committed"
    finally:
        writer.send_signal(signal.SIGKILL)
        writer.wait(10)


def test_a_killed_service_loses_nothing_it_committed(tmp_path: Path) -> None:
    path = tmp_path / "DEV.sqlite"
    _killed_writer(path, 40)
    assert _in_database(path, "processes") == 0
    expected = [("A", i, [1, 2] if i % 2 else [1]) for i in range(1, 41)]
    assert _summary(path) == expected  # from the log, while nobody holds the journal

    again = Journal(path, "DEV")  # opening moves what the dead one left
    assert _in_database(path, "processes") == 40
    assert log_path(path).stat().st_size == HEADER.size  # the log starts afresh
    assert _summary(path) == expected
    assert again.recover("interrupted") == 20  # the even ones had not ended
    again.close()
    assert [s for s in _summary(path) if s[1] == 2] == [("A", 2, [1, 2])]


def test_a_torn_write_at_the_end_is_dropped_and_the_log_goes_on(tmp_path: Path) -> None:
    path = tmp_path / "DEV.sqlite"
    _killed_writer(path, 3)
    whole = encode([(journal_log.PROCESS, ["DEV", "A", 99] + [""] * 10)],
                   msgspec.msgpack.Encoder())
    with open(log_path(path), "ab") as f:
        f.write(whole[: len(whole) // 2])  # a crash in the middle of a write
    assert [s[1] for s in _summary(path)] == [1, 2, 3]  # the torn record is not read
    journal = Journal(path, "DEV")
    _process(journal, 4)
    journal.commit()
    assert [s[1] for s in _summary(path)] == [1, 2, 3, 4]  # not stuck behind it
    journal.close()
    assert [s[1] for s in _summary(path)] == [1, 2, 3, 4]


def test_a_restarted_log_without_its_mark_is_read_whole(tmp_path: Path) -> None:
    """A crash after the log restarted and before the database learnt its new
    generation: the log's rows are all new, for readers and for the next opening."""
    path = tmp_path / "DEV.sqlite"
    journal = Journal(path, "DEV")
    _process(journal, 1)
    journal.close()
    encoder = msgspec.msgpack.Encoder()
    row = ["DEV", "A", 2, "r", "s", "Measure", "", "SingleData", "", 2, 2, "Queued", ""]
    log_path(path).write_bytes(HEADER.pack(MAGIC, 12345)
                               + encode([(journal_log.PROCESS, row)], encoder))
    assert [s[1] for s in _summary(path)] == [1, 2]
    Journal(path, "DEV").close()
    assert _in_database(path, "processes") == 2
    assert [s[1] for s in _summary(path)] == [1, 2]


def test_a_foreign_file_in_place_of_the_log_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "DEV.sqlite"
    log_path(path).write_bytes(b"not a journal log at all")
    with pytest.raises(ValueError, match="is not a plugcell journal log"):
        Journal(path, "DEV")
    log_path(path).unlink()
    Journal(path, "DEV").close()  # the failed opening released the journal


def test_a_duplicate_identifier_is_refused_wherever_the_first_one_is(tmp_path: Path) -> None:
    path = tmp_path / "DEV.sqlite"
    journal = Journal(path, "DEV")
    _process(journal, 10)
    with pytest.raises(DuplicateProcessError, match="process 10 from A"):
        _process(journal, 10)  # recorded, not committed
    journal.commit()
    with pytest.raises(DuplicateProcessError):
        _process(journal, 10)  # in the log
    journal.settle()
    with pytest.raises(DuplicateProcessError):
        _process(journal, 10)  # in the database
    _process(journal, 5)  # lower, but new: accepted
    _process(journal, 10, sender="B")  # the same identifier from another sender
    journal.close()
    again = Journal(path, "DEV")
    with pytest.raises(DuplicateProcessError):
        _process(again, 5)  # an earlier incarnation's
    _process(again, 11)
    again.close()
    assert sorted((s[0], s[1]) for s in _summary(path)) == [
        ("A", 5), ("A", 10), ("A", 11), ("B", 10)]


def test_a_full_disk_keeps_the_rows_for_the_next_commit(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tmp_path / "DEV.sqlite"
    journal = Journal(path, "DEV")
    _process(journal, 1)
    journal.commit()
    size = log_path(path).stat().st_size
    real_write = os.write

    def half_then_full(fd: int, data: bytes) -> int:
        real_write(fd, bytes(data)[: len(data) // 2])
        raise OSError(errno.ENOSPC, "No space left on device")

    _process(journal, 2)
    monkeypatch.setattr(journal_log.os, "write", half_then_full)
    with pytest.raises(OSError, match="No space left"):
        journal.commit()
    monkeypatch.setattr(journal_log.os, "write", real_write)
    assert log_path(path).stat().st_size == size  # the half record was cut off again
    _process(journal, 3)
    journal.commit()  # 2 and 3
    assert [s[1] for s in _summary(path)] == [1, 2, 3]
    journal.close()
    assert [s[1] for s in _summary(path)] == [1, 2, 3]


def test_durable_syncs_each_append(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    synced: list[int] = []
    monkeypatch.setattr(journal_log.os, "fdatasync", synced.append)
    journal = Journal(tmp_path / "DEV.sqlite", "DEV", durable=True)
    before = len(synced)  # the fresh log's header
    _process(journal, 1)
    journal.commit()
    journal.commit()  # nothing recorded: nothing written
    assert len(synced) == before + 1
    journal.close()


def test_the_log_restarts_once_long_and_every_row_is_shown_once(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """With the background mover on, a tiny restart size and the tail polling all along."""
    journal, tail = _churning(tmp_path, monkeypatch, 300)
    path = journal.path
    shown: list[tuple[int, ...]] = []
    generations = set()
    try:
        for i in range(1, 121):
            _commit_completed(journal, i)
            if i % 7 == 0:
                time.sleep(0.003)
                shown += _poll(tail)
                found = read_log(log_path(path))
                if found is not None:
                    generations.add(found.generation)
        journal.settle()
        shown += _poll(tail)
    finally:
        tail.close()
        journal.close()
    assert len(generations) > 1  # the log did restart
    assert sorted(shown) == sorted([(i,) for i in range(1, 121)]
                                   + [(i, 1) for i in range(1, 121)])
    assert [s[1] for s in _summary(path)] == list(range(1, 121))


OPERATIONS = st.lists(
    st.sampled_from(["process", "update", "commit", "settle", "restart", "reopen", "poll"]),
    min_size=1, max_size=40,
)


@settings(max_examples=80, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(operations=OPERATIONS)
@example(operations=["process", "update", "commit", "poll", "settle", "poll"])
def test_readers_see_exactly_what_was_committed(
    tmp_path_factory: pytest.TempPathFactory, monkeypatch: pytest.MonkeyPatch,
    operations: list[str],
) -> None:
    """Any sequence of records, commits, moves, log restarts and reopenings: after each,
    ``read_journal`` holds exactly the committed rows, and the tail has shown each
    committed row exactly once (with a history longer than the test)."""
    monkeypatch.setattr(tail_module, "HISTORY", 1000)
    monkeypatch.setattr(journal_module, "LOG_RESTART_BYTES", 0)
    home = tmp_path_factory.mktemp("home")
    path = journal_dir("C", home) / "DEV.sqlite"
    journal = Journal(path, "DEV")
    tail = JournalTail("C", home)
    recorded: list[tuple[int, ...]] = []
    committed: list[tuple[int, ...]] = []
    shown: list[tuple[int, ...]] = []
    identifier, seq = 0, 0
    try:
        for op in operations:
            if op == "process":
                identifier, seq = identifier + 1, 0
                _process(journal, identifier)
                recorded.append((identifier,))
            elif op == "update" and identifier:
                seq += 1
                journal.record_update("A", identifier, seq, "Running", "", "")
                recorded.append((identifier, seq))
            elif op in ("commit", "settle"):
                getattr(journal, op)()
                committed += recorded
                recorded = []
            elif op == "restart":
                journal.settle()
                committed += recorded
                recorded = []
                journal._restart_log_if_long(journal._db)
            elif op == "reopen":
                journal.close()
                committed += recorded
                recorded = []
                journal = Journal(path, "DEV")
            elif op == "poll":
                shown += _poll(tail)
            in_journal = [((p["identifier"],), [(p["identifier"], u["seq"])
                                                for u in p["updates"]])
                          for p in read_journal([path])]
            flat = [row for process, updates in in_journal for row in [process, *updates]]
            assert sorted(flat) == sorted(committed)
        shown += _poll(tail)
        assert sorted(shown) == sorted(committed)
    finally:
        tail.close()
        journal.close()


def test_the_log_is_read_from_a_mark_on_and_a_stale_mark_is_told(tmp_path: Path) -> None:
    """Readers read only the part after the database's mark; a mark of another
    generation (the log restarted since) asks them to take a new snapshot."""
    encoder = msgspec.msgpack.Encoder()
    writer = journal_log.LogWriter(tmp_path / "DEV.sqlite.log", durable=False)
    generation = writer.restart()
    ends = [writer.append(encode([(journal_log.UPDATE, [f"row{i}"])], encoder))
            for i in range(3)]
    writer.close(delete=False)
    whole = read_log(tmp_path / "DEV.sqlite.log")
    assert whole is not None and [end for end, _ in whole.records] == ends
    after_first = read_log(tmp_path / "DEV.sqlite.log", ends[0])
    assert after_first is not None
    assert after_first.rows == [(journal_log.UPDATE, ["row1"]), (journal_log.UPDATE, ["row2"])]
    assert [end for end, _ in after_first.records] == ends[1:]
    assert after_first.end == ends[-1] == whole.end
    database = tmp_path / "DEV.sqlite"
    assert journal_module.unmoved_rows(database, (generation, ends[1])) == [
        (journal_log.UPDATE, ["row2"])]
    assert journal_module.unmoved_rows(database, (generation + 1, ends[1])) is None
    assert journal_module.unmoved_rows(database, None) == whole.rows
    assert journal_module.unmoved_rows(tmp_path / "NONE.sqlite", None) == []


def test_a_full_disk_while_the_log_restarts_loses_nothing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The restart emptied the file and could not write its header: the next commit
    starts the file itself, and readers still see every row once — the database's mark
    names the old generation, so they take the whole new file as not moved."""
    monkeypatch.setattr(journal_module, "LOG_RESTART_BYTES", 0)
    path = tmp_path / "DEV.sqlite"
    journal = Journal(path, "DEV")
    _process(journal, 1)
    journal.settle()
    real_write = os.write

    def disk_full(fd: int, data: bytes) -> int:
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(journal_log.os, "write", disk_full)
    with pytest.raises(OSError, match="No space left"):
        journal._restart_log_if_long(journal._db)  # the background thread logs and retries
    monkeypatch.setattr(journal_log.os, "write", real_write)
    assert log_path(path).stat().st_size == 0
    _process(journal, 2)
    journal.commit()
    found = read_log(log_path(path))
    assert found is not None and [row[1][2] for row in found.rows] == [2]
    assert [s[1] for s in _summary(path)] == [1, 2]
    journal.settle()
    assert [s[1] for s in _summary(path)] == [1, 2]
    journal.close()
    again = Journal(path, "DEV")
    again.close()
    assert [s[1] for s in _summary(path)] == [1, 2]


def test_a_tail_in_another_thread_sees_every_row_once_while_the_log_moves_and_restarts(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The controller polls from a worker thread while the service commits, the rows
    move every millisecond and the log restarts every 2 KiB: whatever the interleaving,
    each committed row is shown once and ``read_journal`` ends with all of them."""
    monkeypatch.setattr(tail_module, "HISTORY", 10_000)
    journal, tail = _churning(tmp_path, monkeypatch, 2048)
    path = journal.path
    shown: list[tuple[int, ...]] = []
    done = threading.Event()
    errors: list[BaseException] = []

    def poll_until_done() -> None:
        try:
            while True:
                last = done.is_set()
                shown.extend(_poll(tail))
                if last:
                    return
        except BaseException as exc:  # reported below
            errors.append(exc)

    poller = threading.Thread(target=poll_until_done)
    poller.start()
    try:
        for i in range(1, 801):
            _commit_completed(journal, i)
            if i % 50 == 0:
                time.sleep(0.002)
        journal.settle()
    finally:
        done.set()
        poller.join(30)
        tail.close()
        journal.close()
    assert not errors
    expected = [(i,) for i in range(1, 801)] + [(i, 1) for i in range(1, 801)]
    assert sorted(shown) == sorted(expected)
    assert [s[1] for s in _summary(path)] == list(range(1, 801))
