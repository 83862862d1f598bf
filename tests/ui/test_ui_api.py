"""The controller's web API with Starlette's TestClient against real services (thesis 7.6)."""

from __future__ import annotations

import json
import math
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from cell_testlib import PROGRAMS
from fastapi.testclient import TestClient
from ui_testlib import HEADERS, make_client, services, until

from plugcell.apps.ui.app import STATIC


@pytest.fixture(scope="module")
def docs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("docs")
    (root / "results").mkdir()
    (root / "results" / "8.1.md").write_text("# 8.1\n\n| a | b |\n|---|---|\n| 1 | 2 |\n")
    (root / "results" / "8.1-convergence.png").write_bytes(b"\x89PNG\r\n\x1a\n")
    (root / "results" / "secret.py").write_text("x = 1")
    (root / "report.html").write_text("<html><body>calibration</body></html>")
    return root


@pytest.fixture(scope="module")
def client(module_cell: str, launcher: Any, docs: Path) -> Iterator[TestClient]:
    launcher.serve("drill", module_cell, "--param", "time_scale=0.001")
    launcher.serve("camera", module_cell, "--param", "time_scale=0.001")
    launcher.serve("robot", module_cell, "--param", "sim=true", "--param", "speed=50", name="R1")
    with make_client(module_cell, docs, [docs / "report.html"]) as c:
        until(lambda: services(c), lambda s: {"TOOL", "CAMERA", "R1"} <= {
            n for n, v in s.items() if v["alive"] and v["commands"]}
            and {"TOOL", "CAMERA", "R1"} <= set(s["CONTROLLER"]["partners"]))
        yield c


def test_the_page_is_served_from_plugcell_alone(client: TestClient) -> None:
    page = client.get("/")
    assert page.status_code == 200
    assert '<script type="module" src="/static/js/main.js">' in page.text
    assert "default-src 'self'" in page.headers["content-security-policy"]
    for path in STATIC.rglob("*"):
        if path.suffix in (".html", ".js", ".css"):
            text = path.read_text(encoding="utf-8")
            # no CDN (XML namespace names are not fetched)
            assert not re.search(r"https?://(?!www\.w3\.org/(2000/svg|1999/xhtml))", text), path
            assert client.get(f"/static/{path.relative_to(STATIC)}").status_code == 200


def test_only_local_pages_may_act(client: TestClient) -> None:
    assert client.post("/api/wire", json={}).status_code == 403  # no X-Plugcell header
    assert client.get("/api/snapshot", headers={"Host": "evil.example"}).status_code == 403
    r = client.post("/api/wire", json={}, headers={**HEADERS, "Origin": "http://evil.example"})
    assert r.status_code == 403 and "not accepted" in r.json()["errors"]["_"]
    assert client.post("/api/wire", content=b"{", headers=HEADERS).status_code == 400
    assert client.post("/api/wire", json=[1], headers=HEADERS).status_code == 400


def test_snapshot_has_services_catalogues_and_the_controller(client: TestClient) -> None:
    s = services(client)
    assert s["CONTROLLER"]["controller"]
    assert {"TOOL", "CAMERA", "R1"} <= set(s["CONTROLLER"]["partners"])
    drill = next(c for c in s["TOOL"]["commands"] if c["name"] == "Drill")
    assert drill["input"] == {"type": "Integer", "size": [2], "text": "Integer[2]"}
    assert s["R1"]["kind"] == "robot"


def test_wire_and_unwire_with_inline_refusals(client: TestClient) -> None:
    post = lambda url, body: client.post(url, json=body, headers=HEADERS).json()  # noqa: E731
    assert post("/api/wire", {"service": "R1", "partner": "TOOL"}) == {"ok": True, "reason": ""}
    assert post("/api/wire", {"service": "R1", "partner": "CAMERA"})["ok"]
    assert set(services(client)["R1"]["partners"]) == {"TOOL", "CAMERA"}
    missing = post("/api/wire", {"service": "R1"})
    assert missing["ok"] is False and missing["errors"] == {"partner": "choose a partner"}
    ghost = post("/api/wire", {"service": "R1", "partner": "GHOST"})
    assert ghost["ok"] is False and "GHOST" in ghost["errors"]["partner"]
    assert post("/api/unwire", {"service": "R1", "partner": "CAMERA"})["ok"]
    assert services(client)["R1"]["partners"] == ["TOOL"]
    assert post("/api/wire", {"service": "R1", "partner": "CAMERA"})["ok"]


