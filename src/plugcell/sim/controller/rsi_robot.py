"""The twin's robot side of KUKA RSI: a simulated controller that owns the IPOC clock.

:class:`RsiRobot` runs one thread that, every cycle ``T`` (4 ms ``#IPO_FAST``):

1. sends ``<Rob Type="KUKA">`` (:func:`~plugcell.devices.robot.rsi.codec.encode_rob`) to
   the sensor's address: ``AIPos`` the dynamic twin's encoder readings, ``ASPos`` the
   commanded joints, ``RIst``/``RSol`` the controller's *nominal* forward kinematics of
   them (a real controller reports its model, not the true TCP), ``<Delay D>`` the late
   answers counted so far, and the IPOC (ms, advancing by ``T``);
2. waits until the cycle ends for the answer echoing that IPOC
   (:func:`~plugcell.devices.robot.rsi.codec.parse_sen`); an answer that is missing,
   late, wrong or for another IPOC counts as late (``Delay`` + 1) and, as ``HOLDON``
   says (plugcell's controller files: 0 for relative, 1 for absolute), adds nothing or
   repeats the last correction;
3. applies the correction to its commanded position — relative (summed into the offset
   ``o``) or absolute (the offset ``o``) — on top of the controller's own path
   ``q_p(k)``: without a path (a program holding still at ``RSI_ON``) ``q_p(k) = q_0``;
   with one (``path=``, a :class:`~plugcell.motion.Trajectory` sampled at the cycle,
   standing in for the LIN/PTP motions a KRL program runs with ``RSI_MOVECORR``)
   cycle ``k``'s setpoint, held at its end.  ``AKorr``: ``q = q_p(k) + o``.  ``RKorr``:
   the nominal TCP pose of the path ``T_p = (R_p, p_p)`` corrected in the configured
   frame, with ``R_o = Rz(A)·Ry(B)·Rx(C)``::

       base:  p = p_p + o_xyz,        R = R_o · R_p
       tool:  p = p_p + R_p · o_xyz,  R = R_p · R_o

   followed in joints by one Newton step of the nominal model per cycle from
   ``q_p(k)`` plus the joint correction of the cycle before, ``q ← q + J⁺ e`` with
   ``e`` the exact pose error at ``q`` and ``J`` the Jacobian at ``q_p(k)`` (computed
   with the path's poses for the whole path at once: a chord step, whose fixed point
   is the exact pose);
4. advances the dynamic twin by one cycle (:class:`~plugcell.sim.twin.dynamics.DynamicTwin`).

``<Rob>`` reports, as KUKA's controller does, the commanded position *with* the
correction (``ASPos``; ``RSol`` the corrected Cartesian setpoint ``T`` for ``RKorr``,
the nominal pose of ``ASPos`` for ``AKorr``) and the actual one (``AIPos``, ``RIst``).  While the
sensor is silent the path goes on (with ``HOLDON`` as above) until ``Timeout``.

After ``Timeout`` late answers RSI stops: no more packets, :attr:`RsiRobot.stopped` says
why — as a real controller breaks off.  The configuration is the sensor side's own
:class:`~plugcell.devices.robot.rsi.config.RsiConfig` (the one plugcell writes the
controller's files from): ``listen_host``/``listen_port`` is where the robot sends.
"""

from __future__ import annotations

import contextlib
import dataclasses
import socket
import threading
import time
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from plugcell.devices.robot.rsi.codec import PacketError, encode_rob, parse_sen
from plugcell.devices.robot.rsi.config import RsiConfig
from plugcell.devices.robot.stream.realtime import LoopScheduling, RealTime
from plugcell.kinematics import forward
from plugcell.kinematics.jacobian import manipulator_jacobian
from plugcell.kinematics.pose_corrections import correct_pose
from plugcell.kinematics.rotations import matrix_to_rpy
from plugcell.kinematics.transforms import so3_log
from plugcell.motion import Trajectory
from plugcell.sim.twin.dynamics import DynamicTwin

Array = NDArray[np.float64]

__all__ = ["RsiRobot", "RsiRobotStats"]


@dataclass
class RsiRobotStats:
    """What the simulated controller counted (``delay`` is what it reports in ``<Delay>``)."""

    cycles: int = 0
    answered: int = 0
    delay: int = 0
    malformed: int = 0
    #: per cycle: IPOC, command, link angles, the correction offset applied (SI)
    log: list[tuple[int, Array, Array, Array, bool]] = field(default_factory=list)


