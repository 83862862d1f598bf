"""The wiring of a cell, saved to a file and loaded again (thesis 7.6, Figure 7-9).

"The result of this service integration can be saved and loaded for the next run":
the wiring is the set of *wires* ``A → B`` — service A has B among its Partners
(Table 5-1), so A's programs can create processes at B.  The file is JSON::

    {"format": "plugcell-cell-wiring", "version": 1, "cell": "lab",
     "saved": "2025-01-01T12:00:00+00:00",
     "wires": [{"service": "ROBOT", "partner": "TRACKER"},
               {"service": "ROBOT", "partner": "COMPUTE"}]}

:class:`WiringKeeper` holds the wiring the operator wants and says which wires are
missing given who is alive and whose partners are what — the cell controller
re-applies those as services (re)appear.  Pure bookkeeping: no I/O but the file.
"""

from __future__ import annotations

import asyncio
import json
import time
from collections.abc import Awaitable, Callable, Iterable, Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from plugcell.framework.keys import check_name

FORMAT = "plugcell-cell-wiring"
VERSION = 1
#: Most wires a file may hold (a cell has tens of services, not thousands).
MAX_WIRES = 10_000
#: Seconds before a failed wire is tried again, doubling up to :data:`MAX_BACKOFF`.
FIRST_BACKOFF = 0.5
MAX_BACKOFF = 10.0

__all__ = [
    "FORMAT",
    "VERSION",
    "Wire",
    "WiringError",
    "WiringKeeper",
    "dump_wiring",
    "load_wiring",
    "parse_wiring",
    "read_wiring",
    "save_wiring",
    "wires_in_place",
]


class WiringError(ValueError):
    """A wiring file or wire that cannot be used; the message says why."""


@dataclass(frozen=True, order=True)
class Wire:
    """Service ``service`` has ``partner`` among its Partners."""

    service: str
    partner: str

    def __post_init__(self) -> None:
        try:
            check_name(self.service, "service name")
            check_name(self.partner, "partner name")
        except ValueError as exc:
            raise WiringError(str(exc)) from None
        if self.service == self.partner:
            raise WiringError(f"{self.service} cannot be wired to itself")

    def to_json(self) -> dict[str, str]:
        return {"service": self.service, "partner": self.partner}

    def __str__(self) -> str:
        return f"{self.service} → {self.partner}"


def wires_in_place(partners: Mapping[str, Iterable[str]]) -> list[Wire]:
    """The wires in place: ``A → B`` for each partner B of each service A (a service's
    own name among its partners left out), sorted.

    The one reading of the wiring of the cell controller
    (:meth:`~plugcell.devices.cell.directory.CellDirectory.wiring_now`) and of
    ``plugcell cell ls``/``save``; each leaves the cell controllers out of ``partners`` first
    (their subscriptions are how they watch, not wiring).
    """
    return sorted({Wire(a, b) for a, bs in partners.items() for b in bs if b != a})


def dump_wiring(wires: list[Wire] | set[Wire], cell: str) -> dict[str, Any]:
    """The JSON document of ``wires`` (sorted, so files diff well)."""
    return {
        "format": FORMAT,
        "version": VERSION,
        "cell": cell,
        "saved": datetime.now(UTC).isoformat(timespec="seconds"),
        "wires": [w.to_json() for w in sorted(set(wires))],
    }


def parse_wiring(doc: Any) -> tuple[list[Wire], str]:
    """The wires and the cell name of a wiring document (WiringError if it is not one)."""
    if not isinstance(doc, dict):
        raise WiringError("a wiring document is a JSON object with a 'wires' list")
    if doc.get("format", FORMAT) != FORMAT:
        raise WiringError(f"not a cell wiring file (format {doc.get('format')!r})")
    version = doc.get("version", VERSION)
    if version != VERSION:
        raise WiringError(f"unsupported wiring file version {version!r} (this is {VERSION})")
    wires = doc.get("wires")
    if not isinstance(wires, list):
        raise WiringError("'wires' must be a list of {service, partner} objects")
    if len(wires) > MAX_WIRES:
        raise WiringError(f"{len(wires)} wires: more than the limit of {MAX_WIRES}")
    out: list[Wire] = []
    for i, item in enumerate(wires):
        if not isinstance(item, dict):
            raise WiringError(f"wire {i + 1}: expected an object, got {type(item).__name__}")
        service, partner = item.get("service"), item.get("partner")
        if not isinstance(service, str) or not isinstance(partner, str):
            raise WiringError(f"wire {i + 1}: 'service' and 'partner' must be names")
        try:
            out.append(Wire(service, partner))
        except WiringError as exc:
            raise WiringError(f"wire {i + 1}: {exc}") from None
    cell = doc.get("cell", "")
    return sorted(set(out)), cell if isinstance(cell, str) else ""


def read_wiring(text: str) -> tuple[list[Wire], str]:
    """Parse the text of a wiring file."""
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise WiringError(f"not JSON: {exc}") from None
    return parse_wiring(doc)


