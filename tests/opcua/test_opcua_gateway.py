"""`plugcell opcua serve` seen by an independent OPC UA stack (node-opcua, tests/opcua/js).

One cell per module — CAMERA and TRACKER (simulated) and the gateway, each its own
OS process — and one node-opcua client run per test (docs/opcua.md).
"""

from __future__ import annotations

import numpy as np
import pytest
from opcua_testlib import run_js, wait_shown

from plugcell.framework.bus import Bus
from plugcell.framework.keys import KeySpace
from plugcell.framework.transport import TransportConfig, open_session
from plugcell.io.units import pose_from_robot
from plugcell.sim.world import ReflectorPublisher

pytestmark = pytest.mark.slow

BASE, PROBE = [2500.0, -800.0, -600.0, 30.0, 2.0, -20.0], [0.0, 0.0, 120.0, 0.0, 0.0, 0.0]
POSE = [1200.0, 100.0, 900.0, 10.0, 150.0, -20.0]


def browse(ua_cell, want: set[str]) -> dict:
    """node-opcua's browse once the gateway shows (at least) the services ``want``."""
    wait_shown(ua_cell.url, ua_cell.name, want)
    return run_js("client.js", "browse", ua_cell.url, ua_cell.name)


def test_browse_the_cell_and_read_a_cameras_device_info(ua_cell):
    seen = browse(ua_cell, {"CAMERA", "TRACKER"})
    assert seen["services"] == ["CAMERA", "TRACKER"]
    info = seen["info"]
    assert info["Kind"] == "camera" and info["Model"] == "camera"
    assert info["Vendor"] == info["Manufacturer"] == "plugcell (simulated)"
    assert info["Info"].startswith("Specs: 640x480")
    assert len(info["Instance"]) > 16
    assert info["DeviceState"] == "Ready" and info["ConnectionState"] == "Online"
    assert info["DeviceHealth"] == 0 and info["Partners"] in ([], None)
    for name in ("Connect", "Disconnect", "SnapShot", "MovieShot", "StopMovie", "Processes"):
        assert name in seen["children"]
    # SnapShot(Option: String, Data: Int32 scalar) -> Data: Byte[480, 640]
    assert [(a["name"], a["dataType"], a["valueRank"]) for a in seen["inputArguments"]] == [
        ("Option", 12, -1), ("Data", 6, -1)]
    assert seen["outputArguments"] == [
        {"name": "Data", "dataType": 3, "valueRank": 2, "arrayDimensions": [480, 640]},
        {"name": "Reason", "dataType": 12, "valueRank": -1, "arrayDimensions": []}]


def test_snapshot_returns_the_480_by_640_image(ua_cell):
    wait_shown(ua_cell.url, ua_cell.name, {"CAMERA"})
    got = run_js("client.js", "snapshot", ua_cell.url, ua_cell.name)
    assert got["status"] == "Good"
    image = got["image"]
    assert image["dataType"] == "Byte" and image["dimensions"] == [480, 640]
    assert image["length"] == 480 * 640 and 0 <= image["min"] < image["max"] <= 255


def test_bad_arguments_and_an_unknown_method_are_refused_and_the_server_keeps_serving(ua_cell):
    wait_shown(ua_cell.url, ua_cell.name, {"CAMERA"})
    got = run_js("client.js", "bad", ua_cell.url, ua_cell.name)
    assert got["double"]["status"] == "BadInvalidArgument"
    assert got["double"]["inputResults"] == ["Good", "BadInvalidArgument"]
    assert got["double"]["diagnostics"][1] == (
        "SnapShot: argument Data: Int32 expected (Integer[1]), got scalar Double")
    assert got["vector"]["status"] == "BadInvalidArgument"
    assert got["vector"]["diagnostics"][1] == (
        "SnapShot: argument Data: size [2] does not match the declared [1]")
    assert got["option"]["status"] == "BadInvalidArgument"
    assert got["option"]["diagnostics"][0] == (
        "SnapShot: argument Option must be a String, got scalar Int32")
    assert got["missing"]["status"] == "BadInvalidArgument"
    assert "Integer[1] expected, got nothing" in got["missing"]["diagnostics"][1]
    assert got["tooMany"]["status"] == "BadTooManyArguments"
    assert got["tooMany"]["reason"] == "SnapShot: 3 arguments, but it takes 2 (Option, Data)"
    # the reason is the result's last output (Reason), beside the argument's diagnostics
    assert got["double"]["reason"] == got["double"]["diagnostics"][1]
    assert [o["dataType"] for o in got["double"]["outputs"]] == ["Null", "String"]
    assert got["unknown"]["status"] == "BadNodeIdInvalid"
    assert got["good"] == "Good"


