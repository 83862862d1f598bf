"""The PC drives: a planned trajectory streamed to a KUKA robot as absolute joint corrections.

:class:`RsiDrive` is a :class:`~plugcell.devices.robot.planned_motion.Drive` over an
:class:`~.link.RsiLink` configured for joint (``AKorr``) corrections in absolute mode: the
controller's program only starts RSI where the robot stands and follows the sensor
(``plugcell rsi files --mode absolute``).  For one move it

1. samples the whole trajectory ahead at the controller's cycle ``T``
   (``Trajectory.setpoints``; one sample per cycle would not fit the cycle in Python,
   docs/motion.md);
2. takes, at the motion's first cycle, the base of the session's offsets — where the
   controller started RSI — from the robot's packet: ``q_base = ASPos − o`` (the set-point
   joints minus the offset commanded so far; ``AIPos`` if the controller sends no
   ``ASPos``);
3. answers the motion's ``k``-th answered packet (of ``K + 1``) with the absolute correction

       o_k = q(k T) − q_base + (1 − k/K) · (q_set,0 − q(0))   (rad)

   — the move is planned from the actual joints ``q(0)`` (AIPos), the command stands at
   the set-point ``q_set,0`` (ASPos): their difference (the following error at the
   start) fades out along the move, so the command neither jumps at the start nor misses
   the target at the end — and ends with the last sample; the link then holds the robot
   there (absolute: the offset kept).  A missed cycle (a packet lost or answered late)
   delays the rest of the move by one cycle instead of skipping a sample: the command never
   steps by more than one cycle of the planned motion, so the link's limits
   (:func:`~plugcell.devices.robot.rsi_controller.streaming_limits`) hold even on a busy PC.

Joint feedback is the newest packet's ``AIPos``.  A failed stream (silence, missed
cycles, a refused correction) or a motion that does not end in time is a
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

from .link import Correction, CycleState, RsiLink, RsiLinkError

__all__ = ["RsiDrive"]

Array = NDArray[np.float64]

#: Seconds a motion may take beyond its duration and two controller timeouts.
SLACK_S = 2.0


class RsiDrive:
    """A Drive that streams each trajectory through an RSI link (module docstring).

    Parameters
    ----------
    link : RsiLink
        A link with ``correction="joint"`` and ``mode="absolute"``, started.
    """

    def __init__(self, link: RsiLink) -> None:
        cfg = link.config
        if cfg.correction != "joint" or cfg.mode != "absolute":
            raise ValueError(f"the PC drives the robot with absolute joint corrections; the "
                             f"link is configured for {cfg.mode} {cfg.correction} ones")
        self.link = link
        self.followed = 0

    def joint_readings(self) -> Array:
        """The robot's actual joints (``AIPos`` of the newest packet), rad, shape (6,)."""
        state = self.link.latest
        if state is None or not self.link.streaming:
            raise MotionError(self.link.failure.args[0] if self.link.failure is not None
                              else "no RSI stream from the controller")
        if state.joints is None:
            raise MotionError("the controller's RSI packets carry no AIPos (joint feedback)")
        return np.array(state.joints, dtype=float)

    def follow(self, trajectory: Trajectory,
               adjust: Callable[[CycleState, int, Array], Array] | None = None) -> None:
        """Stream ``trajectory`` from its start to its end (blocks for its duration).

        ``adjust(state, k, q_k)``, if given, is added to sample ``k``'s joints each cycle
        (rad, (6,)): a tracked move's correction (:mod:`~..tracked_moves`).

        Raises
        ------
        MotionError
            The stream failed or the motion did not end in time: the link's reason.
        """
        cfg = self.link.config
        _, q = trajectory.setpoints(cfg.cycle_s)
        q = np.asarray(q, dtype=float)
        if q.ndim != 2 or q.shape[1] != 6:
            raise MotionError(f"RSI streams six axes; the trajectory has shape {q.shape}")
        last = len(q) - 1
        motion: dict[str, Any] = {}

        def source(state: CycleState) -> Correction:
            if not motion:  # the motion's first cycle: where the session's offsets start
                robot = state.robot
                ref = robot.joints_setpoint if robot.joints_setpoint is not None \
                    else robot.joints
                if ref is None:
                    raise MotionError("the controller's RSI packets carry no joints")
                # the move was planned from AIPos; the command stands at ASPos: fade the
                # difference out along the move, so it starts without a jump and ends on
                # the target
                motion.update(base=ref - state.offset, gap=ref - q[0], k=-1)
            k = motion["k"] = min(motion["k"] + 1, last)
            fade = 1.0 - k / last if last else 0.0
            extra = 0.0 if adjust is None else adjust(state, k, q[k])
            return Correction(offset=q[k] - motion["base"] + fade * motion["gap"] + extra)

        def done(state: CycleState) -> bool:
            return motion.get("k", -1) >= last

        timeout = trajectory.duration + 2 * cfg.timeout_s + SLACK_S
        try:
            self.link.follow(source, done, timeout)
        except RsiLinkError as exc:
            raise MotionError(str(exc)) from None
        except TimeoutError as exc:
            raise MotionError(str(exc)) from None
        self.followed += 1