def load_wiring(path: Path) -> tuple[list[Wire], str]:
    """Read a wiring file (WiringError with the path if it cannot be read)."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError as exc:
        raise WiringError(f"{path}: cannot read: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        raise WiringError(f"{path}: not a text file") from None
    try:
        return read_wiring(text)
    except WiringError as exc:
        raise WiringError(f"{path}: {exc}") from None


def save_wiring(wires: list[Wire] | set[Wire], cell: str, path: Path) -> dict[str, Any]:
    """Write the wiring file (atomically: a temporary file renamed); return the document."""
    doc = dump_wiring(wires, cell)
    path = Path(path)
    if not path.name or path.name in (".", "..") or "\x00" in str(path):
        raise WiringError(f"{str(path)!r}: not a file name to save the wiring to")
    tmp = path.with_name(path.name + ".tmp")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp.write_text(json.dumps(doc, indent=2) + "\n", encoding="utf-8")
        tmp.replace(path)
    except OSError as exc:
        raise WiringError(f"{path}: cannot write: {exc.strerror or exc}") from None
    return doc


@dataclass
class _Attempt:
    failures: int = 0
    next_try: float = 0.0
    reason: str = ""


@dataclass
class WiringKeeper:
    """The wiring the operator wants, and which wires are missing right now."""

    wanted: set[Wire] = field(default_factory=set)
    _attempts: dict[Wire, _Attempt] = field(default_factory=dict)

    def want(self, wire: Wire) -> None:
        self.wanted.add(wire)
        self._attempts.pop(wire, None)

    def drop(self, wire: Wire) -> None:
        self.wanted.discard(wire)
        self._attempts.pop(wire, None)

    def replace(self, wires: list[Wire]) -> None:
        """Want exactly ``wires`` (a loaded file)."""
        self.wanted = set(wires)
        self._attempts.clear()

    def missing(
        self, alive: set[str], partners: dict[str, set[str]], now: float | None = None
    ) -> list[Wire]:
        """Wanted wires whose two ends are alive but that are not in place, due for a try."""
        now = time.monotonic() if now is None else now
        out = []
        for wire in sorted(self.wanted):
            if wire.service not in alive or wire.partner not in alive:
                continue
            if wire.partner in partners.get(wire.service, set()):
                self._attempts.pop(wire, None)
                continue
            attempt = self._attempts.get(wire)
            if attempt is None or attempt.next_try <= now:
                out.append(wire)
        return out

    def failed(self, wire: Wire, reason: str, now: float | None = None) -> None:
        """Note a failed try: the next one waits (exponential back-off)."""
        now = time.monotonic() if now is None else now
        attempt = self._attempts.setdefault(wire, _Attempt())
        attempt.failures += 1
        attempt.reason = reason
        attempt.next_try = now + min(MAX_BACKOFF, FIRST_BACKOFF * 2 ** (attempt.failures - 1))

    def succeeded(self, wire: Wire) -> None:
        self._attempts.pop(wire, None)

    async def reapply(
        self, alive: set[str], partners: dict[str, set[str]],
        ask: Callable[[Wire], Awaitable[tuple[bool, str]]],
    ) -> list[tuple[Wire, bool, str]]:
        """Ask for every :meth:`missing` wire at once (``ask(wire)`` → ``(ok, reason)``)
        and note each answer (:meth:`succeeded`, or :meth:`failed` with its back-off).

        The one re-apply of the cell controller and of ``plugcell cell load``.

        Returns
        -------
        list of (Wire, bool, str)
            Each wire asked for, whether it is now in place, and the service's reason.
        """
        missing = self.missing(alive, partners)
        answers = await asyncio.gather(*(ask(w) for w in missing))
        for wire, (ok, reason) in zip(missing, answers, strict=True):
            if ok:
                self.succeeded(wire)
            else:
                self.failed(wire, reason)
        return [(w, ok, reason) for w, (ok, reason) in zip(missing, answers, strict=True)]

    def reset_backoff(self, service: str) -> None:
        """A service (re)appeared: try its wires at once."""
        for wire, attempt in self._attempts.items():
            if service in (wire.service, wire.partner):
                attempt.next_try = 0.0

    def status(
        self, alive: set[str], partners: dict[str, set[str]]
    ) -> list[dict[str, Any]]:
        """Each wanted wire: ``in place``, ``waiting`` (an end is absent) or ``failing``."""
        out = []
        for wire in sorted(self.wanted):
            attempt = self._attempts.get(wire)
            if wire.partner in partners.get(wire.service, set()):
                state, reason = "in place", ""
            elif wire.service not in alive or wire.partner not in alive:
                absent = [n for n in (wire.service, wire.partner) if n not in alive]
                state, reason = "waiting", f"waiting for {', '.join(absent)}"
            elif attempt is not None:
                state, reason = "failing", attempt.reason
            else:
                state, reason = "pending", ""
            out.append({**wire.to_json(), "state": state, "reason": reason})
        return out
