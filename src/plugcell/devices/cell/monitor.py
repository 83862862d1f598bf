"""The process monitor of the cell controller (thesis 7.6, Figure 7-11).

"When the robot executes the given robot program, it will generate and send
multiple processes to its peripheral devices.  The cell controller monitors and
visualizes the evolution of the generated processes, including their statuses and
data."  :class:`ProcessMonitor` keeps one :class:`ProcessRecord` per process of the
cell — who asked whom (the Tag of F.7), the command, its state, when it was
received, started and ended, how many data updates it produced and the last data —
fed from three sources, merged by ``(recipient, sender, identifier)``:

* every ProcessUpdate of the cell (``svc/*/process/*``, live, any host);
* the processes the controller itself created (their acknowledgements);
* the journals of the services on this host (``journal.py``): they also show the
  processes still **queued**, which no notification announces — hence the queue
  length of each shared device (8.4.3: robots waiting for the tracker).

Pure bookkeeping, used from one event loop.
"""

from __future__ import annotations

import time
from collections import OrderedDict
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

from plugcell.framework.data import DataError, summary, to_json_value
from plugcell.framework.messages import Data, ProcessStates, ProcessUpdateNotification

#: Processes kept in memory; the oldest finished ones go first.
MAX_RECORDS = 5000
#: Most values of one update's data sent to the UI (a 6-vector, a few points …).
MAX_VALUES = 96

Key = tuple[str, str, int]
_ORDER = {"Queued": 0, "Running": 1, "Completed": 2, "Failed": 2}

__all__ = ["MonitorFeed", "ProcessMonitor", "ProcessRecord"]


@dataclass
class ProcessRecord:
    """One process as the controller sees it."""

    recipient: str
    sender: str
    identifier: int
    command: str = ""
    option: str = ""
    type: str = ""
    state: str = "Queued"
    reason: str = ""
    seq: int = 0
    received_ns: int = 0
    started_ns: int = 0
    ended_ns: int = 0
    frames: int = 0
    data: Any = None
    data_text: str = ""
    sources: set[str] = field(default_factory=set)

    @property
    def key(self) -> Key:
        return (self.recipient, self.sender, self.identifier)

    @property
    def final(self) -> bool:
        return self.state in ("Completed", "Failed")

    def duration(self, now_ns: int | None = None) -> float | None:
        """Seconds from received (or started) to ended, or to now while it is going on."""
        start = self.received_ns or self.started_ns
        if not start:
            return None
        end = self.ended_ns or (now_ns if now_ns is not None else time.time_ns())
        return max(0.0, (end - start) / 1e9)

    def to_json(self, now_ns: int | None = None) -> dict[str, Any]:
        return {
            "id": f"{self.recipient}/{self.sender}/{self.identifier}",
            "recipient": self.recipient,
            "sender": self.sender,
            "identifier": str(self.identifier),
            "command": self.command,
            "option": self.option,
            "type": self.type,
            "state": self.state,
            "reason": self.reason,
            "seq": self.seq,
            "receivedNs": self.received_ns,
            "startedNs": self.started_ns,
            "endedNs": self.ended_ns,
            "duration": self.duration(now_ns),
            "frames": self.frames,
            "data": self.data,
            "dataText": self.data_text,
        }


def data_view(data: Data | None) -> tuple[Any, str]:
    """The data of an update for people: small values in full, else a summary."""
    if data is None:
        return None, ""
    try:
        value = to_json_value(data, max_items=MAX_VALUES)
    except (DataError, ValueError, TypeError):
        value = None
    return value, summary(data, limit=8)


