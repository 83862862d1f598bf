"""``python -m plugcell.sim.controller.egm_twin``: the twin as an ABB robot streaming EGM.

A process that stands where an ABB controller running plugcell's RAPID module
(``plugcell egm files --mode joint``: ``EGMRunJoint`` where the robot stands) stands: the
controller's EGM loop (:class:`~.egm_robot.EgmRobotSim`: an ``EgmRobot`` to the sensor's
address every sample, the newest ``EgmSensor`` followed, ``\\CommTimeout``) with the
dynamic twin (:class:`~plugcell.sim.twin.dynamics.DynamicTwin`) as its axes: each sample
the joint target goes to the twin's servo loops (:class:`TwinFollower`), the feedback
joints are its encoder readings, and the feedback pose is the controller's *nominal*
forward kinematics of them (a real controller reports its model, not the true TCP).  It
prints one line with its own address, then runs until SIGTERM/SIGINT or until EGM stops
(no answer for ``\\CommTimeout``: exit status 3 with the reason, as the controller's
communication error ends EGM).

``python -m plugcell.sim.controller.egm_twin --sensor 127.0.0.1:6510 [--robot smart_h4]
[--payload-kg M] [--seed S] [--timeout 1.0] [--bind HOST:PORT]``
"""

from __future__ import annotations

import sys
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from plugcell.sim.controller.egm_robot import EgmRobotSim
from plugcell.sim.controller.twin_process import TwinProcess, run_twin, twin_parser

__all__ = ["EgmTwinProcess", "TwinFollower", "egm_twin", "main"]

Array = NDArray[np.float64]
PREFIX = "egm-twin:"


class TwinFollower:
    """The dynamic twin as :class:`~.egm_robot.EgmRobotSim`'s axes (a ``Follower``).

    Parameters
    ----------
    arm : DynamicTwin
        The arm; its cycle is the EGM sample.
    """

    def __init__(self, arm: object) -> None:
        self.arm = arm

    def step(self, x: Array, target: Array, dt: float) -> Array:
        """One sample of the twin commanded to ``target`` (rad); its encoder readings."""
        cycle = self.arm.params.cycle  # type: ignore[attr-defined]
        if abs(dt - cycle) > 1e-12:
            raise ValueError(f"the EGM sample {dt} s is not the twin's cycle {cycle} s")
        self.arm.step(target)  # type: ignore[attr-defined]
        return np.array(self.arm.measured, dtype=float)  # type: ignore[attr-defined]


class _TwinEgmRobot(EgmRobotSim):
    """EgmRobotSim in joint mode whose feedback pose is the nominal model's of its joints."""

    def __init__(self, arm: object, sensor: tuple[str, int], **kwargs: object) -> None:
        self.description = arm.twin.description  # type: ignore[attr-defined]
        q = np.array(arm.measured, dtype=float)  # type: ignore[attr-defined]
        p, quat = self._pose(q)
        super().__init__(sensor, "joint", joints=q, position=p, quaternion=quat,
                         sample_s=arm.params.cycle,  # type: ignore[attr-defined]
                         follower=TwinFollower(arm), **kwargs)  # type: ignore[arg-type]

    def _pose(self, q: Array) -> tuple[Array, Array]:
        from plugcell.kinematics import forward
        from plugcell.kinematics.rotations import matrix_to_quat

        T = forward(self.description, None, q, "nominal").tcp
        return T[:3, 3].copy(), matrix_to_quat(T[:3, :3])

    def advance(self, dt: float) -> None:
        super().advance(dt)
        self.p, self.quat = self._pose(self.q)


def egm_twin(sensor: tuple[str, int], robot: str = "smart_h4", seed: int = 0,
             payload_kg: float = 0.0, comm_timeout_s: float = 1.0,
             bind: tuple[str, int] = ("127.0.0.1", 0)) -> EgmRobotSim:
    """The twin's EGM robot side (joint mode), not started.

    Parameters
    ----------
    sensor : tuple of (str, int)
        Where plugcell listens.
    robot, seed, payload_kg
        The twin's scenario.
    comm_timeout_s : float
        ``\\CommTimeout`` (s).
    bind : tuple of (str, int)
        The controller's own address.

    Returns
    -------
    EgmRobotSim
        Its axes the dynamic twin's.
    """
    from plugcell.sim.twin.dynamics import DynamicTwin
    from plugcell.sim.twin.scenario import TwinScenario

    arm = DynamicTwin(TwinScenario(robot=robot, seed=seed, payload_kg=payload_kg))
    return _TwinEgmRobot(arm, sensor, comm_timeout_s=comm_timeout_s, bind=bind)


class EgmTwinProcess(TwinProcess):
    """The twin's EGM side in a process of its own: ``EgmTwinProcess(sensor, *options)``."""

    def __init__(self, sensor: str, *options: str) -> None:
        super().__init__("plugcell.sim.controller.egm_twin", PREFIX, sensor, *options)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the twin's EGM robot side (module docstring); the exit status."""
    p = twin_parser("python -m plugcell.sim.controller.egm_twin",
                    "The dynamic twin as an ABB controller streaming EGM (EGMRunJoint) to "
                    "plugcell's sensor side.")
    p.add_argument("--timeout", type=float, default=1.0,
                   help="EGMSetupUC's \\CommTimeout (s)")
    args = p.parse_args(argv)
    return run_twin(args, lambda sensor, bind: egm_twin(
        sensor, args.robot, args.seed, args.payload_kg, args.timeout, bind),
        "EGM (joint)", PREFIX, lambda r: {
            "cycles": r.sent, "answered": r.answers, "late": r.unanswered,  # type: ignore
            "rtt_ns": list(r.rtts)})  # type: ignore[attr-defined]


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
