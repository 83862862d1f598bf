"""EGM's messages: ``EgmRobot`` in, ``EgmSensor`` / ``EgmSensorPathCorr`` out.

The messages are ABB's ``egm.proto`` (package ``abb.egm``) compiled by ``protobuf``;
the compiled module comes with the ``abb-robot-client`` package (Apache-2.0, Wason
Technology / Rensselaer Polytechnic Institute), which ships it as
``abb_robot_client._egm_protobuf.egm_pb2`` — no codec is written here.  The controller
sends, every cycle (4 ms), one ``EgmRobot``::

    header { seqno tm mtype: MSGTYPE_DATA }            sequence number, controller clock (ms)
    feedBack { joints { joints: [deg × 6] } cartesian { pos {x y z} (mm) orient {u0..u3} } }
    planned { … }                                       what the controller commands
    motorState { state: MOTORS_ON }  mciState { … }  mciConvergenceMet  rapidExecState { … }
    testSignals { signals: […] }  utilizationRate  moveIndex

and follows, until its next cycle, the newest ``EgmSensor``: ``planned.joints`` (degrees,
``EGMActJoint`` / ``EGMRunJoint``) or ``planned.cartesian`` (mm and a unit quaternion
``u0 + u1 i + u2 j + u3 k``, ``EGMActPose`` / ``EGMRunPose``), or an ``EgmSensorPathCorr``
(``pathCorr.pos`` in mm in path coordinates, ``EGMActMove`` / ``EGMMoveL``).

:func:`parse_egm_robot` reads a datagram into an :class:`EgmState` in SI — ``mm → m``,
``deg → rad`` through :mod:`plugcell.io.units` — and raises
:class:`~..stream.errors.PacketError` (``malformed``, ``oversized``, ``foreign``) for
anything else; the ``encode_*`` functions write the answers from SI values.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from plugcell.io.units import DEG, M_PER_MM, MM_PER_M

from ..stream.errors import PacketError

try:
    from abb_robot_client._egm_protobuf import egm_pb2
except ImportError as exc:  # pragma: no cover - a dependency of the package
    raise ImportError("ABB EGM needs the compiled egm.proto of the 'abb-robot-client' "
                      "package: pip install 'abb-robot-client>=0.4,<0.5'") from exc
from google.protobuf.message import DecodeError
from google.protobuf.unknown_fields import UnknownFieldSet

Array = NDArray[np.float64]

__all__ = [
    "EgmState",
    "egm_pb2",
    "encode_joints",
    "encode_path_correction",
    "encode_pose",
    "parse_egm_robot",
    "quat_multiply",
    "rotvec_to_quat",
]

_DATA = egm_pb2.EgmHeader.MSGTYPE_DATA
_CORRECTION = egm_pb2.EgmHeader.MSGTYPE_CORRECTION
_PATH_CORRECTION = egm_pb2.EgmHeader.MSGTYPE_PATH_CORRECTION
_MOTORS_ON = egm_pb2.EgmMotorState.MOTORS_ON
_RAPID_RUNNING = egm_pb2.EgmRapidCtrlExecState.RAPID_RUNNING
_MCI_RUNNING = egm_pb2.EgmMCIState.MCI_RUNNING
#: A unit quaternion's norm may be off by this much (the controller sends 6-8 digits).
QUAT_TOL = 1e-3
#: Larger joint values (deg) or coordinates (mm) are no robot's: a corrupted number.
MAX_JOINT_DEG = 3600.0
MAX_COORD_MM = 1e6


@dataclass(frozen=True)
class EgmState:
    """One ``EgmRobot`` message in SI.

    Attributes
    ----------
    seqno : int
        ``header.seqno``: +1 each message of the stream.
    tm : int
        ``header.tm``: the controller's clock (ms).
    joints : ndarray, shape (n,)
        ``feedBack.joints`` (rad), n = 6 (7 on a seven-axis arm).
    position : ndarray, shape (3,) or None
        ``feedBack.cartesian.pos``, the TCP in the work object (m).
    quaternion : ndarray, shape (4,) or None
        ``feedBack.cartesian.orient``, ``(w, x, y, z)``, unit.
    planned_joints : ndarray, shape (n,) or None
        ``planned.joints`` (rad).
    planned_position, planned_quaternion : ndarray or None
        ``planned.cartesian`` (m; ``(w, x, y, z)``).
    external_joints : ndarray or None
        ``feedBack.externalJoints`` (robot units).
    motors_on, rapid_running, mci_running : bool or None
        ``motorState``, ``rapidExecState``, ``mciState``; ``None`` when not sent.
    convergence_met : bool or None
        ``mciConvergenceMet``: the robot is within the EGM condition's tolerance.
    test_signals : tuple of float
        ``testSignals.signals``.
    utilization : float or None
        ``utilizationRate`` (%).
    """

    seqno: int
    tm: int
    joints: Array
    position: Array | None = None
    quaternion: Array | None = None
    planned_joints: Array | None = None
    planned_position: Array | None = None
    planned_quaternion: Array | None = None
    external_joints: Array | None = None
    motors_on: bool | None = None
    rapid_running: bool | None = None
    mci_running: bool | None = None
    convergence_met: bool | None = None
    test_signals: tuple[float, ...] = ()
    utilization: float | None = None

    @property
    def joints_setpoint(self) -> Array | None:
        """``planned.joints``: the joints the controller commands (rad), as RSI's ``ASPos``."""
        return self.planned_joints


