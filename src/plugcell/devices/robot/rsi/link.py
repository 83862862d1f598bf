"""The sensor side of one KUKA RSI stream: :class:`RsiLink`.

The cycle loop, its sessions, counters and failures are every vendor's
(:class:`~..stream.link.StreamLink`, whose doc says what happens to each datagram); RSI
gives it the codec — ``<Rob>`` parsed by :func:`.codec.parse_rob`, the IPOC as the
sequence (one cycle = ``ipoc_step`` ms), the controller's ``<Delay>`` as its own count of
late packets, ``<Sen>`` written by :func:`.codec.encode_sen` echoing the IPOC with the
step (``#RELATIVE``) or the offset (``#ABSOLUTE``) and the output words.
"""

from __future__ import annotations

import numpy as np

from plugcell.io.units import DEG, M_PER_MM

from ..stream.errors import (
    ControllerStoppedError,
    CorrectionRefusedError,
    SourceFailedError,
    StreamLinkError,
    StreamStoppedError,
)
from ..stream.limits import Limited, OffsetLimiter
from ..stream.link import LinkStats, StreamLink
from ..stream.realtime import RealTime
from ..stream.source import Correction, CorrectionSource, CycleState, SourceLike
from .codec import CARTESIAN_AXES, JOINT_AXES, RobotState, encode_sen, parse_rob
from .config import RsiConfig
from .reader import RobReader

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

#: Why an RSI stream failed: the one error of every streaming link.
RsiLinkError = StreamLinkError


class RsiLink(StreamLink):
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
    realtime : RealTime, optional
        The loop's whole scheduling instead: priority, CPUs, locked memory
        (:mod:`..stream.realtime`); not with ``rt_priority``.
    """

    VENDOR = "RSI"
    TIMEOUT_WORD = "Timeout"
    DELAY_WORD = " (<Delay>)"

    def __init__(self, config: RsiConfig, source: SourceLike | None = None,
                 record_latency: bool = False, rt_priority: int | None = None,
                 realtime: RealTime | None = None) -> None:
        joint = config.correction == "joint"
        axes = JOINT_AXES if joint else CARTESIAN_AXES
        units = (("deg", DEG),) * 6 if joint else (("mm", M_PER_MM),) * 3 + (("deg", DEG),) * 3
        super().__init__(config, source, axes, units, record_latency, rt_priority, realtime)
        self._kind = config.correction
        self._outputs_spec = {o.tag: o for o in config.outputs}
        self._outputs = {o.tag: o.initial for o in config.outputs}
        self._read = RobReader(config.max_packet_bytes)  # parse_rob, fast for the repeated layout
        self._ipoc_step = config.ipoc_step

    def _parse(self, data: bytes) -> RobotState:
        return self._read(data)

    def _seq(self, state: RobotState) -> int:
        return state.ipoc

    def _lost(self, gap: int) -> int:
        return round(gap / self._ipoc_step) - 1

    def _clock_ms(self, state: RobotState) -> int:
        return state.ipoc  # the controller's IPOC counts milliseconds

    def _delay(self, state: RobotState) -> int | None:
        return state.delay

    def _where(self, state: RobotState) -> str:
        return f"IPOC {state.ipoc}"

    def _where_last(self) -> str:
        return f"IPOC {self._last_seq}"

    def _encode(self, state: RobotState, limited: Limited) -> bytes:
        values = limited.step if self.config.mode == "relative" else limited.offset
        return encode_sen(state.ipoc, self._kind, values, self._outputs, self.config.sentype)

    def _take_outputs(self, corr: Correction) -> None:
        if corr.outputs:
            new = {tag: self._outputs_spec[tag].check(v) if tag in self._outputs_spec
                   else self._unknown_output(tag) for tag, v in corr.outputs.items()}
            self._outputs.update(new)

    def _unknown_output(self, tag: str) -> int:
        raise ValueError(f"output {tag!r} is not configured (configured: "
                         f"{sorted(self._outputs_spec) or 'none'})")

    def _warm_up(self) -> None:
        probe = (b'<Rob Type="KUKA"><AIPos A1="0" A2="0" A3="0" A4="0" A5="0" A6="0"/>'
                 b'<Delay D="0"/><IPOC>0</IPOC></Rob>')
        state = parse_rob(probe, self.config.max_packet_bytes)
        limiter = OffsetLimiter(self.config.limits, self.config.cycle_s, self._limiter.axes,
                                self._limiter.units)
        limited = limiter.apply(np.zeros(6))
        encode_sen(state.ipoc, self._kind, limited.step, self._outputs, self.config.sentype)
        CycleState(robot=state, offset=limited.offset, session=0, cycle=0, t=0.0)