class ProcessMonitor:
    """Every process of the cell, merged from notifications, acknowledgements and journals."""

    def __init__(self, max_records: int = MAX_RECORDS) -> None:
        self.records: OrderedDict[Key, ProcessRecord] = OrderedDict()
        self.max_records = max_records

    def _record(self, recipient: str, sender: str, identifier: int) -> ProcessRecord:
        key = (recipient, sender, identifier)
        record = self.records.get(key)
        if record is None:
            record = ProcessRecord(recipient, sender, identifier)
            self.records[key] = record
            self._trim()
        return record

    def _trim(self) -> None:
        if len(self.records) <= self.max_records:
            return
        for key in [k for k, r in self.records.items() if r.final]:
            if len(self.records) <= self.max_records:
                return
            del self.records[key]
        while len(self.records) > self.max_records:  # all still running: drop the oldest
            self.records.popitem(last=False)

    @staticmethod
    def _advance(record: ProcessRecord, state: str, t_ns: int) -> bool:
        """Move ``record`` to ``state`` unless it is already further on."""
        if record.final or _ORDER.get(state, 0) < _ORDER.get(record.state, 0):
            return False
        record.state = state
        if state == "Running" and not record.started_ns:
            record.started_ns = t_ns
        if state in ("Completed", "Failed"):
            record.ended_ns = record.ended_ns or t_ns
            if not record.started_ns and state == "Completed":
                record.started_ns = t_ns
        return True

    # -- inputs --------------------------------------------------------------------------

    def created(
        self,
        recipient: str,
        sender: str,
        identifier: int,
        *,
        command: str = "",
        option: str = "",
        type: str = "",
        state: str = "Queued",
        reason: str = "",
        t_ns: int | None = None,
        source: str = "controller",
    ) -> ProcessRecord:
        """A process was created (an acknowledgement, or a journal row)."""
        t = t_ns or time.time_ns()
        record = self._record(recipient, sender, identifier)
        record.command = record.command or command
        record.option = record.option or option
        record.type = record.type or type
        if not record.received_ns or t < record.received_ns:
            record.received_ns = t
        if self._advance(record, state, t) and reason:
            record.reason = reason
        record.sources.add(source)
        return record

    def updated(
        self,
        recipient: str,
        update: ProcessUpdateNotification,
        t_ns: int | None = None,
        source: str = "live",
    ) -> ProcessRecord:
        """A ProcessUpdate of ``recipient`` (from the cell, or from a process of ours)."""
        t = t_ns or time.time_ns()
        record = self._record(recipient, update.tag.sender, update.identifier)
        record.sources.add(source)
        if update.seq and update.seq <= record.seq:
            return record
        record.seq = max(record.seq, update.seq)
        if update.data is not None:
            record.frames += 1
            record.data, record.data_text = data_view(update.data)
        if self._advance(record, update.state.value, t) and update.reason:
            record.reason = update.reason
        return record

    def journal_update(
        self, recipient: str, sender: str, identifier: int, seq: int, state: str,
        reason: str, data_text: str, t_ns: int,
    ) -> ProcessRecord | None:
        """An update row of a journal (a summary of the data, not the data).

        Only for a process already known (its journal row comes first): None otherwise.
        """
        record = self.records.get((recipient, sender, identifier))
        if record is None:
            return None
        record.sources.add("journal")
        if seq <= record.seq:
            return record
        record.seq = seq
        if data_text:
            record.data_text = data_text
            if state == "Running":
                record.frames += 1
        if self._advance(record, state, t_ns) and reason:
            record.reason = reason
        return record

    def from_journal(
        self, processes: Iterable[Mapping[str, Any]], updates: Iterable[Mapping[str, Any]]
    ) -> list[ProcessRecord]:
        """The rows a :class:`~plugcell.devices.cell.journal_tail.JournalTail` poll read:
        each process row is :meth:`created` (``source="journal"``), each update row a
        :meth:`journal_update`.

        Returns
        -------
        list of ProcessRecord
            The records the rows touched, in row order (processes first); an update of
            a process not known is left out.
        """
        touched = [
            self.created(
                p["recipient"], p["sender"], p["identifier"], command=p["command"] or "",
                option=p["option"] or "", type=p["command_type"] or "",
                state=p["state"], reason=p["reason"] or "", t_ns=p["received_ns"],
                source="journal",
            )
            for p in processes
        ]
        for u in updates:
            found = self.journal_update(
                u["recipient"], u["sender"], u["identifier"], u["seq"], u["state"],
                u["reason"] or "", u["data"] or "", u["t_ns"],
            )
            if found is not None:
                touched.append(found)
        return touched

    def service_lost(self, name: str, t_ns: int | None = None) -> list[ProcessRecord]:
        """``name`` left the cell: what it had not finished ends Failed (as its senders see)."""
        t = t_ns or time.time_ns()
        out = []
        for record in self.records.values():
            if record.recipient == name and not record.final:
                record.state = ProcessStates.Failed.value
                record.reason = record.reason or f"service {name} lost"
                record.ended_ns = t
                out.append(record)
        return out

    # -- outputs -------------------------------------------------------------------------

    def queues(self) -> dict[str, dict[str, Any]]:
        """Per service: the running process and the queued ones (oldest first)."""
        out: dict[str, dict[str, Any]] = {}
        for record in self.records.values():
            if record.final:
                continue
            q = out.setdefault(record.recipient, {"running": [], "queued": []})
            item = {"sender": record.sender, "command": record.command,
                    "identifier": str(record.identifier)}
            q["running" if record.state == "Running" else "queued"].append(item)
        for q in out.values():
            q["length"] = len(q["queued"])
        return out

    def snapshot(self, limit: int = 500) -> list[dict[str, Any]]:
        """The latest ``limit`` processes, oldest first."""
        now = time.time_ns()
        records = sorted(self.records.values(), key=lambda r: r.received_ns or r.started_ns)
        return [r.to_json(now) for r in records[-limit:]]

    def counts(self) -> dict[str, int]:
        out = {"Queued": 0, "Running": 0, "Completed": 0, "Failed": 0}
        for record in self.records.values():
            out[record.state] = out.get(record.state, 0) + 1
        return out


class MonitorFeed:
    """Which changes of the records a line-per-change feed (``plugcell cell monitor``)
    prints, and how many processes it has seen end.

    A record is printed when its state changes, and once more when its command becomes
    known (a ProcessUpdate does not name it; the journal row does, a little later).  A
    record without a command is held back up to ``hold_s`` for that row, then printed
    anyway.  ``history`` marks what was already there as printed.  ``service`` keeps
    only the processes it sent or received.  Pure bookkeeping with an injected clock.
    """

    def __init__(self, *, service: str | None = None, hold_s: float = 1.0,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.service = service
        self.hold_s = hold_s
        self.clock = clock
        self.ended = 0
        self._shown: dict[Key, tuple[str, str]] = {}
        self._held: dict[Key, float] = {}

    def history(self, records: Iterable[ProcessRecord]) -> None:
        """What ``records`` show now is past: never printed."""
        self._shown.update({r.key: (r.state, r.command) for r in records})

    def held(self) -> list[Key]:
        """The records waiting for their command (offer them again to release them)."""
        return list(self._held)

    def offer(self, record: ProcessRecord) -> bool:
        """Whether to print ``record`` now (it is then counted as shown)."""
        if self.service and self.service not in (record.sender, record.recipient):
            return False
        first_seen = self._held.setdefault(record.key, self.clock())
        if self.hold_s > 0 and not record.command and self.clock() - first_seen < self.hold_s:
            return False
        del self._held[record.key]
        before = self._shown.get(record.key)
        if before == (record.state, record.command):
            return False
        self._shown[record.key] = (record.state, record.command)
        if record.final and (before is None or before[0] != record.state):
            self.ended += 1
        return True
