"""A tracked move as it goes: the display stream the web UI plots live (issue 38 §2).

While :class:`~.tracked_moves.TrackedMoves` streams a ``MOVE LINEAR TO p WITH TRACKING``
its cycle loop appends, per robot cycle, the offset it applied and the newest good
tracker sample of the cycle (nothing more: the real-time path only appends).  A
:class:`LiveTracking` of the robot service reads what was appended since its last batch
— from the service's event loop, at most :data:`DEFAULT_RATE_HZ` times a second — and
publishes one :class:`TrackingBatch` (msgpack, msgspec) on
``plugcell/<cell>/tracking/<service>`` (:meth:`KeySpace.tracking
<plugcell.framework.keys.KeySpace.tracking>`), with Zenoh's DROP congestion control: a
display stream, a lost batch is a gap in the plot, never a late robot cycle.

Each batch names the move (robot service, program and run, the move's key ``P.n`` —
the ``n``-th tracked move of the run — tracker, start time) and holds one
:class:`TrackingPoint` per cycle since the last batch, decimated to at most
``max_points`` by bins of consecutive cycles (each bin's largest values, so a peak is
never hidden).  Per cycle ``k`` of the move, in SI units (m, s):

* ``t_s = k·T − settle_s`` — the path's time (s from the motion's start; negative while
  the robot stands at the start, the correction blending in);
* ``corrected_m = ‖Δp_k‖`` — the deviation of the corrected command from the commanded
  path: the position part of the offset ``o_k = [Δp; φ]`` the cycle applied;
* ``measured_m = ‖p_s − p_c(k_s)‖`` — the deviation of the tracker's measurement from the
  commanded path: the newest good sample of the cycle (TCP position ``p_s`` in F0 at
  robot time ``t``) against the planned TCP position ``p_c`` at the sample's own cycle
  ``k_s`` (the cycles' robot times ``(t_j, k_j)`` interpolated at ``t``, ``p_c``
  interpolated between samples) — ``None`` when the cycle got no good sample (a beam
  break, a late tracker);
* ``holding`` — the loop held on the model alone in the cycle (a window without
  tracking, shown as it goes).

The last batch of a move carries ``end`` (:class:`TrackingEnd`): the loop's counts, its
windows on the model alone (on the path's time) and why the move failed, if it did.
:func:`decode_tracking` refuses any payload that is not such a batch with a ValueError
naming the cause.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Annotated, Any

import msgspec
import numpy as np
from numpy.typing import NDArray

from plugcell.framework.keys import check_name

__all__ = [
    "DEFAULT_RATE_HZ",
    "MAX_POINTS_PER_BATCH",
    "HoldSpan",
    "LiveTracking",
    "MoveIdentity",
    "TrackingBatch",
    "TrackingEnd",
    "TrackingPoint",
    "decimate",
    "decode_tracking",
    "encode_tracking",
    "identity_now",
    "live_tracking_of",
]

log = logging.getLogger(__name__)

Array = NDArray[np.float64]

#: Batches per second at most (the plot follows at this rate).
DEFAULT_RATE_HZ = 10.0
#: Points of one batch at most (250 a second at the default rate: a 4 ms cycle in full).
MAX_POINTS_PER_BATCH = 25
#: What a decoder accepts at most: points of one batch, windows of one move.
MAX_DECODED_POINTS, MAX_WINDOWS = 10_000, 1_000
#: Cycles a sample's own cycle is looked up among (2 s at 4 ms).
HISTORY = 500

_Text = Annotated[str, msgspec.Meta(max_length=512)]


class TrackingPoint(msgspec.Struct, frozen=True, array_like=True):
    """One plotted cycle (module doc): path time (s), deviations (m) of the corrected
    command and of the measurement (None: no fresh sample) from the commanded path, and
    whether the loop held on the model alone (its state ``"holding"``)."""

    t_s: float
    corrected_m: float
    measured_m: float | None
    holding: bool = False


class HoldSpan(msgspec.Struct, frozen=True, array_like=True):
    """A window on the model alone, on the path's time (s; ``end_s`` None: not resumed)."""

    start_s: float
    end_s: float | None
    reason: _Text


