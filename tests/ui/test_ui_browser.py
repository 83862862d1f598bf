"""The controller UI in a real browser (Debian's chromium, headless, driven by Playwright).

An engineer's session, end to end, against real service processes (thesis 7.6,
Figures 7-9 … 7-11): discover the cell → wire the robot to its peripherals (with
the toolbar and by dragging in the graph) → a task with an inline error, then
Completed → run a robot program → watch its processes complete in the monitor →
save the wiring, unwire, load it back, reload the page → a service dies and greys
out → the PROBE wizard of appendix D → calibration residuals in the 3-D view → the
reports.  Screenshots are kept under
``test-artifacts/ui/``; any console error of the page fails the test.  Skipped
only when ``/usr/bin/chromium`` is absent (CI installs it).
"""

from __future__ import annotations

import json
import math
import re
import tempfile
from pathlib import Path
from typing import Any

import pytest
from cell_testlib import PROGRAMS, plugcell_argv

CHROMIUM = Path("/usr/bin/chromium")
ARTIFACTS = Path(__file__).resolve().parents[2] / "test-artifacts" / "ui"
ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
        "--disable-background-networking", "--disable-component-update", "--disable-sync"]

pytestmark = [
    pytest.mark.skipif(not CHROMIUM.exists(),
                       reason="needs Debian's chromium at /usr/bin/chromium"),
    pytest.mark.timeout(150),
]


def circle_text(n: int = 16) -> str:
    return "\n".join(f"{1000 + 80 * math.cos(2 * math.pi * i / n):.4f} "
                     f"{200 + 80 * math.sin(2 * math.pi * i / n):.4f} 600" for i in range(n))


def residual_file(n: int = 24) -> bytes:
    """A small file in the format of ``plugcell calibrate --residuals``."""
    poses = []
    for i in range(n):
        a = 2 * math.pi * i / n
        poses.append({
            "set": "calibration" if i < 18 else "validation", "index": i + 1 if i < 18 else i - 17,
            "measured_mm": [1000 + 300 * math.cos(a), 200 + 300 * math.sin(a), 600 + 20 * i],
            "before_mm": [2 * math.cos(a), 1.5, -1.0],
            "after_mm": [0.02 * math.sin(a), 0.05, 0.01]})
    return json.dumps({"format": "plugcell-residuals", "format_version": 1, "robot": "smart_h4",
                       "model": {"number": 4, "name": "loop+gravity"}, "poses": poses}).encode()