@pytest.mark.timeout(60)
def test_a_task_runs_and_its_updates_reach_the_websocket(client: TestClient) -> None:
    bad = client.post("/api/tasks/check", headers=HEADERS, json={
        "service": "TOOL", "command": "Drill", "option": "Air", "data": [15], "timeout": -2}).json()
    assert bad["ok"] is False
    assert bad["errors"] == {"data": "size [1] does not match the declared [2]",
                             "timeout": "between 0 and 604800 s"}
    with client.websocket_connect("/ws") as ws:
        first = ws.receive_json()
        assert first["type"] == "snapshot" and first["cell"]
        ack = client.post("/api/tasks", headers=HEADERS, json={
            "service": "CAMERA", "command": "SnapShot", "data": 5}).json()
        assert ack["ok"] and ack["state"] == "Queued"
        for _ in range(200):
            msg = ws.receive_json()
            if msg["type"] == "task" and msg["id"] == ack["id"] and msg["state"] == "Completed":
                assert msg["data"] == {"type": "Byte", "size": [480, 640], "min": 0,
                                       "max": msg["data"]["max"], "mean": msg["data"]["mean"]}
                break
        else:
            pytest.fail("the task's final update never reached the websocket")
    refused = client.post("/api/tasks", headers=HEADERS, json={
        "service": "TOOL", "command": "Drill", "option": "Oil", "data": [550, 1100]}).json()
    assert refused["ok"] is True  # accepted; the device fails it — see the monitor
    snap = until(lambda: client.get("/api/snapshot").json(),
                 lambda s: any(p["id"] == refused["id"] and p["state"] == "Failed"
                               for p in s["processes"]))
    failed = next(p for p in snap["processes"] if p["id"] == refused["id"])
    assert "unknown option 'Oil'" in failed["reason"] and failed["sender"] == "CONTROLLER"


def test_a_robot_program_runs_and_its_processes_are_monitored(client: TestClient) -> None:
    bad = client.post("/api/runs", headers=HEADERS, json={"items": [], "mode": "sequential"}).json()
    assert bad["ok"] is False and "at least one" in bad["errors"]["items"]
    bad = client.post("/api/runs", headers=HEADERS, json={"items": ["R1:x"], "mode": "both"}).json()
    assert "mode must be one of" in bad["errors"]["items"]
    run = client.post("/api/runs", headers=HEADERS, json={
        "items": [{"robot": "R1", "program": str(PROGRAMS / "cellcheck.pdl")}]}).json()["run"]
    snap = until(lambda: client.get("/api/snapshot").json(),
                 lambda s: any(r["id"] == run["id"] and r["state"] != "Running" for r in s["runs"]))
    done = next(r for r in snap["runs"] if r["id"] == run["id"])
    assert done["state"] == "Completed", done
    item = done["items"][0]  # how the program ended: the robot's PROGRAM_STATUS
    assert item["programState"] == "FINISHED" and item["simS"] > 0, json.dumps(item)
    until(lambda: client.get("/api/snapshot").json()["processes"],
          lambda ps: {("R1", "TOOL", "Drill", "Completed"),
                      ("R1", "CAMERA", "SnapShot", "Completed"),
                      ("CONTROLLER", "R1", "ACTIVATE", "Completed")}
          <= {(p["sender"], p["recipient"], p["command"], p["state"]) for p in ps})
    programs = client.get("/api/programs").json()["programs"]
    assert {"example", "calibration"} <= {p["name"] for p in programs}
    assert "PROGRAM" in client.get("/api/programs/example").text.upper()
    assert client.get("/api/programs/nothing").status_code == 404


