"""The cell controller relays a robot's tracked move as it goes (issue 38 §2): a
:class:`LiveTracking` publishing on its own Zenoh session (as a robot service does) and
the controller app (Starlette's TestClient): each batch reaches the websocket as a
``tracking`` event, and a listener that comes late finds the move so far in the snapshot.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient
from ui_testlib import make_client, until

from plugcell.devices.robot.live_tracking import LiveTracking, MoveIdentity, TrackingEnd
from plugcell.framework.bus import Bus
from plugcell.framework.keys import KeySpace
from plugcell.framework.transport import TransportConfig

pytestmark = pytest.mark.timeout(90)


@pytest.fixture
def cell_with_robot(module_cell: str) -> Iterator[tuple[TestClient, LiveTracking]]:
    bus = Bus.connect(TransportConfig.from_env(), KeySpace(module_cell))
    publisher = bus.tracking_publisher("H4")
    try:
        with make_client(module_cell) as client:
            yield client, LiveTracking("H4", publisher.put)
    finally:
        publisher.undeclare()
        bus.close()


def _cycles(n: int) -> tuple[np.ndarray, list[Any], list[Any]]:
    """A line's planned positions and n cycles: 0.5 mm offsets, samples 0.2 mm off."""
    plan_p = np.zeros((n + 1, 3))
    plan_p[:, 0] = 4e-4 * np.arange(n + 1)
    record = [(1.0 + 0.004 * k, np.r_[0.0, 0.0, 5e-4, 0, 0, 0], "tracking", None, 1.0)
              for k in range(n)]
    cycles = [(k, (1.0 + 0.004 * k, plan_p[k, 0], 2e-4, 0.0)) for k in range(n)]
    return plan_p, record, cycles


def test_batches_reach_the_websocket_and_the_snapshot(cell_with_robot) -> None:
    client, live = cell_with_robot
    plan_p, record, cycles = _cycles(60)
    shown_r: list[Any] = []
    shown_c: list[Any] = []
    ident = MoveIdentity("line.pdl", 1, "line.1", 1, "TRACKER", 10**18)
    with client.websocket_connect("/ws") as ws:
        assert ws.receive_json()["type"] == "snapshot"
        # the controller's subscriber meets the publisher's session (Zenoh's discovery):
        # publish the move's identity until it is heard
        until(lambda: (live.begin(ident, 0.004, 0.0, plan_p, shown_r, shown_c),
                       client.get("/api/snapshot").json()["tracking"])[1], bool)
        shown_r.extend(record[:30])
        shown_c.extend(cycles[:30])
        live.flush()
        for _ in range(200):
            event = ws.receive_json()
            if event["type"] == "tracking" and event["points"]:
                break
        else:
            pytest.fail("no tracking event with points reached the websocket")
        assert event["service"] == "H4" and event["running"]
        assert event["identity"]["move"] == "line.1"
        # ≤ MAX_POINTS_PER_BATCH (25): the 30 cycles by bins of 2
        t, corrected, measured, holding = np.array(event["points"], dtype=float).T
        np.testing.assert_allclose(t, 0.004 * np.arange(1, 30, 2))
        np.testing.assert_allclose(corrected, 5e-4)
        np.testing.assert_allclose(measured, 2e-4, atol=1e-12)
        assert not holding.any()
        shown_r.extend(record[30:])
        shown_c.extend(cycles[30:])
        live.end(TrackingEnd(60, 60, [], "the nominal model"))
        for _ in range(200):
            event = ws.receive_json()
            if event["type"] == "tracking" and not event["running"]:
                break
        else:
            pytest.fail("the move's end never reached the websocket")
        assert event["end"]["cycles"] == 60
    # a late listener: the move so far, whole
    (snap,) = client.get("/api/snapshot").json()["tracking"]
    assert snap["whole"] and not snap["running"] and snap["service"] == "H4"
    assert len(snap["points"]) == 15 + 15 and snap["points"][-1][0] == pytest.approx(59 * 0.004)
