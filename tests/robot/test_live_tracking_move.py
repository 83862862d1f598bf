"""A real tracked move shown live (issue 38 §2): the 80 mm line of
tests/robot/test_tracked_moves.py on the twin's KUKA RSI side (simulated time, the link's
cycle loop in this process) with the beam blocked 0.7–1.2 s of robot time, its cycles
published by a :class:`LiveTracking` as the move goes.  The batches hold one point a
cycle of the move (settle and line), in order on the path's time; their corrected
deviations are the applied offsets' positions; the measured one is millimetres at the
start (the nominal model), a fraction of one once the correction is in, and one gap
(no good sample) from the break until the tracker has the reflector again; the last
batch ends the move with the loop's counts and its window on the path's time, the
window the points marked as holding as they went.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_tracked_moves import _there_and_back, cell  # noqa: F401

from plugcell.devices.robot.live_tracking import LiveTracking, decode_tracking

pytestmark = pytest.mark.timeout(900)


@pytest.mark.slow
@pytest.mark.parametrize("cell", ["thread"], indirect=True)
def test_a_tracked_move_is_published_as_it_goes(cell):  # noqa: F811
    _, _, motion, tracked, feed = cell
    sent: list[bytes] = []
    live = LiveTracking("H4", sent.append, max_points=10_000)
    tracked.live = lambda: live
    feed.blocked = (0.7, 1.2)
    try:
        assert tracked.move_tracked(_there_and_back(motion, 1.0), "TRACKER") > 1.0
    finally:
        feed.blocked, tracked.live = None, None
    batches = [decode_tracking(b) for b in sent]
    assert [b.seq for b in batches] == list(range(len(batches)))
    assert all(b.end is None for b in batches[:-1]) and batches[-1].end is not None
    assert {b.identity.move for b in batches} == {"move.1"}  # no program runs
    points = [p for b in batches for p in b.points]
    record = tracked.last_record
    assert len(points) == len(record) == tracked.last_loop.stats.cycles
    t = np.array([p.t_s for p in points])
    cycle_s = 0.004
    np.testing.assert_allclose(t, np.arange(len(t)) * cycle_s - round(0.5 / cycle_s) * cycle_s,
                               atol=1e-9)
    np.testing.assert_allclose([p.corrected_m for p in points],
                               [np.linalg.norm(r[1][:3]) for r in record], atol=1e-12)
    robot_t = np.array([r[0] for r in record]) - record[0][0]
    gap = np.array([p.measured_m is None for p in points])
    blocked = (robot_t >= 0.7 + 2 * cycle_s) & (robot_t < 1.2)
    # the feed's first poll starts its stream (no sample yet), then one a cycle until the
    # beam is blocked
    assert gap[0] and gap[blocked].all() and not gap[1:][robot_t[1:] < 0.7].any()
    # one gap, from the break until the tracker has the reflector again (it re-locks
    # after the beam is back: the twin's tracker model), before the move's end
    off = np.flatnonzero(gap[1:]) + 1
    assert np.all(np.diff(off) == 1), off
    assert robot_t[off[-1]] >= 1.2 - cycle_s and off[-1] < len(points) - 1
    print(f"\nno sample from {robot_t[off[0]]:.3f} s to {robot_t[off[-1]]:.3f} s")
    # what the tracker saw: millimetres off with the nominal model at the start, a
    # fraction of one once the loop's correction is in (before the break)
    measured = np.array([np.nan if p.measured_m is None else p.measured_m for p in points])
    before = (robot_t > 0.3) & (robot_t < 0.7)
    assert measured[1] > 1.5e-3 and np.nanmin(measured[before]) < 0.5e-3, measured[1]
    seen = measured[~np.isnan(measured)]
    end = batches[-1].end
    loop = tracked.last_loop
    assert (end.cycles, end.tracking_cycles) == (loop.stats.cycles, loop.stats.tracking_cycles)
    assert [w.reason for w in end.windows] == ["line_of_sight"] and end.failure == ""
    # the cycles the loop held, shown as they went: the window the loop reports
    held = np.array([p.t_s for p in points if p.holding])
    window = end.windows[0]
    assert held.min() == pytest.approx(window.start_s, abs=1e-9)
    assert window.end_s is not None and held.max() == pytest.approx(window.end_s - cycle_s,
                                                                    abs=1e-9)
    start = end.windows[0].start_s + round(0.5 / cycle_s) * cycle_s  # from the move's start
    assert 0.7 <= start <= 0.7 + loop.settings.max_age_s + 0.02, start
    print(f"\n{len(batches)} batches, {len(points)} points; measured max "
          f"{seen.max() * 1e3:.3f} mm; window {end.windows[0]}")
