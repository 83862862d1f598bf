"""The sensor side of one real-time stream: a UDP socket answering every robot packet.

:class:`StreamLink` runs one thread that, per datagram:

1. drops and counts what is no packet of the configured robot — another address,
   oversized, malformed, foreign (the vendor's parser), or older than the last one; of
   several queued packets only the newest is answered (the older are missed cycles);
2. asks its :class:`~.source.CorrectionSource` for the correction of this cycle, given
   the robot's state (:class:`~.source.CycleState`);
3. holds the correction to the limits (:class:`~.limits.OffsetLimiter`) — clamped and
   counted, or refused: then the robot is held and the stream fails with the reason;
4. answers (the vendor's encoder) to the address the packet came from, and counts the
   answer late if it left more than one cycle after the packet arrived.

A stream (a *session*) starts with the first packet and ends when the controller has
been silent for one controller timeout.  Within it, ``timeout_packets`` missed cycles in
a row (late answers and sequence gaps), the controller's own count of late packets
reaching it (RSI's ``<Delay>``), a refused correction or a failing source put the link
into *holding*: every later packet is answered with no motion and the failure is kept in
:attr:`StreamLink.failure` — the robot service turns it into a failed process.  When
packets come back after the silence a new session starts from a zero offset: the link
recovers by itself.

A vendor's link (:class:`~..rsi.link.RsiLink`, :class:`~..egm.link.EgmLink`) gives the
codec: :meth:`StreamLink._parse`, :meth:`StreamLink._encode` and the sequence of a packet.

Real-time notes: the loop allocates little and waits in ``poll``; run it in a process of
its own (the robot service's event loop would otherwise share the GIL with it), under a
real-time priority, on a CPU of its own and with its memory locked where the machine
allows (:class:`~.realtime.RealTime`, applied by the loop's thread when it starts) —
``benchmarks/rsi_latency.py`` and ``benchmarks/egm_latency.py`` measure it so.
"""

from __future__ import annotations

import select
import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from .errors import (
    ControllerStoppedError,
    CorrectionRefusedError,
    PacketError,
    SourceFailedError,
    StreamLinkError,
    StreamStoppedError,
)
from .follow import Following
from .limits import Limited, OffsetLimiter
from .realtime import LoopScheduling, RealTime
from .source import Correction, CycleState, SourceLike, as_source

__all__ = ["LinkStats", "StreamLink"]


#: Datagrams read per wake-up before the newest packet among them is answered.
DRAIN = 64

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
        Cycles the link never answered, from the gaps of the packets' sequence (lost on
        the way or superseded).
    superseded : int
        Packets not answered because a newer one was already queued behind them.
    dropped : dict of str to int
        Datagrams dropped, by reason: ``address``, ``oversized``, ``malformed``,
        ``foreign``, ``stale`` (not newer than the last packet answered),
        ``inconsistent`` (within a session, a sequence number ``timeout_packets`` cycles or
        more ahead of the last: the stream would have been silent that long).
    clamped, refused : int
        Corrections cut to the limits, and refused.
    controller_late : int
        The controller's own count of late packets in the current session (RSI's
        ``<Delay>``; 0 where the interface reports none, as EGM).
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


