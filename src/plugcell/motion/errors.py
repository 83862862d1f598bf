"""Exceptions of :mod:`plugcell.motion`: a move that cannot be made, and why.

Every check before motion raises a :class:`TrajectoryError` subclass whose attributes
locate the problem — the move (its index in the list, its program line if given), the
time and the path fraction at which it occurs, the joint, the offending value and the
limit — and whose message says it in one line, e.g.::

    move 3 (LIN, line 12) at t = 1.240 s (path 41.0 %): joint 4 speed 3.912 rad/s
    exceeds its limit 3.491 rad/s
"""

from __future__ import annotations

import math

__all__ = [
    "JointRangeError",
    "JointSpeedError",
    "MoveError",
    "SingularityError",
    "TrajectoryError",
    "UnreachablePoseError",
]


class TrajectoryError(Exception):
    """A move that cannot be made.

    Attributes
    ----------
    move : int or None
        Index of the move in the list given to the planner (0-based).
    line : int or None
        The move's program line, when the caller gave one.
    kind : str
        The move's type (``"PTP"``, ``"LIN"``, ``"CIRC"``).
    time : float or None, s
        Trajectory time of the problem (``None`` for a problem of the move's data).
    fraction : float or None
        Path fraction of the move in [0, 1] at that time.
    joint : str or None
        The joint concerned, by its reading name.
    value, limit : float or None
        The offending value and the limit it breaks, in SI units (rad, rad/s, m/s…).
    reason : str
        What is wrong, without the location.
    """

    def __init__(
        self,
        reason: str,
        *,
        move: int | None = None,
        line: int | None = None,
        kind: str = "",
        time: float | None = None,
        fraction: float | None = None,
        joint: str | None = None,
        value: float | None = None,
        limit: float | None = None,
    ) -> None:
        self.reason = reason
        self.move = move
        self.line = line
        self.kind = kind
        self.time = time
        self.fraction = fraction
        self.joint = joint
        self.value = value
        self.limit = limit
        super().__init__(self._message())

    def _message(self) -> str:
        where = []
        if self.move is not None:
            what = ", ".join(x for x in (self.kind, f"line {self.line}" if self.line else "") if x)
            where.append(f"move {self.move}" + (f" ({what})" if what else ""))
        if self.time is not None and math.isfinite(self.time):
            at = f"at t = {self.time:.3f} s"
            if self.fraction is not None:
                at += f" (path {100.0 * self.fraction:.1f} %)"
            where.append(at)
        head = " ".join(where)
        return f"{head}: {self.reason}" if head else self.reason


class MoveError(TrajectoryError, ValueError):
    """A move's own data are wrong (a target of the wrong shape, a degenerate circle…)."""


class JointRangeError(TrajectoryError):
    """A joint (or a coupled joint difference) leaves its position limits."""


class JointSpeedError(TrajectoryError):
    """A Cartesian move needs a joint faster than its speed limit."""


class SingularityError(TrajectoryError):
    """The path comes too close to a singularity (the Jacobian's inverse condition
    number falls below the threshold) or the joint solution jumps between branches."""


class UnreachablePoseError(TrajectoryError):
    """Inverse kinematics finds no joint solution for a pose of the path."""
