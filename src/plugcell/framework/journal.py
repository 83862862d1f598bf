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

WAL with ``synchronous=NORMAL`` survives the death of the process (the OS has the
pages); use ``durable=True`` (``synchronous=FULL``) to survive a power cut too.
Checkpoints run in a background thread so a commit never stalls on one.  Only
a summary of the data (type, size, and the values if small) is stored.
"""

from __future__ import annotations

import contextlib
import os
import sqlite3
import threading
import time
from collections.abc import Iterable
from pathlib import Path
from typing import Any

#: Seconds between two WAL checkpoints while commits come (none while idle).
CHECKPOINT_PERIOD_S = 0.5

SCHEMA_VERSION = 2
"""2: ``updates`` has no primary key (version 1 had one on (recipient, sender,
identifier, seq)).  Its b-tree cost every row a second insert — a quarter of what
a streamed frame costs the service (``benchmarks/journal.py``); the service makes
each ``seq`` unique by construction, and the readers look updates up by scanning
once (:meth:`Journal.recover`, the controller's tail) or merge them in Python
(:func:`read_journal`).  Both versions are read and written alike."""
_SCHEMA = """
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


class Journal:
    """The journal of one service (written from its event loop only)."""

    enabled = True
    """(A service without a journal has a stand-in whose ``enabled`` is False.)"""

    def __init__(self, path: Path, owner: str, *, durable: bool = False) -> None:
        self.path = path
        self.owner = owner
        path.parent.mkdir(parents=True, exist_ok=True)
        self._lock_fd = _lock(path)  # raises JournalInUseError
        try:
            self._db = _connect(path)
            self._db.execute(f"PRAGMA synchronous={'FULL' if durable else 'NORMAL'}")
            self._db.execute("PRAGMA wal_autocheckpoint=0")
            self._db.executescript(_SCHEMA)
            self._db.execute(
                "INSERT OR IGNORE INTO meta VALUES ('schema_version', ?)", (str(SCHEMA_VERSION),)
            )
        except BaseException:
            if self._lock_fd is not None:
                os.close(self._lock_fd)
            raise
        self._pending: list[tuple[Any, ...]] = []
        self._stop = threading.Event()
        self._written = threading.Event()
        """Set by each commit, cleared by the checkpointer: an idle journal sleeps."""
        self._checkpointer = threading.Thread(
            target=self._checkpoint_loop, name=f"journal-checkpoint-{owner}", daemon=True
        )
        self._checkpointer.start()

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

        Commit before acknowledging it.  Its later states are its updates.
        """
        self._db.execute(
            "INSERT INTO processes (recipient, sender, identifier, recipient_instance,"
            " sender_instance, command, option, command_type, input, received_ns, acked_ns,"
            " state, reason) VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?)",
            (
                self.owner,
                sender,
                identifier,
                recipient_instance,
                sender_instance,
                command,
                option,
                command_type,
                input_summary,
                received_ns,
                time.time_ns(),
                state,
                reason,
            ),
        )

    def record_update(
        self, sender: str, identifier: int, seq: int, state: str, reason: str, data: str
    ) -> None:
        """One ProcessUpdate (queued; written by the next :meth:`commit`)."""
        self._pending.append(
            (self.owner, sender, identifier, seq, time.time_ns(), state, reason, data)
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
        self._db.execute(
            "INSERT INTO rejections VALUES (?,?,?,?,?,?,?)",
            (self.owner, time.time_ns(), sender, identifier, command, size, reason),
        )

    def flush(self) -> None:
        """Write queued update rows (inside the current transaction)."""
        if self._pending:
            rows, self._pending = self._pending, []
            self._db.executemany("INSERT INTO updates VALUES (?,?,?,?,?,?,?,?)", rows)

    def commit(self) -> None:
        """Make everything recorded so far durable."""
        self.flush()
        if self._db.in_transaction:
            self._db.commit()
            self._written.set()

    def recover(self, reason: str) -> int:
        """Close processes a previous incarnation left unfinished with a Failed update.

        One pass over the updates (grouped per process), not a lookup per process:
        the ``updates`` table has no index (see :data:`SCHEMA_VERSION`).  The pass
        starts where the last recovery ended (``meta.recovered_through``: every
        process up to there has finished), so a start-up reads only what the
        previous incarnation wrote, however long the journal.
        """
        self.commit()
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
        """Commit, checkpoint and close."""
        self._stop.set()
        self._written.set()  # wake the checkpointer so that it sees the stop
        self._checkpointer.join(timeout=5)
        with contextlib.suppress(sqlite3.Error):
            self.commit()
            self._db.execute("PRAGMA wal_checkpoint(TRUNCATE)")
        self._db.close()
        if self._lock_fd is not None:
            os.close(self._lock_fd)  # releases the lock
            self._lock_fd = None

    def _checkpoint_loop(self) -> None:
        """Copy the WAL back into the database (a PASSIVE checkpoint, never blocking a
        writer) at most every :data:`CHECKPOINT_PERIOD_S` while commits come, and not at
        all while none do: an idle service's journal does not wake its process."""
        db = _connect(self.path)
        try:
            while True:
                self._written.wait()
                if self._stop.wait(CHECKPOINT_PERIOD_S):
                    break
                self._written.clear()
                with contextlib.suppress(sqlite3.Error):
                    db.execute("PRAGMA wal_checkpoint(PASSIVE)")
        finally:
            db.close()


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
    """
    out: list[dict[str, Any]] = []
    for path in paths:
        db = sqlite3.connect(path, timeout=10.0)
        db.row_factory = sqlite3.Row
        try:
            procs = [dict(r) for r in db.execute("SELECT * FROM processes")]
            by_key: dict[tuple[str, str, int], list[dict[str, Any]]] = {}
            for r in db.execute("SELECT * FROM updates ORDER BY seq"):
                row = dict(r)
                key = (row.pop("recipient"), row.pop("sender"), row.pop("identifier"))
                by_key.setdefault(key, []).append(row)
            for p in procs:
                updates = by_key.get((p["recipient"], p["sender"], p["identifier"]), [])
                p["updates"] = updates
                if updates:
                    last = updates[-1]
                    p["state"], p["reason"] = last["state"], last["reason"]
                    if last["state"] in ("Completed", "Failed"):
                        p["finished_ns"] = last["t_ns"]
                elif p["state"] == "Failed":
                    p["finished_ns"] = p["acked_ns"]
            for r in db.execute("SELECT * FROM rejections"):
                row = dict(r)
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
        finally:
            db.close()
    out.sort(key=lambda p: p.get("received_ns") or 0)
    return out
