"""Program filtering: an offline robot program's Cartesian targets → compensated joints.

This is what a user does with a calibrated robot before sending an offline program to
a controller whose kinematic model cannot be changed (thesis 4.2.1.3: "modification
is not allowable. Error compensation thereby is usually done by means of software"):
every Cartesian target is replaced by the joint target that the identified model
says reaches it (6.5.1).

A target is a position (metres) and an orientation (radians) in one of the angle
conventions of :mod:`plugcell.kinematics.rotations` — Comau Euler ``"zyz"`` (A, B, C,
eq. A.4) or roll-pitch-yaw ``"rpy"`` — expressed in the robot base frame or in a
*user frame* (a Comau ``$UFRAME``: the user frame's pose in the robot base frame,
``T_robot = UFRAME · T_user``).  The targets are tool-point poses, see
:mod:`plugcell.compensation.pose_model`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from plugcell.compensation.model_based import (
    MAX_ITERATIONS,
    TOLERANCE,
    CompensationResult,
    compensate,
)
from plugcell.compensation.pose_model import NominalModel, PoseModel
from plugcell.kinematics.description import RobotDescription
from plugcell.kinematics.rotations import matrix_to_angles, pose_to_matrix

Array = NDArray[np.float64]

__all__ = ["CommandedPoses", "commanded_poses", "filter_program", "frame_matrix",
           "joint_program", "target_poses"]


def frame_matrix(xyz: ArrayLike, angles: ArrayLike, convention: str = "zyz") -> Array:
    """A frame (e.g. a user frame) from its position and angles, ``T = [R(angles) xyz; 0 1]``.

    Parameters
    ----------
    xyz : (3,) array_like, m
        Origin.
    angles : (3,) array_like, rad
        Orientation in ``convention``.
    convention : str
        ``"zyz"`` (Comau A, B, C, eq. A.4), ``"rpy"``, … (:mod:`plugcell.kinematics.rotations`).

    Returns
    -------
    (4, 4) array, m
        The frame.

    Raises
    ------
    ValueError
        Wrong shapes, non-finite values or an unknown convention.
    """
    xyz = np.asarray(xyz, dtype=float)
    angles = np.asarray(angles, dtype=float)
    if xyz.shape != (3,) or angles.shape != (3,):
        raise ValueError("a frame needs 3 coordinates and 3 angles")
    if not (np.all(np.isfinite(xyz)) and np.all(np.isfinite(angles))):
        raise ValueError("frame values must be finite")
    return pose_to_matrix(xyz, angles, convention)


def target_poses(
    positions: ArrayLike,
    angles: ArrayLike,
    convention: str = "zyz",
    user_frame: ArrayLike | None = None,
) -> Array:
    """Program targets → poses in the robot base frame, ``T = UFRAME · [R(angles) p; 0 1]``.

    Parameters
    ----------
    positions : (N, 3) array_like, m
        Target positions (in the user frame if given).
    angles : (N, 3) array_like, rad
        Target orientations in ``convention``.
    convention : str
        Angle convention (``"zyz"``, ``"rpy"``, …).
    user_frame : (4, 4) array_like, m, optional
        UFRAME, the user frame in the robot base frame (default: identity).

    Returns
    -------
    (N, 4, 4) array, m
        Tool-point poses in the robot base frame.

    Raises
    ------
    ValueError
        Wrong shapes, non-finite values, an unknown convention or a bad user frame.
    """
    p = np.atleast_2d(np.asarray(positions, dtype=float))
    a = np.atleast_2d(np.asarray(angles, dtype=float))
    if p.shape[-1] != 3 or a.shape != p.shape or p.ndim != 2:
        raise ValueError(f"positions and angles must both be (N, 3), got {p.shape} and {a.shape}")
    if not (np.all(np.isfinite(p)) and np.all(np.isfinite(a))):
        raise ValueError("target values must be finite")
    T = pose_to_matrix(p, a, convention)
    if user_frame is not None:
        U = np.asarray(user_frame, dtype=float)
        if U.shape != (4, 4) or not np.all(np.isfinite(U)):
            raise ValueError(f"user_frame: expected a finite 4x4 transform, got {U.shape}")
        T = U @ T
    return T


def filter_program(
    model: PoseModel,
    positions: ArrayLike,
    angles: ArrayLike,
    convention: str = "zyz",
    *,
    user_frame: ArrayLike | None = None,
    payload_kg: ArrayLike | float = 0.0,
    seed: ArrayLike | None = None,
    tol: float = TOLERANCE,
    max_iterations: int = MAX_ITERATIONS,
    raise_errors: bool = True,
) -> CompensationResult:
    """Compensated joint targets for a program's Cartesian targets (module docstring).

    Nominal IK (the controller's ``POS_TO_JNTP``) then 6.5.1 on ``model``, vectorised
    over the targets: ``q ← q + J⁻¹ e(T_target, T_model(q))`` (eq. 4.11) until
    ``‖Δx‖ < tol``.

    Parameters
    ----------
    model : PoseModel
        The identified model.
    positions : (N, 3) array_like, m
        Target positions.
    angles : (N, 3) array_like, rad
        Target orientations in ``convention``.
    convention : str
        Angle convention (``"zyz"``, ``"rpy"``, …).
    user_frame : (4, 4) array_like, m, optional
        UFRAME the targets are given in.
    payload_kg : float or (N,) array_like, kg
        Payload per target or one for all.
    seed : (n,) or (N, n) array_like, rad, optional
        Start of the nominal IK.
    tol : float
        Convergence tolerance on ‖Δx‖ (m and rad).
    max_iterations : int
        Iteration bound.
    raise_errors : bool
        With ``False`` the failing targets are marked in the result.

    Returns
    -------
    CompensationResult
        Compensated joint readings ``(N, n)``, rad.

    Raises
    ------
    ValueError
        Malformed targets (see :func:`target_poses`).
    CompensationError
        For the first failing target (unless ``raise_errors=False``).
    """
    T = target_poses(positions, angles, convention, user_frame)
    return compensate(model, T, payload_kg, seed=seed, tol=tol, max_iterations=max_iterations,
                      raise_errors=raise_errors)


@dataclass(frozen=True, eq=False)
class CommandedPoses:
    """Compensated targets of a Cartesian program, as poses to give the controller.

    Attributes
    ----------
    result : CompensationResult
        The compensation of every target (``q``: the joints the robot must reach).
    T_command : (N, 4, 4) array, m
        The pose to command in the robot base frame: the controller's nominal model at
        the compensated joints, ``T_cmd = T_nominal(q) · TOOL`` — its own inverse
        kinematics of ``T_cmd`` gives back ``q``, where the identified model reaches the
        target.
    """

    result: CompensationResult
    T_command: Array


def commanded_poses(
    model_for_tool: Callable[[Array], PoseModel],
    T_target: ArrayLike,
    tool_index: ArrayLike,
    tools: ArrayLike,
    payload_kg: ArrayLike | float = 0.0,
    *,
    seed: ArrayLike | None = None,
    tol: float = TOLERANCE,
    max_iterations: int = MAX_ITERATIONS,
) -> CommandedPoses:
    """Compensate Cartesian targets with their tools and turn them back into poses.

    Per tool ``k`` the targets ``i`` with ``tool_index[i] = k`` are compensated as
    ``plugcell compensate --tool`` does — :func:`compensate` on ``model_for_tool(TOOL_k)``
    — and the commanded pose is the nominal model at the compensated joints,
    ``T_cmd = T_nominal(q) · TOOL_k`` (:class:`~plugcell.compensation.pose_model.NominalModel`,
    the controller's own model, whose inverse kinematics started
    the compensation).  Failing targets keep ``T_cmd = T_target``.

    Parameters
    ----------
    model_for_tool : callable
        ``TOOL (4, 4) m → PoseModel`` (the identified model with that tool point).
    T_target : (N, 4, 4) array_like, m
        Target tool poses in the robot base frame.
    tool_index : (N,) array_like of int
        Each target's tool, an index into ``tools``.
    tools : (K, 4, 4) array_like, m
        Tools: the TCP in the flange frame.
    payload_kg : float or (N,) array_like, kg
        Payload.
    seed : (N, n) array_like, rad, optional
        Seeds of the nominal inverse kinematics (default: the description's home, as
        ``plugcell compensate``), e.g. to take the arm configuration a program names.
    tol, max_iterations
        As :func:`compensate`.

    Returns
    -------
    CommandedPoses
        Result and commanded poses, in the targets' order.

    Raises
    ------
    ValueError
        Malformed targets, tools or indices.
    """
    T = np.asarray(T_target, dtype=float).reshape(-1, 4, 4)
    N = T.shape[0]
    idx = np.asarray(tool_index, dtype=int).reshape(-1)
    tl = np.asarray(tools, dtype=float).reshape(-1, 4, 4)
    if idx.shape != (N,) or (N and (idx.min() < 0 or idx.max() >= tl.shape[0])):
        raise ValueError(f"tool_index: expected {N} indices into {tl.shape[0]} tools")
    m = np.broadcast_to(np.asarray(payload_kg, dtype=float), (N,))
    parts: list[tuple[Array, CompensationResult, Array]] = []
    for k in np.unique(idx):
        sel = np.flatnonzero(idx == k)
        model = model_for_tool(tl[k])
        sd = None if seed is None else np.asarray(seed, dtype=float)[sel]
        res = compensate(model, T[sel], m[sel], seed=sd, tol=tol,
                         max_iterations=max_iterations, raise_errors=False)
        Tc = NominalModel(model.description, tl[k]).pose(res.q)
        Tc[~res.ok] = T[sel][~res.ok]
        parts.append((sel, res, Tc))
    return CommandedPoses(_merge(parts, N), _stack(parts, N))


def _stack(parts: list[tuple[Array, CompensationResult, Array]], N: int) -> Array:
    out = np.empty((N, 4, 4))
    for sel, _, Tc in parts:
        out[sel] = Tc
    return out


def _merge(parts: list[tuple[Array, CompensationResult, Array]], N: int) -> CompensationResult:
    """One :class:`CompensationResult` in target order from the per-tool ones."""
    if not parts:
        e = np.empty((0, 0))
        return CompensationResult(q=e, q_start=e, converged=np.zeros(0, bool),
                                  within_limits=np.zeros(0, bool), iterations=np.zeros(0, int),
                                  residual=np.zeros(0), position_error=np.zeros(0),
                                  orientation_error=np.zeros(0),
                                  reason=np.zeros(0, object), kind=np.zeros(0, object))
    fields = ("q", "q_start", "converged", "within_limits", "iterations", "residual",
              "position_error", "orientation_error", "reason", "kind")
    out: dict[str, Any] = {}
    for f in fields:
        first = getattr(parts[0][1], f)
        arr = np.empty((N, *first.shape[1:]), dtype=first.dtype)
        for sel, res, _ in parts:
            arr[sel] = getattr(res, f)
        out[f] = arr
    hf = [r.hybrid_fallback for _, r, _ in parts]
    if all(h is not None for h in hf):
        h = np.zeros(N, bool)
        for (sel, _, _), x in zip(parts, hf, strict=True):
            h[sel] = x
        out["hybrid_fallback"] = h
    return CompensationResult(**out)


def joint_program(
    result: CompensationResult,
    description: RobotDescription | None = None,
    *,
    degrees: bool = True,
) -> Array:
    """The compensated joint targets to send, in degrees by default (a controller's joint
    positions).

    With ``degrees``, a revolute reading is converted ``q_deg = q · 180/π`` and a
    prismatic reading (a linear axis, :attr:`RobotDescription.prismatic_readings`) is
    left in metres — the units of a description file,
    ``q / RobotDescription.reading_scale("file")``.

    Parameters
    ----------
    result : CompensationResult
        The compensation; ``result.q`` ``(N, n_readings)``, rad (m for a prismatic joint).
    description : RobotDescription, optional
        The robot the joints belong to (``model.description``), which says which readings
        are prismatic.  Without it every reading is taken as an angle: give it for a
        robot with a linear axis.
    degrees : bool
        Convert the revolute readings from rad to degrees.

    Returns
    -------
    (N, n_readings) array, deg and m (or rad and m)
        Joint targets (a copy).

    Raises
    ------
    ValueError
        ``description`` has another number of readings than ``result.q`` has columns.
    """
    q = np.array(result.q, dtype=float)
    if not degrees:
        return q
    if description is None:
        return np.degrees(q)
    if description.n_readings != q.shape[-1]:
        raise ValueError(
            f"{description.name} has {description.n_readings} joint readings, "
            f"the program {q.shape[-1]}"
        )
    return q / description.reading_scale("file")


def pose_angles(T: ArrayLike, convention: str = "zyz") -> Array:
    """Angles of poses — the inverse of :func:`target_poses`' rotation.

    Parameters
    ----------
    T : (N, 4, 4) array_like
        Poses.
    convention : str
        Angle convention.

    Returns
    -------
    (N, 3) array, rad
        Angle triples.
    """
    return matrix_to_angles(np.asarray(T, dtype=float)[..., :3, :3], convention)