def test_an_engineer_session_in_the_browser(module_cell: str, launcher: Any,
                                            tmp_path: Path) -> None:
    from playwright.sync_api import expect, sync_playwright

    cell = module_cell
    launcher.serve("drill", cell, "--param", "time_scale=0.001")
    camera = launcher.serve("camera", cell, "--param", "time_scale=0.001")
    launcher.serve("robot", cell, "--param", "sim=true", name="R1")
    docs = Path(__file__).resolve().parents[2] / "docs"
    ui = launcher.start(plugcell_argv("controller", "--port", "0", "--cell", cell,
                                      "--docs", str(docs)))
    url = ui.wait_line(lambda x: "controller UI on" in x, 30.0).split(" on ", 1)[1].split()[0]
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    errors: list[str] = []
    wiring = tmp_path / "cell-wiring.json"

    with sync_playwright() as p, tempfile.TemporaryDirectory() as profile:
        ctx = p.chromium.launch_persistent_context(
            profile, executable_path=str(CHROMIUM), headless=True, args=ARGS,
            viewport={"width": 1480, "height": 920})
        try:
            page = ctx.new_page()
            page.set_default_timeout(15_000)
            # waits, not speed checks: generous for a loaded 2-core CI machine
            expect.set_options(timeout=20_000)
            page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
            page.on("pageerror", lambda e: errors.append(f"page error: {e}"))
            shot = lambda name: page.screenshot(path=str(ARTIFACTS / f"{name}.png"))  # noqa: E731

            # 1. discover
            page.goto(url)
            for name in ("R1", "TOOL", "CAMERA"):
                expect(page.locator(f'.service[data-name="{name}"][data-alive="true"]')).to_be_visible()
            expect(page.locator("#conn")).to_have_attribute("data-state", "open")
            expect(page.locator('#graph g.node[data-name="CONTROLLER"]')).to_be_visible()
            shot("01-discovered")

            # 2. wire: the toolbar, then a drag in the graph
            page.select_option("#wire-service", "R1")
            page.select_option("#wire-partner", "R1")
            page.click("#wire-btn")
            expect(page.locator("#wire-error")).to_have_text("a service cannot be its own partner")
            page.select_option("#wire-partner", "TOOL")
            page.click("#wire-btn")
            expect(page.locator('[data-wire="R1>TOOL"] path.edge')).to_be_visible()
            src = page.locator('#graph g.node[data-name="R1"] rect').bounding_box()
            dst = page.locator('#graph g.node[data-name="CAMERA"] rect').bounding_box()
            page.mouse.move(src["x"] + 30, src["y"] + 20)
            page.mouse.down()
            page.mouse.move(src["x"] + 60, src["y"] + 40, steps=4)
            page.mouse.move(dst["x"] + 40, dst["y"] + 20, steps=8)
            page.mouse.up()
            expect(page.locator('[data-wire="R1>CAMERA"] path.edge')).to_be_visible()
            expect(page.locator('.service[data-name="R1"] .meta')).to_contain_text("→ CAMERA, TOOL")
            shot("02-wired")

            # 3. a task from the generated form: inline errors first, then Completed
            page.click('.service[data-name="TOOL"]')
            page.click('.cmd[data-command="Drill"]')
            page.fill('input[name="data-0"]', "fast")
            data_error = page.locator('.field-error[data-for="data"]')
            expect(data_error).to_have_text("value 1: not a number")
            expect(page.locator("#task-form button[type=submit]")).to_be_disabled()
            page.fill('input[name="data-0"]', "550.5")
            expect(page.locator('.field-error[data-for="data"]')).to_contain_text("a whole number")
            page.fill('input[name="data-0"]', "550")
            page.fill('input[name="data-1"]', "1100")
            page.fill('input[name="option"]', "Air")
            page.fill('input[name="timeout"]', "-1")
            expect(page.locator('.field-error[data-for="timeout"]')).to_have_text(
                "between 0 and 604800 s")
            page.fill('input[name="timeout"]', "")
            page.click("#task-form button[type=submit]")
            done = page.locator('#task-results li[data-state="Completed"]').first
            expect(done).to_contain_text("TOOL.Drill")
            expect(done).not_to_contain_text("null")
            shot("03-task")

            # 4. a robot program; 5. its processes complete in the monitor
            page.select_option(".run-robot", "R1")
            page.fill(".run-program", str(PROGRAMS / "cellcheck.pdl"))
            page.click("#run-btn")
            expect(page.locator('#runs li[data-state="Completed"]').first).to_be_visible()
            page.click('button[data-tab="processes"]')
            table = page.locator("#proc-table tbody")
            for command in ("Drill", "SnapShot", "ACTIVATE"):
                expect(table.locator(f'tr[data-command="{command}"][data-state="Completed"]').first
                       ).to_be_visible()
            expect(table.locator("tr", has_text=re.compile(r"R1\s*→\s*TOOL")).first).to_be_visible()
            expect(page.locator("#timeline rect.bar-Completed").first).to_be_attached()
            expect(page.locator('.queue[data-service="TOOL"]')).to_be_visible()
            shot("04-processes")

            # 6. save, unwire, load back, reload the page
            page.click('button[data-tab="cell"]')
            page.fill("#wiring-path", str(wiring))
            page.click("#save-btn")
            expect(page.locator("#file-ok")).to_have_text("saved 2 wires")
            assert wiring.is_file()
            page.locator('[data-wire="R1>CAMERA"] path.edge-hit').dispatch_event("click")
            expect(page.locator("#wire-partner")).to_have_value("CAMERA")
            page.click("#unwire-btn")
            expect(page.locator('[data-wire="R1>CAMERA"]')).to_have_count(0)
            page.click("#load-btn")
            expect(page.locator("#file-ok")).to_have_text("loaded 2 wires")
            expect(page.locator('[data-wire="R1>CAMERA"] path.edge')).to_be_visible()
            page.reload()
            expect(page.locator('[data-wire="R1>CAMERA"] path.edge')).to_be_visible()
            expect(page.locator('[data-wire="R1>TOOL"] path.edge')).to_be_visible()
            expect(page.locator("#wanted li", has_text="R1 → CAMERA")).to_have_attribute(
                "data-state", "in place")
            shot("05-saved-and-reloaded")

            # 7. a service dies: it greys out, the page goes on
            camera.stop()
            expect(page.locator('.service[data-name="CAMERA"]')).to_have_class(re.compile(r"\bdead\b"))
            expect(page.locator('#graph g.node[data-name="CAMERA"]')).to_have_class(
                re.compile(r"\bdead\b"))
            expect(page.locator("#activity")).to_contain_text("CAMERA left the cell")
            page.click('.service[data-name="CAMERA"]')
            expect(page.locator('.cmd[data-command="SnapShot"]')).to_be_disabled()
            shot("06-camera-gone")

            # 8. the PROBE wizard of appendix D
            page.click('button[data-tab="metrology"]')
            page.fill('textarea[name="points-circle"]', "1 2\n")
            expect(page.locator('.field-error[data-for="circle"]')).to_have_text(
                "line 1: expected x y z")
            page.fill('textarea[name="points-circle"]', circle_text())
            page.fill('textarea[name="points-holes"]', "1000 150 600\n1000 250 600\n")
            for label, value in zip(("x", "y", "z", "roll", "pitch", "yaw"),
                                    ("1000", "200", "700", "0", "0", "0"), strict=True):
                page.fill(f'input[aria-label="T-MAC {label}"]', value)
            expect(page.locator(".fitline").first).to_contain_text("radius 80.000 mm")
            page.click("#wizard button.primary")
            result = page.locator('.result[data-result="probe"]')
            expect(result).to_contain_text("rpy2tr vector: 0.0000, 0.0000, 106.3500")
            result.scroll_into_view_if_needed()
            shot("07-probe-wizard")

            # 9. calibration residuals in the 3-D view (the file of plugcell calibrate --residuals)
            page.click('#wizard-tabs button[data-wizard="residuals"]')
            page.fill('textarea[name="residual-text"]', "1000 200 600 0.1\n")
            page.click('[data-step="residual-file"] button.primary')
            expect(page.locator('.field-error[data-for="residuals"]')).to_have_text(
                "line 1: expected 6 numbers x y z dx dy dz (mm)")
            page.fill('textarea[name="residual-text"]', '{"format": "x"}')
            page.click('[data-step="residual-file"] button.primary')
            expect(page.locator('.field-error[data-for="residuals"]')).to_contain_text(
                "not a residual file")
            page.set_input_files('input[aria-label="residual file"]', files=[{
                "name": "residuals.json", "mimeType": "application/json",
                "buffer": residual_file()}])
            table = page.locator('.result[data-result="residuals"]')
            expect(table).to_contain_text("smart_h4 · model 4 (loop+gravity)")
            expect(table.locator('tr[data-set="calibration"] td').nth(1)).to_have_text("18")
            expect(table.locator('tr[data-set="validation"] td').nth(1)).to_have_text("6")
            expect(page.locator('.field-error[data-for="residuals"]')).to_have_text("")
            expect(page.locator("#legend")).to_contain_text("calibration residual after")
            page.check('input[aria-label="arrows before calibration"]')
            expect(page.locator("#legend")).to_contain_text("grey: before")
            page.select_option('select[aria-label="poses shown"]', "validation")
            page.locator("#view3d").scroll_into_view_if_needed()
            shot("08-residuals")

            # 10. the reports
            page.click('button[data-tab="reports"]')
            expect(page.locator("#report-list a").first).to_be_visible()
            page.locator("#report-list a", has_text="8.3-fig-8-12.png").click()
            expect(page.locator('#report-view img[alt="8.3-fig-8-12.png"]')).to_be_visible()
            expect(page.locator("#report-title")).to_have_text("8.3-fig-8-12.png")
            shot("09-reports")
        finally:
            ctx.close()
    assert not errors, f"console errors: {errors}"
