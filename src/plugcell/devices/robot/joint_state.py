"""A robot service's joint state: what the cell's 3-D view draws, live.

The robot service reads its controller's joints several times a second and publishes
them on ``plugcell/<cell>/joints/<service>`` (:meth:`KeySpace.joints`) — the joint
readings *and* every link frame of the robot's description at those readings, as
ROS's ``joint_states`` and ``robot_state_publisher`` do together.  The frames are
computed here because only the robot service surely has the robot's description (a
real controller's robot, an imported URDF on this machine); the cell controller and
the browser then draw without knowing the robot.

Each :class:`JointState` (msgpack, msgspec) holds, in SI units and the robot base
frame F0 (thesis eq. 6.1):

* ``q`` — the readings, rad (m for a prismatic joint), the controller's order;
* ``links`` — the link tree once per message: name, parent (``"base"`` for the
  first), joint kind (``actuated``/``passive``/``fixed``/``prismatic``) and the DH
  offset ``d`` (m), so a link can be drawn as the DH path
  ``O_parent → O_parent + d·z_parent → O_link``;
* ``frames`` — ``F_i = F_parent(i) · A_i`` of :func:`plugcell.kinematics.forward`, 16
  numbers each (row-major 4×4, m) — empty when a loop cannot close at ``q``;
* ``base`` — the description's BASE (robot base in the world frame, 4×4, m),
  ``tool`` — its TOOL (flange → TCP).

A display stream: published at a fixed rate (:data:`DEFAULT_RATE_HZ`), moving or not
(a late joiner sees the robot within one period), with Zenoh's DROP congestion
control — a lost state is replaced by the next one.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import Awaitable, Callable
from typing import Any

import msgspec
import numpy as np

from plugcell.devices.robot.protocol import ArmJntp, ProtocolError, parse_numbers
from plugcell.io.units import joints_to_si
from plugcell.kinematics import RobotDescription, forward

__all__ = [
    "DEFAULT_RATE_HZ",
    "JointState",
    "JointStatePublisher",
    "LinkInfo",
    "decode_joint_state",
    "joint_state",
    "publish_joint_state",
]

log = logging.getLogger(__name__)

#: Joint states per second a robot service publishes (the UI follows at ≥ 20 Hz).
DEFAULT_RATE_HZ = 25.0


class LinkInfo(msgspec.Struct, frozen=True, array_like=True):
    """One link of the tree: name, parent (``"base"``), joint kind, DH ``d`` (m)."""

    name: str
    parent: str
    joint: str
    d: float


class JointState(msgspec.Struct, frozen=True):
    """One joint state of one robot (module doc); SI units, robot base frame."""

    robot: str
    q: list[float]
    links: list[LinkInfo]
    frames: list[list[float]]
    base: list[float]
    tool: list[float]
    flange: str
    t_ns: int
    seq: int


_ENCODER = msgspec.msgpack.Encoder()
_DECODER = msgspec.msgpack.Decoder(JointState)


def joint_state(desc: RobotDescription, q: np.ndarray, *, seq: int = 0,
                t_ns: int | None = None) -> JointState:
    """The joint state of ``desc`` at readings ``q``: its link frames by
    :func:`plugcell.kinematics.forward` (nominal parameters, four-bar closure).

    Parameters
    ----------
    desc
        The robot.
    q : (n_readings,) array, rad (m for a prismatic joint)
        The joint readings.
    seq, t_ns
        Sequence number and time stamp (ns since the epoch; default: now).

    Returns
    -------
    JointState
        ``frames``: ``F_i`` (16 numbers, m) of every link in F0 — empty when a loop
        cannot close at ``q``.

    Raises
    ------
    ValueError
        ``q`` is not ``n_readings`` finite numbers.
    """
    q = np.asarray(q, dtype=float).reshape(-1)
    if q.size != desc.n_readings or not np.all(np.isfinite(q)):
        raise ValueError(f"{desc.name}: expected {desc.n_readings} finite joint readings, "
                         f"got {q.tolist()}")
    fk = forward(desc, None, q, raise_errors=False)
    frames = fk.frames.reshape(len(desc.links), 16).tolist() if bool(fk.valid) else []
    params = desc.nominal_parameters()
    links = [LinkInfo(lk.name, lk.parent, lk.joint, float(lk.d)) for lk in desc.links]
    return JointState(
        robot=desc.name, q=q.tolist(), links=links, frames=frames,
        base=np.asarray(params.base).ravel().tolist(),
        tool=np.asarray(params.tool).ravel().tolist(), flange=desc.flange,
        t_ns=time.time_ns() if t_ns is None else t_ns, seq=seq)


def encode_joint_state(state: JointState) -> bytes:
    """A joint state as the bytes published."""
    return _ENCODER.encode(state)


def decode_joint_state(payload: bytes) -> JointState:
    """The joint state of a published payload; msgspec.DecodeError (a ValueError) if the
    bytes are not one."""
    return _DECODER.decode(payload)


class JointStatePublisher:
    """Reads the joints with ``read()`` every ``1/rate_hz`` s and publishes the state.

    Parameters
    ----------
    read
        Returns the joint readings (rad), or None while they cannot be read (the
        controller is not connected); an exception skips that period (logged once).
    describe
        Returns the robot's description, or None while it is unknown (nothing is
        published then).
    publish
        Sends one encoded state (``publisher.put``).
    rate_hz
        States per second.
    """

    def __init__(self, read: Callable[[], Awaitable[np.ndarray | None]],
                 describe: Callable[[], RobotDescription | None],
                 publish: Callable[[bytes], Any], rate_hz: float = DEFAULT_RATE_HZ) -> None:
        if not (rate_hz > 0):
            raise ValueError(f"the joint state rate must be positive, not {rate_hz}")
        self.read, self.describe, self.publish = read, describe, publish
        self.period = 1.0 / rate_hz
        self.seq = 0
        self._task: asyncio.Task[None] | None = None
        self._failing = ""

    def start(self) -> None:
        """Publish from now on (in the running loop)."""
        if self._task is None:
            self._task = asyncio.get_running_loop().create_task(self._run(),
                                                                name="joint-state")

    async def close(self) -> None:
        """Stop publishing."""
        task, self._task = self._task, None
        if task is not None:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task

    async def once(self) -> bool:
        """Read and publish one state; whether one was published."""
        desc = self.describe()
        if desc is None:
            return False
        try:
            q = await self.read()
            if q is None:
                return False
            self.seq += 1
            self.publish(encode_joint_state(joint_state(desc, q, seq=self.seq)))
        except Exception as exc:  # a period lost; the next one tries again
            reason = f"{type(exc).__name__}: {exc}"
            if reason != self._failing:
                log.warning("joint state not published: %s", reason)
            self._failing = reason
            return False
        self._failing = ""
        return True

    async def _run(self) -> None:
        loop = asyncio.get_running_loop()
        next_at = loop.time()
        while True:
            await self.once()
            next_at += self.period
            delay = next_at - loop.time()
            if delay < 0:  # fell behind (a slow controller): no burst to catch up
                next_at, delay = loop.time(), 0.0
            await asyncio.sleep(delay)


def publish_joint_state(service: Any, rate_hz: float) -> JointStatePublisher | None:
    """Start publishing a robot service's joint state (None if ``rate_hz`` ≤ 0).

    The readings are its controller's ``ARM_JNTP`` (degrees, mm) in SI; its description
    is the one the service loaded for its controller (``service.robot_description``).

    Parameters
    ----------
    service : plugcell.devices.robot.service.RobotService
        A robot whose service has started (its host's bus; its bridge and description).
    rate_hz
        States per second.
    """
    host = service.host
    bus = host.participant.bus
    if rate_hz <= 0 or bus is None:
        return None
    publisher = host.own(bus.joint_state_publisher(host.name))  # closed with it
    bridge = service.bridge

    async def read() -> np.ndarray | None:
        desc = service.robot_description
        if not bridge.connected or desc is None:
            return None
        text = await bridge.request(ArmJntp(bridge.new_id()))
        try:
            degrees = parse_numbers(text, desc.n_readings, "ARM_JNTP answer")
        except ProtocolError as exc:
            raise ValueError(str(exc)) from None
        return joints_to_si(np.asarray(degrees, dtype=float), desc.reading_scale())

    states = JointStatePublisher(read, lambda: service.robot_description, publisher.put,
                                 rate_hz)
    states.start()
    return states
