"""A tracked move as it goes (:mod:`plugcell.devices.robot.live_tracking`, issue 38 §2):
the batch message and its decoder (any bytes: a batch or a ValueError naming the cause),
the decimation of a batch's cycles (each bin's largest deviations, a bin without samples
a gap), and :class:`LiveTracking` reading the cycles a tracked move appends — the
deviations of the corrected command and of the measurement from the commanded path, on
the path's time — published by hand (no loop) and from an event loop in batches.
"""

from __future__ import annotations

import asyncio
import math
import threading

import msgspec
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from plugcell.devices.robot.live_tracking import (
    HoldSpan,
    LiveTracking,
    MoveIdentity,
    TrackingBatch,
    TrackingEnd,
    TrackingPoint,
    decimate,
    decode_tracking,
    encode_tracking,
    identity_now,
)
from plugcell.framework.keys import KeySpace

IDENTITY = MoveIdentity("/tmp/line.pdl", 2, "line.1", 1, "TRACKER", 1_700_000_000_000_000_000)


def _batch(**kw) -> TrackingBatch:
    fields = dict(service="H4", identity=IDENTITY, seq=3,
                  points=[TrackingPoint(-0.5, 0.0, 1e-4), TrackingPoint(0.1, 2e-4, None)],
                  end=TrackingEnd(10, 8, [HoldSpan(0.2, None, "line_of_sight")], "nominal"))
    fields.update(kw)
    return TrackingBatch(**fields)


def test_a_batch_round_trips_and_the_keys_name_the_robot():
    batch = _batch()
    assert decode_tracking(encode_tracking(batch)) == batch
    keys = KeySpace("c1")
    assert keys.tracking("H4") == "plugcell/c1/tracking/H4"
    assert keys.parse_tracking(keys.tracking("H4")) == "H4"
    assert keys.parse_tracking("plugcell/c1/joints/H4") is None
    assert keys.parse_tracking("plugcell/c2/tracking/H4") is None


@pytest.mark.parametrize(("change", "why"), [
    (dict(points=[TrackingPoint(math.nan, 0.0, None)]), r"points\[0\]\.t_s: nan"),
    (dict(points=[TrackingPoint(0.0, -1e-3, None)]), r"points\[0\]\.corrected_m: -0.001 is "
                                                     "not a non-negative finite number"),
    (dict(points=[TrackingPoint(0.0, 0.0, math.inf)]), r"points\[0\]\.measured_m: inf"),
    (dict(service="a/b"), "invalid robot service 'a/b'"),
    (dict(end=TrackingEnd(1, 1, [HoldSpan(math.inf, None, "x")])),
     r"end\.windows\[0\]\.start_s"),
    (dict(seq=-1), r"Expected `int` >= 0 - at `\$.seq`"),
])
def test_a_malformed_batch_is_refused_with_the_cause(change, why):
    with pytest.raises(ValueError, match=why):
        decode_tracking(encode_tracking(_batch(**change)))


def test_a_payload_of_something_else_is_refused():
    with pytest.raises(ValueError, match="Object missing required field `identity`"):
        decode_tracking(msgspec.msgpack.encode({"service": "H4", "seq": 0, "points": []}))
    with pytest.raises(ValueError, match="Input data was truncated"):
        decode_tracking(encode_tracking(_batch())[:-3])


@settings(max_examples=300, deadline=None)
@given(st.one_of(st.binary(max_size=300),
                 st.builds(lambda b, i, x: b[:i] + x + b[i:],
                           st.just(encode_tracking(_batch())), st.integers(0, 200),
                           st.binary(max_size=8))))
def test_any_bytes_are_a_batch_or_a_clean_refusal(payload):
    try:
        batch = decode_tracking(payload)
    except ValueError:
        return
    assert isinstance(batch, TrackingBatch)
    for p in batch.points:
        assert math.isfinite(p.t_s) and p.corrected_m >= 0
        assert p.measured_m is None or p.measured_m >= 0