def test_movieshot_is_a_process_object_to_subscribe_to_and_stop(ua_cell):
    wait_shown(ua_cell.url, ua_cell.name, {"CAMERA"})
    got = run_js("client.js", "movie", ua_cell.url, ua_cell.name)
    assert got["status"] == "Good"
    assert got["process"].startswith("ns=") and "/CAMERA/Processes/" in got["process"]
    assert len(got["frames"]) >= 3
    for frame in got["frames"]:
        assert frame["dataType"] == "Byte" and frame["dimensions"] == [480, 640]
        assert frame["length"] == 480 * 640
    assert got["stop"] == "Good" and got["state"] == "Completed"
    assert got["counted"] >= 3
    assert got["stopAgain"] == "BadInvalidState"
    # the DeviceInfo variables are live: Busy while filming; Offline/Online as it goes
    assert got["busy"] == "Busy"
    assert (got["disconnect"], got["offline"]) == ("Good", "Offline")
    assert (got["reconnect"], got["online"]) == ("Good", "Online")


def test_a_closed_session_stops_the_streams_it_started(ua_cell):
    wait_shown(ua_cell.url, ua_cell.name, {"CAMERA"})
    left = run_js("client.js", "abandon", ua_cell.url, ua_cell.name)
    assert left["status"] == "Good" and left["frames"] >= 1
    # the camera is free again: a SnapShot does not wait behind a 10-minute MovieShot hold
    got = run_js("client.js", "snapshot", ua_cell.url, ua_cell.name, limit_s=20.0)
    assert got["status"] == "Good"


def test_a_failed_process_is_a_bad_status_with_the_reason_in_the_result_and_an_event(ua_cell):
    wait_shown(ua_cell.url, ua_cell.name, {"CAMERA"})
    got = run_js("client.js", "events", ua_cell.url, ua_cell.name)
    assert got["fail"] == "BadDeviceFailure"
    assert got["failReason"] == "MovieShot: frame rate 5000 outside 1…80 frames/s"
    assert got["bad"] == "BadInvalidArgument" and got["good"] == "Good"
    assert got["badReason"].startswith("SnapShot: argument Data: Int32 expected")
    assert got["goodReason"] == ""
    by_state = {}
    for event in got["events"]:
        assert event["SourceName"] == event["Service"] == "CAMERA"
        assert event["Sender"] == "OPCUA"
        by_state.setdefault((event["Command"], event["State"]), []).append(event)
    failed = by_state[("MovieShot", "Failed")][0]
    assert failed["Reason"] == "MovieShot: frame rate 5000 outside 1…80 frames/s"
    assert failed["Reason"] in failed["Message"] and failed["Severity"] == 700
    refused = by_state[("SnapShot", "Refused")][0]
    assert "Int32 expected" in refused["Reason"]
    assert by_state[("SnapShot", "Completed")][0]["Reason"] == ""