class TrackingEnd(msgspec.Struct, frozen=True):
    """How a tracked move ended: the loop's cycles, those with the tracker term fully on,
    its windows on the model alone, the loop's model (words) and the failure ("": none)."""

    cycles: Annotated[int, msgspec.Meta(ge=0)]
    tracking_cycles: Annotated[int, msgspec.Meta(ge=0)]
    windows: Annotated[list[HoldSpan], msgspec.Meta(max_length=MAX_WINDOWS)]
    model: _Text = ""
    failure: _Text = ""


class MoveIdentity(msgspec.Struct, frozen=True):
    """Which move: program (``""``: none runs), its run, the move's key ``P.n`` and
    number ``n`` in the run, the tracker, the start (ns since the epoch)."""

    program: _Text
    run: Annotated[int, msgspec.Meta(ge=0)]
    move: _Text
    number: Annotated[int, msgspec.Meta(ge=1)]
    tracker: _Text
    start_ns: Annotated[int, msgspec.Meta(ge=0)]


class TrackingBatch(msgspec.Struct, frozen=True):
    """One batch of a robot service's tracked move (module doc); SI units."""

    service: str
    identity: MoveIdentity
    seq: Annotated[int, msgspec.Meta(ge=0)]
    points: Annotated[list[TrackingPoint], msgspec.Meta(max_length=MAX_DECODED_POINTS)]
    end: TrackingEnd | None = None


_ENCODER = msgspec.msgpack.Encoder()
_DECODER = msgspec.msgpack.Decoder(TrackingBatch)


def encode_tracking(batch: TrackingBatch) -> bytes:
    """A batch as the bytes published."""
    return _ENCODER.encode(batch)


def _finite(x: float | None, what: str, *, nonneg: bool = False) -> None:
    if x is None:
        return
    if not math.isfinite(x) or (nonneg and x < 0):
        raise ValueError(f"{what}: {x!r} is not a {'non-negative ' if nonneg else ''}"
                         "finite number")


def decode_tracking(payload: bytes) -> TrackingBatch:
    """The batch of a published payload.

    Raises
    ------
    ValueError
        The bytes are not a batch (msgspec.DecodeError, itself a ValueError), or one of
        its numbers is not finite (a deviation negative), or its service is not a name.
    """
    batch = _DECODER.decode(payload)
    check_name(batch.service, "robot service")
    for i, p in enumerate(batch.points):
        _finite(p.t_s, f"points[{i}].t_s")
        _finite(p.corrected_m, f"points[{i}].corrected_m", nonneg=True)
        _finite(p.measured_m, f"points[{i}].measured_m", nonneg=True)
    if batch.end is not None:
        for i, w in enumerate(batch.end.windows):
            _finite(w.start_s, f"end.windows[{i}].start_s")
            _finite(w.end_s, f"end.windows[{i}].end_s")
    return batch


