"""The controller's own program on the twin: what mode (b) corrects.

In issue 37's mode (b), *the robot drives, the PC corrects*, the controller runs its own
motion program — a KRL program's ``LIN`` moves between ``RSI_ON`` and ``RSI_OFF`` — and
the PC superimposes corrections.  :func:`linear_program` plans such a program for the
twin's controller (:class:`~.rsi_robot.RsiRobot`'s ``path``): straight lines from where
the arm stands, each given as a displacement of the TCP in the base frame, at a TCP
speed, with the controller's nominal model; :func:`path_shift` is what the corrections
did to it at this instant — the controller's commanded TCP minus its program's.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from plugcell.kinematics import RobotDescription, forward
from plugcell.motion import (
    LIN,
    CartesianLimits,
    JointLimits,
    Trajectory,
    TrajectoryError,
    plan,
)

__all__ = ["linear_program", "parse_lins", "path_shift"]

Array = NDArray[np.float64]


def linear_program(desc: RobotDescription, q0: ArrayLike, lines: Sequence[ArrayLike],
                   speed: float) -> Trajectory:
    """The program ``LIN p₁; LIN p₂; …`` from the joints ``q0``, ``p_i = p_{i−1} + d_i``.

    Planned with :func:`plugcell.motion.plan` on the nominal model: TCP speed ``v``,
    acceleration ``20 v`` per second and jerk ``200 v`` per second² (a move of 100 mm/s
    reaches its speed in about 0.1 s), the orientation kept; the joints within 100 °/s,
    300 °/s², 2000 °/s³.

    Parameters
    ----------
    desc : RobotDescription
        The robot (its nominal model is the controller's).
    q0 : array_like, shape (6,)
        Where the arm stands at ``RSI_ON`` (rad).
    lines : sequence of array_like, shape (3,)
        Each move's TCP displacement ``d_i`` in the base frame (m).
    speed : float
        ``v``, the TCP speed (m/s).

    Returns
    -------
    Trajectory
        The program, starting at ``q0``.

    Raises
    ------
    ValueError
        No move, a displacement that is not three finite numbers, a speed that is not
        positive, or a move the planner refuses (unreachable, beyond the joint limits).
    """
    if not lines:
        raise ValueError("the program needs at least one LIN")
    if not (np.isfinite(speed) and speed > 0):
        raise ValueError(f"the TCP speed must be positive, not {speed!r}")
    T = forward(desc, None, np.asarray(q0, dtype=float), "nominal").tcp.copy()
    moves = []
    for d in lines:
        step = np.asarray(d, dtype=float).reshape(-1)
        if step.shape != (3,) or not np.isfinite(step).all():
            raise ValueError(f"a LIN is a displacement of three finite numbers, got {d!r}")
        T = T.copy()
        T[:3, 3] += step
        moves.append(LIN(target=T))
    joint = JointLimits(*np.radians([[100.0] * 6, [300.0] * 6, [2000.0] * 6]))
    cart = CartesianLimits(speed, 20 * speed, 200 * speed, 1.0, 4.0, 40.0)
    try:
        return plan(desc, np.asarray(q0, dtype=float), moves, joint, cart)
    except TrajectoryError as exc:
        raise ValueError(f"the controller's program: {exc}") from None


def parse_lins(texts: Sequence[str]) -> list[Array]:
    """``["DX,DY,DZ", …]`` in mm → the displacements in m (``ValueError`` naming a bad one)."""
    out = []
    for text in texts:
        try:
            values = [float(v) for v in text.split(",")]
        except ValueError:
            values = []
        if len(values) != 3 or not np.isfinite(values).all():
            raise ValueError(f"--lin {text!r}: expected DX,DY,DZ in mm")
        out.append(np.array(values) * 1e-3)
    return out


def path_shift(desc: RobotDescription, command: ArrayLike, path_pose: ArrayLike) -> Array:
    """The corrections' shift of the controller's TCP now, ``p(q_cmd) − p_path`` (m, (3,)):
    the nominal TCP of the commanded joints minus the program's own nominal TCP."""
    T = forward(desc, None, np.asarray(command, dtype=float), "nominal").tcp
    return T[:3, 3] - np.asarray(path_pose, dtype=float)[:3, 3]
