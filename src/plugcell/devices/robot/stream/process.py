"""The cycle loop in a process of its own: :class:`LinkProcess`.

A robot service runs its event loop, the program runner and the planner in one Python
process; a link's thread there shares the interpreter with them and answers late whenever
they hold it (issue 37 §7: in-service answers measured up to 150 ms late).  So the
streaming controller (:mod:`plugcell.devices.robot.stream_controller`) puts the link — the
vendor's :class:`~.link.StreamLink` and its :class:`~.drive.StreamDrive` — into a child
process (``multiprocessing``, *spawn*), which does nothing but the cycle loop, and talks to
it through two channels:

* a pipe for the motions: ``("follow", n, q, timeout, adjusted)`` — the planned
  trajectory sampled at the cycle, ``q`` of shape (K+1, 6) rad — answered ``("followed",
  n, reason)`` when the motion ended (``reason`` empty) or failed; a motion is a few
  kilobytes once per move.  The parent waits for the answer as the child's link waits
  for the motion (:func:`await_answer`): in the controller's cycles, on the wall clock
  only while none come, and not at all once the child is gone or its session failed;
* a second pipe for the corrections of mode (b), *the robot drives, the PC corrects*
  (:mod:`.correcting`): the child's :class:`~.correcting.Corrector` called through
  :class:`CorrectorClient` (start, set the offset, finish, poll), while a correction
  runs the PC's moves are refused;
* shared memory for the feedback, written by the link's thread after every cycle
  (:class:`Publisher`, the link's ``observer``) and read by the service whenever it
  wants (ARM_JNTP, every move's start, the stream's watch) without asking the child
  anything: whether a session streams, the session count, the newest actual joints, the
  counters, and the current failure's text.  A sequence number makes each read
  consistent (a *seqlock*: the writer makes it odd while writing; a reader retries a
  read that saw it odd or changed);
* for an *adjusted* motion (a tracked move: a correction added to each cycle's joints,
  computed in the service from the tracker's samples), two more seqlocked blocks: the
  cycle the child is answering, and the newest adjustment the service computed for it
  (:mod:`.adjusting`).

The parent end is a :class:`~plugcell.devices.robot.planned_motion.Drive` with the link's
``start``/``wait``/``streaming``/``failure``/``latest``/``close``, so the controller uses it
in place of an in-process link and drive.  The child ends when the parent closes it, or
when the parent is gone (the pipe's end of file).
"""

from __future__ import annotations

import contextlib
import gc
import importlib
import multiprocessing
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from plugcell.motion import Trajectory
from plugcell.pdl.interfaces import MotionError

from .adjusting import CYCLE_SLOTS, OFFSET_SLOTS, AdjustPump, ChildAdjust, SeqVector, WireLimits
from .correcting import CorrectionSpec, Corrector
from .drive import SETTLE_S, Adjust, StreamDrive, drive_refusal, motion_timeout, samples
from .errors import StreamLinkError
from .realtime import RealTime

__all__ = ["BUSY", "LINKS", "CorrectorClient", "Feedback", "LinkProcess", "NoAnswerError",
           "Publisher", "await_answer", "link_class", "serve_corrections"]

Array = NDArray[np.float64]

# the shared values: [seq, streaming, sessions, failures, failed, has_joints, joints × 6,
#                     received, answered, late, missed]
SEQ, STREAMING, SESSIONS, FAILURES, FAILED, HAS_JOINTS = range(6)
JOINTS = slice(6, 12)
RECEIVED, ANSWERED, LATE, MISSED = range(12, 16)
SLOTS = 16
#: Bytes kept of a failure's text.
TEXT_BYTES = 2048
#: How often :meth:`LinkProcess.wait` looks (s).
POLL_S = 0.01
#: How long the parent waits on the pipe between looks at the child while a motion runs (s).
POLL_ANSWER_S = 0.05
#: Each vendor's link class (``module:Class``), by the configuration's ``vendor``: imported
#: where it runs (the child imports only its own).
LINKS = {"RSI": "plugcell.devices.robot.rsi.link:RsiLink",
         "EGM": "plugcell.devices.robot.egm.link:EgmLink"}


def link_class(vendor: str) -> Any:
    """The link class of ``vendor`` (``"RSI"``, ``"EGM"``)."""
    module, _, name = LINKS[vendor].partition(":")
    return getattr(importlib.import_module(module), name)


@dataclass(frozen=True)
class Feedback:
    """The newest packet's actual joints, as the service sees them (``latest.joints``)."""

    joints: Array | None


