"""A motion's per-cycle adjustment computed in the service while the link runs in its child.

A tracked move (:mod:`~plugcell.devices.robot.tracked_moves`) adds a correction to every
cycle's joints, computed from the laser tracker's samples, which arrive in the robot
service's process (its participant holds the tracker's ``Stream Measurement``).  With the
link in a child process (:class:`~.process.LinkProcess`) the correction crosses the
process boundary through two small blocks of shared memory, each a seqlock
(:class:`SeqVector`):

* **the cycle** — written by the child in the link's thread, each cycle of an adjusted
  motion, before the answer: the motion's number, the sample index ``k``, the robot's time
  ``t`` (s, the session's clock), the PC time it was handled (``time.time()``: a tracked
  move maps its tracker's samples onto the robot's clock with it) and the actual joints
  ``q`` (rad; NaN if the packet had none) — what the in-process hook is given — and,
  again after the answer, the :class:`WirePeaks` of what it sent so far;
* **the adjustment** — written by the service's :class:`AdjustPump` (a thread) whenever it
  has computed one for a newer cycle: the motion's number, the cycle's ``k``, ``Δq``
  (rad, (6,)) and the motion's :class:`WireLimits` (the robot cycle ``T`` and the
  joints' speed and acceleration bounds; ``T = 0``: none).

The child never waits for an adjustment, as the in-process link takes the newest offset
of its worker thread (``tracked_moves._Worker``): the loop's cost and the service's
interpreter never make an answer late; an adjustment reaches the wire one or two cycles
after the cycle it was computed for.  The newest ``Δq`` of its motion (zeros before the
first) is the *target* of what the child sends: each robot cycle it moves the sent
``Δq_wire`` towards it with the loop's own limiter
(:class:`~plugcell.compensation.tracking.RateLimiter`, ``n = 1``: the child answers every
cycle) at the motion's :class:`WireLimits`, so on the wire, in the robot's time::

    |Δq_wire,k − Δq_wire,k−1| ≤ v T,     |Δq_wire,k − 2 Δq_wire,k−1 + Δq_wire,k−2| ≤ a T²

whatever cycles the service's loop skipped (a loaded machine: the ``n``-cycle step the
loop computed for a cycle ``n`` after its last would otherwise reach the robot in one),
and a held target is reached without overshoot (but for the limiter's ``a T²/8``).
Nothing but floats crosses: no pickling, no lock shared between the processes.

In *simulated time* (a controller that waits for each answer: a test, ``plugcell path
run``) the child may wait instead (``wait_s``): for the adjustment of the very cycle it
answers, at most that long — each cycle then runs the loop, as an in-process link's
hook does, and the result does not depend on how the two processes were scheduled.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from plugcell.compensation.tracking import RateLimiter

from .source import CycleState

__all__ = ["CYCLE_SLOTS", "OFFSET_SLOTS", "AdjustPump", "ChildAdjust", "SeqVector",
           "WireLimits", "WirePeaks"]

Array = NDArray[np.float64]

#: The cycle block: [seq, motion, k, t, pc, q × 6, peak step × 6, peak change × 6].
CYCLE_SLOTS = 23
#: The adjustment block: [seq, motion, k, Δq × 6, T, v × 6, a × 6] (:class:`WireLimits`).
OFFSET_SLOTS = 22


class SeqVector:
    """Doubles in shared memory behind a sequence number (slot 0): one writer, any readers.

    The writer makes the number odd while it writes and even when done; a reader copies
    the values and retries when it saw the number odd or changed (a *seqlock*).

    Parameters
    ----------
    raw : RawArray of double
        The shared block; slot 0 is the sequence number.
    """

    def __init__(self, raw: Any) -> None:
        self.raw = raw
        self.v = np.frombuffer(raw, dtype=np.float64)

    def write(self, values: Array) -> None:
        """Write ``values`` into slots 1… (one writer only)."""
        v = self.v
        v[0] += 1  # odd: being written
        v[1:1 + len(values)] = values
        v[0] += 1  # even: consistent

    def snapshot(self) -> Array:
        """A consistent copy of every slot, the sequence number's included."""
        v = self.v
        while True:
            seq = v[0]
            if seq % 2 == 0:
                values = v.copy()
                if v[0] == seq:
                    return values
            time.sleep(0)

    def read(self) -> Array:
        """A consistent copy of slots 1…."""
        return self.snapshot()[1:]


