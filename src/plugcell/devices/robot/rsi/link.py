"""The sensor side of one KUKA RSI stream: a UDP socket answering every robot packet.

:class:`RsiLink` runs one thread that, per datagram:

1. drops and counts what is no packet of the configured robot — another address,
   oversized, malformed, foreign (:func:`.codec.parse_rob`), or older than the last one;
   of several queued packets only the newest is answered (the older are missed cycles);
2. asks its :class:`CorrectionSource` for the correction of this cycle, given the
   robot's state (:class:`CycleState`);
3. holds the correction to the limits (:class:`.limits.OffsetLimiter`) — clamped and
   counted, or refused: then the robot is held and the stream fails with the reason;
4. answers ``<Sen>`` with the packet's IPOC (:func:`.codec.encode_sen`) to the address the
   packet came from, and counts the answer late if it left more than one cycle after the
   packet arrived.

A stream (a *session*) starts with the first packet and ends when the controller has
been silent for one controller timeout (``Timeout · T``).  Within it, ``Timeout`` missed
cycles in a row (late answers and IPOC gaps), the controller's own count of late packets
(``<Delay>``) reaching ``Timeout``, a refused correction or a failing source put the link
into *holding*: every later packet is answered with no motion (relative: zero step;
absolute: the offset kept) and the failure is kept in :attr:`RsiLink.failure` — the
robot service turns it into a failed process.  When packets come back after the silence
a new session starts from a zero offset: the link recovers by itself.

Real-time notes: the loop allocates little and waits in ``poll``; run it in a process of
its own (the robot service's event loop would otherwise share the GIL with it) —
``benchmarks/rsi_latency.py`` measures it so.
"""

from __future__ import annotations

import os
import select
import socket
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from plugcell.io.units import DEG, M_PER_MM

from .codec import CARTESIAN_AXES, JOINT_AXES, PacketError, RobotState, encode_sen, parse_rob
from .config import RsiConfig
from .limits import Limited, OffsetLimiter

Array = NDArray[np.float64]

#: Datagrams read per wake-up before the newest packet among them is answered.
DRAIN = 64

__all__ = [
    "ControllerStoppedError",
    "Correction",
    "CorrectionRefusedError",
    "CorrectionSource",
    "CycleState",
    "LinkStats",
    "RsiLink",
    "RsiLinkError",
    "SourceFailedError",
    "StreamStoppedError",
]


class RsiLinkError(RuntimeError):
    """Why an RSI stream failed; ``str(error)`` is the reason for the user."""


class StreamStoppedError(RsiLinkError):
    """The controller went silent, or missed cycles reached its ``Timeout``."""


class ControllerStoppedError(RsiLinkError):
    """The controller's own count of late packets (``<Delay>``) reached ``Timeout``."""


class CorrectionRefusedError(RsiLinkError):
    """A correction beyond the configured limits (policy ``"refuse"``), or not sendable."""


class SourceFailedError(RsiLinkError):
    """The correction source raised; the link holds the robot."""


@dataclass(frozen=True)
class Correction:
    """What a correction source wants this cycle (SI).

    Give ``offset`` (the whole offset from where the stream started: the absolute-mode
    view, natural for a trajectory) or ``step`` (the change this cycle: the relative
    view, natural for a tracker's correction), not both; neither: no motion.  The link
    sends whichever its mode needs.

    Attributes
    ----------
    offset : array_like, shape (6,), optional
        Joint: A1..A6 (rad); Cartesian: X, Y, Z (m), A, B, C (rad).
    step : array_like, shape (6,), optional
        Like ``offset``, the change of this cycle.
    outputs : mapping of str to int
        New values of the configured output words (``{"DiO": 5}``); they stay until set
        again.
    """

    offset: ArrayLike | None = None
    step: ArrayLike | None = None
    outputs: Mapping[str, int] = field(default_factory=dict)


