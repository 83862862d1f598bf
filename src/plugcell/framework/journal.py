"""The journal: every process and every update in SQLite (WAL), per service.

A cell controller in the thesis "monitors and visualizes the evolution of the
generated processes, including their statuses and data" (7.6, Figure 7-11); the
journal is that record, made durable.  Each service writes its own file
``<home>/cells/<cell>/journal/<service>.sqlite`` (no lock contention between
services); :func:`read_journal` merges them.

Durability rules (what "killing a service loses nothing it acknowledged" means):

* a process row is **committed before its acknowledgement is sent**;
* every update is **committed before it is published** — the updates produced in
  one event-loop turn (a burst of MultipleData frames) share one commit.

A commit is one append to the journal's log (``<service>.sqlite.log``,
:mod:`.journal_log`), which, like SQLite's WAL with ``synchronous=NORMAL``, survives
the death of the process (the kernel has the bytes); ``durable=True`` also syncs each
append to the disk, surviving a power cut.  A background thread moves the rows into
the SQLite database (WAL) and checkpoints it, so a commit never waits for SQLite.
Only a summary of the data (type, size, and the values if small) is stored.
"""

from __future__ import annotations

import logging
import os
import sqlite3
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any, TypeVar

import msgspec

from plugcell.framework.journal_log import (
    HEADER,
    PROCESS,
    REJECTION,
    UPDATE,
    LogWriter,
    Row,
    encode,
    log_path,
    read_log,
)

log = logging.getLogger("plugcell.framework.journal")
_T = TypeVar("_T")

#: Seconds between two moves of the log's rows into the database while commits come.
MOVE_PERIOD_S = 0.05

#: Seconds between two WAL checkpoints while commits come (none while idle).
CHECKPOINT_PERIOD_S = 0.5

#: Once all moved, a log this long starts afresh.
LOG_RESTART_BYTES = 1 << 20

SCHEMA_VERSION = 2
"""2: ``updates`` has no primary key (version 1 had one on (recipient, sender,
identifier, seq)).  Its b-tree cost every row a second insert — a quarter of what
a streamed frame costs the service (``benchmarks/journal.py``); the service makes
each ``seq`` unique by construction, and the readers look updates up by scanning
once (:meth:`Journal.recover`, the controller's tail) or merge them in Python
(:func:`read_journal`).  Both versions are read and written alike."""
TABLES = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT);
CREATE TABLE IF NOT EXISTS processes (  -- append-only: later states are updates
    recipient TEXT NOT NULL, sender TEXT NOT NULL, identifier INTEGER NOT NULL,
    recipient_instance TEXT, sender_instance TEXT,
    command TEXT, option TEXT, command_type TEXT, input TEXT,
    received_ns INTEGER, acked_ns INTEGER,
    state TEXT NOT NULL, reason TEXT NOT NULL DEFAULT '',
    PRIMARY KEY (recipient, sender, identifier));
CREATE TABLE IF NOT EXISTS updates (
    recipient TEXT NOT NULL, sender TEXT NOT NULL, identifier INTEGER NOT NULL,
    seq INTEGER NOT NULL, t_ns INTEGER NOT NULL, state TEXT NOT NULL,
    reason TEXT NOT NULL DEFAULT '', data TEXT NOT NULL DEFAULT '');
CREATE TABLE IF NOT EXISTS rejections (
    recipient TEXT NOT NULL, t_ns INTEGER NOT NULL, sender TEXT, identifier INTEGER,
    command TEXT, size INTEGER, reason TEXT NOT NULL);
"""
"""The journal's tables (SQL, idempotent)."""


def plugcell_home() -> Path:
    """``$PLUGCELL_HOME``, else ``$XDG_STATE_HOME/plugcell``, else ``~/.local/state/plugcell``."""
    if os.environ.get("PLUGCELL_HOME"):
        return Path(os.environ["PLUGCELL_HOME"])
    state = os.environ.get("XDG_STATE_HOME") or str(Path.home() / ".local" / "state")
    return Path(state) / "plugcell"


def journal_dir(cell: str, home: Path | None = None) -> Path:
    """Directory holding the journals of ``cell``."""
    return (home or plugcell_home()) / "cells" / cell / "journal"