@dataclass(frozen=True)
class WireLimits:
    """How fast the joint correction sent to the robot may change, in the robot's time.

    Attributes
    ----------
    cycle_s : float
        The robot's cycle ``T`` (s), > 0.
    max_speed : (6,) array_like
        ``v`` per joint (rad/s), > 0.
    max_accel : (6,) array_like
        ``a`` per joint (rad/s²), > 0.
    """

    cycle_s: float
    max_speed: Array
    max_accel: Array

    def __post_init__(self) -> None:
        self.limiter()  # refuses bad values with the limiter's reason

    def limiter(self) -> RateLimiter:
        """A limiter of the rate alone (no bound on the total), at rest at zero."""
        return RateLimiter(self.cycle_s, self.max_speed, self.max_accel, np.full(6, np.inf))

    def slots(self) -> Array:
        """``[T, v × 6, a × 6]``: the adjustment block's tail."""
        return np.r_[self.cycle_s, np.asarray(self.max_speed, dtype=float).reshape(6),
                     np.asarray(self.max_accel, dtype=float).reshape(6)]

    @staticmethod
    def from_slots(values: Array) -> WireLimits | None:
        """The limits of :meth:`slots` (``None`` when ``T`` is 0: no limits)."""
        if values[0] == 0:
            return None
        return WireLimits(float(values[0]), values[1:7].copy(), values[7:13].copy())


class WirePeaks:
    """The largest step a robot cycle ``|Δq_k − Δq_k−1|`` and change of step
    ``|Δq_k − 2 Δq_k−1 + Δq_k−2|`` of the joint correction sent, per joint (rad), from
    rest at zero: what the robot was given, in its time (:class:`WireLimits` bound them).
    """

    def __init__(self) -> None:
        self.last, self.last_step = np.zeros(6), np.zeros(6)
        self.step, self.change = np.zeros(6), np.zeros(6)

    def add(self, sent: Array) -> Array:
        """Count one robot cycle's ``sent`` (rad, (6,)); returns it."""
        step = sent - self.last
        self.step = np.maximum(self.step, np.abs(step))
        self.change = np.maximum(self.change, np.abs(step - self.last_step))
        self.last, self.last_step = sent, step
        return sent

    def slots(self) -> Array:
        """``[step × 6, change × 6]``."""
        return np.r_[self.step, self.change]


#: The adjustment block's tail without limits.
_NO_LIMITS = np.zeros(13)


@dataclass(frozen=True)
class PumpedRobot:
    """The part of a cycle's packet the service's hook is given: the actual joints (rad)
    and the PC time the child handled the packet (``time.time()``, s)."""

    joints: Array | None
    pc_time_s: float


