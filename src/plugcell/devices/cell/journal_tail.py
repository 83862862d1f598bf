"""Reading the journals of the cell's services as they grow (thesis 7.6, Figure 7-11).

Each service on this host journals every process it accepts *before* it
acknowledges it (``framework/journal.py``).  No notification announces a process
that waits in a queue, so the cell controller tails the journals to show the
queued processes and the queue length of each shared device.  Reads are
incremental (by SQLite ``rowid``), read-only in effect, and never block a writer
(WAL).  Services on other hosts are simply not seen here; the live notifications
still show their processes once they run.
"""

from __future__ import annotations

import contextlib
import sqlite3
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from plugcell.framework.journal import journal_dir

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
        db = f.db
        if not f.started:
            top = db.execute("SELECT COALESCE(MAX(rowid), 0) FROM processes").fetchone()[0]
            f.last_process = max(0, top - HISTORY)
            first = db.execute(
                "SELECT MIN(rowid) FROM updates WHERE (recipient, sender, identifier) IN"
                " (SELECT recipient, sender, identifier FROM processes WHERE rowid > ?)",
                (f.last_process,),
            ).fetchone()[0]
            f.last_update = (first - 1) if first else db.execute(
                "SELECT COALESCE(MAX(rowid), 0) FROM updates").fetchone()[0]
            f.started = True
        rows = db.execute(
            "SELECT rowid, recipient, sender, identifier, command, option, command_type,"
            " received_ns, state, reason FROM processes WHERE rowid > ? ORDER BY rowid",
            (f.last_process,),
        ).fetchall()
        for r in rows:
            f.last_process = r["rowid"]
            processes.append(dict(r))
        rows = db.execute(
            "SELECT rowid, recipient, sender, identifier, seq, t_ns, state, reason, data"
            " FROM updates WHERE rowid > ? ORDER BY rowid",
            (f.last_update,),
        ).fetchall()
        for r in rows:
            f.last_update = r["rowid"]
            updates.append(dict(r))

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
