"""The tracked path in the browser (issue 38): a real ``plugcell path run --out`` result
loaded in the metrology panel's "Tracked path" sub-tab — the plot of the corrected,
actual and measured deviations from the commanded path, the window without tracking
shaded, the accuracy table; a file of another kind refused inline."""

from __future__ import annotations

import json
from typing import Any

import pytest
from cell_testlib import unique_cell
from test_ui_browser import CHROMIUM, _browser, _controller_ui

from plugcell.apps.commands.path import result_document
from plugcell.io.path_files import parse_path
from plugcell.sim.path_run import PathRunOptions, run_path

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(not CHROMIUM.exists(),
                       reason="needs Debian's chromium at /usr/bin/chromium"),
    pytest.mark.timeout(240),
]

LINE = """x,y,z,a,b,c,speed
1473.3,-231.7,2488.4,-60,30,-90,
1473.3,-131.7,2488.4,-60,30,-90,100
"""


def test_a_tracked_paths_result_is_plotted(launcher: Any) -> None:
    from playwright.sync_api import expect

    run = run_path(parse_path(LINE, "line.csv"), PathRunOptions(beam_breaks=((0.05, 0.1),)))
    doc = result_document(run, "line.csv")
    url = _controller_ui(launcher, unique_cell("t"))
    errors: list[str] = []
    with _browser(errors) as (page, shot):
        page.goto(url)
        page.click('.tabs button[data-tab="metrology"]')
        page.click('#wizard-tabs button[data-wizard="tracked"]')
        page.fill('textarea[name="tracked-text"]', '{"format": "plugcell-residuals"}')
        page.click('[data-step="tracked-file"] button.primary')
        expect(page.locator('.field-error[data-for="tracked"]')).to_contain_text(
            "not a tracked path's result")
        page.set_input_files('input[aria-label="tracked path result"]', files=[{
            "name": "result.json", "mimeType": "application/json",
            "buffer": json.dumps(doc).encode()}])
        result = page.locator('.result[data-result="tracked"]')
        expect(result).to_contain_text("line.csv")
        for name in ("corrected", "actual", "measured"):
            line = result.locator(f'polyline.series[data-series="{name}"]')
            expect(line).to_have_count(1)
            assert int(line.get_attribute("data-points")) > 100
        expect(result.locator('rect.window[data-reason="line_of_sight"]')).to_have_count(1)
        expect(result.locator('[data-window="line_of_sight"]')).to_contain_text(
            "without tracking")
        expect(result.locator('tr[data-segment="0"][data-state="tracking"]')).to_have_count(1)
        result.scroll_into_view_if_needed()
        shot("tracked-path")
    assert not errors, errors
