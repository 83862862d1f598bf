"""What a running program talks to: the arm, the PC link, and the clock.

The interpreter depends only on these three small protocols; the simulated
controller implements :class:`Motion` with the twin and nominal IK and
:class:`Channel` with its TCP link, tests implement them in memory.  Nothing here
imports the twin, the framework or sockets.

Units are the robot language's: millimetres and degrees.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Sequence
from typing import Protocol, runtime_checkable

from plugcell.pdl.values import JointPos, Position

__all__ = ["Channel", "Clock", "Motion", "MotionError", "SimClock", "TrackedMotion"]


class MotionError(Exception):
    """Raised by a :class:`Motion` implementation for a move it cannot make.

    The interpreter turns it (and any other exception from the motion interface)
    into a :class:`~.errors.MotionFailedError` at the program line.
    """


@runtime_checkable
class Motion(Protocol):
    """The arm, as the program sees it.

    Each ``move_*`` blocks until the move is planned, returns its duration in
    *simulated* seconds (or ``None`` for instantaneous), and the interpreter
    advances the :class:`Clock` by it.
    """

    def move_joints(self, q_deg: Sequence[float]) -> float | None:
        """Joint move to ``q_deg`` (one angle per axis, degrees)."""
        ...

    def move_to(self, pose: Position, linear: bool = False) -> float | None:
        """Move to a Cartesian pose (joint-interpolated, or straight if ``linear``)."""
        ...

    def move_relative(self, offset_mm: Sequence[float], frame: str) -> float | None:
        """Translate the tool by ``offset_mm`` (x, y, z) in ``frame`` ``"BASE"``/``"TOOL"``."""
        ...

    def arm_pos(self) -> Position:
        """Current Cartesian pose from the controller's (nominal) kinematics."""
        ...

    def arm_jntp(self) -> JointPos:
        """Current joint readings."""
        ...

    def pos_to_jntp(self, pose: Position) -> JointPos:
        """Inverse kinematics (the controller's model)."""
        ...

    def jntp_to_pos(self, joints: JointPos) -> Position:
        """Forward kinematics (the controller's model)."""
        ...


@runtime_checkable
class TrackedMotion(Motion, Protocol):
    """An arm whose moves a laser tracker can correct while they run (issue 38): one
    moved over a streaming link (KUKA RSI, ABB EGM), where each cycle's command can take
    a correction.  ``MOVE LINEAR TO p WITH TRACKING T`` calls :meth:`move_tracked`; an
    arm without it (a controller that runs its moves by itself) fails the move."""

    def move_tracked(self, pose: Position, tracker: str) -> float | None:
        """Straight move to ``pose`` with the tracker service ``tracker`` correcting it."""
        ...


@runtime_checkable
class Channel(Protocol):
    """The program's line to the PC (``WRITE pc_client``).

    ``write`` gets one complete line per WRITE statement (no trailing newline).
    Answers come back through :meth:`Execution.post
    <plugcell.pdl.interpreter.Execution.post>`, not through here.
    Raising from ``write`` (e.g. a dropped connection) fails the program at that
    line with :class:`~.errors.ChannelError`.
    """

    def write(self, line: str) -> None:
        """Send one line."""
        ...


@runtime_checkable
class Clock(Protocol):
    """Simulated time.

    ``speed`` is simulated seconds per real second (``math.inf``: do not sleep
    at all).  The interpreter sleeps ``duration / speed`` real seconds for a move
    or a DELAY and then calls :meth:`advance`; while it WAITs it advances the
    clock by ``speed`` times the real time that passed.
    """

    @property
    def speed(self) -> float:
        """Simulated seconds per real second."""
        ...

    def now(self) -> float:
        """Simulated seconds."""
        ...

    def advance(self, seconds: float) -> None:
        """Move simulated time forward."""
        ...


class SimClock:
    """A thread-safe simulated clock starting at ``start`` seconds.

    ``SimClock(speed=100)`` runs a 15-minute program in 9 s of real time;
    ``speed=math.inf`` never sleeps (unit tests).
    """

    def __init__(self, speed: float = 1.0, start: float = 0.0) -> None:
        if not (speed > 0 and not math.isnan(speed)):
            raise ValueError(f"speed must be positive, not {speed}")
        self._speed = float(speed)
        self._now = float(start)
        self._lock = threading.Lock()

    @property
    def speed(self) -> float:
        return self._speed

    def now(self) -> float:
        with self._lock:
            return self._now

    def advance(self, seconds: float) -> None:
        if seconds < 0 or math.isnan(seconds):
            raise ValueError(f"cannot advance the clock by {seconds}")
        with self._lock:
            self._now += seconds

    def __repr__(self) -> str:
        return f"SimClock(speed={self._speed:g}, now={self.now():.3f})"
