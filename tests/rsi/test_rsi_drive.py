"""RsiDrive (the PC drives): a planned trajectory as absolute joint corrections, checked on a
link that plays the controller cycle by cycle (no UDP): the command starts where the
controller holds the robot (no jump, though the move was planned from the lagging AIPos),
ends exactly on the trajectory's end, never steps by more than one cycle of the motion
(missed cycles delay it), and a failed stream is a MotionError with the link's reason."""

from __future__ import annotations

import numpy as np
import pytest

from plugcell.devices.robot.rsi import CycleState, RobotState, RsiConfig, StreamStoppedError
from plugcell.devices.robot.rsi.drive import RsiDrive
from plugcell.io.robots import load_robot
from plugcell.io.units import DEG
from plugcell.motion import PTP, JointLimits, plan
from plugcell.pdl.interfaces import MotionError

CONFIG = RsiConfig(robot_host="127.0.0.1", listen_host="127.0.0.1", listen_port=0,
                   mode="absolute")
V = 20 * DEG


class _PlayedLink:
    """A link whose follow() plays the controller: ASPos = base + offset, AIPos lags."""

    def __init__(self, base: np.ndarray, held: np.ndarray, lag: np.ndarray,
                 ipoc_gap: int = 4, fail: Exception | None = None) -> None:
        self.config = CONFIG
        self.base, self.offset, self.lag = base, held.copy(), lag
        self.ipoc, self.ipoc_gap, self.fail = 1000, ipoc_gap, fail
        self.sent: list[np.ndarray] = []
        self.streaming, self.failure = True, None

    @property
    def latest(self) -> RobotState:
        q_set = self.base + self.offset
        return RobotState(self.ipoc, joints=q_set - self.lag, joints_setpoint=q_set)

    def wait(self, predicate, timeout):
        """The held robot settles: the lag decays by half a cycle until the predicate holds
        (the cycles it took in ``settled``), or ``timeout`` worth of cycles pass."""
        self.settled = 0
        while not predicate(self):
            if self.settled * CONFIG.cycle_s >= timeout:
                return False
            self.lag = self.lag / 2
            self.settled += 1
        return True

    def follow(self, source, done, timeout):
        if self.fail is not None:
            raise self.fail
        for cycle in range(100_000):
            state = CycleState(self.latest, self.offset.copy(), 1, cycle, 0.0)
            corr = source(state)
            self.offset = np.asarray(corr.offset, dtype=float)
            self.sent.append(self.offset)
            self.ipoc += self.ipoc_gap  # a gap: cycles lost on the way
            if done(state):
                return state
        raise TimeoutError


def _trajectory(q0: np.ndarray):
    desc = load_robot("smart_h4")
    target = q0 + np.array([6.0, -3.0, 2.0, 0.0, 4.0, -5.0]) * DEG
    return plan(desc, q0, [PTP(target=target)], JointLimits.uniform(6, V, 3 * V, 30 * V))


@pytest.mark.parametrize("gap", [4, 12])
def test_the_command_starts_held_ends_on_target_and_never_skips(gap):
    base = np.radians([0.0, -90.0, -187.0, 0.0, 90.0, 0.0])
    held = np.radians([1.0, 0.5, -0.2, 0.0, 0.3, 0.1])
    lag = np.radians([0.02, -0.05, 0.01, 0.0, 0.03, -0.01])
    link = _PlayedLink(base, held, lag, ipoc_gap=gap)
    drive = RsiDrive(link)  # type: ignore[arg-type]
    q0 = drive.joint_readings()  # AIPos: the move is planned from there
    np.testing.assert_allclose(q0, base + held - lag)
    traj = _trajectory(q0)
    drive.follow(traj)
    sent = np.array(link.sent)
    _, q = traj.setpoints(CONFIG.cycle_s)
    assert len(sent) == len(q)  # one answered packet per sample, gaps or not
    np.testing.assert_allclose(sent[0], held, atol=1e-12)  # no jump from the held command
    np.testing.assert_allclose(sent[-1] + base, q[-1], atol=1e-12)  # on the target
    steps = np.abs(np.diff(np.vstack([held, sent]), axis=0))
    bound = V * CONFIG.cycle_s + np.abs(lag) / (len(q) - 1) + 1e-12
    assert np.all(steps <= bound)
    assert drive.followed == 1


def test_a_failed_stream_is_a_motion_error_with_the_reason():
    base = np.zeros(6)
    link = _PlayedLink(base, np.zeros(6), np.zeros(6),
                       fail=StreamStoppedError("RSI stream stopped: no packet for 0.4 s"))
    drive = RsiDrive(link)  # type: ignore[arg-type]
    with pytest.raises(MotionError, match=r"RSI stream stopped: no packet for 0\.4 s"):
        drive.follow(_trajectory(np.radians([0.0, -90.0, -187.0, 0.0, 90.0, 0.0])))
    link.streaming = False
    with pytest.raises(MotionError, match="no RSI stream from the controller"):
        drive.joint_readings()


def test_only_absolute_joint_corrections_drive_the_robot():
    import dataclasses

    for kw in ({"mode": "relative"}, {"correction": "cartesian"}):
        link = _PlayedLink(np.zeros(6), np.zeros(6), np.zeros(6))
        link.config = dataclasses.replace(CONFIG, **kw, limits=None)
        with pytest.raises(ValueError, match="absolute joint corrections"):
            RsiDrive(link)  # type: ignore[arg-type]


def test_a_move_ends_with_the_exact_stop():
    """The move returns once the actual joints are within the positioning window of its
    end (as a controller's exact stop), not when the last setpoint left."""
    from plugcell.devices.robot.rsi.drive import IN_POSITION_RAD

    base = np.radians([0.0, -90.0, -187.0, 0.0, 90.0, 0.0])
    link = _PlayedLink(base, np.zeros(6), np.radians([0.05, 0.0, 0.0, 0.0, 0.0, 0.0]))
    drive = RsiDrive(link)  # type: ignore[arg-type]
    traj = _trajectory(drive.joint_readings())
    drive.follow(traj)
    assert link.settled > 0  # it waited, holding
    assert np.max(np.abs(drive.joint_readings() - traj.setpoints(CONFIG.cycle_s)[1][-1])) \
        <= IN_POSITION_RAD