def test_a_program_that_deactivates_itself_fails_its_run(client: TestClient,
                                                         tmp_path: Path) -> None:
    """Issue 39 §1: a program's own DEACTIVATE fails the run (the next one is skipped) and
    the run shows how it ended; a program that never started shows no earlier status."""
    program = tmp_path / "quits.pdl"
    program.write_text("PROGRAM quits\nBEGIN\n  WRITE LUN_CRT ('quits: no beam')\n"
                       "  DEACTIVATE\nEND quits\n")

    def ended(items: list[Any]) -> dict[str, Any]:
        run = client.post("/api/runs", headers=HEADERS, json={"items": items}).json()["run"]
        snap = until(lambda: client.get("/api/snapshot").json(), lambda s: any(
            r["id"] == run["id"] and r["state"] != "Running" for r in s["runs"]))
        return next(r for r in snap["runs"] if r["id"] == run["id"])

    done = ended([{"robot": "R1", "program": str(program)},
                  {"robot": "R1", "program": str(PROGRAMS / "cellcheck.pdl")}])
    assert done["state"] == "Failed", done
    first, second = done["items"]
    assert first["state"] == "Failed" and "deactivated itself: quits: no beam" in first["reason"]
    assert first["programState"] == "DEACTIVATED", first
    assert first["message"].startswith("quits: no beam (DEACTIVATE at "), first
    assert second["state"] == "Skipped", second
    missing = ended([{"robot": "R1", "program": str(tmp_path / "quits_not.pdl")}])["items"][0]
    assert missing["state"] == "Failed" and "no such program file" in missing["reason"]
    assert missing["programState"] == "", missing  # not the status of quits' run


def test_a_program_gets_its_values(client: TestClient) -> None:
    """The EXAMPLE's taught points come with the ACTIVATE (docs/robot-programs.md)."""
    post = lambda items: client.post("/api/runs", headers=HEADERS, json={"items": items}).json()  # noqa: E731

    def ended(run: dict[str, Any]) -> dict[str, Any]:
        snap = until(lambda: client.get("/api/snapshot").json(), lambda s: any(
            r["id"] == run["id"] and r["state"] != "Running" for r in s["runs"]))
        return next(r for r in snap["runs"] if r["id"] == run["id"])

    points = ["pnt0001=1500,0,1300,0,90,0", "pnt0002 = 1500,200,1000,0,90,0"]
    done = ended(post([{"robot": "R1", "program": "example", "values": points}])["run"])
    assert done["state"] == "Completed", done
    assert done["items"][0]["values"] == 2 and done["items"][0]["programState"] == "FINISHED"
    # the controller's Run command's form: values follow their program
    assert ended(post(["R1:example", *points])["run"])["state"] == "Completed"
    # without them the program fails, and says why
    bare = ended(post([{"robot": "R1", "program": "example"}])["run"])
    assert bare["state"] == "Failed" and "pnt0001" in bare["items"][0]["reason"], bare
    # bad values are refused before anything runs
    for values, words in ((["pnt0001"], "value 1 'pnt0001': expected name=value"),
                          (["1x=2"], "expected name=value"), ("a=1", "values are"),
                          (["a=1\nb=2"], "line break"), ({"a": [1]}, "text or a number")):
        bad = post([{"robot": "R1", "program": "example", "values": values}])
        assert bad["ok"] is False and words in bad["errors"]["items"], (values, bad)
    assert post([{"robot": "R1", "program": "example", "values": {"n": 3, "s": "x"}}])["ok"]


def test_wiring_is_saved_downloaded_and_loaded(client: TestClient, tmp_path: Path) -> None:
    r = client.post("/api/wiring/save", headers=HEADERS, json={"path": str(tmp_path / "w.json")})
    assert r.json()["ok"] and {"service": "R1", "partner": "TOOL"} in r.json()["document"]["wires"]
    down = client.get("/api/wiring")
    assert "attachment" in down.headers["content-disposition"]
    assert down.json()["wires"] == r.json()["document"]["wires"]
    bad = client.post("/api/wiring/save", headers=HEADERS, json={"path": str(tmp_path)}).json()
    assert bad["ok"] is False and "cannot write" in bad["errors"]["path"]
    bad = client.post("/api/wiring/load", headers=HEADERS,
                      json={"path": str(tmp_path / "no")}).json()
    assert bad["ok"] is False and "cannot read" in bad["errors"]["path"]
    loaded = client.post("/api/wiring/load", headers=HEADERS, json={"document": {
        "wires": [{"service": "R1", "partner": "TOOL"}, {"service": "TOOL", "partner": "GHOST"}]}}
    ).json()
    assert loaded["ok"]
    states = {(w["service"], w["partner"]): w["state"] for w in loaded["wiring"]}
    assert states[("R1", "TOOL")] == "in place" and states[("TOOL", "GHOST")] == "waiting"


def circle(n: int = 12, r: float = 100.0) -> list[list[float]]:
    return [[1000 + r * math.cos(2 * math.pi * i / n), 200 + r * math.sin(2 * math.pi * i / n),
             500.0] for i in range(n)]


