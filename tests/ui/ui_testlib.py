"""Helpers of the web UI tests: the app on a real controller, polling it boundedly."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from fastapi.testclient import TestClient

from plugcell.apps.ui.app import create_app
from plugcell.apps.ui.reports import ReportFiles
from plugcell.devices.cell.service import cell_controller

HEADERS = {"X-Plugcell": "1"}


def make_client(cell: str, docs: Path | None = None, reports: list[Path] | None = None
                ) -> TestClient:
    controller = cell_controller(cell=cell)
    app = create_app(controller, reports=ReportFiles(docs, reports or []))
    return TestClient(app, base_url="http://127.0.0.1")


def until(fetch: Callable[[], Any], predicate: Callable[[Any], bool], timeout: float = 15.0
          ) -> Any:
    """Poll ``fetch()`` until ``predicate`` holds (AssertionError after ``timeout``)."""
    deadline = time.monotonic() + timeout
    while True:
        value = fetch()
        if predicate(value):
            return value
        assert time.monotonic() < deadline, f"condition not reached in time: {value!r:.600}"
        time.sleep(0.1)


def services(client: TestClient) -> dict[str, Any]:
    return {s["name"]: s for s in client.get("/api/snapshot").json()["services"]}