def _finite(where: str, values, bound: float = math.inf) -> list[float]:
    vals = list(values)
    for v in vals:
        if not math.isfinite(v):
            raise PacketError("malformed", f"{where}: {v!r} is not a finite number")
        if abs(v) > bound:
            raise PacketError("malformed", f"{where}: {v:.6g} is beyond ±{bound:g}")
    return vals


def _pose(where: str, pose) -> tuple[Array | None, Array | None]:
    if not pose.HasField("pos") or not pose.HasField("orient"):
        return None, None
    p, o = pose.pos, pose.orient
    pos = np.array(_finite(f"{where}.pos", (p.x, p.y, p.z), MAX_COORD_MM)) * M_PER_MM
    q = np.array(_finite(f"{where}.orient", (o.u0, o.u1, o.u2, o.u3), 1.5))
    norm = float(np.sqrt(q @ q))
    if abs(norm - 1.0) > QUAT_TOL:
        raise PacketError("malformed", f"{where}.orient: |q| = {norm:.6g}, not a unit "
                          "quaternion")
    return pos, q / norm


def parse_egm_robot(data: bytes, max_bytes: int = 1400) -> EgmState:
    """An ``EgmRobot`` datagram as an :class:`EgmState` (SI).

    Parameters
    ----------
    data : bytes
        The datagram.
    max_bytes : int
        Larger datagrams are ``oversized``.

    Returns
    -------
    EgmState
        The robot's state.

    Raises
    ------
    PacketError
        ``oversized``; ``malformed`` (no protobuf, a missing required field, a number
        that is not finite, a quaternion that is not unit); ``foreign`` (protobuf, but
        not a robot's message: unknown fields, no header or feedback, a sensor's type).
    """
    if len(data) > max_bytes:
        raise PacketError("oversized", f"{len(data)} bytes > {max_bytes}")
    # a new message each time: parsed into a kept one, upb's arena grows with every
    # parse (measured: 142 MB over 200 000 messages, ~13 minutes of a 4 ms stream)
    msg = egm_pb2.EgmRobot()
    try:
        msg.ParseFromString(data)
    except (DecodeError, ValueError, RuntimeError) as exc:
        raise PacketError("malformed", f"not an EgmRobot message: {exc}") from None
    if len(UnknownFieldSet(msg)):
        raise PacketError("foreign", "fields that EgmRobot does not have")
    h = msg.header
    if not (msg.HasField("header") and h.HasField("seqno") and h.HasField("tm")):
        raise PacketError("foreign", "no header with seqno and tm")
    if h.mtype in (_CORRECTION, _PATH_CORRECTION) or (
            h.HasField("mtype") and h.mtype != _DATA):
        raise PacketError("foreign", f"header type {h.mtype}: not a robot's data message")
    fb = msg.feedBack
    if not (msg.HasField("feedBack") and fb.HasField("joints")):
        raise PacketError("foreign", "no feedback joints")
    joints = _finite("feedBack.joints", fb.joints.joints, MAX_JOINT_DEG)
    if len(joints) not in (6, 7):
        raise PacketError("foreign", f"{len(joints)} feedback joints, expected 6 or 7")
    position, quaternion = _pose("feedBack.cartesian", fb.cartesian) \
        if fb.HasField("cartesian") else (None, None)
    pl = msg.planned
    planned_joints = planned_position = planned_quaternion = None
    if msg.HasField("planned"):
        if pl.HasField("joints"):
            planned_joints = np.array(_finite("planned.joints", pl.joints.joints,
                                              MAX_JOINT_DEG)) * DEG
        if pl.HasField("cartesian"):
            planned_position, planned_quaternion = _pose("planned.cartesian", pl.cartesian)
    ext = (np.array(_finite("feedBack.externalJoints", fb.externalJoints.joints))
           if fb.HasField("externalJoints") else None)
    return EgmState(
        seqno=h.seqno, tm=h.tm, joints=np.array(joints) * DEG, position=position,
        quaternion=quaternion, planned_joints=planned_joints,
        planned_position=planned_position, planned_quaternion=planned_quaternion,
        external_joints=ext,
        motors_on=msg.motorState.state == _MOTORS_ON if msg.HasField("motorState") else None,
        rapid_running=(msg.rapidExecState.state == _RAPID_RUNNING
                       if msg.HasField("rapidExecState") else None),
        mci_running=msg.mciState.state == _MCI_RUNNING if msg.HasField("mciState") else None,
        convergence_met=(msg.mciConvergenceMet if msg.HasField("mciConvergenceMet")
                         else None),
        test_signals=tuple(msg.testSignals.signals),
        utilization=msg.utilizationRate if msg.HasField("utilizationRate") else None)