def test_fits_and_the_appendix_d_wizards(client: TestClient) -> None:
    post = lambda url, body: client.post(url, json=body, headers=HEADERS).json()  # noqa: E731
    fit = post("/api/fit", {"kind": "circle", "points": circle()})
    assert fit["ok"] and abs(fit["radius"] - 100) < 1e-9 and len(fit["residuals"]) == 12
    assert fit["oriented"] and fit["normal"] == pytest.approx([0, 0, 1])
    back = post("/api/fit", {"kind": "circle", "points": [circle()[i] for i in (0, 3, 1, 5)]})
    assert back["ok"] and back["oriented"] is False  # its normal's sign means nothing
    bad = post("/api/fit", {"kind": "circle", "points": [[0, 0, 0], [1, 1, 1]]})
    assert bad["ok"] is False and "at least 3 points" in bad["errors"]["points"]
    bad = post("/api/fit", {"kind": "line", "points": [[0, 0, 0], [0, 0, 0]]})
    assert bad["ok"] is False and bad["errors"]["points"]
    assert post("/api/fit", {"kind": "sphere", "points": []})["errors"] == {
        "kind": "one of circle, line, plane"}
    probe = post("/api/wizard/probe", {"circle": circle(), "holes": [[1000, 150, 500],
                                                                     [1000, 250, 500]],
                                       "tmac": [1000, 200, 600, 0, 0, 0], "smr_offset": 0})
    assert probe["ok"]
    assert probe["probe"]["vector"] == pytest.approx([0, 0, 100, 0, 0, 0], abs=1e-6)
    base = post("/api/wizard/base", {
        "circle": circle(r=300), "plane": [[0, 0, 0], [500, 0, 0], [0, 500, 0], [400, 400, 0]],
        "line": [[0, 0, 900], [100, 0, 900]], "smr_offset": 0})
    assert base["ok"] and base["base"]["xyz_mm"] == pytest.approx([1000, 200, 0], abs=1e-6)
    assert post("/api/wizard/base", {"circle": circle()})["errors"]["plane"]
    assert post("/api/wizard/probe", {"circle": circle(), "holes": [[0, 0, 0], [0, 1, 0]],
                                      "tmac": [1, 2]})["errors"] == {
        "tmac": "a 6-vector [x, y, z mm, roll, pitch, yaw deg] or 4×4"}


def test_reports_are_listed_and_only_they_are_served(client: TestClient) -> None:
    listing = client.get("/api/reports").json()["reports"]
    names = {r["name"] for r in listing}
    assert names == {"report.html", "8.1.md", "8.1-convergence.png"}
    assert client.get("/reports/results/8.1.md").text.startswith("# 8.1")
    assert client.get("/reports/results/8.1-convergence.png").headers["content-type"] == "image/png"
    assert client.get("/reports/results/secret.py").status_code == 404
    assert client.get("/reports/results/..%2F..%2Freport.html").status_code == 404
    cal = client.get("/reports/calibration/0")
    assert cal.status_code == 200 and "calibration" in cal.text
    assert "default-src 'none'" in cal.headers["content-security-policy"]
    assert client.get("/reports/calibration/5").status_code == 404


@pytest.fixture(scope="module")
def residual_document() -> dict[str, Any]:
    """A real ``plugcell calibrate --residuals`` document: the twin, 30 + 12 poses, model 2."""
    import json

    import numpy as np

    from plugcell.calibration import CalibrationData, Calibrator
    from plugcell.io.params import residuals_json
    from plugcell.io.robots import load_robot
    from plugcell.sim.twin.campaign import measure_poses, working_volume_joints
    from plugcell.sim.twin.robot import RobotTwin
    from plugcell.sim.twin.scenario import TwinScenario
    from plugcell.sim.twin.tracker import LaserTracker

    robot = RobotTwin(TwinScenario(seed=2))
    sets = []
    for n, seed in ((30, 1), (12, 2)):
        q = working_volume_joints(robot.description, robot.reveal_truth().profile, n,
                                  np.random.default_rng(seed))
        sets.append(CalibrationData.from_measurements(measure_poses(robot, LaserTracker(seed=2),
                                                                    q)[0]))
    result = Calibrator(load_robot("smart_h4"), "loop").fit(sets[0], validation=sets[1])
    return json.loads(residuals_json(result))


