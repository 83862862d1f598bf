"""The sensor side of one ABB EGM stream: :class:`EgmLink`.

The cycle loop, its sessions, counters and failures are every vendor's
(:class:`~..stream.link.StreamLink`, whose doc says what happens to each datagram); EGM
gives it the codec — ``EgmRobot`` parsed by :func:`.messages.parse_egm_robot`, the
header's ``seqno`` as the sequence and ``tm`` as the clock — and turns the commanded
offset ``o`` (held to the limits like RSI's) into the answer:

* ``joint``: ``EgmSensor.planned.joints = q₀ + o`` (``q₀``: the feedback joints of the
  session's first message);
* ``pose``: ``planned.cartesian`` with ``p = p₀ + o[:3]`` and ``q = q(o[3:]) ⊗ q₀`` — the
  rotation vector ``o[3:]`` applied in the work object's frame after the pose at the
  session's start ``(p₀, q₀)``;
* ``pathcorr``: ``EgmSensorPathCorr.pathCorr.pos = o[:3]``; a rotation is refused.
  While it sends no correction the link watches the controller's own path —
  :attr:`EgmLink.path_chord`, the last pair of its planned joints at least
  :data:`PATH_CHORD_RAD` apart — from which a compensation started later, the arm
  standing, knows the direction the path last moved in: the x of ABB's path frame
  (:mod:`plugcell.kinematics.path_frame`).

The answer's header echoes the message's ``seqno`` and ``tm`` (ABB's sensor examples
count their own; the controller follows the newest message either way, and the echo
lets the robot side time each answer).
"""

from __future__ import annotations

import numpy as np

from plugcell.io.units import DEG, M_PER_MM

from ..stream.errors import PacketError, StreamLinkError
from ..stream.limits import Limited
from ..stream.link import StreamLink
from ..stream.realtime import RealTime
from ..stream.source import SourceLike
from .config import EgmConfig
from .messages import (
    EgmState,
    egm_pb2,
    encode_joints,
    encode_path_correction,
    encode_pose,
    parse_egm_robot,
    quat_multiply,
    rotvec_to_quat,
)

__all__ = ["EgmLink", "EgmLinkError"]

#: Why an EGM stream failed: the one error of every streaming link.
EgmLinkError = StreamLinkError

#: The least joint motion (rad, on one axis) the link takes a chord of the controller's
#: path from (:attr:`EgmLink.path_chord`): some 10 µm of the TCP on an arm of 1 m.
PATH_CHORD_RAD = 1e-5

_JOINTS = ("A1", "A2", "A3", "A4", "A5", "A6")
_CARTESIAN = ("X", "Y", "Z", "RX", "RY", "RZ")


