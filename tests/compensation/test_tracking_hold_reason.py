"""A tracker that falls silent and is then known to be gone (issue 38 §4: the tracker
service killed mid-path): the loop holds at once on the silence (``late``), and the
window, still open, then says why for good — the reason given to ``hold()``."""

from __future__ import annotations

import numpy as np

from plugcell.compensation import NominalModel
from plugcell.compensation.tracking import TrackerMeasurement, TrackingLoop
from plugcell.io.robots import load_robot


def test_a_silence_then_a_stop_is_one_window_with_both_reasons():
    model = NominalModel(load_robot("smart_h4"))
    q = np.radians([0.0, -20.0, -100.0, 0.0, 30.0, 0.0])
    T = model.evaluate(q)[0][0]
    loop = TrackingLoop(model)
    for k in range(250):  # 1 s of 4 ms cycles; samples until 0.6 s, the stop at 0.8 s
        t = k * 0.004
        if t < 0.6:
            loop.add(TrackerMeasurement(ts, T) for ts in np.arange(t - 0.006, t - 0.002, 0.001)
                     if ts > 0)
        if abs(t - 0.8) < 1e-9:
            loop.hold("tracker stopped: service TRACKER lost")
        loop.cycle(t, q, T)
    assert len(loop.windows) == 1
    w = loop.windows[0]
    assert w.reason == "late, then tracker stopped: service TRACKER lost"
    assert w.end_s is None and 0.6 < w.start_s < 0.7 and loop.state == "holding"


def test_a_stop_while_tracking_opens_the_window_with_its_reason_alone():
    model = NominalModel(load_robot("smart_h4"))
    q = np.radians([0.0, -20.0, -100.0, 0.0, 30.0, 0.0])
    T = model.evaluate(q)[0][0]
    loop = TrackingLoop(model)
    for k in range(100):
        t = k * 0.004
        loop.add(TrackerMeasurement(ts, T) for ts in np.arange(t - 0.006, t - 0.002, 0.001)
                 if ts > 0)
        if k == 80:
            loop.hold("tracker stopped")
        loop.cycle(t, q, T)
    assert [(w.reason, w.end_s) for w in loop.windows] == [("tracker stopped", None)]