def test_calibration_residuals_for_the_3d_view(client: TestClient, launcher: Any,
                                               module_cell: str,
                                               residual_document: dict[str, Any]) -> None:
    post = lambda body: client.post("/api/residuals", json=body, headers=HEADERS).json()  # noqa: E731
    # a residual file of plugcell calibrate: every pose, its norms, the summaries it carries
    doc = residual_document
    view = post({"document": doc})
    assert view["ok"] and view["source"] == "document"
    assert view["title"] == "smart_h4 · model 2 (loop)"
    assert len(view["poses"]) == 42 and view["poses"][0]["measured"] == doc["poses"][0][
        "measured_mm"]
    for name in ("calibration", "validation"):
        assert view["sets"][name]["poses"] == doc["sets"][name]["poses"]
        assert view["sets"][name]["mean_mm"] == pytest.approx(doc["sets"][name]["mean_mm"])
        assert view["sets"][name]["max_mm"] == pytest.approx(doc["sets"][name]["max_mm"])
        assert view["sets"][name]["before_mean_mm"] == pytest.approx(
            doc["sets"][name]["before"]["mean_mm"])
    assert view["max_mm"] == pytest.approx(max(p["after_norm_mm"] for p in doc["poses"]))
    # bad files and matrices: inline errors naming the field and the pose
    assert "not a residual file" in post({"document": {"format": "plugcell-calibration"}})[
        "errors"]["document"]
    broken = {**doc, "poses": [dict(p) for p in doc["poses"][:3]]}
    broken["poses"][2]["measured_mm"] = [1.0, 2.0]
    assert post({"document": broken})["errors"] == {
        "document": "pose 3: measured_mm must be [x, y, z] in mm"}
    broken["poses"][2] = {**doc["poses"][2], "set": "test"}
    assert "pose 3: set must be one of" in post({"document": broken})["errors"]["document"]
    assert post({"document": {**doc, "format_version": 9}})["errors"]["document"].startswith(
        "format_version 9")
    rows = [[1000.0 + 10 * i, 200.0, 500.0, 0.01 * i, -0.02, 0.03] for i in range(20)]
    view = post({"matrix": rows})
    assert view["ok"] and set(view["sets"]) == {"calibration"}
    assert view["poses"][1]["after_norm"] == pytest.approx(math.hypot(0.01, 0.02, 0.03))
    assert view["sets"]["calibration"]["before_mean_mm"] is None
    assert post({"matrix": [rows[0], rows[1][:5]]})["errors"]["matrix"].startswith(
        "row 2: 6 numbers")
    assert post({"matrix": []})["errors"] == {"matrix": "no rows: a non-empty list expected"}
    nan = client.post("/api/residuals", content=b'{"matrix": [[1, 2, 3, 4, 5, NaN]]}',
                      headers={**HEADERS, "Content-Type": "application/json"}).json()
    assert nan["errors"]["matrix"].startswith("row 1: 6 numbers")
    assert post({"matrix": [[1, 2, 3, 4, 5, True]]})["ok"] is False
    assert set(post({})["errors"]) == {"_"}
    # a compute service's matrix, from a robot's workspace (Get Matrix; for=R1)
    launcher.serve("compute", module_cell)
    until(lambda: services(client), lambda s: s.get("COMPUTE", {}).get("alive")
          and s["COMPUTE"]["commands"])
    ack = client.post("/api/tasks", headers=HEADERS, json={
        "service": "COMPUTE", "command": "Set Matrix", "option": "res; for=R1",
        "data": rows}).json()
    assert ack["ok"], ack
    until(lambda: client.get("/api/snapshot").json()["processes"],
          lambda ps: any(p["id"] == ack["id"] and p["state"] == "Completed" for p in ps))
    view = post({"service": "COMPUTE", "name": "res", "workspace": "R1"})
    assert view["ok"], view
    assert view["title"] == "COMPUTE: res of R1" and len(view["poses"]) == 20
    assert view["poses"][3]["measured"] == rows[3][:3] and view["poses"][3]["after"] == rows[3][3:]
    missing = post({"service": "COMPUTE", "name": "res"})  # the controller's own: empty
    assert "Get Matrix res" in missing["errors"]["name"]
    assert post({"service": "TOOL", "name": "res"})["errors"] == {
        "service": "a live compute service (one with Get Matrix)"}
    assert set(post({"service": "COMPUTE", "name": "1x"})["errors"]) == {"name"}
    assert set(post({"service": "COMPUTE", "name": "res", "workspace": "a/b"})["errors"]) == {
        "workspace"}