class EgmLink(StreamLink):
    """The sensor side of one EGM stream (module doc).

    Parameters
    ----------
    config : EgmConfig
        The stream's configuration.
    source : CorrectionSource or callable, optional
        Gives the offset of each cycle; ``None``: hold the start.
    record_latency : bool
        Keep every packet-in → answer-out time (ns) in :attr:`latencies` (benchmarks).
    rt_priority : int, optional
        Run the link's thread under ``SCHED_FIFO`` at this priority (1..99; Linux, needs
        ``CAP_SYS_NICE``).
    realtime : RealTime, optional
        The loop's whole scheduling instead: priority, CPUs, locked memory
        (:mod:`..stream.realtime`); not with ``rt_priority``.
    """

    VENDOR = "EGM"
    TIMEOUT_WORD = "CommTimeout in cycles"

    def __init__(self, config: EgmConfig, source: SourceLike | None = None,
                 record_latency: bool = False, rt_priority: int | None = None,
                 realtime: RealTime | None = None) -> None:
        joint = config.mode == "joint"
        axes = _JOINTS if joint else _CARTESIAN
        units = (("deg", DEG),) * 6 if joint else (("mm", M_PER_MM),) * 3 + (("deg", DEG),) * 3
        super().__init__(config, source, axes, units, record_latency, rt_priority, realtime)
        self._mode = config.mode
        self._q0 = np.zeros(6)
        self._p0 = np.zeros(3)
        self._quat0: tuple[float, ...] = (1.0, 0.0, 0.0, 0.0)
        # the answer written over each cycle (the link's thread only); the robot's
        # message is a new one each cycle (messages.parse_egm_robot says why)
        self._sensor_msg = egm_pb2.EgmSensor()
        self._chord_anchor: np.ndarray | None = None
        #: pathcorr: the last chord of the controller's own path, ``(q_a, q_b)`` — planned
        #: joints (rad) :data:`PATH_CHORD_RAD` or more apart, taken while no correction
        #: was sent; ``None`` before the path has moved in this session
        self.path_chord: tuple[np.ndarray, np.ndarray] | None = None

    def _parse(self, data: bytes) -> EgmState:
        state = parse_egm_robot(data, self.config.max_packet_bytes)
        if len(state.joints) != 6:
            raise PacketError("foreign", f"{len(state.joints)} joints: the link drives "
                              "six-axis arms")
        if self._mode == "pose" and state.position is None:
            raise PacketError("foreign", "no feedback pose (pose mode needs "
                              "feedBack.cartesian)")
        return state

    def _seq(self, state: EgmState) -> int:
        return state.seqno

    def _restarted(self, seq: int) -> bool:
        # a new EGMRun… counts from the start again: more than one CommTimeout of cycles
        # behind is no reordered message but a new stream
        return self._last_seq - seq > self.config.timeout_packets

    def _clock_ms(self, state: EgmState) -> int:
        return state.tm

    def joint_base(self, state: object) -> np.ndarray:
        """Where the session's joint offsets start: ``q₀``, the feedback joints of its first
        message (every joint target sent is ``q₀ + o``)."""
        return self._q0.copy()

    def _on_begin(self, state: EgmState) -> None:
        self._q0 = state.joints.copy()
        self._chord_anchor, self.path_chord = None, None
        if state.position is not None and state.quaternion is not None:
            self._p0 = state.position.copy()
            self._quat0 = tuple(float(v) for v in state.quaternion)

    def _watch_path(self, state: EgmState) -> None:
        """Take the chord of the path (:attr:`path_chord`) while no correction is sent."""
        q = state.planned_joints if state.planned_joints is not None else state.joints
        if np.any(self._limiter.offset):  # the joints are the path's plus a correction
            self._chord_anchor = None
            return
        a = self._chord_anchor
        if a is None or len(a) != len(q):
            self._chord_anchor = q
        elif np.max(np.abs(q - a)) >= PATH_CHORD_RAD:
            self.path_chord, self._chord_anchor = (a, q), q

    def _ask(self, state: EgmState) -> Limited:
        if self._mode == "pathcorr":
            self._watch_path(state)
        limited = super()._ask(state)
        if self._mode == "pathcorr" and not limited.refused and np.any(limited.offset[3:]):
            self._limiter.offset = self._limiter.offset - limited.step  # not sent: undo
            return self._refuse(f"correction refused at seqno {state.seqno}: a path "
                                f"correction has no rotation, got {limited.offset[3:]} rad")
        return limited

    def _encode(self, state: EgmState, limited: Limited) -> bytes:
        o = limited.offset
        if self._mode == "joint":
            return encode_joints(state.seqno, state.tm, self._q0 + o, self._sensor_msg)
        if self._mode == "pose":
            quat = quat_multiply(rotvec_to_quat(o[3:]), self._quat0)
            return encode_pose(state.seqno, state.tm, self._p0 + o[:3], quat)
        return encode_path_correction(state.seqno, state.tm, o[:3], self.config.path_age_ms)

    def _warm_up(self) -> None:
        msg = egm_pb2.EgmRobot()
        msg.header.seqno, msg.header.tm = 1, 0
        msg.header.mtype = egm_pb2.EgmHeader.MSGTYPE_DATA
        msg.feedBack.joints.joints.extend([0.0] * 6)
        fb = msg.feedBack.cartesian
        fb.pos.x = fb.pos.y = fb.pos.z = 0.0
        fb.orient.u0, fb.orient.u1, fb.orient.u2, fb.orient.u3 = 1.0, 0.0, 0.0, 0.0
        state = parse_egm_robot(msg.SerializeToString(), self.config.max_packet_bytes)
        zero = Limited(np.zeros(6), np.zeros(6))
        encode_joints(1, 0, state.joints, self._sensor_msg)
        encode_pose(1, 0, np.zeros(3), quat_multiply(rotvec_to_quat(zero.offset[3:]),
                                                      (1.0, 0.0, 0.0, 0.0)))
        encode_path_correction(1, 0, zero.offset[:3])
