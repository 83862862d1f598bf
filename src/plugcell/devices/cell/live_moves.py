"""The robots' tracked moves as they go, relayed by the cell controller to its listeners
(the web UI's live plot: **Metrology** → **Tracked path** → live).

Each robot service publishes the tracked move it streams in batches
(``plugcell.devices.robot.live_tracking``: per cycle the path time and the deviations of
the corrected command and of the tracker's measurement from the commanded path, SI);
:class:`LiveMoves` turns each batch into a ``tracking`` event sent at once, and keeps each
robot's latest move — its points so far, at most :data:`MAX_POINTS` (beyond, the points
are halved by pairs, each pair's largest deviations: the whole move stays, coarser) — for
a new listener's snapshot.
"""

from __future__ import annotations

from typing import Any

import msgspec
import numpy as np

from plugcell.devices.cell.feed import UiFeed
from plugcell.devices.robot.live_tracking import TrackingBatch, decimate, decode_tracking

__all__ = ["MAX_POINTS", "LiveMoves"]

#: Points of one move a controller keeps at most (a 16 s move at 4 ms in full).
MAX_POINTS = 4000


class _Move:
    """One robot's latest move: its identity, points ``[t_s, corrected_m, measured_m,
    holding]`` so far (``measured_m`` None: no fresh sample), end (None: running)."""

    def __init__(self, batch: TrackingBatch) -> None:
        self.identity = msgspec.to_builtins(batch.identity)
        self.points: list[list[float | None]] = []
        self.end: dict[str, Any] | None = None
        self.seq = batch.seq

    def add(self, points: list[list[float | None]]) -> None:
        self.points.extend(points)
        if len(self.points) > MAX_POINTS:
            arr = np.array([[p[0], p[1], np.nan if p[2] is None else p[2], p[3]]
                            for p in self.points], dtype=float)
            self.points = msgspec.to_builtins(decimate(
                arr[:, 0], arr[:, 1], arr[:, 2], len(self.points) // 2, arr[:, 3] > 0))


class LiveMoves:
    """The latest tracked move of each robot service; each new batch to ``feed``."""

    def __init__(self, feed: UiFeed) -> None:
        self.feed = feed
        self.moves: dict[str, _Move] = {}
        self.bad = 0
        """Payloads that were not a batch (dropped)."""

    def on_payload(self, service: str, payload: bytes) -> None:
        """A batch published by robot service ``service`` → a ``tracking`` event
        ``{"type": "tracking", "service", "identity", "seq", "points", "end", "running"}``
        (``points``: this batch's ``[t_s, corrected_m, measured_m, holding]``; SI
        units)."""
        try:
            batch = decode_tracking(payload)
        except ValueError:  # msgspec.DecodeError, or a number not finite
            self.bad += 1
            return
        move = self.moves.get(service)
        if move is None or move.identity != msgspec.to_builtins(batch.identity):
            move = self.moves[service] = _Move(batch)
        points = msgspec.to_builtins(batch.points)
        move.add(points)
        move.seq = batch.seq
        if batch.end is not None:
            move.end = msgspec.to_builtins(batch.end)
        self.feed.emit({"type": "tracking", "service": service, "identity": move.identity,
                        "seq": batch.seq, "points": points, "end": move.end,
                        "running": move.end is None})

    def forget(self, service: str) -> None:
        """``service`` left the cell."""
        self.moves.pop(service, None)

    def snapshot(self) -> list[dict[str, Any]]:
        """The latest move of every robot: ``tracking`` events with all its points."""
        return [{"type": "tracking", "service": name, "identity": m.identity, "seq": m.seq,
                 "points": m.points, "end": m.end, "running": m.end is None, "whole": True}
                for name, m in self.moves.items()]