@dataclass(frozen=True)
class CycleState:
    """What a correction source is given each cycle.

    Attributes
    ----------
    robot : RobotState
        The robot's packet of this cycle (SI).
    offset : ndarray, shape (6,)
        The offset the link has commanded so far in this session (SI).
    session : int
        Counts the streams since the link started (1 for the first).
    cycle : int
        Packets answered in this session before this one.
    t : float
        Seconds since the session's first packet, by the controller's IPOC clock.
    """

    robot: RobotState
    offset: Array
    session: int
    cycle: int
    t: float


@runtime_checkable
class CorrectionSource(Protocol):
    """Anything that gives a correction per cycle (a trajectory streamer, a tracker loop)."""

    def correction(self, state: CycleState) -> Correction | None:
        """The correction of this cycle; ``None``: no motion."""


SourceLike = CorrectionSource | Callable[[CycleState], "Correction | None"]


@dataclass(frozen=True)
class LinkStats:
    """Counters of a link since it started (a snapshot).

    Attributes
    ----------
    received : int
        Datagrams that were robot packets of the configured robot.  Every datagram is
        either received or dropped for ``address``, ``oversized``, ``malformed`` or
        ``foreign``; every received packet is answered, superseded or dropped as
        ``stale`` or ``inconsistent`` (or its answer could not be sent: ``last_reason``
        says so).
    answered : int
        Answers sent.
    late : int
        Answers sent more than one cycle after their packet arrived.
    missed : int
        Cycles the link never answered, from the gaps of the IPOC (lost on the way or
        superseded).
    superseded : int
        Packets not answered because a newer one was already queued behind them.
    dropped : dict of str to int
        Datagrams dropped, by reason: ``address``, ``oversized``, ``malformed``,
        ``foreign``, ``stale`` (not newer than the last packet answered),
        ``inconsistent`` (within a session, an IPOC ``Timeout`` cycles or more ahead of
        the last: the stream would have been silent that long, and the session ended).
    clamped, refused : int
        Corrections cut to the limits, and refused.
    controller_late : int
        The controller's own count (``<Delay>``) in the current session.
    sessions : int
        Streams started.
    streaming : bool
        A session is running (packets within the last controller timeout).
    max_latency_ns : int
        The longest packet-in → answer-out time.
    last_reason : str
        The last clamp, refusal or failure, as a sentence.
    """

    received: int
    answered: int
    late: int
    missed: int
    superseded: int
    dropped: dict[str, int]
    clamped: int
    refused: int
    controller_late: int
    sessions: int
    streaming: bool
    max_latency_ns: int
    last_reason: str


def _as_source(source: SourceLike | None) -> Callable[[CycleState], Correction | None]:
    if source is None:
        return lambda state: None
    if isinstance(source, CorrectionSource):
        return source.correction
    if callable(source):
        return source
    raise TypeError(f"a correction source has correction(state) or is callable, got "
                    f"{type(source).__name__}")