def _header(header, seqno: int, tm: int, mtype: int) -> None:
    header.seqno = seqno & 0xFFFFFFFF
    header.tm = tm & 0xFFFFFFFF
    header.mtype = mtype


def encode_joints(seqno: int, tm: int, joints: Array, into=None) -> bytes:
    """``EgmSensor`` with the joint targets ``planned.joints`` (``EGMRunJoint``).

    Parameters
    ----------
    seqno, tm : int
        The answer's sequence number and time (ms).
    joints : ndarray, shape (n,)
        The targets (rad), sent in degrees.
    into : EgmSensor, optional
        A message kept by the caller and written over (a link: no new message a cycle;
        it must hold nothing but what this function writes); by default a new one.

    Returns
    -------
    bytes
        The serialized message.
    """
    msg = egm_pb2.EgmSensor() if into is None else into
    _header(msg.header, seqno, tm, _CORRECTION)
    msg.planned.joints.joints[:] = [float(q) / DEG for q in joints]
    return msg.SerializeToString()


def encode_pose(seqno: int, tm: int, position: Array, quaternion: Array) -> bytes:
    """``EgmSensor`` with the pose target ``planned.cartesian`` (``EGMRunPose``).

    Parameters
    ----------
    seqno, tm : int
        The answer's sequence number and time (ms).
    position : ndarray, shape (3,)
        The TCP in the work object (m), sent in mm.
    quaternion : ndarray, shape (4,)
        ``(w, x, y, z)``, unit: ``orient.u0..u3``.

    Returns
    -------
    bytes
        The serialized message.
    """
    msg = egm_pb2.EgmSensor()
    _header(msg.header, seqno, tm, _CORRECTION)
    pos, orient = msg.planned.cartesian.pos, msg.planned.cartesian.orient
    pos.x, pos.y, pos.z = (float(v) * MM_PER_M for v in position)
    orient.u0, orient.u1, orient.u2, orient.u3 = (float(v) for v in quaternion)
    return msg.SerializeToString()


def encode_path_correction(seqno: int, tm: int, offset: Array, age_ms: int = 1) -> bytes:
    """``EgmSensorPathCorr``: a displacement in path coordinates (``EGMMoveL``).

    Parameters
    ----------
    seqno, tm : int
        The answer's sequence number and time (ms).
    offset : ndarray, shape (3,)
        The displacement (m) along the path's x (direction of motion), y and z, sent in mm.
    age_ms : int
        ``pathCorr.age``: how old the measurement behind it is (ms).

    Returns
    -------
    bytes
        The serialized message.
    """
    msg = egm_pb2.EgmSensorPathCorr()
    _header(msg.header, seqno, tm, _PATH_CORRECTION)
    pos = msg.pathCorr.pos
    pos.x, pos.y, pos.z = (float(v) * MM_PER_M for v in offset[:3])
    msg.pathCorr.age = age_ms
    return msg.SerializeToString()


def rotvec_to_quat(w: Array) -> tuple[float, float, float, float]:
    """The unit quaternion of the rotation vector ``ω``.

    ``q = (cos(θ/2), sin(θ/2) · ω/θ)``, ``θ = |ω|``; for small θ the series
    ``sin(θ/2)/θ ≈ 1/2 − θ²/48`` keeps it exact to rounding.

    Parameters
    ----------
    w : array_like, shape (3,)
        The rotation vector (rad).

    Returns
    -------
    tuple of 4 float
        ``(w, x, y, z)``.
    """
    x, y, z = float(w[0]), float(w[1]), float(w[2])
    theta = math.sqrt(x * x + y * y + z * z)
    s = 0.5 - theta * theta / 48.0 if theta < 1e-4 else math.sin(theta / 2) / theta
    return (math.cos(theta / 2), s * x, s * y, s * z)


def quat_multiply(a, b) -> tuple[float, float, float, float]:
    """The Hamilton product ``a ⊗ b`` of ``(w, x, y, z)`` quaternions: the rotation
    ``b`` then ``a`` (``R(a ⊗ b) = R(a) R(b)``).

    Parameters
    ----------
    a, b : sequence of 4 float
        ``(w, x, y, z)``.

    Returns
    -------
    tuple of 4 float
        ``a ⊗ b``.
    """
    aw, ax, ay, az = (float(v) for v in a)
    bw, bx, by, bz = (float(v) for v in b)
    return (aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw)
