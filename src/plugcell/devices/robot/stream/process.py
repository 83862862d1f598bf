"""The cycle loop in a process of its own: :class:`LinkProcess`.

A robot service runs its event loop, the program runner and the planner in one Python
process; a link's thread there shares the interpreter with them and answers late whenever
they hold it (issue 37 §7: in-service answers measured up to 150 ms late).  So the
streaming controller (:mod:`plugcell.devices.robot.stream_controller`) puts the link — the
vendor's :class:`~.link.StreamLink` and its :class:`~.drive.StreamDrive` — into a child
process (``multiprocessing``, *spawn*), which does nothing but the cycle loop, and talks to
it through two channels:

* a pipe for the motions: ``("follow", n, q, timeout)`` — the planned trajectory sampled
  at the cycle, ``q`` of shape (K+1, 6) rad — answered ``("followed", n, reason)`` when
  the motion ended (``reason`` empty) or failed; a motion is a few kilobytes once per move;
* shared memory for the feedback, written by the link's thread after every cycle
  (:class:`Publisher`, the link's ``observer``) and read by the service whenever it
  wants (ARM_JNTP, every move's start, the stream's watch) without asking the child
  anything: whether a session streams, the session count, the newest actual joints, the
  counters, and the current failure's text.  A sequence number makes each read
  consistent (a *seqlock*: the writer makes it odd while writing; a reader retries a
  read that saw it odd or changed).

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

from .drive import StreamDrive, motion_timeout, samples
from .errors import StreamLinkError

__all__ = ["LINKS", "Feedback", "LinkProcess", "Publisher", "link_class"]

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


def _child(conn: Any, values: Any, text: Any, vendor: str, config: Any,
           rt_priority: int | None) -> None:
    """The child process: the link, its drive, and the motions from the pipe."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the service's to handle
    link = link_class(vendor)(config, rt_priority=rt_priority)
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
    conn.send(("started", host, port, link.rt_note))
    drive = StreamDrive(link)
    try:
        while True:
            try:
                message = conn.recv()
            except (EOFError, OSError):  # the parent is gone
                break
            if message[0] != "follow":
                break
            _, motion, q, timeout = message
            try:
                drive.follow_samples(q, timeout)
            except MotionError as exc:
                conn.send(("followed", motion, str(exc) or "the motion failed"))
            except Exception as exc:  # a bug must reach the program, not end the child
                conn.send(("followed", motion,
                           f"{vendor} link process: {type(exc).__name__}: {exc}"))
            else:
                conn.send(("followed", motion, ""))
    finally:
        link.close()


class LinkProcess:
    """A vendor's link and drive in a child process; the service's end (module docstring).

    Parameters
    ----------
    config : RsiConfig or EgmConfig
        The stream (``joint_targets`` must hold).
    rt_priority : int, optional
        The child's link thread under ``SCHED_FIFO`` at this priority (Linux,
        ``CAP_SYS_NICE``).
    """

    def __init__(self, config: Any, rt_priority: int | None = None) -> None:
        if not config.joint_targets:
            raise ValueError(f"the PC drives the robot with whole joint commands; the "
                             f"{config.vendor} link is not configured for them")
        self.config = config
        self.vendor = config.vendor
        self.rt_priority = rt_priority
        self.rt_note = ""
        self.followed = 0
        ctx = multiprocessing.get_context("spawn")
        self._values = ctx.RawArray("d", SLOTS)
        self._text = ctx.RawArray("c", TEXT_BYTES)
        self._v = np.frombuffer(self._values, dtype=np.float64)
        self._ctx = ctx
        self._conn: Any = None
        self._proc: Any = None
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
        self._proc = self._ctx.Process(
            target=_child, name=f"plugcell-{self.vendor.lower()}-link", daemon=True,
            args=(child_end, self._values, self._text, self.vendor, self.config,
                  self.rt_priority))
        self._proc.start()
        child_end.close()
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
        if proc is not None:
            proc.join(5.0)
            if proc.is_alive():
                proc.kill()
                proc.join(5.0)

    @property
    def alive(self) -> bool:
        """The child runs."""
        return self._proc is not None and self._proc.is_alive()

    # ------------------------------------------------------------------ the feedback
    def snapshot(self) -> Array:
        """A consistent copy of the shared values (module docstring)."""
        v = self._v
        while True:
            seq = v[SEQ]
            if seq % 2 == 0:
                values = v.copy()
                if v[SEQ] == seq:
                    return values
            time.sleep(0)

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

    def follow(self, trajectory: Trajectory) -> None:
        """Stream ``trajectory`` in the child (blocks for its duration).

        Raises
        ------
        MotionError
            The stream failed, the motion did not end in time, or the child is gone.
        """
        q = samples(trajectory, self.config.cycle_s)
        timeout = motion_timeout(trajectory.duration, self.config)
        with self._lock:
            self._motions += 1
            try:
                self._conn.send(("follow", self._motions, q, timeout))
            except (OSError, AttributeError):
                raise MotionError(f"the {self.vendor} link process is not running") from None
            end = time.monotonic() + timeout + 10.0
            while True:  # the answer to this motion (an earlier one's, given up on, is old)
                while not self._conn.poll(0.1):
                    if not self.alive or time.monotonic() > end:
                        raise MotionError(str(self.failure or f"the {self.vendor} link "
                                              "process did not answer"))
                _, motion, reason = self._conn.recv()
                if motion == self._motions:
                    break
        if reason:
            raise MotionError(reason)
        self.followed += 1