class Publisher:
    """The child's end of the shared memory: the link's ``observer`` (module docstring).

    Parameters
    ----------
    values : RawArray of double
        :data:`SLOTS` shared values.
    text : RawArray of char
        :data:`TEXT_BYTES` for the failure's text.
    """

    def __init__(self, values: Any, text: Any) -> None:
        self.v = np.frombuffer(values, dtype=np.float64)
        self.text = text
        self._failure: object = None

    def __call__(self, link: Any) -> None:
        """Publish the link's state now (called by its thread after each cycle and event)."""
        v = self.v
        failure = link.failure
        v[SEQ] += 1  # odd: being written
        if failure is not self._failure:
            self._failure = failure
            if failure is not None:
                self.text.value = str(failure).encode()[:TEXT_BYTES - 1]
                v[FAILURES] += 1
        v[FAILED] = failure is not None
        v[STREAMING] = link.streaming
        v[SESSIONS] = link._sessions
        latest = link.latest
        joints = None if latest is None else latest.joints
        if joints is not None:
            v[JOINTS] = joints
        v[HAS_JOINTS] = joints is not None
        v[RECEIVED], v[ANSWERED] = link._received, link._answered
        v[LATE], v[MISSED] = link._late, link._missed
        v[SEQ] += 1  # even: consistent