class RsiLink:
    """The sensor side of one RSI stream (module doc).

    Parameters
    ----------
    config : RsiConfig
        The stream's configuration.
    source : CorrectionSource or callable, optional
        Gives the correction of each cycle; ``None``: no motion until one is set with
        :meth:`set_source`.
    record_latency : bool
        Keep every packet-in → answer-out time (ns) in :attr:`latencies` (benchmarks).
    rt_priority : int, optional
        Run the link's thread under ``SCHED_FIFO`` at this priority (1..99; Linux, needs
        ``CAP_SYS_NICE``): the kernel then runs it as soon as a packet arrives, ahead of
        every ordinary process.  What happened is in :attr:`rt_note`; without the right
        the link runs at normal priority.
    """

    def __init__(self, config: RsiConfig, source: SourceLike | None = None,
                 record_latency: bool = False, rt_priority: int | None = None) -> None:
        if rt_priority is not None and not 1 <= rt_priority <= 99:
            raise ValueError(f"rt_priority {rt_priority}: expected 1..99 (SCHED_FIFO)")
        self.rt_priority = rt_priority
        self.rt_note = "normal priority"
        self.config = config
        self._source = _as_source(source)
        self._kind = config.correction
        joint = config.correction == "joint"
        axes = JOINT_AXES if joint else CARTESIAN_AXES
        units = (("deg", DEG),) * 6 if joint else (("mm", M_PER_MM),) * 3 + (("deg", DEG),) * 3
        self._limiter = OffsetLimiter(config.limits, config.cycle_s, axes, units)
        self._outputs_spec = {o.tag: o for o in config.outputs}
        self._outputs = {o.tag: o.initial for o in config.outputs}
        self._cycle_ns = int(config.cycle_s * 1e9)
        self._timeout_ns = int(config.timeout_s * 1e9)
        self.latencies: list[int] | None = [] if record_latency else None
        self._cond = threading.Condition()
        self._sock: socket.socket | None = None
        self._thread: threading.Thread | None = None
        self._closing = False
        # counters (written by the link's thread only)
        self._received = self._answered = self._late = self._missed = self._superseded = 0
        self._clamped = self._refused = 0
        self._dropped = dict.fromkeys(
            ("address", "oversized", "malformed", "foreign", "stale", "inconsistent"), 0)
        self._max_latency = 0
        self._last_reason = ""
        # the session
        self._sessions = 0
        self._streaming = False
        self._failure: RsiLinkError | None = None
        self._last_failure: RsiLinkError | None = None
        self._last_ipoc = 0
        self._ipoc0 = 0
        self._cycle = 0
        self._streak = 0
        self._delay0 = 0
        self._controller_late = 0
        self._last_rx = 0
        self._latest: RobotState | None = None

    # ------------------------------------------------------------------ public

    def start(self) -> tuple[str, int]:
        """Bind the socket and start answering; returns the address bound.

        Returns
        -------
        tuple of (str, int)
            The host and port the link listens on (the port chosen when configured 0).
        """
        if self._thread is not None:
            raise RuntimeError("the RSI link is already started")
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            sock.bind((self.config.listen_host, self.config.listen_port))
        except OSError as exc:
            sock.close()
            raise OSError(exc.errno, f"RSI link cannot listen on {self.config.listen_host}:"
                          f"{self.config.listen_port}: {exc.strerror}") from None
        sock.setblocking(False)
        self._sock = sock
        self._warm_up()
        self._thread = threading.Thread(target=self._run, name="rsi-link", daemon=True)
        self._thread.start()
        return sock.getsockname()[:2]

    def _warm_up(self) -> None:
        """Run the per-cycle code once, so the first real cycle is not the slow one."""
        probe = (b'<Rob Type="KUKA"><AIPos A1="0" A2="0" A3="0" A4="0" A5="0" A6="0"/>'
                 b'<Delay D="0"/><IPOC>0</IPOC></Rob>')
        state = parse_rob(probe, self.config.max_packet_bytes)
        limiter = OffsetLimiter(self.config.limits, self.config.cycle_s, self._limiter.axes,
                                self._limiter.units)
        limited = limiter.apply(np.zeros(6))
        encode_sen(state.ipoc, self._kind, limited.step, self._outputs, self.config.sentype)
        CycleState(robot=state, offset=limited.offset, session=0, cycle=0, t=0.0)

    @property
    def address(self) -> tuple[str, int]:
        """The bound ``(host, port)``."""
        if self._sock is None:
            raise RuntimeError("the RSI link is not started")
        return self._sock.getsockname()[:2]

    def close(self) -> None:
        """Stop the thread and close the socket (idempotent)."""
        self._closing = True
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        if self._sock is not None:
            self._sock.close()
        with self._cond:
            self._streaming = False
            self._cond.notify_all()

    def __enter__(self) -> RsiLink:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def set_source(self, source: SourceLike | None) -> None:
        """Use ``source`` from the next cycle on (``None``: no motion)."""
        self._source = _as_source(source)

    @property
    def failure(self) -> RsiLinkError | None:
        """Why the current or last session failed (``None``: it did not)."""
        return self._failure

    @property
    def last_failure(self) -> RsiLinkError | None:
        """The failure of the latest session that failed (kept across sessions)."""
        return self._last_failure

    @property
    def streaming(self) -> bool:
        """A session is running."""
        return self._streaming

    @property
    def latest(self) -> RobotState | None:
        """The robot's state in the newest packet answered (``None`` before the first):
        the joint feedback of a robot service, between motions too."""
        return self._latest

    def stats(self) -> LinkStats:
        """A snapshot of the counters.

        Returns
        -------
        LinkStats
            The counters now.
        """
        return LinkStats(self._received, self._answered, self._late, self._missed,
                         self._superseded, dict(self._dropped), self._clamped, self._refused,
                         self._controller_late, self._sessions, self._streaming,
                         self._max_latency, self._last_reason)

    def wait(self, predicate: Callable[[RsiLink], bool], timeout: float) -> bool:
        """Wait until ``predicate(link)`` holds (checked at each session event and cycle).

        Parameters
        ----------
        predicate : callable
            Tested on this link.
        timeout : float
            Seconds at most.

        Returns
        -------
        bool
            Whether it holds.
        """
        with self._cond:
            return self._cond.wait_for(lambda: predicate(self), timeout)

    def check(self) -> None:
        """Raise the session's failure, if any."""
        if self._failure is not None:
            raise self._failure

    def follow(self, source: SourceLike, done: Callable[[CycleState], bool],
               timeout: float) -> CycleState:
        """Stream ``source`` until ``done(state)`` holds, then hold the robot: one motion
        as a robot service runs it, ending in a result or in the stream's failure.

        Parameters
        ----------
        source : CorrectionSource or callable
            The motion's corrections.
        done : callable
            Tested on each cycle's state after ``source`` answered it; the cycle where it
            first holds is the motion's last (its correction is sent).
        timeout : float
            Seconds the motion may take, waiting for the controller's stream included.

        Returns
        -------
        CycleState
            The state of the last cycle.

        Raises
        ------
        RsiLinkError
            The stream failed (before or during the motion): its reason, as a
            :class:`StreamStoppedError`, :class:`CorrectionRefusedError` … — a robot
            service turns it into a failed process.
        TimeoutError
            ``done`` did not hold within ``timeout`` seconds.
        """
        self.check()  # a held session is over: the controller has to start a new one
        ask = _as_source(source)
        finished: list[CycleState] = []

        def motion(state: CycleState) -> Correction | None:
            if finished:
                return None  # the motion is over: hold
            corr = ask(state)
            if done(state):
                finished.append(state)
            return corr

        self.set_source(motion)
        try:
            ended = self.wait(lambda lk: bool(finished) or lk.failure is not None, timeout)
            if self._failure is not None:
                raise self._failure
            if not ended:
                where = "streaming" if self._streaming else "no stream from the controller"
                raise TimeoutError(f"the motion did not end within {timeout:g} s ({where})")
            return finished[0]
        finally:
            self.set_source(None)  # the motion is over, however it ended: hold

    async def follow_async(self, source: SourceLike, done: Callable[[CycleState], bool],
                           timeout: float) -> CycleState:
        """:meth:`follow` without blocking an event loop (it waits in a worker thread).

        Parameters
        ----------
        source, done, timeout
            As :meth:`follow`.

        Returns
        -------
        CycleState
            As :meth:`follow`.
        """
        import asyncio

        return await asyncio.to_thread(self.follow, source, done, timeout)

    # ------------------------------------------------------------------ the loop

    def _realtime(self) -> None:
        """Put the calling thread (the link's) under SCHED_FIFO, if asked and allowed."""
        if self.rt_priority is None:
            return
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(self.rt_priority))
        except (AttributeError, OSError) as exc:  # not Linux, or no CAP_SYS_NICE
            self.rt_note = f"SCHED_FIFO refused ({exc}); normal priority"
        else:
            self.rt_note = f"SCHED_FIFO priority {self.rt_priority}"

    def _run(self) -> None:
        sock = self._sock
        assert sock is not None
        self._realtime()
        poller = select.poll()
        poller.register(sock, select.POLLIN)
        bufsize = self.config.max_packet_bytes + 1
        while not self._closing:
            if self._streaming:
                wait_ms = max(0, (self._last_rx + self._timeout_ns - time.monotonic_ns())
                              // 1_000_000 + 1)
            else:
                wait_ms = 100  # idle: look at _closing ten times a second
            if not poller.poll(min(wait_ms, 100)):
                if self._streaming and time.monotonic_ns() - self._last_rx >= self._timeout_ns:
                    self._end_session()
                continue
            newest: tuple[RobotState, tuple[str, int], int] | None = None
            # the queued datagrams (at most DRAIN: a flood cannot keep the loop from
            # answering); the newest packet is answered
            for _ in range(DRAIN):
                try:
                    data, addr = sock.recvfrom(bufsize)
                except (BlockingIOError, InterruptedError):
                    break
                except OSError:
                    if self._closing:
                        return
                    break  # e.g. ICMP port unreachable reported on a later receive
                t_in = time.monotonic_ns()
                state = self._accept(data, addr)
                if state is not None:
                    if newest is not None:
                        self._superseded += 1
                    newest = (state, addr, t_in)
            if newest is not None:
                try:
                    self._cycle_once(*newest)
                except Exception as exc:  # a bug must not end the thread silently
                    self._fail(RsiLinkError(f"RSI link internal error at IPOC "
                                            f"{newest[0].ipoc}: {type(exc).__name__}: {exc}"))

    def _accept(self, data: bytes, addr: tuple[str, int]) -> RobotState | None:
        cfg = self.config
        if addr[0] != cfg.robot_host or (cfg.robot_port is not None
                                         and addr[1] != cfg.robot_port):
            self._dropped["address"] += 1
            return None
        try:
            state = parse_rob(data, cfg.max_packet_bytes)
        except PacketError as exc:
            self._dropped[exc.kind] += 1
            return None
        self._received += 1
        return state

    def _cycle_once(self, state: RobotState, addr: tuple[str, int], t_in: int) -> None:
        lost = 0
        if not self._streaming:
            self._begin_session(state)
        else:
            gap = state.ipoc - self._last_ipoc
            if gap <= 0:
                self._dropped["stale"] += 1
                return
            # the cycles between the last answered packet and this one: lost on the way
            # or superseded in the queue (the controller counts them late either way)
            lost = max(0, round(gap / self.config.ipoc_step) - 1)
            if lost >= self.config.timeout_packets:
                self._dropped["inconsistent"] += 1
                return
            self._missed += lost
            self._streak += lost
        self._last_ipoc = state.ipoc
        self._last_rx = t_in
        self._latest = state
        if state.delay is not None:
            self._controller_late = max(0, state.delay - self._delay0)
        limited = self._limiter.hold() if self._failure is not None else self._ask(state)
        values = limited.step if self.config.mode == "relative" else limited.offset
        packet = encode_sen(state.ipoc, self._kind, values, self._outputs,
                            self.config.sentype)
        try:
            self._sock.sendto(packet, addr)  # type: ignore[union-attr]
        except OSError as exc:  # an unreachable controller: the cycle is missed
            self._streak += 1
            self._missed += 1
            self._last_reason = f"answer not sent: {exc}"
        else:
            self._answered += 1
            latency = time.monotonic_ns() - t_in
            if self.latencies is not None:
                self.latencies.append(latency)
            self._max_latency = max(self._max_latency, latency)
            if latency > self._cycle_ns:
                self._late += 1
                self._streak += 1
            elif lost == 0:
                self._streak = 0
        self._cycle += 1
        timeout = self.config.timeout_packets
        if self._failure is None:
            if self._streak >= timeout:
                self._fail(StreamStoppedError(
                    f"RSI stream stopped: {self._streak} cycles in a row missed or late "
                    f"(the controller's Timeout is {timeout}); last IPOC {state.ipoc}"))
            elif self._controller_late >= timeout:
                self._fail(ControllerStoppedError(
                    f"RSI stream stopped: the controller counted {self._controller_late} "
                    f"late packets (<Delay>), its Timeout is {timeout}"))
        with self._cond:
            self._cond.notify_all()

    def _ask(self, state: RobotState) -> Limited:
        cstate = CycleState(robot=state, offset=self._limiter.offset.copy(),
                            session=self._sessions, cycle=self._cycle,
                            t=(state.ipoc - self._ipoc0) / 1000.0)
        try:
            corr = self._source(cstate)
        except Exception as exc:
            self._fail(SourceFailedError(f"the correction source failed: "
                                    f"{type(exc).__name__}: {exc}"))
            return self._limiter.hold()
        if corr is None:
            return self._limiter.hold()
        if corr.outputs:
            try:
                new = {tag: self._outputs_spec[tag].check(v) if tag in self._outputs_spec
                       else self._unknown_output(tag) for tag, v in corr.outputs.items()}
            except ValueError as exc:
                self._refused += 1
                self._fail(CorrectionRefusedError(f"correction refused: {exc}"))
                return self._limiter.hold()
            self._outputs.update(new)
        if corr.offset is not None and corr.step is not None:
            self._refused += 1
            self._fail(CorrectionRefusedError("correction refused: give an offset or a step, "
                                         "not both"))
            return self._limiter.hold()
        if corr.offset is None and corr.step is None:
            return self._limiter.hold()
        if corr.offset is not None:
            target = np.asarray(corr.offset, dtype=float).reshape(-1)
        else:
            step = np.asarray(corr.step, dtype=float).reshape(-1)
            # a step of the wrong size is passed on as is: the limiter refuses it
            target = self._limiter.offset + step if step.shape == (6,) else step
        limited = self._limiter.apply(target)
        if limited.refused:
            self._refused += 1
            self._fail(CorrectionRefusedError(f"correction refused at IPOC {state.ipoc}: "
                                         f"{limited.reason}"))
        elif limited.clamped:
            self._clamped += 1
            self._last_reason = f"correction clamped at IPOC {state.ipoc}: {limited.reason}"
        return limited

    def _unknown_output(self, tag: str) -> int:
        raise ValueError(f"output {tag!r} is not configured (configured: "
                         f"{sorted(self._outputs_spec) or 'none'})")

    def _begin_session(self, state: RobotState) -> None:
        with self._cond:
            self._sessions += 1
            self._streaming = True
            self._failure = None
            self._limiter.reset()
            self._ipoc0 = state.ipoc
            self._cycle = 0
            self._streak = 0
            self._delay0 = state.delay or 0
            self._controller_late = 0
            self._cond.notify_all()

    def _end_session(self) -> None:
        silent = (time.monotonic_ns() - self._last_rx) / 1e9
        if self._failure is None:
            self._fail(StreamStoppedError(
                f"RSI stream stopped: no packet from the controller for {silent:.3f} s "
                f"(one controller timeout: {self.config.timeout_packets} × "
                f"{self.config.cycle_s * 1000:g} ms); last IPOC {self._last_ipoc}"))
        with self._cond:
            self._streaming = False
            self._cond.notify_all()

    def _fail(self, error: RsiLinkError) -> None:
        with self._cond:
            self._failure = self._last_failure = error
            self._last_reason = str(error)
            self._cond.notify_all()

