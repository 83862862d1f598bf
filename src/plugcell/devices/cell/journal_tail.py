"""Reading the journals of the cell's services as they grow (thesis 7.6, Figure 7-11).

Each service on this host journals every process it accepts *before* it
acknowledges it (``framework/journal.py``).  No notification announces a process
that waits in a queue, so the cell controller tails the journals to show the
queued processes and the queue length of each shared device.  Reads are
incremental (by SQLite ``rowid``), read-only in effect, and never block a writer
(WAL); each also reads the rows still in the journal's log (committed, not yet moved
into the database) and skips them when they reach the database.  Services on other
hosts are simply not seen here; the live notifications still show their processes
once they run.
"""

from __future__ import annotations

import contextlib
import sqlite3
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from plugcell.framework.journal import as_dict, journal_dir, snapshot
from plugcell.framework.journal_log import PROCESS, UPDATE

#: Processes read from each journal at the first poll (history shown on start-up).
HISTORY = 200

__all__ = ["JournalTail"]


@dataclass
class _File:
    path: Path
    db: sqlite3.Connection | None = None
    last_process: int = 0
    last_update: int = 0
    started: bool = False
    from_log: set[tuple[Any, ...]] = field(default_factory=set)
    """Keys of the rows taken from the log (shown or passed over) and not yet seen in
    the database."""


@dataclass
class JournalTail:
    """Incremental reader of ``<home>/cells/<cell>/journal/*.sqlite``."""

    cell: str
    home: Path | None = None
    files: dict[Path, _File] = field(default_factory=dict)
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False)
    """:meth:`poll` runs in a worker thread; :meth:`close` must not close a
    connection under it (sqlite3 with ``check_same_thread=False`` would crash)."""

    @property
    def folder(self) -> Path:
        return journal_dir(self.cell, self.home)

    def poll(self) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
        """New process rows and new update rows since the last poll, of every journal."""
        with self._lock:
            return self._poll()

    def _poll(self) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
        processes: list[dict[str, Any]] = []
        updates: list[dict[str, Any]] = []
        folder = self.folder
        if not folder.is_dir():
            return processes, updates
        for path in sorted(folder.glob("*.sqlite")):
            f = self.files.get(path)
            if f is None:
                f = self.files[path] = _File(path)
            try:
                self._poll_file(f, processes, updates)
            except sqlite3.Error:  # a journal being created, or damaged: try again later
                self._close(f)
        return processes, updates

    def _poll_file(
        self, f: _File, processes: list[dict[str, Any]], updates: list[dict[str, Any]]
    ) -> None:
        if f.db is None:
            f.db = sqlite3.connect(f"file:{f.path}?mode=ro", uri=True, timeout=0.5,
                                   check_same_thread=False)
            f.db.row_factory = sqlite3.Row
        (last_process, last_update, db_processes, db_updates), unmoved = snapshot(
            f.db, f.path, lambda db: self._read_database(f, db)
        )
        f.last_process = db_processes[-1]["rowid"] if db_processes else last_process
        f.last_update = db_updates[-1]["rowid"] if db_updates else last_update
        log_rows = [(kind, as_dict(kind, row)) for kind, row in unmoved
                    if kind in (PROCESS, UPDATE)]
        if not f.started:
            f.started = True
            db_processes, db_updates = _history(f, db_processes, db_updates, log_rows)
        for row in db_processes:
            _show_once(f, _process_key(row), row, processes, from_log=False)
        for row in db_updates:
            _show_once(f, _update_key(row), row, updates, from_log=False)
        for kind, row in log_rows:
            if kind == PROCESS:
                _show_once(f, _process_key(row), row, processes, from_log=True)
            else:
                _show_once(f, _update_key(row), row, updates, from_log=True)

    @staticmethod
    def _read_database(
        f: _File, db: sqlite3.Connection
    ) -> tuple[int, int, list[dict[str, Any]], list[dict[str, Any]]]:
        """The rows after the file's marks — at the first poll, the last :data:`HISTORY`
        processes with every update from the first of theirs on — and the marks they
        follow (read in one snapshot; the caller moves the marks)."""
        last_process, last_update = f.last_process, f.last_update
        if not f.started:
            top = db.execute("SELECT COALESCE(MAX(rowid), 0) FROM processes").fetchone()[0]
            last_process = max(0, top - HISTORY)
            first = db.execute(
                "SELECT MIN(rowid) FROM updates WHERE (recipient, sender, identifier) IN"
                " (SELECT recipient, sender, identifier FROM processes WHERE rowid > ?)",
                (last_process,),
            ).fetchone()[0]
            last_update = (first - 1) if first else db.execute(
                "SELECT COALESCE(MAX(rowid), 0) FROM updates").fetchone()[0]
        new_processes = [dict(r) for r in db.execute(
            "SELECT rowid, recipient, sender, identifier, command, option, command_type,"
            " received_ns, state, reason FROM processes WHERE rowid > ? ORDER BY rowid",
            (last_process,),
        )]
        new_updates = [dict(r) for r in db.execute(
            "SELECT rowid, recipient, sender, identifier, seq, t_ns, state, reason, data"
            " FROM updates WHERE rowid > ? ORDER BY rowid",
            (last_update,),
        )]
        return last_process, last_update, new_processes, new_updates

    @staticmethod
    def _close(f: _File) -> None:
        if f.db is not None:
            with contextlib.suppress(sqlite3.Error):
                f.db.close()
        f.db = None

    def close(self) -> None:
        """Close every journal (after a poll under way in another thread ends)."""
        with self._lock:
            for f in self.files.values():
                self._close(f)
            self.files.clear()


def _process_key(row: dict[str, Any]) -> tuple[Any, ...]:
    return ("process", row["recipient"], row["sender"], row["identifier"])


def _update_key(row: dict[str, Any]) -> tuple[Any, ...]:
    return ("update", row["recipient"], row["sender"], row["identifier"], row["seq"])


def _show_once(f: _File, key: tuple[Any, ...], row: dict[str, Any],
               shown: list[dict[str, Any]], *, from_log: bool) -> None:
    """Show a row the first time it is read: from the log, or from the database unless
    it was read from the log before."""
    if from_log:
        if key not in f.from_log:
            f.from_log.add(key)
            shown.append(row)
    elif key in f.from_log:
        f.from_log.discard(key)
    else:
        shown.append(row)


def _history(
    f: _File,
    db_processes: list[dict[str, Any]],
    db_updates: list[dict[str, Any]],
    log_rows: list[tuple[int, dict[str, Any]]],
) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """At the first poll, over the database's rows followed by the log's: keep the last
    :data:`HISTORY` processes and the updates from the first of theirs on.  Returns the
    database rows kept; the log rows passed over go into ``f.from_log`` (never shown)."""
    log_processes = [row for kind, row in log_rows if kind == PROCESS]
    log_updates = [row for kind, row in log_rows if kind == UPDATE]
    everything = db_processes + log_processes
    kept = everything[len(everything) - HISTORY:] if HISTORY else []
    cut = len(everything) - len(kept)
    for row in log_processes[: max(0, cut - len(db_processes))]:
        f.from_log.add(_process_key(row))
    history = {(p["recipient"], p["sender"], p["identifier"]) for p in kept}
    updates = db_updates + log_updates
    first = next((i for i, u in enumerate(updates)
                  if (u["recipient"], u["sender"], u["identifier"]) in history), len(updates))
    for row in log_updates[: max(0, first - len(db_updates))]:
        f.from_log.add(_update_key(row))
    return db_processes[min(cut, len(db_processes)):], db_updates[first:]