def _kuka_abc(T: Array) -> Array:
    """x, y, z (m) and KUKA's A, B, C (rad) of a pose: ``R = Rz(A)·Ry(B)·Rx(C)``."""
    roll, pitch, yaw = matrix_to_rpy(T[:3, :3])
    return np.array([*T[:3, 3], yaw, pitch, roll])


class RsiRobot:
    """A simulated KUKA controller streaming RSI with the dynamic twin (module docstring).

    Parameters
    ----------
    arm : DynamicTwin
        The arm; its cycle must be the configuration's.
    config : RsiConfig
        The stream: where to send (``listen_host``, ``listen_port`` of the sensor),
        correction kind and mode, cycle, ``Timeout``.
    bind : tuple, optional
        Where the controller's socket binds (default: an ephemeral port on loopback).
    ipoc0 : int
        The first IPOC.
    holdon : bool, optional
        The ethernet configuration's ``HOLDON`` (default: as plugcell's files — 0 for
        relative, 1 for absolute corrections).
    record : bool
        Keep every cycle's IPOC, command, link angles, offset and whether the sensor answered
        in time in ``stats().log``.
    path : Trajectory, optional
        The controller's own motion (the KRL program's LIN/PTP moves): cycle ``k``'s
        setpoint is ``path.setpoints(T)[k]``; it must start where the arm stands.
        Default: the arm holds still and only the corrections move it.
    lockstep_s : float
        0 (default): the controller's deadline, the end of the cycle.  > 0: *lockstep*,
        a simulation of a sensor that always answers in time on a machine that cannot —
        each cycle waits up to ``lockstep_s`` seconds for its answer (only a longer
        silence counts as late), and the cycles keep at most real-time pace.  The arm
        moves as with a real-time PC; the IPOC clock runs slower than the wall clock
        while answers take longer than a cycle: a run that must not depend on the machine's
        load (``plugcell path run``, a simulated-time test).
    tool : (4, 4) array_like, optional
        The controller's TCP in the flange frame (KUKA's ``$TOOL``; default the
        description's tool): ``RIst``/``RSol`` and Cartesian corrections refer to it.
    path_delay_s : float
        The program waits this long at ``RSI_ON`` before its path starts (s).
    realtime : RealTime, optional
        The cycle thread's scheduling (real-time priority, CPUs, locked memory), applied
        by it when it starts; what happened is :attr:`scheduling`'s note.

    Raises
    ------
    ValueError
        A cycle other than the arm's, an arm without six axes, or a path that does not
        start where the arm stands (to 1e-3 rad).
    """

    def __init__(self, arm: DynamicTwin, config: RsiConfig, *,
                 bind: tuple[str, int] = ("127.0.0.1", 0), ipoc0: int = 1_000_000,
                 holdon: bool | None = None, record: bool = False,
                 path: Trajectory | None = None, tool: ArrayLike | None = None,
                 path_delay_s: float = 0.0, lockstep_s: float = 0.0,
                 realtime: RealTime | None = None) -> None:
        if not (lockstep_s >= 0 and lockstep_s < float("inf")):
            raise ValueError(f"lockstep_s must be 0 or a positive number of seconds, not "
                             f"{lockstep_s}")
        if abs(arm.params.cycle - config.cycle_s) > 1e-12:
            raise ValueError(f"the arm's cycle {arm.params.cycle} s is not the stream's "
                             f"{config.cycle_s} s ({config.cycle})")
        if arm.twin.description.n_readings != 6:
            raise ValueError("RSI streams six axes; the arm has "
                             f"{arm.twin.description.n_readings}")
        self.arm, self.config = arm, config
        self.holdon = (config.mode == "absolute") if holdon is None else holdon
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sock.bind(bind)
        self._sensor = (config.listen_host, config.listen_port)
        self._ipoc = ipoc0
        self._record = record
        self.lockstep_s = float(lockstep_s)
        self._stats = RsiRobotStats()
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.stopped: str | None = None
        #: the cycle thread's scheduling (``plugcell twin rsi --rt-priority …``)
        self.scheduling = LoopScheduling(realtime)
        desc = arm.twin.description
        if tool is not None:
            desc = dataclasses.replace(desc, tool=np.array(tool, dtype=float))
        self._desc = desc
        self._q_start = arm.measured.copy()
        if path is None:
            self._path = self._q_start[None].copy()
        else:
            self._path = path.setpoints(config.cycle_s)[1]
            gap = float(np.max(np.abs(self._path[0] - self._q_start)))
            if gap > 1e-3:
                raise ValueError(f"the path starts {np.degrees(gap):.3g}° from where the "
                                 "arm stands; start it at the arm's joints")
        if not (np.isfinite(path_delay_s) and path_delay_s >= 0):
            raise ValueError(f"path_delay_s must be ≥ 0 seconds, got {path_delay_s!r}")
        wait = round(path_delay_s / config.cycle_s)
        self._path = np.vstack([np.repeat(self._path[:1], wait, 0), self._path])
        # the path's nominal poses and Jacobians, all at once (cheap in a batch, a
        # millisecond each per cycle)
        self._T_path = forward(desc, None, self._path, "nominal").tcp
        self._J_path = (manipulator_jacobian(desc, None, self._path, "tcp", "nominal")
                        if config.correction == "cartesian" else None)
        self._T_set = self._T_path[0]
        self._k = 0  # the path's cycle
        self._command = self._q_start.copy()
        self._setpoint = (0, self._command.copy())
        self._offset = np.zeros(6)
        self._last = np.zeros(6)
        #: every cycle's (packet sent, round trip until its answer arrived) in ns; −1: no
        #: answer in the cycle (late)
        self.rtts: list[tuple[int, int]] = []
        self._t_sent = 0

    @property
    def address(self) -> tuple[str, int]:
        """The controller's own address (where the sensor's answers go)."""
        return self._sock.getsockname()

    def start(self) -> RsiRobot:
        """``RSI_ON``: start sending, one packet per cycle."""
        self._thread = threading.Thread(target=self._run, name="rsi-robot", daemon=True)
        self._thread.start()
        self.scheduling.wait()
        return self

    def stop(self) -> None:
        """``RSI_OFF`` (or the program ends): stop sending and close the socket."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        self._sock.close()

    def __enter__(self) -> RsiRobot:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def stats(self) -> RsiRobotStats:
        with self._lock:
            s = self._stats
            return RsiRobotStats(s.cycles, s.answered, s.delay, s.malformed, list(s.log))

    @property
    def command(self) -> Array:
        """The commanded joints now (rad)."""
        return self._command.copy()

    @property
    def offset(self) -> Array:
        """The correction offset applied now (SI: rad, or m and rad)."""
        return self._offset.copy()

    @property
    def path_poses(self) -> Array:
        """The path's nominal TCP poses, one per cycle (F0, (K, 4, 4)), without correction."""
        return self._T_path

    @property
    def tool(self) -> Array:
        """The controller's TCP in the flange frame (``$TOOL``)."""
        return self._desc.tool

    @property
    def path_index(self) -> int:
        """The path's cycle whose setpoint is commanded now."""
        return self._k

    @property
    def setpoint(self) -> tuple[int, Array]:
        """The path's cycle and the joints commanded in it (rad), of the same cycle (read
        from another thread while the controller runs)."""
        return self._setpoint

    @property
    def path_done(self) -> bool:
        """The controller's own path has reached its end (always, without a path)."""
        return self._k >= len(self._path) - 1

    # ------------------------------------------------------------------ the cycle
    def packet(self) -> bytes:
        """This cycle's ``<Rob>`` (module docstring, 1): what :meth:`start`'s thread sends.

        With :meth:`advance`, the controller runs in the caller's process and time (a
        simulation without sockets: the same packets, corrections and arm).

        Returns
        -------
        bytes
            The XML packet for the current IPOC.
        """
        q = self.arm.measured
        tcp = _kuka_abc(forward(self._desc, None, q, "nominal").tcp)
        tcp_set = _kuka_abc(self._T_set if self.config.correction == "cartesian" else
                            forward(self._desc, None, self._command, "nominal").tcp)
        with self._lock:
            delay = self._stats.delay
        return encode_rob(self._ipoc, q, tcp, joints_setpoint=self._command,
                          tcp_setpoint=tcp_set, delay=delay)

    def advance(self, answer: Array | None) -> str | None:
        """End this cycle with the sensor's correction (module docstring, 2–4).

        Parameters
        ----------
        answer : (6,) array or None
            The correction echoing this cycle's IPOC (SI, as ``parse_sen`` gives it), or
            ``None`` when it was missing or late (counted in ``<Delay>``).

        Returns
        -------
        str or None
            Why RSI stopped (``Timeout`` reached), else ``None``.
        """
        self._k = min(self._k + 1, len(self._path) - 1)  # the program's motion goes on
        offset = self._apply(answer)
        self._setpoint = (self._k, self._command.copy())  # one assignment: read whole
        state = self.arm.step(self._command)
        with self._lock:
            st = self._stats
            st.cycles += 1
            if answer is None:
                st.delay += 1
            else:
                st.answered += 1
            if self._record:
                st.log.append((self._ipoc, state.command, state.link, offset.copy(),
                               answer is not None))
            late = st.delay
        self._ipoc += self.config.ipoc_step
        if late >= self.config.timeout_packets:
            self.stopped = (f"RSI stopped: {late} late sensor packets reached the "
                            f"Timeout of {self.config.timeout_packets}")
        return self.stopped

    def _run(self) -> None:
        self.scheduling.apply_here()
        T = self.config.cycle_s
        next_t = time.monotonic()
        packet = self.packet()
        while not self._stop.is_set():
            with contextlib.suppress(OSError):  # unreachable: its answer will be missing
                self._sock.sendto(packet, self._sensor)
            self._t_sent = time.monotonic_ns()
            next_t += T
            answer = self._await(self._ipoc, max(next_t, time.monotonic() + self.lockstep_s))
            self.rtts.append((self._t_sent, time.monotonic_ns() - self._t_sent
                              if answer is not None else -1))
            if self.advance(answer) is not None:
                return
            packet = self.packet()  # ready when the next cycle starts: the sensor gets
            pause = next_t - time.monotonic()  # the whole cycle to answer
            if pause > 0:
                self._stop.wait(pause)
            else:
                next_t = time.monotonic()  # the controller's own clock slipped: resync

    def _await(self, ipoc: int, deadline: float) -> Array | None:
        """The correction answering ``ipoc`` if it arrives before ``deadline``."""
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                return None
            self._sock.settimeout(left)
            try:
                data, _ = self._sock.recvfrom(65535)
            except (TimeoutError, OSError):
                return None
            try:
                ans = parse_sen(data, self.config.correction, self.config.max_packet_bytes)
            except PacketError:
                with self._lock:
                    self._stats.malformed += 1
                continue
            if ans.ipoc == ipoc:
                return ans.correction
            # an answer to an older packet arrives too late: ignored (counted as late then)

    def _apply(self, correction: Array | None) -> Array:
        """The commanded position after this cycle's correction (module docstring, 2–3)."""
        relative = self.config.mode == "relative"
        if correction is None:
            # HOLDON 1 repeats the last correction; 0 adds nothing (relative) or drops
            # the offset (absolute)
            correction = self._last if self.holdon else (np.zeros(6) if relative else None)
        if correction is None:  # absolute, HOLDON 0: back to the start
            self._offset = np.zeros(6)
        elif relative:
            self._offset = self._offset + correction
        else:
            self._offset = np.array(correction, dtype=float)
        if correction is not None:
            self._last = np.array(correction, dtype=float)
        q_path = self._path[self._k]
        if self.config.correction == "joint":
            self._command = q_path + self._offset
        else:
            # the joint correction of the last cycle carried onto this cycle's setpoint
            guess = q_path + (self._command - self._q_prev_path())
            self._T_set = self._target_pose()
            self._command = self._follow_pose(self._T_set, guess)
        return self._offset

    def _q_prev_path(self) -> Array:
        return self._path[max(self._k - 1, 0)]

    def _target_pose(self) -> Array:
        """The path's pose corrected by the offset in the configured frame (module doc)."""
        return correct_pose(self._T_path[self._k], self._offset, self.config.frame)

    def _follow_pose(self, T: Array, q: Array) -> Array:
        """One chord Newton step of the nominal model from ``q`` towards ``T``."""
        fk = forward(self._desc, None, q, "nominal")
        err = np.concatenate([T[:3, 3] - fk.tcp[:3, 3],
                              so3_log(T[:3, :3] @ fk.tcp[:3, :3].T)])
        J = self._J_path[self._k]
        return q + J.T @ np.linalg.solve(J @ J.T + 1e-12 * np.eye(6), err)