def test_decimation_keeps_each_bins_largest_deviations_and_its_gaps():
    t = np.arange(10) * 0.004
    corrected = np.array([1, 5, 2, 0, 0, 0, 3, 0, 9, 1], float) * 1e-5
    measured = np.array([2, np.nan, 1, np.nan, np.nan, np.nan, np.nan, 4, np.nan, 3]) * 1e-5
    holding = np.arange(10) == 4
    every = decimate(t, corrected, measured, 10, holding)  # no decimation: one a cycle
    assert [p.t_s for p in every] == pytest.approx(t)
    assert [p.measured_m is None for p in every] == list(np.isnan(measured))
    assert [p.holding for p in every] == list(holding)
    points = decimate(t, corrected, measured, 4, holding)  # bins of 3: [0-2] [3-5] [6-8] [9]
    assert [p.holding for p in points] == [False, True, False, False]
    assert [p.t_s for p in points] == pytest.approx(t[[2, 5, 8, 9]])
    assert [p.corrected_m for p in points] == pytest.approx(np.array([5, 0, 9, 1]) * 1e-5)
    assert [p.measured_m for p in points] == [pytest.approx(2e-5), None, pytest.approx(4e-5),
                                              pytest.approx(3e-5)]
    assert decimate(t[:0], corrected[:0], measured[:0], 4) == []


def _line_move(n: int, cycle_s: float = 0.004) -> tuple[np.ndarray, list, list]:
    """A planned line along x at 0.1 m/s (n+1 samples), its cycles' offsets (1 mm along z
    from cycle 20) and their newest samples: 0.3 mm off the line in y, taken 2 cycles
    before their cycle, none in cycles 40-59 (a beam break, the loop holding in 42-61)."""
    plan_p = np.zeros((n + 1, 3))
    plan_p[:, 0] = 0.1 * cycle_s * np.arange(n + 1)
    record, cycles = [], []
    for k in range(n):
        t = 10.0 + k * cycle_s
        o = np.zeros(6)
        o[2] = 1e-3 if k >= 20 else 0.0
        record.append((t, o, "holding" if 42 <= k < 62 else "tracking", o, 1.0))
        ks = max(k - 2, 0)
        sample = None if 40 <= k < 60 else (t - (k - ks) * cycle_s, plan_p[ks, 0], 3e-4, 0.0)
        cycles.append((k, sample))
    return plan_p, record, cycles


def test_live_tracking_publishes_the_deviations_on_the_paths_time():
    sent: list[bytes] = []
    live = LiveTracking("H4", sent.append, max_points=1000)
    plan_p, record, cycles = _line_move(100)
    shown_record, shown_cycles = [], []
    live.begin(IDENTITY, 0.004, 0.2, plan_p, shown_record, shown_cycles)
    first = decode_tracking(sent[-1])  # at once: the move's identity, no point yet
    assert (first.service, first.identity, first.points, first.end) == ("H4", IDENTITY, [], None)
    shown_cycles.extend(cycles[:31])  # a cycle half appended (its record not yet) waits
    shown_record.extend(record[:30])
    batch = live.flush()
    assert batch is not None and decode_tracking(sent[-1]) == batch
    assert [p.t_s for p in batch.points] == pytest.approx(np.arange(30) * 0.004 - 0.2)
    assert [p.corrected_m for p in batch.points] == [0.0] * 20 + [pytest.approx(1e-3)] * 10
    # the sample 2 cycles old against the commanded position of its own cycle: 0.3 mm
    assert [p.measured_m for p in batch.points] == [pytest.approx(3e-4, abs=1e-12)] * 30
    shown_cycles.extend(cycles[31:])
    shown_record.extend(record[30:])
    batch = live.flush()
    assert batch is not None and len(batch.points) == 70 and batch.seq == first.seq + 2
    gap = [p.t_s for p in batch.points if p.measured_m is None]
    assert gap == pytest.approx(np.arange(40, 60) * 0.004 - 0.2)
    held = [p.t_s for p in batch.points if p.holding]
    assert held == pytest.approx(np.arange(42, 62) * 0.004 - 0.2)
    live.end(TrackingEnd(100, 80, [HoldSpan(10.0 + 40 * 0.004, 10.0 + 62 * 0.004,
                                            "line_of_sight")], "the nominal model", ""))
    last = decode_tracking(sent[-1])
    assert last.points == [] and last.end is not None
    assert (last.end.cycles, last.end.tracking_cycles) == (100, 80)
    window = last.end.windows[0]  # on the path's time
    assert (window.start_s, window.end_s) == (pytest.approx(-0.04), pytest.approx(0.048))
    assert live.flush() is None  # no move runs


