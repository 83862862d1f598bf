"""The robot side of ABB EGM, played by the simulation: an ABB controller's EGM loop.

No robot-side EGM simulator with a usable licence exists, so this one stands in for an
IRC5/OmniCore controller running ``EGMRunJoint`` / ``EGMRunPose`` / ``EGMMoveL``: every
sample (4 ms) it sends an ``EgmRobot`` (ABB's ``egm.proto``, compiled by protobuf — the
same messages a real controller sends: header seqno/tm/``MSGTYPE_DATA``, feedback joints
and pose, planned, motor, MCI and RAPID execution state, test signals) to the sensor's
address, takes the newest ``EgmSensor`` (or ``EgmSensorPathCorr``) that came back, and
moves its axes toward the target through a :class:`FirstOrderFollower`.  Without a
message from the sensor for ``comm_timeout_s`` it stops, as the controller's EGM does
(``\\CommTimeout``), and says why in :attr:`EgmRobotSim.stopped`.

What is modelled, and what is not:

* joint mode: the joints follow the targets; the feedback pose is the one the robot was
  given (no kinematics here — a real controller's is its forward kinematics);
* pose mode: the TCP pose follows the target (position first-order, orientation along
  the shortest arc); the joints stay where they were (no inverse kinematics);
* path-correction mode: the TCP runs its own linear path along the work object's x at
  ``path_speed``, its orientation kept, and the correction is added to it as a
  controller does: in ABB's path coordinate system (x the path's direction, y = x ×
  z_tool, z = x × y; :mod:`plugcell.kinematics.path_frame`), y and z only — with the
  tool's z down (the default quaternion) the path frame is the work object's.

The follower is the simple servo ``x ← x + (1 − e^(−T/τ)) (x* − x)`` with the speed
capped; in joint mode the twin's dynamics model (servo loops, structural modes, friction)
replaces it behind the same :class:`Follower` interface (:class:`DynamicFollower`,
``plugcell twin egm``).
"""

from __future__ import annotations

import contextlib
import math
import select
import socket
import threading
import time
from dataclasses import dataclass
from typing import Literal, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from plugcell.devices.robot.egm.messages import egm_pb2
from plugcell.devices.robot.stream.realtime import LoopScheduling, RealTime
from plugcell.io.units import DEG, M_PER_MM, MM_PER_M
from plugcell.kinematics.path_frame import applied_displacement, path_frame
from plugcell.kinematics.rotations import quat_to_matrix
from plugcell.sim.twin.dynamics import DynamicTwin

Array = NDArray[np.float64]

__all__ = ["DynamicFollower", "EgmRobotSim", "FirstOrderFollower", "Follower"]


class Follower(Protocol):
    """How the simulated axes move toward a target each sample."""

    def step(self, x: Array, target: Array, dt: float) -> Array:
        """The axes after ``dt`` seconds, from ``x`` toward ``target``."""


@dataclass(frozen=True)
class FirstOrderFollower:
    """A first-order servo with a speed cap: ``x ← x + clip((1 − e^(−dt/τ)) (x* − x), ±v dt)``.

    Attributes
    ----------
    tau : float
        Time constant τ (s); ABB's EGM default filter bandwidth (20 Hz) is τ ≈ 8 ms.
    max_speed : float
        Largest speed of any axis (units/s: rad/s for joints, m/s for positions).
    """

    tau: float = 0.008
    max_speed: float = 2.0

    def step(self, x: Array, target: Array, dt: float) -> Array:
        """The axes after ``dt`` (module doc)."""
        move = (1.0 - math.exp(-dt / self.tau)) * (target - x)
        cap = self.max_speed * dt
        return x + np.clip(move, -cap, cap)


class DynamicFollower:
    """The dynamic twin (:class:`~plugcell.sim.twin.dynamics.DynamicTwin`) as the
    follower of joint targets (``EGMRunJoint``): each sample is one cycle of its servos,
    backlash and modes with the target as the command, and the axes are its encoder
    readings.  The sample must be the twin's cycle."""

    def __init__(self, arm: DynamicTwin) -> None:
        self.arm = arm

    def step(self, x: Array, target: Array, dt: float) -> Array:
        """The readings after one cycle toward ``target`` (``x``: the arm's own state)."""
        if abs(dt - self.arm.params.cycle) > 1e-12:
            raise ValueError(f"the EGM sample {dt} s is not the twin's cycle "
                             f"{self.arm.params.cycle} s")
        self.arm.step(target)
        return np.array(self.arm.measured, dtype=float)


def _slerp_toward(q: Array, target: Array, fraction: float) -> Array:
    """``q`` turned by ``fraction`` of the shortest arc to ``target`` (unit quaternions)."""
    if q @ target < 0:
        target = -target
    out = q + fraction * (target - q)  # nlerp: exact enough for a servo's small steps
    return out / np.linalg.norm(out)


