"""ABB EGM answer latency at 250 Hz: plugcell's link beside a bare UDP echo (issue 37 §7).

    python benchmarks/egm_latency.py [--seconds 60] [--cycle-ms 4] [--cell N]
        [--rt-priority N] [--no-native] [--json FILE] [--plot PNG]

The harness is rsi_latency.py's (its doc says how it measures): a robot side sends an
``EgmRobot`` (ABB's egm.proto, as the simulated controller sends it: feedback and planned
joints and pose, motor/MCI/RAPID state, test signals; ~250 bytes) every cycle to
plugcell's :class:`~plugcell.devices.robot.egm.EgmLink` (a process of its own, joint
mode, a swinging joint offset as the target, as ``plugcell egm run`` runs it) and to a
bare UDP echo (``recvfrom`` → ``sendto`` of the message's header) and the same echo in
Rust (rust_echo.py), interleaved a third of a cycle apart, and times each answer by the
``seqno`` it echoes.

Goal (issue 37): p99.9 ≤ 1 ms, ≤ 3× the bare echo, zero missed cycles, ≤ 10 % of one
core.  Nothing is asserted; the table says which goals the run met.
"""

from __future__ import annotations

import sys

from plugcell.devices.robot.egm.messages import egm_pb2
from plugcell.devices.robot.stream.realtime import RealTime
from rsi_latency import EchoPart, Vendor, main


def egm_message(seqno: int, q: float) -> bytes:
    """An ``EgmRobot`` as a controller sends it in EGMRunJoint."""
    msg = egm_pb2.EgmRobot()
    msg.header.seqno, msg.header.tm = seqno, seqno * 4
    msg.header.mtype = egm_pb2.EgmHeader.MSGTYPE_DATA
    joints = [q + i for i in range(6)]
    for part in (msg.feedBack, msg.planned):
        part.joints.joints.extend(joints)
        c = part.cartesian
        c.pos.x, c.pos.y, c.pos.z = 600.0 + q, 0.0, 800.0
        c.orient.u0, c.orient.u1, c.orient.u2, c.orient.u3 = 0.0, 0.0, 1.0, 0.0
    msg.motorState.state = egm_pb2.EgmMotorState.MOTORS_ON
    msg.mciState.state = egm_pb2.EgmMCIState.MCI_RUNNING
    msg.mciConvergenceMet = True
    msg.rapidExecState.state = egm_pb2.EgmRapidCtrlExecState.RAPID_RUNNING
    msg.testSignals.signals.extend([0.0] * 6)
    msg.utilizationRate = 10.0
    return msg.SerializeToString()


def seqno_of(answer: bytes) -> int:
    """The seqno of an answer: an EgmSensor's or the echoed header."""
    return egm_pb2.EgmHeader.FromString(answer[2:2 + answer[1]]).seqno


def run_link(cycle_ms: float, rt: RealTime) -> None:
    from plugcell.devices.robot.egm import EgmConfig, EgmLink
    from plugcell.devices.robot.stream.source import SineOffset
    from plugcell.io.units import DEG
    from rsi_latency import serve_link

    cfg = EgmConfig(robot_host="127.0.0.1", listen_host="127.0.0.1", listen_port=0,
                    mode="joint", sample_rate_ms=int(cycle_ms))
    serve_link(EgmLink(cfg, SineOffset(axis=5, amplitude=2 * DEG, period=4.0, periods=10**6),
                       record_latency=True, realtime=rt))


EGM = Vendor("EGM", __file__, egm_message, seqno_of, lambda cycle_ms: 1,
             EchoPart(),  # the header (field 1, serialized first) carries the seqno
             run_link, first_seq=0)

if __name__ == "__main__":
    sys.exit(main(sys.argv[1:], EGM, __doc__))