def test_a_loaded_loops_cycles_are_decimated_to_the_batch_size():
    sent: list[bytes] = []
    live = LiveTracking("H4", sent.append, max_points=25)
    plan_p, record, cycles = _line_move(100)
    live.begin(IDENTITY, 0.004, 0.0, plan_p, record, cycles)  # 100 cycles at once
    batch = decode_tracking(sent[-1])
    assert len(batch.points) == 25
    assert [p.measured_m is None for p in batch.points] == [False] * 10 + [True] * 5 + \
        [False] * 10


def test_batches_are_published_from_the_event_loop_while_the_move_runs():
    """begin/end from the program's thread; the batches from the loop's thread."""
    loop = asyncio.new_event_loop()
    runner = threading.Thread(target=loop.run_forever, daemon=True)
    runner.start()
    published: list[tuple[str, TrackingBatch]] = []
    got_end = threading.Event()

    def publish(payload: bytes) -> None:
        batch = decode_tracking(payload)
        published.append((threading.current_thread().name, batch))
        if batch.end is not None:
            got_end.set()

    try:
        live = LiveTracking("H4", publish, loop, rate_hz=200.0, max_points=1000)
        plan_p, record, cycles = _line_move(100)
        shown_record, shown_cycles = [], []
        live.begin(IDENTITY, 0.004, 0.0, plan_p, shown_record, shown_cycles)
        for r, c in zip(record, cycles, strict=True):
            shown_cycles.append(c)
            shown_record.append(r)
        live.end(TrackingEnd(100, 100, [], "nominal"))
        assert got_end.wait(10)
    finally:
        loop.call_soon_threadsafe(loop.stop)
        runner.join(5)
        loop.close()
    assert {name for name, _ in published} == {runner.name}
    assert sum(len(b.points) for _, b in published) == 100
    assert [b.seq for _, b in published] == list(range(len(published)))
    assert published[-1][1].end is not None


def test_a_publisher_that_fails_never_fails_the_move(caplog):
    def broken(payload: bytes) -> None:
        raise RuntimeError("session closed")

    live = LiveTracking("H4", broken)
    plan_p, record, cycles = _line_move(10)
    live.begin(IDENTITY, 0.004, 0.0, plan_p, record, cycles)
    assert live.flush() is not None
    assert "live tracking not published: RuntimeError: session closed" in caplog.text


def test_the_identity_counts_the_moves_of_a_program_run():
    ident = identity_now(("/x/line.pdl", 4), 2, "TRACKER")
    assert (ident.program, ident.run, ident.move, ident.number) == ("/x/line.pdl", 4,
                                                                     "line.2", 2)
    assert identity_now(None, 1, "T").move == "move.1"
    with pytest.raises(ValueError, match="must be positive"):
        LiveTracking("H4", print, rate_hz=0)


def test_a_live_view_that_fails_never_fails_the_move(caplog):
    """A service whose live display cannot be made (its bus refusing): the move is not
    shown, the reason logged, and nothing raised into the move."""
    from plugcell.devices.robot.tracked_moves import TrackedMoves

    def broken() -> LiveTracking:
        raise RuntimeError("the session is closed")

    moves = TrackedMoves(None, lambda name: None, live=broken)
    moves._live_begin("TRACKER", 0.004)
    assert moves._live is None
    assert "not shown live (RuntimeError: the session is closed)" in caplog.text
    counted: list[bytes] = []
    moves.live = lambda: LiveTracking("H4", counted.append)
    moves.program = lambda: ("/p/line.pdl", 7)
    moves._live_begin("TRACKER", 0.004)
    moves._live_begin("TRACKER", 0.004)  # the run's second tracked move
    assert [decode_tracking(b).identity.move for b in counted] == ["line.1", "line.2"]