def decimate(t_s: Array, corrected: Array, measured: Array, max_points: int,
             holding: NDArray[np.bool_] | None = None) -> list[TrackingPoint]:
    """At most ``max_points`` points of consecutive cycles: bins of ``⌈n / max_points⌉``
    cycles, each the bin's last path time and largest deviations (``measured`` NaN where
    a cycle had no sample: the bin's None when none of its cycles had one), holding if
    any of its cycles held.

    Parameters
    ----------
    t_s, corrected, measured : (n,) arrays
        Path times (s) and deviations (m) of the cycles.
    holding : (n,) bool array, optional
        The cycles the loop held on the model alone (default: none).
    max_points : int
        Points at most (≥ 1).

    Returns
    -------
    list of TrackingPoint
        ``⌈n / ⌈n / max_points⌉⌉`` points, in order (none for no cycle).
    """
    n = len(t_s)
    if n == 0:
        return []
    size = -(-n // max_points)
    starts = np.arange(0, n, size)
    last = np.minimum(starts + size, n) - 1
    c = np.maximum.reduceat(corrected, starts)
    seen = ~np.isnan(measured)
    any_seen = np.logical_or.reduceat(seen, starts)
    m = np.maximum.reduceat(np.where(seen, measured, -np.inf), starts)
    held = np.zeros(len(starts), bool) if holding is None else \
        np.logical_or.reduceat(np.asarray(holding, bool), starts)
    return [TrackingPoint(float(t_s[j]), float(ci), float(mi) if ok else None, bool(hi))
            for j, ci, mi, ok, hi in zip(last, c, m, any_seen, held, strict=True)]


class _Move:
    """What :class:`LiveTracking` reads of the move in progress (filled by its cycles)."""

    def __init__(self, identity: MoveIdentity, cycle_s: float, settle_s: float,
                 plan_p: Array, record: Sequence[Any], cycles: Sequence[Any]) -> None:
        self.identity, self.cycle_s, self.settle_s = identity, cycle_s, settle_s
        self.plan_p, self.record, self.cycles = plan_p, record, cycles
        self.done = 0  # cycles published
        self.t: list[float] = []  # robot time of each cycle read (for the samples' k)
        self.k: list[int] = []

    def path_time(self, robot_t: float) -> float:
        """The path time (s) at robot time ``robot_t`` (the cycles read so far)."""
        t, k = np.asarray(self.t), np.asarray(self.k, dtype=float)
        if len(t) == 0:
            return -self.settle_s
        keep = np.concatenate([[True], np.diff(t) > 0])
        return float(np.interp(robot_t, t[keep], k[keep])) * self.cycle_s - self.settle_s

    def read(self) -> tuple[Array, Array, Array, NDArray[np.bool_]]:
        """Path times, corrected and measured deviations (m) and whether the loop held, of
        the cycles since the last read (a sample's cycle is looked up among the last
        :data:`HISTORY` cycles: older ones — a tracker seconds late — are put at the
        oldest of them)."""
        n = min(len(self.record), len(self.cycles))
        rec, cyc = self.record[self.done:n], self.cycles[self.done:n]
        self.done = n
        if not rec:
            return np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0, bool)
        self.t.extend(float(r[0]) for r in rec)
        k = np.array([c[0] for c in cyc], dtype=float)
        self.k.extend(k.astype(int).tolist())
        corrected = np.linalg.norm(np.array([np.asarray(r[1])[:3] for r in rec]), axis=1)
        holding = np.array([r[2] == "holding" for r in rec], dtype=bool)
        measured = np.full(len(cyc), np.nan)
        rows = [(i, c[1]) for i, c in enumerate(cyc) if c[1] is not None]
        if rows:
            t_all = np.asarray(self.t[-(len(rec) + HISTORY):])
            k_all = np.asarray(self.k[-(len(rec) + HISTORY):], dtype=float)
            keep = np.concatenate([[True], np.diff(t_all) > 0])
            smp = np.array([s for _, s in rows], dtype=float)
            ks = np.interp(smp[:, 0], t_all[keep], k_all[keep])
            idx = np.arange(len(self.plan_p), dtype=float)
            p_c = np.stack([np.interp(ks, idx, self.plan_p[:, j]) for j in range(3)], 1)
            measured[[i for i, _ in rows]] = np.linalg.norm(smp[:, 1:4] - p_c, axis=1)
        return k * self.cycle_s - self.settle_s, corrected, measured, holding


