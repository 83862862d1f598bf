"""A robot's tracked move plotted live in the browser (issue 38 §2): a real
:class:`LiveTracking` on its own Zenoh session, publishing from an event loop as a robot
service does, while the test appends the cycles of a 3 s move at the robot's rate (4 ms)
— the correction blending in, the beam broken for 0.4 s — to ``plugcell cell serve``'s
page in headless chromium, Metrology → Tracked path → Live.

While the move runs the page says so and its points grow batch by batch (several
batches, not one at the end), the stretch the loop holds on the model alone shaded as
it comes; the measured line breaks where the beam was (two runs of
polyline, the gap counted); at the end it says "ended" with the window on the model
alone, and a page opened after the move finds the whole move in the snapshot.
Screenshots under ``test-artifacts/ui/``.
"""

from __future__ import annotations

import asyncio
import threading
import time
from typing import Any

import numpy as np
import pytest
from cell_testlib import unique_cell
from test_ui_browser import CHROMIUM, _browser, _controller_ui

from plugcell.devices.robot.live_tracking import (
    HoldSpan,
    LiveTracking,
    TrackingEnd,
    identity_now,
)
from plugcell.framework.bus import Bus
from plugcell.framework.keys import KeySpace
from plugcell.framework.transport import TransportConfig

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(not CHROMIUM.exists(),
                       reason="needs Debian's chromium at /usr/bin/chromium"),
    pytest.mark.timeout(240),
]

CYCLE_S, N, SETTLE_S = 0.004, 750, 0.2
BREAK = (300, 400)  # cycles without a fresh sample
HOLD = (305, 410)  # cycles the loop holds on the model alone


def _cycle(k: int, plan_p: np.ndarray) -> tuple[tuple[Any, ...], tuple[Any, Any]]:
    """Cycle k of the move: an offset blending in to 0.6 mm, a sample 0.1 mm off (none in
    the break; the loop holding in HOLD)."""
    t = 100.0 + k * CYCLE_S
    o = np.zeros(6)
    o[1] = 6e-4 * min(1.0, k / 50)
    sample = None if BREAK[0] <= k < BREAK[1] else (t, plan_p[k, 0], plan_p[k, 1] + 1e-4, 0.0)
    state = "holding" if HOLD[0] <= k < HOLD[1] else "tracking"
    return (t, o, state, o, 1.0), (k, sample)


def test_a_tracked_move_is_plotted_as_it_goes(launcher: Any) -> None:
    from playwright.sync_api import expect

    cell = unique_cell("l")
    url = _controller_ui(launcher, cell)
    bus = Bus.connect(TransportConfig.from_env(), KeySpace(cell))
    publisher = bus.tracking_publisher("H4")
    loop = asyncio.new_event_loop()
    runner = threading.Thread(target=loop.run_forever, daemon=True)
    runner.start()
    live = LiveTracking("H4", publisher.put, loop)
    plan_p = np.zeros((N + 1, 3))
    plan_p[:, 0] = 1.0 + 1e-4 * np.arange(N + 1)
    record: list[Any] = []
    cycles: list[Any] = []
    errors: list[str] = []
    try:
        with _browser(errors) as (page, shot):
            page.goto(url)
            page.click('.tabs button[data-tab="metrology"]')
            page.click('#wizard-tabs button[data-wizard="tracked"]')
            page.click('#wizard .subtabs button[data-mode="live"]')
            expect(page.locator("#tracked-live")).to_contain_text("No tracked move yet")
            ident = identity_now(("/progs/line.pdl", 3), 2, "TRACKER")
            # the controller's subscriber meets this session (Zenoh's discovery): the
            # move's identity is published until the page shows it
            deadline = time.monotonic() + 30
            while page.evaluate("window.plugcellTracking.robots()") != ["H4"]:
                assert time.monotonic() < deadline, "the move never reached the page"
                live.begin(ident, CYCLE_S, SETTLE_S, plan_p, record, cycles)
                page.wait_for_timeout(300)
            status = page.locator("#tracked-live .live-status")
            expect(status).to_contain_text("move 2 of program line.pdl (run 3) with TRACKER")
            expect(status).to_contain_text("running")
            counts = []
            result = page.locator('.result[data-result="tracked-live"]')
            for k in range(N):  # at the robot's rate, roughly
                if k == HOLD[1] + 50:  # the window without tracking, shaded as it goes
                    expect(result.locator('[data-window="holding"]')).to_contain_text(
                        f"{HOLD[0] * CYCLE_S - SETTLE_S:.3f} s")
                    shot("tracked-live-01-held")
                r, c = _cycle(k, plan_p)
                cycles.append(c)
                record.append(r)
                if k % 25 == 24:
                    time.sleep(0.1)
                    counts.append(page.evaluate("window.plugcellTracking.points('H4')"))
            shot("tracked-live-02-running")
            live.end(TrackingEnd(N, N - 150, [HoldSpan(100.0 + BREAK[0] * CYCLE_S,
                                                       100.0 + (BREAK[1] + 10) * CYCLE_S,
                                                       "line_of_sight")],
                                 "the nominal model (no calibration loaded)"))
            expect(status).to_contain_text("ended")
            # the whole move (decimated if the batches were late: a loaded machine)
            assert page.evaluate("window.plugcellTracking.lastT('H4')") == pytest.approx(
                (N - 1) * CYCLE_S - SETTLE_S)
            final = page.evaluate("window.plugcellTracking.points('H4')")
            expect(result).to_have_attribute("data-running", "false")
            shot("tracked-live-03-ended")
            # live: the points grew while the move ran, batch after batch
            assert len({c for c in counts if 0 < c < N}) >= 3, counts
            assert page.evaluate("window.plugcellTracking.batches('H4')") >= 5
            measured = result.locator('polyline.series[data-series="measured"]')
            assert measured.count() == 2  # the beam break: the line breaks
            assert result.locator('polyline.series[data-series="corrected"]').count() == 1
            gaps = int(result.locator("[data-gaps]").get_attribute("data-gaps"))
            assert 0 < gaps <= BREAK[1] - BREAK[0], gaps
            expect(result.locator('[data-window="line_of_sight"]')).to_contain_text(
                f"{BREAK[0] * CYCLE_S - SETTLE_S:.3f} s")
            expect(result.locator('[data-legend="corrected"]')).to_contain_text(
                "max 0.600 mm")
            expect(result.locator('[data-legend="measured"]')).to_contain_text("max 0.100 mm")
            # a page opened after the move: the whole move from the snapshot
            page.goto(url)
            page.click('.tabs button[data-tab="metrology"]')
            page.click('#wizard-tabs button[data-wizard="tracked"]')
            page.click('#wizard .subtabs button[data-mode="live"]')
            expect(page.locator("#tracked-live .live-status")).to_contain_text("ended")
            assert page.evaluate("window.plugcellTracking.points('H4')") == final
    finally:
        loop.call_soon_threadsafe(loop.stop)
        runner.join(5)
        publisher.undeclare()
        bus.close()
    assert not errors, errors
