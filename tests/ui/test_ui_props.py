"""Property tests of the web API's inputs: whatever a page sends, a precise answer, never a 500."""

from __future__ import annotations

import json
from collections.abc import Iterator
from typing import Any

import pytest
from fastapi.testclient import TestClient
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from ui_testlib import HEADERS, make_client, services, until

JSON = st.recursive(
    st.none() | st.booleans() | st.integers(-2**70, 2**70) | st.floats() | st.text(max_size=8),
    lambda inner: st.lists(inner, max_size=6)
    | st.dictionaries(st.text(max_size=6), inner, max_size=4),
    max_leaves=30,
)
COMMANDS = st.sampled_from(["Drill", "SnapShot", "Connect", "MovieShot", "StopMovie", "", "?"])
SETTINGS = settings(max_examples=150, deadline=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture])


@pytest.fixture(scope="module")
def client(module_cell: str, launcher: Any) -> Iterator[TestClient]:
    launcher.serve("drill", module_cell, "--param", "time_scale=0.001")
    launcher.serve("camera", module_cell, "--param", "time_scale=0.001")
    with make_client(module_cell) as c:
        until(lambda: services(c), lambda s: all(
            s.get(n, {}).get("commands") for n in ("TOOL", "CAMERA")))
        yield c


def send(client: TestClient, url: str, body: Any) -> Any:
    """POST ``body`` as Python writes JSON (NaN and Infinity included, as some clients do)."""
    return client.post(url, headers={**HEADERS, "Content-Type": "application/json"},
                       content=json.dumps(body))


def answered(response: Any) -> dict[str, Any]:
    assert response.status_code in (200, 400, 413), response.text
    body = response.json()
    assert isinstance(body.get("ok"), bool)
    if not body["ok"]:
        assert body["errors"] and all(isinstance(v, str) and v for v in body["errors"].values())
    return body


@SETTINGS
@given(service=st.sampled_from(["TOOL", "CAMERA", "GHOST", "", "a/b"]) | JSON,
       command=COMMANDS | JSON, option=JSON, data=JSON, timeout=JSON)
def test_task_checks_answer_every_body(client: TestClient, service: Any, command: Any, option: Any,
                                       data: Any, timeout: Any) -> None:
    body = answered(send(client, "/api/tasks/check", {
        "service": service, "command": command, "option": option, "data": data,
        "timeout": timeout}))
    if body["ok"]:
        assert service in ("TOOL", "CAMERA")
    else:
        assert set(body["errors"]) <= {"service", "command", "option", "data", "timeout"}


@SETTINGS
@given(kind=st.sampled_from(["circle", "line", "plane"]) | JSON,
       points=st.lists(st.lists(st.floats(-1e4, 1e4) | JSON, min_size=0, max_size=4), max_size=8)
       | JSON)
def test_fits_answer_every_body(client: TestClient, kind: Any, points: Any) -> None:
    body = answered(send(client, "/api/fit", {"kind": kind, "points": points}))
    if body["ok"]:
        assert len(body["residuals"]) == len(points)


@SETTINGS
@given(which=st.sampled_from(["probe", "base"]), body=st.dictionaries(
    st.sampled_from(["circle", "holes", "tmac", "plane", "line", "smr_offset"]), JSON, max_size=6))
def test_wizards_answer_every_body(client: TestClient, which: str, body: dict[str, Any]) -> None:
    answered(send(client, f"/api/wizard/{which}", body))


@SETTINGS
@given(raw=st.binary(max_size=64))
def test_any_bytes_are_refused_cleanly(client: TestClient, raw: bytes) -> None:
    answered(client.post("/api/wiring/load", headers=HEADERS, content=raw))


NUMBER = st.floats(-1e4, 1e4) | st.floats() | st.integers(-2**70, 2**70)
XYZ = st.lists(NUMBER, min_size=3, max_size=3)
POSE = st.dictionaries(st.sampled_from(["set", "index", "measured_mm", "after_mm", "before_mm"]),
                       st.sampled_from(["calibration", "validation"]) | XYZ | JSON, max_size=5)
RESIDUAL_FILE = st.fixed_dictionaries({
    "format": st.just("plugcell-residuals") | JSON, "format_version": st.just(1) | JSON,
    "poses": st.lists(POSE, max_size=4) | JSON, "robot": JSON, "model": JSON})


@SETTINGS
@given(body=st.fixed_dictionaries({"document": RESIDUAL_FILE | JSON})
       | st.fixed_dictionaries({"matrix": st.lists(st.lists(NUMBER, min_size=5, max_size=7),
                                                   min_size=1, max_size=5) | JSON})
       | st.dictionaries(st.sampled_from(["service", "name", "workspace"]), JSON, max_size=3))
@example(body={"matrix": [[1e308, 1e308, 0, 1e308, 1e308, 0]]})  # norms must stay finite
def test_residual_views_answer_every_body(client: TestClient, body: dict[str, Any]) -> None:
    answer = answered(send(client, "/api/residuals", body))
    if answer["ok"]:
        assert answer["poses"] and all(len(p["measured"]) == 3 for p in answer["poses"])
    else:
        assert set(answer["errors"]) <= {"document", "matrix", "service", "name", "workspace",
                                         "_"}


LIVE_FIELDS = {"robot", "tracker", "compute", "reflectors", "base_est", "duration_ms", "matrix",
               "timeout", "joints", "sweep", "line", "_"}
SIX = st.lists(NUMBER, min_size=3, max_size=6)


@SETTINGS
@given(body=st.fixed_dictionaries({
    "reflectors": st.lists(SIX, min_size=1, max_size=3) | JSON,
    "base_est": st.lists(NUMBER, min_size=6, max_size=6) | JSON,
}, optional={
    "robot": st.sampled_from(["TOOL", "GHOST", ""]) | JSON,
    "duration_ms": st.integers(-5, 70_000) | JSON, "matrix": st.sampled_from(["pts", "1x"]) | JSON,
    "timeout": NUMBER | JSON, "joints": st.lists(NUMBER, max_size=11) | JSON,
    "sweep": st.fixed_dictionaries({"joint": st.integers(-1, 12) | JSON, "from": NUMBER | JSON,
                                    "to": NUMBER | JSON, "count": st.integers(-1, 120) | JSON})
    | JSON,
    "line": st.fixed_dictionaries({"axis": st.sampled_from(["x", "q"]) | JSON,
                                   "length": NUMBER | JSON, "count": st.integers(-1, 120)})
    | JSON}))
def test_live_wizard_steps_answer_every_body(client: TestClient, body: dict[str, Any]) -> None:
    """No robot here: every body is refused, each with the field it concerns."""
    answer = answered(send(client, "/api/wizard/live", body))
    assert answer["ok"] is False and set(answer["errors"]) <= LIVE_FIELDS, answer


@SETTINGS
@given(values=st.lists(st.text(max_size=12) | st.sampled_from(["a=1", "b = 2", "=3", "x"]),
                       max_size=5) | st.dictionaries(st.text(max_size=4), JSON, max_size=3)
       | JSON)
def test_run_values_answer_every_body(client: TestClient, values: Any) -> None:
    answer = answered(send(client, "/api/runs", {
        "items": [{"robot": "GHOST", "program": "example", "values": values}]}))
    if not answer["ok"]:
        assert set(answer["errors"]) == {"items"}
