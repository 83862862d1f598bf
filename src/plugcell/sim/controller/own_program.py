"""The controller's own program on the twin: what mode (b) corrects.

In issue 37's mode (b), *the robot drives, the PC corrects*, the controller runs its own
motion program — a KRL program's ``LIN`` moves between ``RSI_ON`` and ``RSI_OFF`` — and
the PC superimposes corrections.  :func:`linear_program` plans such a program for the
twin's controller (:class:`~.rsi_robot.RsiRobot`'s ``path``): straight lines from where
the arm stands, each given as a displacement of the TCP in the base frame, at a TCP
speed, with the controller's nominal model; :func:`program_path` plans a path file
(``plugcell path run``'s CSV, :mod:`plugcell.io.path_files`) or the straight moves of a
robot program (``.pdl``, :mod:`plugcell.sim.path_program`) instead; :func:`path_shift`
is what the corrections did to it at this instant — the controller's commanded TCP
minus its program's; :func:`probe_error` is how far the arm truly is
from where the program means it.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

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

__all__ = ["linear_program", "parse_lins", "path_shift", "probe_error", "program_path"]

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


def probe_error(arm, path_pose: ArrayLike, tool: ArrayLike,
                frames: tuple[ArrayLike, ArrayLike]) -> Array:
    """How far the T-MAC truly is from where the program means it now, in the tracker
    frame (m, (3,)): ``BASE_t · T_true · PROBE_t − BASE · T_path · tool⁻¹ · PROBE``, the
    twin's true T-MAC minus the program's nominal TCP pose carried to the T-MAC and into
    the tracker frame by a calibration's ``BASE`` and ``PROBE`` — what a laser tracker
    in the calibrated cell sees, and what a compensation removes.  Simulators only.

    Parameters
    ----------
    arm : DynamicTwin
        The twin (its truth and its true flange now).
    path_pose : (4, 4) array_like
        The program's nominal TCP pose now (robot base frame, m).
    tool : (4, 4) array_like
        The controller's TCP in the flange frame.
    frames : tuple of two (4, 4) array_like
        ``BASE`` (the robot base in the tracker frame) and ``PROBE`` (the T-MAC in the
        flange frame) of a calibration.
    """
    base, probe = (np.asarray(f, dtype=float) for f in frames)
    twin = arm.twin
    true = twin.true_base() @ arm.true_flange() @ twin.reveal_truth().probe
    meant = base @ np.asarray(path_pose, dtype=float) @ np.linalg.inv(
        np.asarray(tool, dtype=float)) @ probe
    return true[:3, 3] - meant[:3, 3]


def program_path(desc: RobotDescription, file: str | Path, speed_mm_s: float,
                 library: Sequence[str | Path] = ()) -> tuple[Array, Trajectory]:
    """The controller's own program from a file: where it starts and its motion.

    A ``.pdl`` file is a robot program whose straight moves make the path
    (:func:`~plugcell.sim.path_program.path_of_program`, run on a recorder; every
    segment at ``speed_mm_s``); any other file is a path file, ``plugcell path run
    --path``'s CSV (:func:`~plugcell.io.path_files.read_path`; ``speed_mm_s`` where a row
    gives none).  Both are planned as ``plugcell path run`` plans them
    (:func:`~plugcell.sim.path_run.plan_path`: the nominal inverse kinematics of the first
    point, LIN moves through the others at each segment's speed).

    Parameters
    ----------
    desc : RobotDescription
        The robot (its nominal model is the controller's).
    file : str or Path
        The path file or robot program.
    speed_mm_s : float
        The TCP speed where the file gives none (mm/s).
    library : sequence of str or Path
        Folders of the libraries a robot program imports.

    Returns
    -------
    ndarray, shape (6,)
        The joints at the first point (rad): where the arm stands at the start.
    Trajectory
        The program.

    Raises
    ------
    ValueError
        A file that does not read (its name, the line and why), a program that fails, a
        point out of reach or a move the planner refuses (the line and why).
    """
    from plugcell.io.path_files import read_path
    from plugcell.sim.path_program import path_of_program
    from plugcell.sim.path_run import plan_path

    name = str(file)
    try:
        path = (path_of_program(file, desc, speed_mm_s, library)[0] if name.endswith(".pdl")
                else read_path(file, speed_mm_s=speed_mm_s))
    except OSError as exc:
        raise ValueError(f"{name}: cannot read: {exc.strerror or exc}") from None
    try:
        q0, trajectory = plan_path(desc, path)
    except ValueError as exc:
        raise ValueError(f"{name}: {exc}") from None
    return np.asarray(q0, dtype=float), trajectory