class EgmRobotSim:
    """A simulated ABB controller's EGM loop (module doc).

    Parameters
    ----------
    sensor : tuple of (str, int)
        The sensor's address: the UDP unit device's remote address and port.
    mode : {"joint", "pose", "pathcorr"}
        ``EGMRunJoint``, ``EGMRunPose`` or ``EGMMoveL`` with path corrections.
    joints : array_like, shape (6,)
        The joints at the start (rad).
    position : array_like, shape (3,)
        The TCP at the start, in the work object (m).
    quaternion : array_like, shape (4,)
        Its orientation ``(w, x, y, z)``.
    sample_s : float
        ``\\SampleRate`` (s).
    comm_timeout_s : float
        ``\\CommTimeout``: silence from the sensor this long stops the loop.
    follower : Follower
        How the axes follow the targets (:class:`FirstOrderFollower`).
    path_speed : float
        Path-correction mode: the programmed path's speed along x (m/s).
    bind : tuple of (str, int)
        The controller's own address (its source port; port 0: any).
    realtime : RealTime, optional
        The sample thread's scheduling (real-time priority, CPUs, locked memory), applied
        by it when it starts; what happened is :attr:`scheduling`'s note.
    """

    def __init__(self, sensor: tuple[str, int], mode: Literal["joint", "pose",
                 "pathcorr"] = "joint", joints: ArrayLike = (0, 0, 0, 0, 0.5, 0),
                 position: ArrayLike = (0.6, 0.0, 0.8), quaternion: ArrayLike = (0, 0, 1, 0),
                 sample_s: float = 0.004, comm_timeout_s: float = 1.0,
                 follower: Follower | None = None, path_speed: float = 0.0,
                 bind: tuple[str, int] = ("127.0.0.1", 0),
                 realtime: RealTime | None = None) -> None:
        if mode not in ("joint", "pose", "pathcorr"):
            raise ValueError(f"mode {mode!r}: expected 'joint', 'pose' or 'pathcorr'")
        self.sensor = sensor
        self.mode = mode
        self.q = np.asarray(joints, dtype=float).copy()
        self.p = np.asarray(position, dtype=float).copy()
        self.quat = np.asarray(quaternion, dtype=float) / np.linalg.norm(quaternion)
        self.q_target, self.p_target, self.quat_target = self.q.copy(), self.p.copy(), \
            self.quat.copy()
        self.path_start = self.p.copy()
        self.path_speed = path_speed
        #: the path frame of path-correction mode (the path along x, the tool's z)
        self.path_frame = (path_frame((1.0, 0.0, 0.0), quat_to_matrix(self.quat)[:, 2])
                           if mode == "pathcorr" else None)
        self.correction = np.zeros(3)
        self.T = sample_s
        self.comm_timeout_s = comm_timeout_s
        self.follower = follower or FirstOrderFollower()
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(bind)
        self.sock.setblocking(False)
        self.seqno = 0
        self.sent = 0
        self.answers = 0  # sensor messages taken
        self.unanswered = 0  # samples that went out with no answer before the next one
        self.rejected = 0  # datagrams that were no sensor message of the mode
        self.stopped: str | None = None
        #: every sample's (message sent, round trip until the first answer) in ns; −1: no
        #: answer before the next sample
        self.rtts: list[tuple[int, int]] = []
        self.test_signals = (0.0,) * 6
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None
        self._t0 = time.monotonic()
        #: the sample thread's scheduling (``plugcell twin egm --rt-priority …``)
        self.scheduling = LoopScheduling(realtime)

    @property
    def address(self) -> tuple[str, int]:
        """The controller's own ``(host, port)``: where the sensor's answers go."""
        return self.sock.getsockname()[:2]

    # ------------------------------------------------------------------ the messages

    def robot_message(self) -> bytes:
        """The ``EgmRobot`` of this sample (the state now, in ABB units)."""
        msg = egm_pb2.EgmRobot()
        h = msg.header
        h.seqno, h.tm = self.seqno, int((time.monotonic() - self._t0) * 1000) & 0xFFFFFFFF
        h.mtype = egm_pb2.EgmHeader.MSGTYPE_DATA
        fb, pl = msg.feedBack, msg.planned
        fb.joints.joints.extend((self.q / DEG).tolist())
        pl.joints.joints.extend((self.q_target / DEG).tolist())
        for pose, p, q in ((fb.cartesian, self.p, self.quat),
                           (pl.cartesian, self.p_target, self.quat_target)):
            pose.pos.x, pose.pos.y, pose.pos.z = (p * MM_PER_M).tolist()
            pose.orient.u0, pose.orient.u1, pose.orient.u2, pose.orient.u3 = q.tolist()
        msg.motorState.state = egm_pb2.EgmMotorState.MOTORS_ON
        msg.mciState.state = egm_pb2.EgmMCIState.MCI_RUNNING
        msg.mciConvergenceMet = bool(np.max(np.abs(self.q - self.q_target)) < 0.01 * DEG)
        msg.rapidExecState.state = egm_pb2.EgmRapidCtrlExecState.RAPID_RUNNING
        msg.testSignals.signals.extend(self.test_signals)
        msg.utilizationRate = 10.0
        return msg.SerializeToString()

    def take(self, data: bytes) -> bool:
        """Apply one sensor message; whether it was one of this mode's."""
        try:
            if self.mode == "pathcorr":
                msg = egm_pb2.EgmSensorPathCorr()
                msg.ParseFromString(data)
                if not msg.HasField("pathCorr"):
                    return False
                c = msg.pathCorr.pos
                self.correction = np.array([c.x, c.y, c.z]) * M_PER_MM
                return True
            msg = egm_pb2.EgmSensor()
            msg.ParseFromString(data)
        except Exception:  # a controller ignores what it cannot read
            return False
        planned = msg.planned
        if self.mode == "joint" and planned.HasField("joints"):
            joints = np.array(planned.joints.joints, dtype=float)
            if joints.shape != (6,) or not np.all(np.isfinite(joints)):
                return False
            self.q_target = joints * DEG
            return True
        if self.mode == "pose" and planned.HasField("cartesian"):
            c = planned.cartesian
            q = np.array([c.orient.u0, c.orient.u1, c.orient.u2, c.orient.u3])
            p = np.array([c.pos.x, c.pos.y, c.pos.z]) * M_PER_MM
            if not (np.all(np.isfinite(q)) and np.all(np.isfinite(p))) or \
                    abs(np.linalg.norm(q) - 1) > 1e-3:
                return False
            self.p_target, self.quat_target = p, q / np.linalg.norm(q)
            return True
        return False

    def advance(self, dt: float) -> None:
        """Move the axes one sample toward the targets."""
        if self.mode == "joint":
            self.q = self.follower.step(self.q, self.q_target, dt)
        elif self.mode == "pose":
            self.p = self.follower.step(self.p, self.p_target, dt)
            frac = 1.0 - math.exp(-dt / getattr(self.follower, "tau", 0.008))
            self.quat = _slerp_toward(self.quat, self.quat_target, frac)
        else:
            self.path_start = self.path_start + np.array([self.path_speed * dt, 0.0, 0.0])
            self.p_target = self.path_start + applied_displacement(self.correction,
                                                                   self.path_frame)
            self.p = self.follower.step(self.p, self.p_target, dt)

    # ------------------------------------------------------------------ the loop

    def start(self) -> EgmRobotSim:
        """Start sending (a thread); returns self."""
        self._thread = threading.Thread(target=self._run, name="egm-robot", daemon=True)
        self._thread.start()
        self.scheduling.wait()
        return self

    def stop(self) -> None:
        """Stop sending, as a controller whose program stopped (the robot gone)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(2.0)
        self.sock.close()

    @property
    def running(self) -> bool:
        """The loop runs (started, not stopped by :meth:`stop` or the timeout)."""
        return self._thread is not None and self._thread.is_alive()

    def wait_stopped(self, timeout: float) -> bool:
        """Wait until the loop stopped by itself (communication timeout)."""
        end = time.monotonic() + timeout
        while time.monotonic() < end and self.stopped is None:
            time.sleep(0.005)
        return self.stopped is not None

    def _run(self) -> None:
        self.scheduling.apply_here()
        poller = select.poll()
        poller.register(self.sock, select.POLLIN)
        next_t = time.monotonic()
        last_answer = next_t
        answered_this = True
        t_sent = 0
        while not self._stop.is_set():
            now = time.monotonic()
            if now >= next_t:
                if not answered_this and self.sent:
                    self.unanswered += 1
                    self.rtts.append((t_sent, -1))
                if now - last_answer >= self.comm_timeout_s:
                    self.stopped = (f"EGM communication timeout: no message from the sensor "
                                    f"for {now - last_answer:.3f} s (\\CommTimeout "
                                    f"{self.comm_timeout_s:g} s)")
                    return
                with self._lock:
                    self.advance(self.T)
                    self.seqno += 1
                    # the sensor's host unreachable: the timeout decides
                    with contextlib.suppress(OSError):
                        self.sock.sendto(self.robot_message(), self.sensor)
                    t_sent = time.monotonic_ns()
                self.sent += 1
                answered_this = False
                next_t += self.T
                if next_t < now:  # fell behind (a loaded machine): resynchronise
                    next_t = now + self.T
            wait_ms = max(0.0, (next_t - time.monotonic()) * 1000)
            if poller.poll(wait_ms):
                while True:
                    try:
                        data = self.sock.recv(65535)
                    except (BlockingIOError, InterruptedError):
                        break
                    except OSError:
                        break
                    with self._lock:
                        ok = self.take(data)
                    if ok:
                        self.answers += 1
                        if not answered_this:  # the first answer to this sample
                            self.rtts.append((t_sent, time.monotonic_ns() - t_sent))
                        answered_this = True
                        last_answer = time.monotonic()
                    else:
                        self.rejected += 1

    def state(self) -> dict[str, Array]:
        """A consistent copy of the axes and targets (SI)."""
        with self._lock:
            return {"joints": self.q.copy(), "joint_targets": self.q_target.copy(),
                    "position": self.p.copy(), "quaternion": self.quat.copy(),
                    "position_target": self.p_target.copy(),
                    "path_start": self.path_start.copy(), "correction": self.correction.copy()}

