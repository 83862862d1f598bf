"""The cell controller's feed to its listeners, on its own (services/cell/feed.py)."""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Iterable
from typing import Any

import pytest

from plugcell.devices.cell import feed as controller_feed
from plugcell.devices.cell.feed import LOG_LINES, UiFeed


class Seams:
    def __init__(self) -> None:
        self.cell_calls = 0
        self.process_calls: list[set[tuple[str, str, int]]] = []

    def cell(self) -> dict[str, Any]:
        self.cell_calls += 1
        return {"services": ["CAMERA"]}

    def processes(self, keys: Iterable[tuple[str, str, int]]) -> dict[str, Any]:
        keys = set(keys)
        self.process_calls.append(keys)
        return {"processes": sorted(keys)}


def feed() -> tuple[UiFeed, Seams]:
    seams = Seams()
    return UiFeed("CONTROLLER", cell=seams.cell, processes=seams.processes,
                  log=logging.getLogger("test.feed")), seams


def drain(queue: asyncio.Queue[dict[str, Any]]) -> list[dict[str, Any]]:
    out = []
    while not queue.empty():
        out.append(queue.get_nowait())
    return out


def test_changes_are_batched_into_one_event_of_each_type_per_flush() -> None:
    async def main() -> None:
        ui, seams = feed()
        queue = ui.listen()
        ui.flush()
        assert drain(queue) == [] and seams.cell_calls == 0  # nothing changed
        for _ in range(50):
            ui.process_changed(("DRILL", "ROBOT", 7))
        ui.process_changed(("CAMERA", "ROBOT", 8))
        ui.cell_changed()
        ui.cell_changed()
        ui.flush()
        events = drain(queue)
        assert [e["type"] for e in events] == ["cell", "processes"]
        assert events[0]["services"] == ["CAMERA"]
        assert events[1]["processes"] == [("CAMERA", "ROBOT", 8), ("DRILL", "ROBOT", 7)]
        ui.flush()
        assert drain(queue) == []
    asyncio.run(main())


def test_a_listener_that_falls_behind_is_emptied_and_told_to_resync() -> None:
    async def main() -> None:
        ui, _ = feed()
        slow, fast = ui.listen(maxsize=3), ui.listen(maxsize=100)
        for k in range(5):
            ui.emit({"type": "n", "k": k})
        # full at k = 3: emptied and told to resync; k = 4 follows the resync
        assert drain(slow) == [{"type": "resync"}, {"type": "n", "k": 4}]
        assert [e["k"] for e in drain(fast)] == [0, 1, 2, 3, 4]
        ui.unlisten(fast)
        ui.emit({"type": "n", "k": 5})
        assert drain(fast) == []
    asyncio.run(main())


def test_the_activity_log_keeps_its_last_lines_and_sends_each(
        caplog: pytest.LogCaptureFixture) -> None:
    async def main() -> None:
        ui, _ = feed()
        queue = ui.listen(maxsize=LOG_LINES + 100)
        with caplog.at_level(logging.INFO, logger="test.feed"):
            for k in range(LOG_LINES + 10):
                ui.log("error" if k == 0 else "info", f"line {k}")
        assert len(ui.activity) == LOG_LINES
        assert ui.activity[0]["text"] == "line 10"
        sent = drain(queue)
        assert len(sent) == LOG_LINES + 10 and sent[0]["line"]["level"] == "error"
        assert caplog.records[0].levelno == logging.WARNING
        assert caplog.records[0].getMessage() == "CONTROLLER: line 0"
    asyncio.run(main())


def test_run_flushes_after_a_change_and_sleeps_while_idle(
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(controller_feed, "FLUSH_PERIOD", 0.01)

    async def main() -> None:
        ui, seams = feed()
        queue = ui.listen()
        runner = asyncio.create_task(ui.run())
        await asyncio.sleep(0.05)
        assert drain(queue) == [] and seams.cell_calls == 0
        ui.cell_changed()
        async with asyncio.timeout(2.0):
            event = await queue.get()
        assert event["type"] == "cell"
        ui.process_changed(("DRILL", "ROBOT", 1))
        async with asyncio.timeout(2.0):
            event = await queue.get()
        assert event["type"] == "processes"
        runner.cancel()
        with pytest.raises(asyncio.CancelledError):
            await runner
    asyncio.run(main())
