"""Bad input everywhere (issue 10 §4): every route of the web API fuzzed with a few
thousand seeded cases — no 5xx, no hang, every refusal a JSON message; the benchmark
``benchmarks/fuzz_web.py`` runs ≥ 100 000.  Then each input the fuzzer found a crash
with, by name."""

from __future__ import annotations

import sys
import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))

from fuzz_web import fuzz_web, judge
from plugcell.apps.ui.app import create_app
from plugcell.apps.ui.reports import ReportFiles
from plugcell.devices.cell.service import cell_controller

pytestmark = [pytest.mark.slow, pytest.mark.timeout(120)]


def test_every_route_answers_bad_input_precisely(tmp_path: Path) -> None:
    report = fuzz_web(3000, seed=7, workdir=tmp_path)
    assert report.failures == [], "\n".join(report.failures[:10])
    assert len(report.rows) >= 20 and all(row.cases >= 60 for row in report.rows)
    statuses = {s for row in report.rows for s in row.statuses}
    assert {200, 400, 403, 404, 405, 413} <= statuses
    accepted = {row.endpoint for row in report.rows if row.accepted}
    assert {"POST /api/tasks", "POST /api/runs", "POST /api/fit", "POST /api/wire",
            "POST /api/wiring/save"} <= accepted  # the mutations get past the checks too
    assert max(row.max_ms for row in report.rows) < 20_000  # no hang (not a speed check)


@pytest.fixture(scope="module")
def client(tmp_path_factory: pytest.TempPathFactory) -> Iterator[TestClient]:
    """The app on a controller that is not started: these inputs are refused before it."""
    docs = tmp_path_factory.mktemp("docs")
    (docs / "results").mkdir()
    controller = cell_controller(cell=f"f{uuid.uuid4().hex[:12]}", journals=False)
    app = create_app(controller, reports=ReportFiles(docs, []), manage=False)
    yield TestClient(app, base_url="http://127.0.0.1")


HEADERS = {"X-Plugcell": "1", "Content-Type": "application/json"}

#: (method, url, extra headers, body, status, words of the message) — each was a 500.
FOUND = {
    "origin-not-a-url": ("GET", "/api/snapshot", {"Origin": "http://["}, b"", 403,
                         "malformed Origin header"),
    "nested-100000-deep": ("POST", "/api/wire", {}, b"[" * 100_000 + b"]" * 100_000, 400,
                           "nested too deeply"),
    "5000-digit-integer": ("POST", "/api/fit", {}, b'{"n": ' + b"9" * 5000 + b"}", 400,
                           "(5000 digits) is beyond ±1.8e+308"),
    "integer-beyond-float-as-a-timeout": (
        "POST", "/api/tasks/check", {},
        b'{"service": "TOOL", "command": "Drill", "timeout": -1' + b"0" * 400 + b"}", 400,
        "(401 digits) is beyond ±1.8e+308"),
    "integer-beyond-float-as-a-coordinate": (
        "POST", "/api/wizard/probe", {}, b'{"circle": [[1' + b"0" * 400 + b', 0, 0]]}', 400,
        "(401 digits) is beyond ±1.8e+308"),
    "lone-surrogate-escape-in-a-run": ("POST", "/api/runs", {}, b'{"items": ["R1:\\ud800"]}',
                                       400, "lone surrogate \\ud800"),
    "lone-surrogate-utf8-in-a-path": ("POST", "/api/wiring/save", {},
                                      b'{"path": "fuzz-\xed\xa0\x80ng.json"}', 400,
                                      "lone surrogate \\ud800"),
    "lone-surrogate-in-utf16": ("POST", "/api/wiring/load", {},
                                '{"path": "\\udfff"}'.encode("utf-16"), 400,
                                "lone surrogate \\udfff"),
    "lone-surrogate-task-id": ("POST", "/api/tasks/stop", {}, b'{"id": "\\ud800\\u00ff="}', 400,
                               "lone surrogate \\ud800"),
    "nul-in-a-wiring-path": ("POST", "/api/wiring/save", {}, b'{"path": "a\\u0000b"}', 200,
                             "NUL character"),
    "home-of-an-unknown-user": ("POST", "/api/wiring/save", {},
                                b'{"path": "~.+]X#\\u007f1["}', 200, "home directory"),
    "dot-as-the-wiring-file": ("POST", "/api/wiring/save", {}, b'{"path": "."}', 200,
                               "is a folder, not a file name"),
    "coordinates-near-float-max": ("POST", "/api/fit", {},
                                   b'{"kind": "line", "points": [[0, 0, 0], [1e302, 1e300, 0],'
                                   b' [200, 0, 1]]}', 200, "beyond ±1e+09 mm"),
    "nul-in-a-result-name": ("GET", "/reports/results/%00", {}, b"", 404, "no result"),
}


@pytest.mark.parametrize("name", sorted(FOUND))
def test_inputs_the_fuzzer_crashed_the_api_with(client: TestClient, name: str) -> None:
    method, url, headers, body, status, words = FOUND[name]
    r = client.request(method, url, headers={**HEADERS, **headers}, content=body)
    assert r.status_code == status, r.text
    assert judge(method, r.status_code, r.headers["content-type"], r.content) == ""
    assert words in " ".join(r.json()["errors"].values())
    assert client.get("/api/snapshot").status_code == 200  # and the UI still works