class ChildAdjust:
    """The child's end: the drive's ``adjust`` hook of motion ``motion`` (module docstring).

    Parameters
    ----------
    cycle, offset : SeqVector
        The cycle block (written here) and the adjustment block (read here).
    motion : int
        The motion's number (an adjustment of another motion is not used).
    wait_s : float
        0: take the newest adjustment at once (real time); > 0: wait for this cycle's, at
        most this long (s; simulated time), then take the newest.

    Each call is one robot cycle; it answers the ``Δq`` to send (module docstring: the
    newest adjustment as its target, moved towards at the motion's :class:`WireLimits`;
    the target as is when the service gave none).
    """

    def __init__(self, cycle: SeqVector, offset: SeqVector, motion: int,
                 wait_s: float = 0.0) -> None:
        self.cycle, self.offset, self.motion, self.wait_s = cycle, offset, motion, wait_s
        self._limiter: RateLimiter | None = None
        self._limited = False  # the motion's limits were read (they come with its block)
        self.peaks = WirePeaks()

    def __call__(self, state: CycleState, k: int, q_k: Array) -> Array:
        joints = state.robot.joints
        q = np.full(6, np.nan) if joints is None else np.asarray(joints, dtype=float)
        row = np.r_[self.motion, k, state.t, time.time(), q, self.peaks.slots()]
        self.cycle.write(row)
        sent = self.peaks.add(self._send(k))
        row[10:] = self.peaks.slots()
        self.cycle.write(row)  # the peaks with this cycle's (AdjustPump.peaks)
        return sent

    def _send(self, k: int) -> Array:
        """The ``Δq`` to send in the cycle of sample ``k`` (class docstring)."""
        newest = self.offset.read()
        if self.wait_s > 0:
            end = time.monotonic() + self.wait_s
            while not (newest[0] == self.motion and newest[1] >= k) and \
                    time.monotonic() < end:
                time.sleep(5e-5)
                newest = self.offset.read()
        if newest[0] != self.motion:
            return np.zeros(6) if self._limiter is None else self._limiter.apply(np.zeros(6))
        if not self._limited:
            self._limited = True
            limits = WireLimits.from_slots(newest[8:21])
            self._limiter = None if limits is None else limits.limiter()
        target = newest[2:8]
        return target if self._limiter is None else self._limiter.apply(target)


class AdjustPump:
    """The service's end: runs ``adjust`` on each new cycle the child published and writes
    the result for the child (module docstring).

    Parameters
    ----------
    adjust : callable
        ``adjust(state, k, q_k) -> Δq`` (rad, (6,)), as for an in-process drive; ``state``
        carries ``robot.joints``, ``robot.pc_time_s``, ``t`` and ``cycle = k``.
    q : ndarray, shape (K+1, 6)
        The motion's samples (``q_k`` is ``q[k]``).
    cycle, offset : SeqVector
        The blocks (read here, written here).
    motion : int
        The motion's number.
    period_s : float
        How often the cycle block is looked at while nothing new is there (s).
    limits : WireLimits, optional
        How fast the child may move what it sends towards the newest ``Δq`` (module
        docstring); ``None``: it sends the newest as is.
    """

    def __init__(self, adjust: Callable[[CycleState, int, Array], Array], q: Array,
                 cycle: SeqVector, offset: SeqVector, motion: int, period_s: float,
                 limits: WireLimits | None = None) -> None:
        self.adjust, self.q = adjust, q
        self.cycle, self.offset, self.motion, self.period_s = cycle, offset, motion, period_s
        self._tail = _NO_LIMITS if limits is None else limits.slots()
        self.offset.write(np.r_[motion, -1, np.zeros(6), self._tail])
        self.failure: BaseException | None = None
        self.cycles = 0
        #: after :meth:`close`: the child's :class:`WirePeaks` of the motion (step, change)
        self.peaks: tuple[Array, Array] | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="adjust-pump", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        last = -1
        while not self._stop.is_set():
            c = self.cycle.read()
            k = int(c[1])
            if c[0] != self.motion or k == last:
                self._stop.wait(self.period_s)
                continue
            last = k
            q = c[4:10]
            state = CycleState(robot=PumpedRobot(None if np.isnan(q).any() else q,
                                                 float(c[3])),
                               offset=np.zeros(6), session=0, cycle=k, t=float(c[2]))
            try:
                dq = np.asarray(self.adjust(state, k, self.q[min(k, len(self.q) - 1)]),
                                dtype=float)
            except Exception as exc:  # the motion fails with it when it ends
                self.failure = exc
                return
            self.offset.write(np.r_[self.motion, k, dq, self._tail])
            self.cycles += 1

    def close(self) -> None:
        """Stop the thread (the child keeps the last adjustment to the motion's end); read
        the child's :attr:`peaks` (the motion has ended)."""
        self._stop.set()
        self._thread.join(5.0)
        c = self.cycle.read()
        if c[0] == self.motion:
            self.peaks = (c[10:16].copy(), c[16:22].copy())