def test_a_trackers_measurements_arrive_by_subscription(ua_cell):
    wait_shown(ua_cell.url, ua_cell.name, {"TRACKER"})
    session = open_session(TransportConfig.from_env())
    try:
        tmac = ReflectorPublisher(Bus(session, KeySpace(ua_cell.name)), "TMAC_UA", "tmac")
        truth = (pose_from_robot(BASE, "zyz") @ pose_from_robot(POSE, "zyz")
                 @ pose_from_robot(PROBE, "zyz"))
        tmac.publish(truth)
        got = run_js("client.js", "track", ua_cell.url, ua_cell.name, limit_s=45.0,
                     options={"tracker": {"base": BASE, "probe": PROBE, "pose": POSE}})
        tmac.close()
    finally:
        session.close()
    assert got["setup"] == ["Good", "Good", "Good"]
    assert got["status"] == "Good" and got["stop"] == "Good" and got["state"] == "Completed"
    assert len(got["samples"]) >= 3
    for sample in got["samples"]:
        assert sample["dataType"] == "Double" and sample["length"] == 6
        # the robot's pose in its own frame (eq. 7.2), within the tracker's accuracy
        np.testing.assert_allclose(sample["value"][:3], POSE[:3], atol=0.2)


def test_services_appear_and_disappear_as_they_come_and_go(ua_cell):
    wait_shown(ua_cell.url, ua_cell.name, {"CAMERA"})
    extra = ua_cell.serve("camera", "--name", "CAMERA2", "--no-journal")
    wait_shown(ua_cell.url, ua_cell.name, {"CAMERA2"})
    seen = run_js("client.js", "browse", ua_cell.url, ua_cell.name)
    assert {"CAMERA", "CAMERA2", "TRACKER"} <= set(seen["services"])
    extra.stop()
    wait_shown(ua_cell.url, ua_cell.name, set(), gone={"CAMERA2"})
    assert "CAMERA2" not in run_js("client.js", "browse", ua_cell.url, ua_cell.name)["services"]


def test_the_quick_start_of_the_docs_runs(ua_cell, capsys):
    """docs/opcua.md's Python example, pointed at this module's gateway and cell."""
    import re
    from pathlib import Path

    doc = (Path(__file__).resolve().parents[2] / "docs" / "opcua.md").read_text()
    code = re.search(r"\(asyncua\), for instance `snapshot.py`:\n\n<!--.*?-->\n```python\n"
                     r"(.*?)```", doc, re.S).group(1)
    cell = 'os.environ.get("PLUGCELL_CELL", "default")'
    assert cell in code
    code = code.replace("opc.tcp://127.0.0.1:4840/plugcell", ua_cell.url).replace(
        cell, repr(ua_cell.name))
    wait_shown(ua_cell.url, ua_cell.name, {"CAMERA"})
    exec(compile(code, "docs/opcua.md", "exec"), {})
    assert capsys.readouterr().out.split()[-2:] == ["480", "640"]


def test_the_reason_of_a_failed_call_read_with_asyncua_as_the_docs_show(ua_cell, capsys):
    """docs/opcua.md's snippet reading a Bad call's Reason output with asyncua."""
    import asyncio
    import re
    from pathlib import Path

    from asyncua import Client, ua

    doc = (Path(__file__).resolve().parents[2] / "docs" / "opcua.md").read_text()
    snippet = re.search(r"returns the whole\nresult:\n\n```python\n(.*?)```", doc,
                        re.S).group(1)
    wait_shown(ua_cell.url, ua_cell.name, {"CAMERA"})

    async def run() -> None:
        async with Client(ua_cell.url) as client:
            ns = await client.get_namespace_index(f"urn:plugcell:cell:{ua_cell.name}")
            camera = client.get_node(ua.NodeId("Cell/CAMERA", ns))
            body = "async def snippet(client, camera, ns):\n" + "".join(
                f"    {line}\n" for line in snippet.splitlines())
            scope: dict = {"ua": ua}
            exec(compile(body, "docs/opcua.md", "exec"), scope)
            await scope["snippet"](client, camera, ns)

    asyncio.run(run())
    assert capsys.readouterr().out.strip().splitlines()[-1] == (
        "BadDeviceFailure MovieShot: frame rate 5000 outside 1…80 frames/s")
