"""Helpers of the EGM tests: robot messages built with the compiled egm.proto, a bare
robot socket, and the seeded mutator of the fuzz."""

from __future__ import annotations

from childproc import wait_until  # noqa: F401  (re-exported for the link tests)
from udp_robot import UdpRobot

from plugcell.devices.robot.egm import EgmConfig, EgmLink
from plugcell.devices.robot.egm.messages import egm_pb2


def robot_message(seqno: int, tm: int | None = None,
                  joints_deg=(0.0, 10.0, 20.0, 0.0, 30.0, 0.0),
                  pos_mm=(600.0, 0.0, 800.0), quat=(0.0, 0.0, 1.0, 0.0)) -> bytes:
    """An ``EgmRobot`` as a controller sends it."""
    msg = egm_pb2.EgmRobot()
    msg.header.seqno = seqno
    msg.header.tm = seqno * 4 if tm is None else tm
    msg.header.mtype = egm_pb2.EgmHeader.MSGTYPE_DATA
    msg.feedBack.joints.joints.extend(joints_deg)
    c = msg.feedBack.cartesian
    c.pos.x, c.pos.y, c.pos.z = pos_mm
    c.orient.u0, c.orient.u1, c.orient.u2, c.orient.u3 = quat
    msg.planned.joints.joints.extend(joints_deg)
    msg.motorState.state = egm_pb2.EgmMotorState.MOTORS_ON
    msg.mciState.state = egm_pb2.EgmMCIState.MCI_RUNNING
    msg.rapidExecState.state = egm_pb2.EgmRapidCtrlExecState.RAPID_RUNNING
    msg.testSignals.signals.extend([1.0, 2.0])
    return msg.SerializeToString()


class BareRobot(UdpRobot):
    """A UDP socket on loopback playing the controller, message by message."""

    def __init__(self, link_address: tuple[str, int]) -> None:
        super().__init__(link_address)
        self.seqno = 0

    def cycle(self, **kw) -> bytes:
        """Send the next message (seqno + 1) and return the answer."""
        self.seqno += 1
        self.send(robot_message(self.seqno, **kw))
        return self.receive()


def local_config(**kw) -> EgmConfig:
    return EgmConfig(robot_host="127.0.0.1", listen_host="127.0.0.1", listen_port=0, **kw)


def started(config: EgmConfig, source=None, **kw) -> EgmLink:
    link = EgmLink(config, source, **kw)
    link.start()
    return link


def mutate(rng, packet: bytes) -> bytes:
    """One to three random edits of a valid message (seeded ``random.Random``): flipped,
    deleted, inserted, duplicated and swapped bytes, truncation, oversizing, a varint
    made endless, a length prefix changed."""
    data = bytearray(packet)
    for _ in range(rng.randint(1, 3)):
        op = rng.choices(range(8), weights=(4, 3, 3, 3, 2, 0.2, 1, 2))[0]
        n = len(data)
        i = rng.randrange(n + 1)
        if op == 0 and n:
            data[min(i, n - 1)] = rng.randrange(256)
        elif op == 1:
            del data[i:i + rng.randint(1, 20)]
        elif op == 2:
            data[i:i] = bytes(rng.randrange(256) for _ in range(rng.randint(1, 8)))
        elif op == 3:
            del data[i:]
        elif op == 4:
            j = min(n, i + rng.randint(1, 40))
            data[j:j] = data[i:j]
        elif op == 5:
            data[i:i] = bytes(rng.randrange(256) for _ in range(rng.randint(1500, 3000)))
        elif op == 6:
            data[i:i] = b"\xff" * rng.randint(10, 12)  # a varint that never ends
        elif n:
            j = rng.randrange(n)
            a, b = sorted((i, j))
            data[a:b] = data[a:b][::-1]
    return bytes(data)