def _child(conn: Any, corrections: Any, values: Any, text: Any, vendor: str, config: Any,
           realtime: RealTime, cycle: Any = None, offset: Any = None) -> None:
    """The child process: the link, its drive, the motions from the pipe and the
    corrections of mode (b) from the other (:func:`serve_corrections`)."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the service's to handle
    # every thread of the process on the stream's CPUs (they start after this), the
    # interpreter handed to the link's thread within half a millisecond of its asking,
    # the other threads one real-time priority below it (RealTime.prepare_process)
    prepared = realtime.prepare_process()
    link = link_class(vendor)(config, realtime=realtime)
    link.observer = Publisher(values, text)
    # the objects of the imports and the link live as long as the process: out of the
    # collector's sight, a full collection scans only what the cycles made (one over all
    # of them takes longer than a cycle and would miss some)
    gc.collect()
    gc.freeze()
    try:
        host, port = link.start()
    except OSError as exc:
        conn.send(("error", str(exc)))
        return
    conn.send(("started", host, port, "; ".join(n for n in (link.rt_note, prepared) if n)))
    refusal = drive_refusal(config)
    drive = None if refusal else StreamDrive(link)
    corrector = Corrector(link)
    threading.Thread(target=serve_corrections, args=(corrections, corrector),
                     name="corrections", daemon=True).start()
    try:
        while True:
            try:
                message = conn.recv()
            except (EOFError, OSError):  # the parent is gone
                break
            if message[0] != "follow":
                break
            _, motion, q, timeout, wait_s = message
            if drive is None or corrector.active:
                conn.send(("followed", motion, refusal or BUSY))
                continue
            adjust = ChildAdjust(SeqVector(cycle), SeqVector(offset), motion, wait_s) \
                if wait_s is not None else None
            try:
                drive.follow_samples(q, timeout, adjust)
            except MotionError as exc:
                conn.send(("followed", motion, str(exc) or "the motion failed"))
            except Exception as exc:  # a bug must reach the program, not end the child
                conn.send(("followed", motion,
                           f"{vendor} link process: {type(exc).__name__}: {exc}"))
            else:
                conn.send(("followed", motion, ""))
    finally:
        link.close()


#: More than a motion's own timeout (:func:`~.drive.motion_timeout`) the parent waits for
#: its answer: the child's exact stop (:data:`~.drive.SETTLE_S`) and the pipe (s).
ANSWER_GRACE_S = SETTLE_S + 2.0
#: How long the child has to answer once the parent sees its session failed (s).
FAILED_GRACE_S = 1.0


class NoAnswerError(Exception):
    """The child did not answer a motion (:func:`await_answer`): why, as the end of a
    sentence about the link process."""


def await_answer(receive: Callable[[float], str | None], alive: Callable[[], bool],
                 cycles: Callable[[], int], failed: Callable[[], bool], timeout: float,
                 cycle_s: float, clock: Callable[[], float] = time.monotonic) -> str:
    """The parent's wait for the child's answer to a motion, by the child's own rules
    (:meth:`~.follow.Following.follow`): the motion's time is counted in the controller's
    cycles, the wall clock counts only while none come.

    It gives up (:class:`NoAnswerError`) when the child is gone (at once); when the session
    failed and the child does not answer within :data:`FAILED_GRACE_S` (the stream
    stopping fails the motion within one controller timeout, whatever the child does);
    when ``(timeout + ANSWER_GRACE_S) / cycle_s`` cycles passed since the motion was sent
    (the child's motion is over by then); when no cycle came for ``timeout +
    ANSWER_GRACE_S`` s (no stream: the child's wait for it is over).

    Parameters
    ----------
    receive : callable
        ``receive(wait)``: the answer's reason (``""``: the motion ended) if it came
        within ``wait`` s, else ``None``.
    alive : callable
        Whether the child runs.
    cycles : callable
        The child's link's answered cycles so far (any count that grows by one a cycle).
    failed : callable
        Whether the child's session has failed.
    timeout : float
        The motion's timeout (s, :func:`~.drive.motion_timeout`).
    cycle_s : float
        The controller's cycle (s).
    clock : callable
        Seconds, monotonic.

    Returns
    -------
    str
        The answer's reason.

    Raises
    ------
    NoAnswerError
        No answer, and why.
    """
    first = seen = cycles()
    limit = (timeout + ANSWER_GRACE_S) / cycle_s
    quiet_since = clock()
    failed_since: float | None = None
    while True:
        reason = receive(POLL_ANSWER_S)
        if reason is not None:
            return reason
        if not alive():
            raise NoAnswerError("has exited")
        now, count = clock(), cycles()
        if count != seen:
            seen, quiet_since = count, now
        if failed():
            failed_since = now if failed_since is None else failed_since
            if now - failed_since > FAILED_GRACE_S:
                raise NoAnswerError("did not answer after its stream failed")
        else:
            failed_since = None
        if count - first > limit:
            raise NoAnswerError(f"did not answer the motion within {limit:.0f} controller cycles")
        if now - quiet_since > timeout + ANSWER_GRACE_S:
            raise NoAnswerError(f"did not answer the motion: no controller cycle for "
                           f"{now - quiet_since:.1f} s")


#: Why the PC cannot move the robot now.
BUSY = ("a correction runs on the controller's own path (CORRECT): the controller drives; "
        "end the correction first")


def serve_corrections(conn: Any, corrector: Corrector) -> None:
    """The child's end of the corrections' pipe: each request ``(name, *args)`` to the
    :class:`~.correcting.Corrector` answered ``("ok", result)`` or ``("error", kind, text)``
    (``ValueError``/``RuntimeError``), until the pipe closes."""
    calls: dict[str, Callable[..., Any]] = {
        "start": corrector.start, "set_offset": corrector.set_offset,
        "finish": corrector.finish, "poll": corrector.poll, "status": corrector.status,
        "active": lambda: corrector.active}
    while True:
        try:
            name, *args = conn.recv()
        except (EOFError, OSError):
            return
        try:
            conn.send(("ok", calls[name](*args)))
        except (ValueError, RuntimeError) as exc:
            conn.send(("error", type(exc).__name__, str(exc)))


class CorrectorClient:
    """The service's end of the corrections' pipe: a :class:`~.correcting.Corrector` in
    the link's process, called as if it were here (the same methods and errors)."""

    def __init__(self, process: LinkProcess) -> None:
        self.process = process
        self._lock = threading.Lock()

    def _call(self, name: str, *args: Any) -> Any:
        conn = self.process.corrections_pipe()
        with self._lock:
            try:
                conn.send((name, *args))
                if not conn.poll(10.0):
                    raise RuntimeError(f"the {self.process.vendor} link process did not "
                                       "answer")
                answer = conn.recv()
            except (OSError, EOFError):
                raise RuntimeError(f"the {self.process.vendor} link process is not "
                                   "running") from None
        if answer[0] == "error":
            raise (ValueError if answer[1] == "ValueError" else RuntimeError)(answer[2])
        return answer[1]

    @property
    def active(self) -> bool:
        """A correction runs."""
        return bool(self._call("active"))

    def start(self, spec: CorrectionSpec) -> None:
        """:meth:`~.correcting.Corrector.start` in the link's process."""
        self._call("start", spec)

    def set_offset(self, g: Array) -> None:
        """:meth:`~.correcting.Corrector.set_offset` in the link's process."""
        self._call("set_offset", np.asarray(g, dtype=float))

    def finish(self) -> None:
        """:meth:`~.correcting.Corrector.finish` in the link's process."""
        self._call("finish")

    def poll(self) -> str | None:
        """:meth:`~.correcting.Corrector.poll` in the link's process."""
        return self._call("poll")  # type: ignore[no-any-return]

    def status(self) -> tuple[float, Array]:
        """:meth:`~.correcting.Corrector.status` in the link's process."""
        return self._call("status")  # type: ignore[no-any-return]


class LinkProcess:
    """A vendor's link and drive in a child process; the service's end (module docstring).

    Parameters
    ----------
    config : RsiConfig or EgmConfig
        The stream (the PC's moves need ``joint_targets``; corrections of mode (b) need
        a stream that corrects the controller's own path).
    rt_priority : int, optional
        The child's link thread under ``SCHED_FIFO`` at this priority (Linux,
        ``CAP_SYS_NICE``).
    realtime : RealTime, optional
        The child's whole scheduling instead (:mod:`.realtime`): its link thread's
        priority, the CPUs of all its threads, its memory locked; not with
        ``rt_priority``.
    """

    def __init__(self, config: Any, rt_priority: int | None = None,
                 realtime: RealTime | None = None) -> None:
        self.realtime = RealTime.given(rt_priority, realtime)
        self.config = config
        self.vendor = config.vendor
        self.rt_priority = self.realtime.priority
        self.rt_note = ""
        self.followed = 0
        #: the last adjusted motion's wire peaks (:class:`~.adjusting.WirePeaks`: step, change)
        self.wire_peaks: tuple[Array, Array] | None = None
        ctx = multiprocessing.get_context("spawn")
        self._values = ctx.RawArray("d", SLOTS)
        self._text = ctx.RawArray("c", TEXT_BYTES)
        self._cycle = ctx.RawArray("d", CYCLE_SLOTS)
        self._offset = ctx.RawArray("d", OFFSET_SLOTS)
        self._v = np.frombuffer(self._values, dtype=np.float64)
        self._ctx = ctx
        self._conn: Any = None
        self._corr: Any = None
        self._proc: Any = None
        #: the corrections of mode (b), run in the child
        self.corrector = CorrectorClient(self)
        self._lock = threading.Lock()  # one motion at a time on the pipe
        self._motions = 0
        self._failure: tuple[int, StreamLinkError] | None = None

    # ------------------------------------------------------------------ the process
    def start(self, timeout: float = 60.0) -> tuple[str, int]:
        """Start the child and its link (again, if it ended); the address it listens on.

        Raises
        ------
        OSError
            The link cannot listen, or the child did not start within ``timeout`` s.
        """
        if self.alive:
            raise RuntimeError(f"the {self.vendor} link process is already started")
        if self._proc is not None:  # it ended (a crash): a new one, with a clean slate
            self.close()
            self._v[:] = 0
            self._failure = None
        self._conn, child_end = self._ctx.Pipe()
        self._corr, child_corr = self._ctx.Pipe()
        self._proc = self._ctx.Process(
            target=_child, name=f"plugcell-{self.vendor.lower()}-link", daemon=True,
            args=(child_end, child_corr, self._values, self._text, self.vendor, self.config,
                  self.realtime, self._cycle, self._offset))
        self._proc.start()
        child_end.close()
        child_corr.close()
        if not self._conn.poll(timeout):
            self.close()
            raise OSError(f"the {self.vendor} link process did not start within {timeout:g} s")
        message = self._conn.recv()
        if message[0] == "error":
            self.close()
            raise OSError(message[1])
        self.rt_note = message[3]
        return message[1], message[2]

    def close(self) -> None:
        """Stop the child (idempotent)."""
        conn, proc = self._conn, self._proc
        if conn is not None:
            with contextlib.suppress(OSError):
                conn.send(("close",))
            conn.close()
        if self._corr is not None:
            self._corr.close()
        if proc is not None:
            proc.join(5.0)
            if proc.is_alive():
                proc.kill()
                proc.join(5.0)

    def corrections_pipe(self) -> Any:
        """The parent's end of the corrections' pipe (``OSError``: no child)."""
        if self._corr is None or not self.alive:
            raise OSError("no link process")
        return self._corr

    @property
    def alive(self) -> bool:
        """The child runs."""
        return self._proc is not None and self._proc.is_alive()

    # ------------------------------------------------------------------ the feedback
    def snapshot(self) -> Array:
        """A consistent copy of the shared values (module docstring)."""
        return SeqVector(self._values).snapshot()

    @property
    def streaming(self) -> bool:
        """A session is running."""
        return bool(self._v[STREAMING]) and self.alive

    @property
    def failure(self) -> StreamLinkError | None:
        """Why the current session failed (``None``: it did not); the child gone fails."""
        values = self.snapshot()
        if self._proc is not None and not self.alive:
            return StreamLinkError(f"the {self.vendor} link process has exited "
                                   f"(exit code {self._proc.exitcode})")
        if not values[FAILED]:
            return None
        count = int(values[FAILURES])
        if self._failure is None or self._failure[0] != count:
            self._failure = (count, StreamLinkError(self._text.value.decode(errors="replace")))
        return self._failure[1]

    @property
    def latest(self) -> Feedback | None:
        """The newest packet's joints (``None`` before the first)."""
        values = self.snapshot()
        if not values[SESSIONS]:
            return None
        return Feedback(values[JOINTS].copy() if values[HAS_JOINTS] else None)

    def counters(self) -> dict[str, int]:
        """``received``, ``answered``, ``late``, ``missed``, ``sessions`` now."""
        v = self.snapshot()
        return {"received": int(v[RECEIVED]), "answered": int(v[ANSWERED]),
                "late": int(v[LATE]), "missed": int(v[MISSED]), "sessions": int(v[SESSIONS])}

    def wait(self, predicate: Callable[[LinkProcess], bool], timeout: float) -> bool:
        """Wait until ``predicate(self)`` holds (looked at every :data:`POLL_S`)."""
        end = time.monotonic() + timeout
        while not predicate(self):
            if time.monotonic() >= end:
                return False
            time.sleep(POLL_S)
        return True

    # ------------------------------------------------------------------ the Drive
    def joint_readings(self) -> Array:
        """The robot's actual joints in the newest packet (rad), shape (6,)."""
        latest = self.latest
        if latest is None or not self.streaming:
            failure = self.failure
            raise MotionError(str(failure) if failure is not None
                              else f"no {self.vendor} stream from the controller")
        if latest.joints is None:
            raise MotionError(f"the controller's {self.vendor} packets carry no joint "
                              "feedback")
        return latest.joints

    def follow(self, trajectory: Trajectory, adjust: Adjust | None = None,
               wait_s: float = 0.0, limits: WireLimits | None = None) -> None:
        """Stream ``trajectory`` in the child (blocks for its duration).

        ``adjust(state, k, q_k)``, if given, runs here, in a thread of this process
        (:class:`~.adjusting.AdjustPump`), on each cycle the child answers; the child
        adds the newest result to its samples' joints (module docstring) — or, with
        ``wait_s`` > 0 (simulated time), waits up to that long for its cycle's —
        moving what it sends towards it at ``limits``, if given, each robot cycle.

        Raises
        ------
        MotionError
            The stream failed, the motion did not end in time, the child is gone, or
            ``adjust`` raised (after the motion, which kept its last adjustment).
        """
        q = samples(trajectory, self.config.cycle_s)
        timeout = motion_timeout(trajectory.duration, self.config)
        with self._lock:
            self._motions += 1
            pump = None if adjust is None else AdjustPump(
                adjust, q, SeqVector(self._cycle), SeqVector(self._offset), self._motions,
                self.config.cycle_s / 4, limits)
            try:
                reason = self._follow(q, timeout, None if adjust is None else wait_s)
            finally:
                if pump is not None:
                    pump.close()
                    self.wire_peaks = pump.peaks
        if reason:
            raise MotionError(reason)
        if pump is not None and pump.failure is not None:
            raise MotionError(f"the correction of the motion failed: "
                              f"{type(pump.failure).__name__}: {pump.failure}")
        self.followed += 1

    def _follow(self, q: Array, timeout: float, wait_s: float | None) -> str:
        """Send motion ``self._motions`` (adjusted unless ``wait_s`` is None) and wait for
        its answer (:func:`await_answer`): the failure's reason (empty: it ended)."""
        try:
            self._conn.send(("follow", self._motions, q, timeout, wait_s))
        except (OSError, AttributeError):
            raise MotionError(f"the {self.vendor} link process is not running") from None
        motion = self._motions

        def receive(wait: float) -> str | None:
            # the answer to this motion (an earlier one's, given up on, is old); the pipe's
            # end of file: the child is gone (its exit reaped, so that alive says so)
            if not self._conn.poll(wait):
                return None
            try:
                _, m, reason = self._conn.recv()
            except (EOFError, OSError):
                self._proc.join(1.0)
                return None
            return str(reason) if m == motion else None

        try:
            return await_answer(receive, lambda: self.alive,
                                lambda: int(self.snapshot()[ANSWERED]),
                                lambda: self.failure is not None, timeout, self.config.cycle_s)
        except NoAnswerError as exc:
            failure = self.failure
            raise MotionError(str(failure) if failure is not None
                              else f"the {self.vendor} link process {exc}") from None