class StreamLink(Following):
    """The sensor side of one stream (module doc); subclassed per vendor.

    Parameters
    ----------
    config : object
        The stream's configuration: ``listen_host``, ``listen_port``, ``robot_host``,
        ``robot_port``, ``max_packet_bytes``, ``cycle_s``, ``timeout_s``,
        ``timeout_packets``, ``limits``.
    source : CorrectionSource or callable, optional
        Gives the correction of each cycle; ``None``: no motion until one is set with
        :meth:`set_source`.
    axes, units : tuple
        The axes' names and their units, for the limiter's reasons
        (:class:`~.limits.OffsetLimiter`).
    record_latency : bool
        Keep every packet-in → answer-out time (ns) in :attr:`latencies` (benchmarks).
    rt_priority : int, optional
        Run the link's thread under ``SCHED_FIFO`` at this priority (1..99; Linux, needs
        ``CAP_SYS_NICE``).  What happened is in :attr:`rt_note`.
    realtime : RealTime, optional
        The loop's whole scheduling instead (:mod:`.realtime`: priority, CPUs, locked
        memory), applied by its thread when it starts; not with ``rt_priority``.
    """

    #: The interface's name in messages ("RSI", "EGM").
    VENDOR = "stream"
    #: The controller's name of its limit of missed cycles, and of its late count.
    TIMEOUT_WORD = "timeout"
    DELAY_WORD = ""

    def __init__(self, config: Any, source: SourceLike | None, axes: tuple[str, ...],
                 units: tuple[tuple[str, float], ...], record_latency: bool = False,
                 rt_priority: int | None = None, realtime: RealTime | None = None) -> None:
        self.realtime = RealTime.given(rt_priority, realtime)
        self.rt_priority = self.realtime.priority
        self.rt_note = "normal priority"
        self.config = config
        self._source = as_source(source)
        self._limiter = OffsetLimiter(config.limits, config.cycle_s, axes, units)
        self._cycle_ns = int(config.cycle_s * 1e9)
        self._timeout_ns = int(config.timeout_s * 1e9)
        self._timeout_packets = config.timeout_packets  # a property of some configs
        self.latencies: list[int] | None = [] if record_latency else None
        self._cond = threading.Condition()
        self._sock: socket.socket | None = None
        self._thread: threading.Thread | None = None
        self._closing = False
        self._scheduling = LoopScheduling(self.realtime)
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
        self._failure: StreamLinkError | None = None
        self._last_failure: StreamLinkError | None = None
        self._last_seq = 0
        self._clock0 = 0
        self._cycle = 0
        self._streak = 0
        self._delay0 = 0
        self._controller_late = 0
        self._last_rx = 0
        self._latest: Any = None
        #: called with the link by its thread after every cycle and session event (the
        #: link process publishes its state so: :mod:`.process`); ``None``: nobody
        self.observer: Callable[[StreamLink], None] | None = None

    # ------------------------------------------------------------ the vendor's codec

    def _parse(self, data: bytes) -> Any:
        """The robot's state (SI) of a datagram, or :class:`PacketError` with the reason."""
        raise NotImplementedError

    def _seq(self, state: Any) -> int:
        """The packet's place in the controller's sequence (RSI's IPOC, EGM's seqno)."""
        raise NotImplementedError

    def _lost(self, gap: int) -> int:
        """Cycles lost between two packets ``gap`` apart in the sequence."""
        return gap - 1

    def _clock_ms(self, state: Any) -> int:
        """The controller's clock of the packet, in milliseconds."""
        raise NotImplementedError

    def _restarted(self, seq: int) -> bool:
        """A sequence number this far behind the last means the controller restarted its
        stream (EGM counts from 0 again after ``EGMReset``); RSI's IPOC never restarts."""
        return False

    def _delay(self, state: Any) -> int | None:
        """The controller's own count of late packets, where it reports one."""
        return None

    def _encode(self, state: Any, limited: Limited) -> bytes:
        """The answer to ``state`` carrying ``limited`` (step or offset, SI)."""
        raise NotImplementedError

    def _take_outputs(self, corr: Correction) -> None:
        """Keep the output words of ``corr``; ``ValueError`` for one not configured."""
        if corr.outputs:
            raise ValueError(f"{self.VENDOR} carries no output words, got "
                             f"{sorted(corr.outputs)}")

    def _on_begin(self, state: Any) -> None:
        """A session starts with ``state`` (the vendor's link keeps what it needs)."""

    def _where(self, state: Any) -> str:
        """The packet, named for messages (``"IPOC 1234"``)."""
        return f"seqno {self._seq(state)}"

    def _warm_up(self) -> None:
        """Run the per-cycle code once, so the first real cycle is not the slow one."""

    # ------------------------------------------------------------------ public

    def start(self) -> tuple[str, int]:
        """Bind the socket and start answering; returns the address bound.

        Returns
        -------
        tuple of (str, int)
            The host and port the link listens on (the port chosen when configured 0).
        """
        if self._thread is not None:
            raise RuntimeError(f"the {self.VENDOR} link is already started")
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            sock.bind((self.config.listen_host, self.config.listen_port))
        except OSError as exc:
            sock.close()
            raise OSError(exc.errno, f"{self.VENDOR} link cannot listen on "
                          f"{self.config.listen_host}:{self.config.listen_port}: "
                          f"{exc.strerror}") from None
        sock.setblocking(False)
        self._sock = sock
        self._warm_up()
        self._thread = threading.Thread(target=self._run, name=f"{self.VENDOR.lower()}-link",
                                        daemon=True)
        self._thread.start()
        self.rt_note = self._scheduling.wait(5.0)  # applied by the loop's thread
        return sock.getsockname()[:2]

    @property
    def address(self) -> tuple[str, int]:
        """The bound ``(host, port)``."""
        if self._sock is None:
            raise RuntimeError(f"the {self.VENDOR} link is not started")
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

    def __enter__(self) -> StreamLink:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def set_source(self, source: SourceLike | None) -> None:
        """Use ``source`` from the next cycle on (``None``: no motion)."""
        self._source = as_source(source)

    @property
    def latest(self) -> Any:
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

    # ------------------------------------------------------------------ the loop

    def _run(self) -> None:
        sock = self._sock
        assert sock is not None
        self._scheduling.apply_here()
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
            newest: tuple[Any, tuple[str, int], int] | None = None
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
                    self._fail(StreamLinkError(
                        f"{self.VENDOR} link internal error at {self._where(newest[0])}: "
                        f"{type(exc).__name__}: {exc}"))

    def _accept(self, data: bytes, addr: tuple[str, int]) -> Any:
        cfg = self.config
        if addr[0] != cfg.robot_host or (cfg.robot_port is not None
                                         and addr[1] != cfg.robot_port):
            self._dropped["address"] += 1
            return None
        try:
            state = self._parse(data)
        except PacketError as exc:
            self._dropped[exc.kind] += 1
            return None
        self._received += 1
        return state

    def _cycle_once(self, state: Any, addr: tuple[str, int], t_in: int) -> None:
        lost = 0
        seq = self._seq(state)
        gap = seq - self._last_seq
        if self._streaming and gap <= 0 and self._restarted(seq):
            self._streaming = False  # the controller began a new stream at once
        if not self._streaming:
            self._begin_session(state)
        elif gap <= 0:
            self._dropped["stale"] += 1
            return
        else:
            # cycles between the last answered packet and this one: lost or superseded
            lost = max(0, self._lost(gap))
            if lost >= self._timeout_packets:
                self._dropped["inconsistent"] += 1
                return
            self._missed += lost
            self._streak += lost
        self._last_seq = seq
        self._last_rx = t_in
        self._latest = state
        delay = self._delay(state)
        if delay is not None:
            self._controller_late = max(0, delay - self._delay0)
        limited = self._limiter.hold() if self._failure is not None else self._ask(state)
        packet = self._encode(state, limited)
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
        self._check_limits(state)
        self._notify()

    def _check_limits(self, state: Any) -> None:
        timeout = self._timeout_packets
        if self._failure is not None:
            return
        if self._streak >= timeout:
            self._fail(StreamStoppedError(
                f"{self.VENDOR} stream stopped: {self._streak} cycles in a row missed or "
                f"late (the controller's {self.TIMEOUT_WORD} is {timeout}); last "
                f"{self._where(state)}"))
        elif self._controller_late >= timeout:
            self._fail(ControllerStoppedError(
                f"{self.VENDOR} stream stopped: the controller counted "
                f"{self._controller_late} late packets{self.DELAY_WORD}, its "
                f"{self.TIMEOUT_WORD} is {timeout}"))

    def _ask(self, state: Any) -> Limited:
        cstate = CycleState(robot=state, offset=self._limiter.offset.copy(),
                            session=self._sessions, cycle=self._cycle,
                            t=(self._clock_ms(state) - self._clock0) / 1000.0)
        try:
            corr = self._source(cstate)
        except Exception as exc:
            self._fail(SourceFailedError(f"the correction source failed: "
                                         f"{type(exc).__name__}: {exc}"))
            return self._limiter.hold()
        if corr is None:
            return self._limiter.hold()
        try:
            self._take_outputs(corr)
        except ValueError as exc:
            return self._refuse(f"correction refused: {exc}")
        try:
            target = corr.target(self._limiter.offset)
        except ValueError as exc:
            return self._refuse(f"correction refused: {exc}")
        if target is None:
            return self._limiter.hold()
        limited = self._limiter.apply(target)
        if limited.refused:
            self._refused += 1
            self._fail(CorrectionRefusedError(f"correction refused at {self._where(state)}: "
                                              f"{limited.reason}"))
        elif limited.clamped:
            self._clamped += 1
            self._last_reason = (f"correction clamped at {self._where(state)}: "
                                 f"{limited.reason}")
        return limited

    def _refuse(self, reason: str) -> Limited:
        self._refused += 1
        self._fail(CorrectionRefusedError(reason))
        return self._limiter.hold()

    def _begin_session(self, state: Any) -> None:
        with self._cond:
            self._sessions += 1
            self._streaming = True
            self._failure = None
            self._limiter.reset()
            self._clock0 = self._clock_ms(state)
            self._cycle = 0
            self._streak = 0
            self._delay0 = self._delay(state) or 0
            self._controller_late = 0
            self._on_begin(state)
            self._cond.notify_all()

    def _end_session(self) -> None:
        silent = (time.monotonic_ns() - self._last_rx) / 1e9
        if self._failure is None:
            self._fail(StreamStoppedError(
                f"{self.VENDOR} stream stopped: no packet from the controller for "
                f"{silent:.3f} s (one controller timeout: {self.config.timeout_packets} × "
                f"{self.config.cycle_s * 1000:g} ms); last {self._where_last()}"))
        self._streaming = False
        self._notify()

    def _notify(self) -> None:
        """Tell the observer, then the waiters (in that order: a waiter woken by a failure
        finds it published)."""
        with self._cond:
            if self.observer is not None:
                self.observer(self)
            self._cond.notify_all()

    def _where_last(self) -> str:
        return f"seqno {self._last_seq}"

    def _fail(self, error: StreamLinkError) -> None:
        with self._cond:
            self._failure = self._last_failure = error
            self._last_reason = str(error)
            self._notify()