class JournalInUseError(RuntimeError):
    """Another process has this journal open: a service of the same name on this host."""


def _lock(path: Path) -> int | None:
    """Hold an exclusive advisory lock on ``<journal>.lock`` while the journal is open.

    Two services of one name on one host would otherwise share the file, and the
    younger's :meth:`Journal.recover` would fail the elder's running processes.
    The kernel releases the lock when its process dies, however it dies.
    """
    try:
        import fcntl
    except ImportError:  # not POSIX: no lock
        return None
    fd = os.open(path.with_name(path.name + ".lock"), os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(fd)
        raise JournalInUseError(f"the journal {path} is in use by another process") from None
    return fd


class DuplicateProcessError(ValueError):
    """A process whose (sender, identifier) the journal already holds."""


class NullJournal:
    """The journal of a service that keeps none (``journal=False``): records nothing.

    It has exactly :class:`Journal`'s writing and life-cycle methods, each doing
    nothing, so a misspelt call fails with ``AttributeError`` as it would on a real
    journal (``tests/framework/test_null_journal.py`` holds the two to one interface).
    """

    enabled = False

    def record_process(
        self,
        *,
        sender: str,
        identifier: int,
        sender_instance: str,
        recipient_instance: str,
        command: str,
        option: str,
        command_type: str,
        input_summary: str,
        received_ns: int,
        state: str,
        reason: str = "",
    ) -> None:
        """Nothing recorded."""

    def record_update(
        self, sender: str, identifier: int, seq: int, state: str, reason: str, data: str
    ) -> None:
        """Nothing recorded."""

    def record_rejection(
        self,
        sender: str | None,
        identifier: int | None,
        command: str | None,
        size: int,
        reason: str,
    ) -> None:
        """Nothing recorded."""

    def commit(self) -> None:
        """Nothing to make durable."""

    def settle(self) -> None:
        """Nothing to move."""

    def recover(self, reason: str) -> int:
        """No earlier incarnation's processes: none recovered."""
        return 0

    def close(self) -> None:
        """Nothing to close."""


class Journal:
    """The journal of one service (written from its event loop only).

    Rows go first to the journal's log (``<service>.sqlite.log``, one ``write`` per
    :meth:`commit`: :mod:`.journal_log`), then, in the background and at most every
    :data:`MOVE_PERIOD_S` while commits come, into the SQLite database in one
    transaction per batch; opening a journal moves whatever its last incarnation left in
    the log.  The readers (:func:`read_journal`, the cell controller's tail) read the
    database and the part of the log not moved yet.
    """

    enabled = True
    """(A service without a journal has a :class:`NullJournal`, whose ``enabled`` is False.)"""

    def __init__(self, path: Path, owner: str, *, durable: bool = False) -> None:
        self.path = path
        self.owner = owner
        path.parent.mkdir(parents=True, exist_ok=True)
        self._lock_fd = _lock(path)  # raises JournalInUseError
        try:
            self._db = _connect(path)
            self._db.execute(f"PRAGMA synchronous={'FULL' if durable else 'NORMAL'}")
            self._db.execute("PRAGMA wal_autocheckpoint=0")
            self._db.executescript(TABLES)
            self._db.execute(
                "INSERT OR IGNORE INTO meta VALUES ('schema_version', ?)", (str(SCHEMA_VERSION),)
            )
            self._db.commit()
            self._log = LogWriter(log_path(path), durable=durable)
            try:
                self._take_over_log()
            except BaseException:
                self._log.close(delete=False)
                raise
        except BaseException:
            if hasattr(self, "_db"):
                self._db.close()
            if self._lock_fd is not None:
                os.close(self._lock_fd)
            raise
        self._rows: list[Row] = []
        """Recorded since the last :meth:`commit`."""
        self._moving: deque[tuple[int, int, list[Row]]] = deque()
        """Committed (in the log), not yet in the database: (generation of the log, offset
        after the record, its rows)."""
        self._highest: dict[str, int] = {}
        """The highest identifier journaled per sender (identifiers only grow)."""
        self._encoder = msgspec.msgpack.Encoder()
        self._log_lock = threading.Lock()
        """Held while the log or :attr:`_moving` changes."""
        self._move_lock = threading.Lock()
        """Held while rows move into the database (or the log restarts)."""
        self._stop = threading.Event()
        self._written = threading.Event()
        """Set by each commit, cleared by the mover: an idle journal sleeps."""
        self._mover = threading.Thread(
            target=self._move_loop, name=f"journal-{owner}", daemon=True
        )
        self._mover.start()

    # -- writing ---------------------------------------------------------------------

    def record_process(
        self,
        *,
        sender: str,
        identifier: int,
        sender_instance: str,
        recipient_instance: str,
        command: str,
        option: str,
        command_type: str,
        input_summary: str,
        received_ns: int,
        state: str,
        reason: str = "",
    ) -> None:
        """A process accepted (Queued) or refused (Failed) by this service.

        Commit before acknowledging it.  Its later states are its updates.  Raises
        :class:`DuplicateProcessError` if the journal holds this (sender, identifier).
        """
        highest = self._highest.get(sender)
        if highest is None:
            highest = self._highest_in_database(sender)
        if highest is not None and identifier <= highest and self._holds(sender, identifier):
            raise DuplicateProcessError(
                f"process {identifier} from {sender} is already in the journal"
            )
        self._highest[sender] = identifier if highest is None else max(highest, identifier)
        self._rows.append((PROCESS, [
            self.owner, sender, identifier, recipient_instance, sender_instance, command,
            option, command_type, input_summary, received_ns, time.time_ns(), state, reason,
        ]))

    def record_update(
        self, sender: str, identifier: int, seq: int, state: str, reason: str, data: str
    ) -> None:
        """One ProcessUpdate (written by the next :meth:`commit`)."""
        self._rows.append(
            (UPDATE, [self.owner, sender, identifier, seq, time.time_ns(), state, reason, data])
        )

    def record_rejection(
        self,
        sender: str | None,
        identifier: int | None,
        command: str | None,
        size: int,
        reason: str,
    ) -> None:
        """A CreateProcess refused before it became a process."""
        self._rows.append(
            (REJECTION, [self.owner, time.time_ns(), sender, identifier, command, size, reason])
        )

    def commit(self) -> None:
        """Make everything recorded so far durable: one append to the log."""
        if self._db.in_transaction:  # written directly (recovery)
            self._db.commit()
        if not self._rows:
            return
        rows, self._rows = self._rows, []
        record = encode(rows, self._encoder)
        with self._log_lock:
            try:
                end = self._log.append(record)
            except BaseException:  # a full disk: the rows wait for the next commit
                self._rows[:0] = rows
                raise
            self._moving.append((self._log.generation, end, rows))
        self._written.set()

    def settle(self) -> None:
        """Commit, and move every committed row into the database now (rather than
        within :data:`MOVE_PERIOD_S`)."""
        self.commit()
        self._move(self._db)

    def _highest_in_database(self, sender: str) -> int | None:
        """At a sender's first process in this incarnation: its highest identifier so far
        (everything earlier incarnations wrote was moved into the database at opening)."""
        row = self._db.execute(
            "SELECT MAX(identifier) FROM processes WHERE recipient = ? AND sender = ?",
            (self.owner, sender),
        ).fetchone()
        return row[0] if row else None

    def _holds(self, sender: str, identifier: int) -> bool:
        """Whether (sender, identifier) is journaled: an identifier that does not grow, so
        rare that it may move everything into the database first and look it up there."""
        self.settle()
        return self._db.execute(
            "SELECT 1 FROM processes WHERE recipient = ? AND sender = ? AND identifier = ?",
            (self.owner, sender, identifier),
        ).fetchone() is not None

    # -- moving rows from the log into the database --------------------------------------

    def _take_over_log(self) -> None:
        """At opening: move what the log holds beyond the database's mark (the rows of an
        incarnation that died), then start the log afresh."""
        mark = _log_mark(self._db)
        found = read_log(self._log.path, mark[1] if mark is not None else None)
        if found is not None and mark is not None and found.generation != mark[0]:
            found = read_log(self._log.path)  # restarted after the mark: all of it is new
        if found is not None:
            _insert(self._db, found.rows)
            _set_log_mark(self._db, found.generation, found.end)
            self._db.commit()
        generation = self._log.restart()  # the file first: a crash here re-reads it
        _set_log_mark(self._db, generation, HEADER.size)
        self._db.commit()

    def _move(self, db: sqlite3.Connection) -> None:
        """Move the committed rows into the database, with the log's mark, in one
        transaction; on an error they stay in the log and in memory for the next try."""
        with self._move_lock:
            with self._log_lock:
                batch = list(self._moving)
            if not batch:
                return
            try:
                _insert(db, [row for _, _, rows in batch for row in rows])
                generation, end, _ = batch[-1]
                _set_log_mark(db, generation, end)
                db.commit()
            except BaseException:
                db.rollback()
                raise
            with self._log_lock:
                for _ in batch:
                    self._moving.popleft()

    def _restart_log_if_long(self, db: sqlite3.Connection) -> None:
        """Empty the log once it is :data:`LOG_RESTART_BYTES` long and all moved."""
        if self._log.size < LOG_RESTART_BYTES:
            return
        with self._move_lock, self._log_lock:
            if self._moving or self._log.size < LOG_RESTART_BYTES:
                return
            generation = self._log.restart()
            _set_log_mark(db, generation, HEADER.size)
            db.commit()

    def _move_loop(self) -> None:
        """Move the rows into the database at most every :data:`MOVE_PERIOD_S` while
        commits come, and checkpoint the WAL (PASSIVE: never blocking a writer) at most
        every :data:`CHECKPOINT_PERIOD_S`; while none come, sleep: an idle journal does
        not wake its process."""
        db = _connect(self.path)
        checkpointed = time.monotonic()
        try:
            while True:
                self._written.wait()
                if self._stop.wait(MOVE_PERIOD_S):
                    break  # close() moves the rest
                self._written.clear()
                try:
                    self._move(db)
                    self._restart_log_if_long(db)
                    if time.monotonic() - checkpointed >= CHECKPOINT_PERIOD_S:
                        db.execute("PRAGMA wal_checkpoint(PASSIVE)")
                        checkpointed = time.monotonic()
                except (sqlite3.Error, OSError) as exc:  # the rows stay in the log: retried
                    log.warning("journal %s: moving rows into the database: %s", self.path, exc)
                    self._written.set()
        finally:
            db.close()

    # -- start-up and shutdown -------------------------------------------------------

    def recover(self, reason: str) -> int:
        """Close processes a previous incarnation left unfinished with a Failed update.

        One pass over the updates (grouped per process), not a lookup per process:
        the ``updates`` table has no index (see :data:`SCHEMA_VERSION`).  The pass
        starts where the last recovery ended (``meta.recovered_through``: every
        process up to there has finished), so a start-up reads only what the
        previous incarnation wrote, however long the journal.
        """
        self.settle()
        with self._move_lock:
            mark = self._db.execute(
                "SELECT value FROM meta WHERE key = 'recovered_through'"
            ).fetchone()
            last_process, last_update = _recovery_mark(mark[0] if mark else None)
            cur = self._db.execute(
                "INSERT INTO updates SELECT p.recipient, p.sender, p.identifier,"
                " COALESCE(l.seq, 0) + 1, :t, 'Failed', :reason, '' FROM processes p"
                " LEFT JOIN (SELECT sender, identifier, MAX(seq) AS seq,"
                " MAX(state IN ('Completed', 'Failed')) AS ended FROM updates"
                " WHERE rowid > :u AND recipient = :owner GROUP BY sender, identifier) l"
                " ON l.sender = p.sender AND l.identifier = p.identifier"
                " WHERE p.rowid > :p AND p.recipient = :owner AND p.state = 'Queued'"
                " AND COALESCE(l.ended, 0) = 0",
                {"t": time.time_ns(), "reason": reason, "owner": self.owner,
                 "p": last_process, "u": last_update},
            )
            recovered = cur.rowcount
            self._db.execute(
                "INSERT OR REPLACE INTO meta SELECT 'recovered_through',"
                " (SELECT COALESCE(MAX(rowid), 0) FROM processes) || ' ' ||"
                " (SELECT COALESCE(MAX(rowid), 0) FROM updates)"
            )
            self._db.commit()
        return recovered

    def close(self) -> None:
        """Commit, move everything into the database, checkpoint and close; the log
        file goes once it is all in the database."""
        self._stop.set()
        self._written.set()  # wake the mover so that it sees the stop
        self._mover.join(timeout=5)
        moved = False
        try:
            self.settle()
            moved = True
            self._db.execute("PRAGMA wal_checkpoint(TRUNCATE)")
        except (sqlite3.Error, OSError) as exc:
            log.warning("journal %s: closing: %s (what is committed stays in its log)",
                        self.path, exc)
        finally:
            self._log.close(delete=moved)
            self._db.close()
            if self._lock_fd is not None:
                os.close(self._lock_fd)  # releases the lock
                self._lock_fd = None


_INSERTS = {
    PROCESS: "INSERT OR IGNORE INTO processes (recipient, sender, identifier,"
    " recipient_instance, sender_instance, command, option, command_type, input,"
    " received_ns, acked_ns, state, reason) VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?)",
    UPDATE: "INSERT INTO updates VALUES (?,?,?,?,?,?,?,?)",
    REJECTION: "INSERT INTO rejections VALUES (?,?,?,?,?,?,?)",
}
"""Per row kind.  ``OR IGNORE``: :meth:`Journal.record_process` refuses a duplicate
before it reaches the log, and a row that reached it anyway must not stop the rows
after it from moving."""

_COLUMNS = {
    PROCESS: ("recipient", "sender", "identifier", "recipient_instance", "sender_instance",
              "command", "option", "command_type", "input", "received_ns", "acked_ns",
              "state", "reason"),
    UPDATE: ("recipient", "sender", "identifier", "seq", "t_ns", "state", "reason", "data"),
    REJECTION: ("recipient", "t_ns", "sender", "identifier", "command", "size", "reason"),
}
"""The columns of each kind's row, as ``SELECT *`` names them."""


def _insert(db: sqlite3.Connection, rows: list[Row]) -> None:
    """Insert log rows, each table's in their log order (inside the current transaction)."""
    by_kind: dict[int, list[list[Any]]] = {kind: [] for kind in _INSERTS}
    for kind, row in rows:
        by_kind[kind].append(row)
    for kind, sql in _INSERTS.items():
        if by_kind[kind]:
            db.executemany(sql, by_kind[kind])


def _log_mark(db: sqlite3.Connection) -> tuple[int, int] | None:
    """``meta.log_moved``: the log's generation and the offset up to which its rows are
    in the database (None if never written or unreadable: then nothing of the log is)."""
    row = db.execute("SELECT value FROM meta WHERE key = 'log_moved'").fetchone()
    parts = row[0].split() if row and isinstance(row[0], str) else []
    if len(parts) == 2 and all(p.isascii() and p.isdigit() for p in parts):
        return int(parts[0]), int(parts[1])
    return None


def _set_log_mark(db: sqlite3.Connection, generation: int, offset: int) -> None:
    db.execute(
        "INSERT OR REPLACE INTO meta VALUES ('log_moved', ?)", (f"{generation} {offset}",)
    )


def unmoved_rows(database: Path, mark: tuple[int, int] | None) -> list[Row] | None:
    """The rows of ``database``'s log that are not in it as of ``mark`` (read in the same
    snapshot); None when the log restarted after that snapshot (read again)."""
    found = read_log(log_path(database), mark[1] if mark is not None else None)
    if found is None:
        return []
    if mark is not None and mark[0] != found.generation:
        return None  # read from an offset of another generation: nothing of it counts
    return found.rows


def snapshot(
    db: sqlite3.Connection, database: Path, read: Callable[[sqlite3.Connection], _T]
) -> tuple[_T, list[Row]]:
    """``read(db)`` and the log rows not in the database, both of one moment.

    ``read`` runs in one read transaction with the log's mark; the log is read after it.
    Should the log restart in between (its rows all moved), the snapshot is taken again;
    if it still disagrees after a few tries — the writer died between restarting the log
    and marking it — every row of the log is new.
    """
    for _ in range(5):
        db.execute("BEGIN")
        try:
            result = read(db)
            mark = _log_mark(db)
        finally:
            db.rollback()
        rows = unmoved_rows(database, mark)
        if rows is not None:
            return result, rows
        time.sleep(0.01)
    found = read_log(log_path(database))
    return result, found.rows if found is not None else []


def as_dict(kind: int, row: list[Any]) -> dict[str, Any]:
    """A log row as the dictionary ``SELECT *`` of its table gives."""
    return dict(zip(_COLUMNS[kind], row, strict=True))


def _recovery_mark(value: object) -> tuple[int, int]:
    """The rowids of ``meta.recovered_through`` (``"<process> <update>"``); a missing or
    unreadable mark reads as (0, 0): recovery then passes over everything, which is
    always right, only slower."""
    parts = value.split() if isinstance(value, str) else []
    if len(parts) == 2 and all(p.isascii() and p.isdigit() for p in parts):
        rowids = int(parts[0]), int(parts[1])
        if max(rowids) < 2**63:  # SQLite's largest rowid
            return rowids
    return 0, 0


def _connect(path: Path) -> sqlite3.Connection:
    db = sqlite3.connect(path, check_same_thread=False, timeout=10.0)
    db.execute("PRAGMA journal_mode=WAL")
    db.execute("PRAGMA busy_timeout=10000")
    return db


# -- reading ---------------------------------------------------------------------------


def journal_files(cell: str, home: Path | None = None) -> list[Path]:
    """The journal files of ``cell`` on this machine."""
    folder = journal_dir(cell, home)
    return sorted(folder.glob("*.sqlite")) if folder.is_dir() else []


def read_journal(paths: Iterable[Path]) -> list[dict[str, Any]]:
    """All processes of the given journals, oldest first, each with its updates.

    A process's ``state``, ``reason`` and ``finished_ns`` are those of its last
    update (``Queued`` if it has none); refused requests have ``rejected: True``.
    Rows still in a journal's log (committed, not yet moved into its database) are
    included.
    """
    out: list[dict[str, Any]] = []
    for path in paths:
        db = sqlite3.connect(path, timeout=10.0)
        db.row_factory = sqlite3.Row
        try:
            tables, unmoved = snapshot(db, path, _read_tables)
        finally:
            db.close()
        procs, updates, rejections = tables
        for kind, row in unmoved:
            {PROCESS: procs, UPDATE: updates, REJECTION: rejections}[kind].append(
                as_dict(kind, row)
            )
        by_key: dict[tuple[str, str, int], list[dict[str, Any]]] = {}
        for row in sorted(updates, key=lambda u: u["seq"]):
            key = (row.pop("recipient"), row.pop("sender"), row.pop("identifier"))
            by_key.setdefault(key, []).append(row)
        for p in procs:
            p_updates = by_key.get((p["recipient"], p["sender"], p["identifier"]), [])
            p["updates"] = p_updates
            if p_updates:
                last = p_updates[-1]
                p["state"], p["reason"] = last["state"], last["reason"]
                if last["state"] in ("Completed", "Failed"):
                    p["finished_ns"] = last["t_ns"]
            elif p["state"] == "Failed":
                p["finished_ns"] = p["acked_ns"]
        for row in rejections:
            out.append(
                {
                    "recipient": row["recipient"],
                    "sender": row["sender"],
                    "identifier": row["identifier"],
                    "command": row["command"],
                    "received_ns": row["t_ns"],
                    "state": "Failed",
                    "reason": row["reason"],
                    "rejected": True,
                    "updates": [],
                }
            )
        out.extend(procs)
    out.sort(key=lambda p: p.get("received_ns") or 0)
    return out


def _read_tables(
    db: sqlite3.Connection,
) -> tuple[list[dict[str, Any]], list[dict[str, Any]], list[dict[str, Any]]]:
    return (
        [dict(r) for r in db.execute("SELECT * FROM processes")],
        [dict(r) for r in db.execute("SELECT * FROM updates")],
        [dict(r) for r in db.execute("SELECT * FROM rejections")],
    )
