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
  ``q`` (rad; NaN if the packet had none) — what the in-process hook is given;
* **the adjustment** — written by the service's :class:`AdjustPump` (a thread) whenever it
  has computed one for a newer cycle: the motion's number, the cycle's ``k`` and ``Δq``
  (rad, (6,)).

The child adds the newest ``Δq`` of its motion each cycle (zeros before the first) and
never waits for it, exactly as the in-process link takes the newest offset of its worker
thread (``tracked_moves._Worker``): the loop's cost and the service's interpreter never
make an answer late; an adjustment reaches the wire one or two cycles after the cycle it
was computed for (the loop's rate bounds hold in the robot's time, whatever cycles it
skipped; between two adjustments the child holds the last one).
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

from .source import CycleState

__all__ = ["CYCLE_SLOTS", "OFFSET_SLOTS", "AdjustPump", "ChildAdjust", "SeqVector"]

Array = NDArray[np.float64]

#: The cycle block: [seq, motion, k, t, pc, q × 6].
CYCLE_SLOTS = 11
#: The adjustment block: [seq, motion, k, Δq × 6].
OFFSET_SLOTS = 9


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
    """

    def __init__(self, cycle: SeqVector, offset: SeqVector, motion: int,
                 wait_s: float = 0.0) -> None:
        self.cycle, self.offset, self.motion, self.wait_s = cycle, offset, motion, wait_s

    def __call__(self, state: CycleState, k: int, q_k: Array) -> Array:
        joints = state.robot.joints
        q = np.full(6, np.nan) if joints is None else np.asarray(joints, dtype=float)
        self.cycle.write(np.array([self.motion, k, state.t, time.time(), *q]))
        newest = self.offset.read()
        if self.wait_s > 0:
            end = time.monotonic() + self.wait_s
            while not (newest[0] == self.motion and newest[1] >= k) and \
                    time.monotonic() < end:
                time.sleep(5e-5)
                newest = self.offset.read()
        return newest[2:8] if newest[0] == self.motion else np.zeros(6)


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
    """

    def __init__(self, adjust: Callable[[CycleState, int, Array], Array], q: Array,
                 cycle: SeqVector, offset: SeqVector, motion: int, period_s: float) -> None:
        self.adjust, self.q = adjust, q
        self.cycle, self.offset, self.motion, self.period_s = cycle, offset, motion, period_s
        self.offset.write(np.array([motion, -1, *np.zeros(6)]))
        self.failure: BaseException | None = None
        self.cycles = 0
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
            self.offset.write(np.array([self.motion, k, *dq]))
            self.cycles += 1

    def close(self) -> None:
        """Stop the thread (the child keeps the last adjustment to the motion's end)."""
        self._stop.set()
        self._thread.join(5.0)
