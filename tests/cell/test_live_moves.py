"""The cell controller's store of the robots' tracked moves as they go
(devices/cell/live_moves.py): each batch a ``tracking`` event at once, the latest move of
each robot kept (a new move replaces it), bounded by halving its points by pairs, bad
payloads dropped and counted, a robot that left forgotten."""

from __future__ import annotations

import asyncio
import logging
from typing import Any

import numpy as np

from plugcell.devices.cell import live_moves
from plugcell.devices.cell.feed import UiFeed
from plugcell.devices.cell.live_moves import LiveMoves
from plugcell.devices.robot.live_tracking import (
    HoldSpan,
    MoveIdentity,
    TrackingBatch,
    TrackingEnd,
    TrackingPoint,
    encode_tracking,
)

MOVE = MoveIdentity("line.pdl", 1, "line.1", 1, "TRACKER", 10**18)


def _feed() -> tuple[UiFeed, asyncio.Queue[dict[str, Any]]]:
    feed = UiFeed("CONTROLLER", cell=lambda: {}, processes=lambda keys: {},
                  log=logging.getLogger("test.live_moves"))
    return feed, feed.listen()


def _drain(queue: asyncio.Queue[dict[str, Any]]) -> list[dict[str, Any]]:
    out = []
    while not queue.empty():
        out.append(queue.get_nowait())
    return out


def _points(t0: float, n: int, gap: bool = False) -> list[TrackingPoint]:
    return [TrackingPoint(t0 + 0.004 * i, 1e-5 * i, None if gap else 2e-5)
            for i in range(n)]


def test_batches_become_events_and_the_latest_move_is_kept() -> None:
    async def main() -> None:
        feed, queue = _feed()
        moves = LiveMoves(feed)
        moves.on_payload("H4", encode_tracking(TrackingBatch("H4", MOVE, 0, _points(0, 3))))
        moves.on_payload("H4", encode_tracking(TrackingBatch("H4", MOVE, 1, _points(0.012, 2,
                                                                                    True))))
        moves.on_payload("H4", b"\x00garbage")
        end = TrackingEnd(5, 3, [HoldSpan(0.01, None, "line_of_sight")], "nominal")
        moves.on_payload("H4", encode_tracking(TrackingBatch("H4", MOVE, 2, [], end)))
        events = _drain(queue)
        assert [(e["type"], e["service"], e["seq"], len(e["points"]), e["running"])
                for e in events] == [("tracking", "H4", 0, 3, True),
                                     ("tracking", "H4", 1, 2, True),
                                     ("tracking", "H4", 2, 0, False)]
        assert events[1]["points"] == [[0.012, 0.0, None, False], [0.016, 1e-5, None, False]]
        assert events[0]["identity"] == {"program": "line.pdl", "run": 1, "move": "line.1",
                                          "number": 1, "tracker": "TRACKER",
                                          "start_ns": 10**18}
        assert events[2]["end"] == {"cycles": 5, "tracking_cycles": 3, "model": "nominal",
                                    "windows": [[0.01, None, "line_of_sight"]],
                                    "failure": ""}
        assert moves.bad == 1
        (snap,) = moves.snapshot()
        assert snap["whole"] and not snap["running"] and len(snap["points"]) == 5
        # the robot's next move replaces it
        second = MoveIdentity("line.pdl", 1, "line.2", 2, "TRACKER", 10**18 + 1)
        moves.on_payload("H4", encode_tracking(TrackingBatch("H4", second, 3, _points(0, 1))))
        (snap,) = moves.snapshot()
        assert snap["identity"]["move"] == "line.2" and snap["running"]
        assert len(snap["points"]) == 1
        moves.forget("H4")
        assert moves.snapshot() == []

    asyncio.run(main())


def test_a_long_move_is_kept_whole_and_coarser(monkeypatch) -> None:
    monkeypatch.setattr(live_moves, "MAX_POINTS", 100)

    async def main() -> None:
        feed, _ = _feed()
        moves = LiveMoves(feed)
        for seq in range(6):  # 150 points: halved once, by pairs
            pts = [TrackingPoint(0.004 * (25 * seq + i), 1e-5 * (25 * seq + i),
                                 None if seq == 3 else 1e-6) for i in range(25)]
            moves.on_payload("H4", encode_tracking(TrackingBatch("H4", MOVE, seq, pts)))
        (snap,) = moves.snapshot()
        t = np.array([p[0] for p in snap["points"]])
        assert 50 <= len(t) <= 100 and t[-1] == 0.004 * 149 and np.all(np.diff(t) > 0)
        # each pair's largest deviation: the last point's is the move's largest
        assert snap["points"][-1][1] == 1e-5 * 149
        gaps = [p[0] for p in snap["points"] if p[2] is None]
        assert gaps and min(gaps) >= 0.004 * 75 and max(gaps) <= 0.004 * 99

    asyncio.run(main())
