"""In-memory stand-ins for the arm and the PC link (tests only)."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

from plugcell.pdl import Execution, JointPos, Position, Program, SimClock


class FakeArm:
    """A 6-axis arm with a toy kinematics: joints = (x/10, y/10, z/10, a, b, c)."""

    def __init__(self, move_s: float = 2.0, unreachable_x: float | None = None) -> None:
        self.q = [0.0, 0.0, 50.0, 0.0, 90.0, 0.0]
        self.move_s = move_s
        self.unreachable_x = unreachable_x
        self.log: list[tuple[str, Any]] = []

    def _fk(self, q: Sequence[float]) -> Position:
        return Position(q[0] * 10, q[1] * 10, q[2] * 10, q[3], q[4], q[5])

    def pos_to_jntp(self, pose: Position) -> JointPos:
        if self.unreachable_x is not None and pose.x > self.unreachable_x:
            raise ValueError(f"x = {pose.x} mm is out of reach")
        return JointPos((pose.x / 10, pose.y / 10, pose.z / 10, pose.a, pose.b, pose.c))

    def jntp_to_pos(self, joints: JointPos) -> Position:
        return self._fk(joints.joints)

    def move_joints(self, q_deg: Sequence[float]) -> float:
        self.q = [float(v) for v in q_deg]
        self.log.append(("joints", tuple(self.q)))
        return self.move_s

    def move_to(self, pose: Position, linear: bool = False) -> float:
        self.q = list(self.pos_to_jntp(pose).joints)
        self.log.append(("linear" if linear else "to", pose))
        return self.move_s

    def move_relative(self, offset_mm: Sequence[float], frame: str) -> float:
        p = self._fk(self.q)
        self.q = list(
            self.pos_to_jntp(
                Position(p.x + offset_mm[0], p.y + offset_mm[1], p.z + offset_mm[2], p.a, p.b, p.c)
            ).joints
        )
        self.log.append(("relative", (tuple(offset_mm), frame)))
        return self.move_s

    def arm_pos(self) -> Position:
        return self._fk(self.q)

    def arm_jntp(self) -> JointPos:
        return JointPos(tuple(self.q))


Responder = Callable[[str], tuple[bool, Any, str] | None]


class FakeChannel:
    """Records WRITE pc_client lines; answers ACTIVATE lines through ``responder``.

    ``responder(line)`` returns ``(ok, data, message)`` (or ``None``: no answer).
    The answer is posted at once (``delay_s=None``) or from another thread after
    ``delay_s`` real seconds, as a service would.
    """

    def __init__(self, responder: Responder | None = None, delay_s: float | None = None) -> None:
        self.lines: list[str] = []
        self.responder = responder or (lambda line: (True, None, ""))
        self.delay_s = delay_s
        self.execution: Execution | None = None
        self.fail_after: int | None = None

    def write(self, line: str) -> None:
        if self.fail_after is not None and len(self.lines) >= self.fail_after:
            raise ConnectionError("connection to the robot service dropped")
        self.lines.append(line)
        answer = self.responder(line)
        if answer is None or self.execution is None:
            return
        ok, data, message = answer
        execution = self.execution
        if self.delay_s is None:
            execution.post_result(ok, data, message)
        else:

            def later() -> None:
                time.sleep(self.delay_s or 0.0)
                execution.post_result(ok, data, message)

            threading.Thread(target=later, daemon=True).start()


def execution(
    program: Program,
    responder: Responder | None = None,
    *,
    speed: float = float("inf"),
    delay_s: float | None = None,
    arm: FakeArm | None = None,
    **kw: Any,
) -> tuple[Execution, FakeArm, FakeChannel]:
    """An Execution wired to a fake arm and channel, with a 5 s WAIT budget."""
    arm = arm or FakeArm()
    channel = FakeChannel(responder, delay_s)
    kw.setdefault("wait_budget_s", 5.0)
    ex = Execution(program, motion=arm, channel=channel, clock=SimClock(speed=speed), **kw)
    channel.execution = ex
    return ex, arm, channel


def run_source(text: str, responder: Responder | None = None, **kw: Any):
    """Load ``text`` as a program, run it; (result, execution, arm, channel)."""
    program = Program.from_source(text, "test.pdl")
    ex, arm, channel = execution(program, responder, **kw)
    return ex.run(), ex, arm, channel
