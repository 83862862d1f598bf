"""The PC drives: a planned trajectory streamed to a robot as whole joint commands.

:class:`StreamDrive` is a :class:`~plugcell.devices.robot.planned_motion.Drive` over a
streaming link (:class:`~.link.StreamLink`) whose every answer carries the whole joint
command: KUKA RSI's joint corrections (``AKorr``) in absolute mode — the KRL program only
starts RSI where the robot stands and follows the sensor (``plugcell rsi files --mode
absolute``) — or ABB EGM's joint targets (``EGMRunJoint``, the link sending ``q₀ + o``,
``plugcell egm files --mode joint``).  For one move it

1. samples the whole trajectory ahead at the controller's cycle ``T``
   (``Trajectory.setpoints``; one sample per cycle would not fit the cycle in Python,
   docs/motion.md);
2. takes, at the motion's first cycle, the base of the session's offsets — where the
   controller started the stream: the link's own (``joint_base``: EGM's ``q₀``) or, from
   the robot's packet, ``q_base = ASPos − o`` (RSI: the set-point joints minus the offset
   commanded so far; the actual joints if the controller sends no set-point);
3. answers the motion's ``k``-th answered packet (of ``K + 1``) with the absolute correction

       o_k = q(k T) − q_base + (1 − k/K) · (q_set,0 − q(0))   (rad)

   — the move is planned from the actual joints ``q(0)`` (AIPos), the command stands at
   the set-point ``q_set,0`` (ASPos): their difference (the following error at the
   start) fades out along the move, so the command neither jumps at the start nor misses
   the target at the end — and ends with the last sample; the link then holds the robot
   there (absolute: the offset kept).  A missed cycle (a packet lost or answered late)
   delays the rest of the move by one cycle instead of skipping a sample: the command never
   steps by more than one cycle of the planned motion, so the link's limits
   (:func:`~plugcell.devices.robot.stream_controller.streaming_limits`) hold even on a
   busy PC.
4. waits, holding, for the exact stop: every actual joint (``AIPos``, ``feedBack.joints``)
   within :data:`IN_POSITION_RAD` of the end (the servos' dead time and lag, as a
   controller's exact stop waits for its positioning window), at most :data:`SETTLE_S` —
   the program's next statement (a measurement) then sees the arm arrived.

Joint feedback is the newest packet's actual joints (``AIPos``, ``feedBack.joints``).  A
failed stream (silence, missed cycles, a refused correction) or a motion that does not end
in time is a
:class:`~plugcell.pdl.interfaces.MotionError` with the link's reason: the program fails at
the move's line.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from plugcell.motion import Trajectory
from plugcell.pdl.interfaces import MotionError

from .errors import StreamLinkError
from .link import StreamLink
from .source import Correction, CycleState

__all__ = ["IN_POSITION_RAD", "SETTLE_S", "StreamDrive", "drive_refusal", "motion_timeout",
           "samples", "setpoint_base"]

Array = NDArray[np.float64]
#: A per-cycle joint adjustment: ``adjust(state, k, q_k) -> Δq`` (rad, (6,)).
Adjust = Callable[[CycleState, int, Array], Array]

#: Seconds a motion may take beyond its duration and two controller timeouts.
SLACK_S = 2.0
#: The exact stop: every actual joint within this of the motion's end (rad) …
IN_POSITION_RAD = np.radians(0.001)
#: … waited for at most this long (s); then the move ends anyway.
SETTLE_S = 1.0


def samples(trajectory: Trajectory, cycle_s: float) -> Array:
    """The joint set-points of ``trajectory`` at every cycle, ``q(kT)`` (rad), shape (K+1, 6).

    Raises
    ------
    MotionError
        The trajectory is not of six axes.
    """
    _, q = trajectory.setpoints(cycle_s)
    q = np.asarray(q, dtype=float)
    if q.ndim != 2 or q.shape[1] != 6:
        raise MotionError(f"the stream drives six axes; the trajectory has shape {q.shape}")
    return q


def setpoint_base(state: CycleState) -> Array | None:
    """Where the session's offsets start, ``q_base = q_set − o``: the packet's set-point
    joints (RSI's ``ASPos``; the actual joints if it has none) minus the offset so far."""
    robot = state.robot
    ref = robot.joints_setpoint if robot.joints_setpoint is not None else robot.joints
    return None if ref is None else np.asarray(ref, dtype=float) - state.offset


def drive_refusal(config: Any) -> str:
    """Why the PC cannot drive a robot over a stream of ``config`` (``""``: it can) — it
    needs whole joint commands (``config.joint_targets``)."""
    if config.joint_targets:
        return ""
    kind = " ".join(str(getattr(config, k)) for k in ("mode", "correction")
                    if hasattr(config, k))
    return (f"the PC drives the robot with absolute joint corrections (RSI AKorr #ABSOLUTE, "
            f"EGM joint targets); the {config.vendor} link is configured for {kind}: it "
            f"corrects the controller's own path (CORRECT)")


def motion_timeout(duration: float, config: Any) -> float:
    """Seconds a motion of ``duration`` s may take: two controller timeouts and
    :data:`SLACK_S` more."""
    return duration + 2 * config.timeout_s + SLACK_S


class StreamDrive:
    """A Drive that streams each trajectory through a link (module docstring).

    Parameters
    ----------
    link : StreamLink
        A started link whose configuration sends whole joint commands
        (``config.joint_targets``: RSI absolute joint corrections, EGM joint mode).
    feedback_only : bool
        Take a link of another configuration too (one that corrects the controller's own
        path): the joints are read, every motion is refused with :func:`drive_refusal`.
    """

    def __init__(self, link: StreamLink, feedback_only: bool = False) -> None:
        self.refusal = drive_refusal(link.config)
        if self.refusal and not feedback_only:
            raise ValueError(self.refusal)
        self.link = link
        self.followed = 0

    def joint_readings(self) -> Array:
        """The robot's actual joints (in the newest packet), rad, shape (6,)."""
        state = self.link.latest
        vendor = self.link.config.vendor
        if state is None or not self.link.streaming:
            raise MotionError(self.link.failure.args[0] if self.link.failure is not None
                              else f"no {vendor} stream from the controller")
        if state.joints is None:
            raise MotionError(f"the controller's {vendor} packets carry no joint feedback")
        return np.array(state.joints, dtype=float)

    def follow(self, trajectory: Trajectory, adjust: Adjust | None = None) -> None:
        """Stream ``trajectory`` from its start to its end (blocks for its duration).

        ``adjust(state, k, q_k)``, if given, is added to sample ``k``'s joints each cycle
        (rad, (6,)): a tracked move's correction (:mod:`~..tracked_moves`).

        Raises
        ------
        MotionError
            The stream failed or the motion did not end in time: the link's reason.
        """
        q = samples(trajectory, self.link.config.cycle_s)
        self.follow_samples(q, motion_timeout(trajectory.duration, self.link.config), adjust)

    def follow_samples(self, q: Array, timeout: float, adjust: Adjust | None = None) -> None:
        """Stream the set-points ``q`` (rad, shape (K+1, 6)), one per answered packet.

        Parameters
        ----------
        q : ndarray, shape (K+1, 6)
            The motion's joints at every cycle (:func:`samples`).
        timeout : float
            Seconds it may take (:func:`motion_timeout`).
        adjust : callable, optional
            ``adjust(state, k, q_k) -> Δq`` (rad, (6,)) added to sample ``k``'s joints in
            its cycle; the exact stop then waits for the last command, ``q_K + Δq_K``.

        Raises
        ------
        MotionError
            The stream failed or the motion did not end in time: the link's reason.
        """
        if self.refusal:
            raise MotionError(self.refusal)
        last = len(q) - 1
        motion: dict[str, Any] = {}
        base_of = getattr(self.link, "joint_base", None) or setpoint_base

        def source(state: CycleState) -> Correction:
            if not motion:  # the motion's first cycle: where the session's offsets start
                base = base_of(state)
                if base is None:
                    raise MotionError(f"the controller's {self.link.config.vendor} packets "
                                      "carry no joints")
                # the move was planned from the actual joints; the command stands at
                # base + offset: fade the difference out along the move, so it starts
                # without a jump and ends on the target
                motion.update(base=base, gap=base + state.offset - q[0], k=-1)
            k = motion["k"] = min(motion["k"] + 1, last)
            fade = 1.0 - k / last if last else 0.0
            target = q[k] if adjust is None else q[k] + adjust(state, k, q[k])
            motion["end"] = target
            return Correction(offset=target - motion["base"] + fade * motion["gap"])

        def done(state: CycleState) -> bool:
            return motion.get("k", -1) >= last

        try:
            self.link.follow(source, done, timeout)
        except (StreamLinkError, TimeoutError) as exc:
            raise MotionError(str(exc)) from None
        end = motion.get("end", q[-1])
        self.link.wait(lambda link: _arrived(link.latest, end), SETTLE_S)
        self.followed += 1


def _arrived(state: Any, end: Array) -> bool:
    """Whether the robot's actual joints (``state.joints``) are within the exact stop of
    ``end``: ``max |q_i − q_end,i| ≤`` :data:`IN_POSITION_RAD`."""
    joints = getattr(state, "joints", None)
    return joints is not None and float(np.max(np.abs(joints - end))) <= IN_POSITION_RAD