class LiveTracking:
    """A robot service's live display of its tracked moves (module doc).

    :meth:`begin` and :meth:`end` are called from the program's thread; the batches are
    published from ``loop`` (the service's event loop) every ``1/rate_hz`` s while a move
    runs — or, without a loop (tests), by calling :meth:`flush`.

    Parameters
    ----------
    service : str
        The robot service's name.
    publish : callable
        Sends one encoded batch (``publisher.put``; DROP congestion control).
    loop : asyncio.AbstractEventLoop, optional
        Where the batches are published from.
    rate_hz : float
        Batches per second at most.
    max_points : int
        Points of one batch at most.
    """

    def __init__(self, service: str, publish: Callable[[bytes], Any],
                 loop: asyncio.AbstractEventLoop | None = None, *,
                 rate_hz: float = DEFAULT_RATE_HZ,
                 max_points: int = MAX_POINTS_PER_BATCH) -> None:
        if not (rate_hz > 0) or max_points < 1:
            raise ValueError(f"live tracking: rate {rate_hz} Hz and {max_points} points a "
                             "batch must be positive")
        self.service, self.publish, self.loop = check_name(service), publish, loop
        self.period, self.max_points = 1.0 / rate_hz, max_points
        self.seq = 0
        self._move: _Move | None = None
        self._lock = threading.Lock()
        self._task: asyncio.Task[None] | None = None
        self._failing = ""

    def begin(self, identity: MoveIdentity, cycle_s: float, settle_s: float, plan_p: Array,
              record: Sequence[Any], cycles: Sequence[Any]) -> None:
        """A tracked move starts: its cycles will be appended to ``record`` (``(t, o, …)``
        of :attr:`TrackedMoves.last_record`) and ``cycles`` (``(k, sample)``, ``sample``
        ``(t, x, y, z)`` robot s and m in F0, or None), ``plan_p`` (K+1, 3) its planned TCP
        positions (m, F0) per sample ``k``."""
        with self._lock:
            self._move = _Move(identity, cycle_s, settle_s, np.asarray(plan_p, dtype=float),
                               record, cycles)
        self._publish_now()  # the move's identity, at once
        if self.loop is not None:
            self._call(self._start_task)

    def flush(self) -> TrackingBatch | None:
        """Publish the cycles since the last batch; the batch (None: no move runs)."""
        with self._lock:
            move = self._move
            return None if move is None else self._publish(move, None)

    def end(self, end: TrackingEnd) -> None:
        """The move ended (``end.windows`` on the robot's time: put on the path's here);
        its last batch is published (from the loop, if any)."""
        with self._lock:
            move, self._move = self._move, None
        if move is None:
            return
        if self.loop is None:
            with self._lock:
                self._publish(move, end)
        else:
            self._call(self._finish, move, end)

    def _publish(self, move: _Move, end: TrackingEnd | None) -> TrackingBatch:
        """Publish ``move``'s cycles since its last batch, with ``end``."""
        t, c, m, held = move.read()
        if end is not None:
            end = msgspec.structs.replace(end, windows=[
                HoldSpan(move.path_time(w.start_s),
                         None if w.end_s is None else move.path_time(w.end_s), w.reason)
                for w in end.windows])
        batch = TrackingBatch(self.service, move.identity, self.seq,
                              decimate(t, c, m, self.max_points, held), end)
        self.seq += 1
        try:
            self.publish(encode_tracking(batch))
        except Exception as exc:  # a display: the move goes on
            reason = f"{type(exc).__name__}: {exc}"
            if reason != self._failing:
                log.warning("live tracking not published: %s", reason)
            self._failing = reason
        return batch

    # -- in the event loop ----------------------------------------------------------------

    def _call(self, fn: Callable[..., Any], *args: Any) -> None:
        loop = self.loop
        if loop is not None and not loop.is_closed():
            with contextlib.suppress(RuntimeError):  # the loop is shutting down
                loop.call_soon_threadsafe(fn, *args)

    def _publish_now(self) -> None:
        if self.loop is None:
            self.flush()
        else:
            self._call(self.flush)

    def _start_task(self) -> None:
        if self._task is None or self._task.done():
            self._task = asyncio.get_running_loop().create_task(self._run(),
                                                                name="live-tracking")

    def _finish(self, move: _Move, end: TrackingEnd) -> None:
        task, self._task = self._task, None
        if task is not None:
            task.cancel()
        with self._lock:
            self._publish(move, end)

    async def _run(self) -> None:
        while True:
            await asyncio.sleep(self.period)
            self.flush()


def identity_now(program: tuple[str, int] | None, number: int, tracker: str
                 ) -> MoveIdentity:
    """The identity of the ``number``-th tracked move of ``program`` ``(name, run)``
    (None: no program runs), starting now."""
    name, run = program if program is not None else ("", 0)
    stem = Path(name).stem[:400] if name else "move"
    return MoveIdentity(name[-512:], run, f"{stem}.{number}", number, tracker[:512],
                        time.time_ns())


def live_tracking_of(device: Callable[[], Any],
                     loop: Callable[[], asyncio.AbstractEventLoop | None]
                     ) -> Callable[[], LiveTracking | None]:
    """``live()`` of a robot service's tracked moves: its :class:`LiveTracking`, made at
    the first move on the service's bus (``device()``: the service; its publisher closed
    with it) and published from ``loop()`` — None while either is missing.

    Parameters
    ----------
    device : callable
        The robot service (:class:`plugcell.framework.service.GenericDevice`: its name,
        participant's bus and ``own``), looked up at the first move.
    loop : callable
        The service's event loop (None: not connected).
    """
    made: list[LiveTracking] = []

    def live() -> LiveTracking | None:
        if made:
            return made[0]
        host = device()
        bus, running = host.participant.bus, loop()
        if bus is None or running is None:
            return None
        publisher = host.own(bus.tracking_publisher(host.name))
        made.append(LiveTracking(host.name, publisher.put, running))
        return made[0]

    return live
