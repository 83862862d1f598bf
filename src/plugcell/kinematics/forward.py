"""Forward kinematics through closed loops, thesis eqs. (6.1)–(6.3).

``forward(desc, params, q)`` evaluates every link frame in the robot base frame
F0 for joint readings ``q`` (``(..., n_readings)``, radians, in the
description's reading order — its ``actuated`` order unless it has a
``coupling``, whose kinematic joints ``θ_kin = M·q + offset`` are what the DH
rows then see, :meth:`RobotDescription.kinematic_joints`).  Each link frame is
its parent's frame times the DH + Hayati link transform (B.1) with the numbers
of ``params`` (never the description's), so every parameter acts on FK.  The
passive angles of each loop come from the closure
(:mod:`plugcell.kinematics.closure`), and the flange pose is taken along the
chain through the loop — for the Smart H4 the branch (1-2'-3'-4'-3) of eq.
(6.2), which carries the loop parameters — while the arm (link 2, off the
chain) is evaluated too, so branch (1-2-3) of eq. (6.3) can be compared
(:func:`branch_cut_transform`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from plugcell.kinematics.closure import fourbar_closure, nominal_closure
from plugcell.kinematics.description import RobotDescription
from plugcell.kinematics.parameters import GeometricParameters
from plugcell.kinematics.transforms import dh_hayati, rot_z

Array = NDArray[np.float64]

CLOSURES: tuple[str, ...] = ("fourbar", "nominal")

__all__ = [
    "CLOSURES",
    "FKResult",
    "branch_cut_transform",
    "compose_frames",
    "forward",
    "joint_angles",
    "link_lengths",
]


@dataclass(frozen=True, eq=False)
class FKResult:
    """Result of :func:`forward` for a batch of configurations (shape ``(...)``).

    Attributes
    ----------
    link_names : tuple of str
        Link names, the order of ``frames`` and ``theta``.
    passive_names : tuple of str
        Passive link names, the order of ``passive``.
    frames : (..., n_links, 4, 4) array, m
        Every link frame ``F_i = F_parent(i) · A_i`` in the robot base frame F0
        (off-chain links such as the Smart H4's arm "2" included).
    theta : (..., n_links) array, rad
        The DH angle θ_i each link used.
    passive : (..., n_passive) array, rad
        Passive angles in ``passive_names`` order.
    passive_jacobian : (..., n_passive, n_actuated) array, rad/rad
        ``∂θ_passive/∂θ_kin``, w.r.t. the kinematic joints (the readings when the
        description has no coupling).
    passive_d_a : (..., n_passive, n_links) array, rad/m
        ``∂θ_passive/∂a_link`` (four-bar only; zeros for the nominal closure).
    flange : (..., 4, 4) array, m
        ``T_n^0`` (eq. 6.1) in the robot base frame.
    tcp : (..., 4, 4) array, m
        ``flange · tool`` in the robot base frame.
    world_flange, world_tcp : (..., 4, 4) array, m
        ``base · flange`` and ``base · tcp`` in the world/metrology frame (eq. 6.23
        with PROBE = tool).
    valid : (...) bool array
        False where a loop could not close (only possible with
        ``forward(..., raise_errors=False)``; frames there are NaN).
    """

    link_names: tuple[str, ...]
    passive_names: tuple[str, ...]
    frames: Array
    theta: Array
    passive: Array
    passive_jacobian: Array
    passive_d_a: Array
    flange: Array
    tcp: Array
    world_flange: Array
    world_tcp: Array
    valid: NDArray[np.bool_]

    def index(self, name: str) -> int:
        """Position of link ``name`` in ``frames``/``theta``.

        Parameters
        ----------
        name : str
            A link name.

        Returns
        -------
        int
            Its index along the ``n_links`` axis.

        Raises
        ------
        KeyError
            Unknown link.
        """
        try:
            return self.link_names.index(name)
        except ValueError:
            raise KeyError(f"unknown link {name!r}; links are {list(self.link_names)}") from None

    def frame(self, name: str) -> Array:
        """Frame ``F_name`` of one link in the robot base frame (``"base"``: F0 = I).

        Parameters
        ----------
        name : str
            A link name, or ``"base"``.

        Returns
        -------
        (..., 4, 4) array, m
            The link frame for every configuration.

        Raises
        ------
        KeyError
            Unknown link.
        """
        if name == "base":
            return np.broadcast_to(np.eye(4), self.flange.shape).copy()
        return self.frames[..., self.index(name), :, :]

    def passive_angle(self, name: str) -> Array:
        """Closure angle of one passive link (θ3' or θ4' of eq. 6.10 / appendix C).

        Parameters
        ----------
        name : str
            A passive link name.

        Returns
        -------
        (...) array, rad
            Its angle for every configuration.

        Raises
        ------
        KeyError
            ``name`` is not a passive link.
        """
        try:
            k = self.passive_names.index(name)
        except ValueError:
            raise KeyError(
                f"{name!r} is not a passive link; they are {list(self.passive_names)}"
            ) from None
        return self.passive[..., k]


def _check_q(desc: RobotDescription, q: ArrayLike) -> Array:
    q = np.asarray(q, dtype=float)
    if q.ndim == 0 or q.shape[-1] != desc.n_readings:
        raise ValueError(
            f"q: expected shape (..., {desc.n_readings}) for joints {list(desc.reading_names)}, "
            f"got {q.shape}"
        )
    if not np.all(np.isfinite(q)):
        raise ValueError("q: joint values must be finite")
    return q


def _check_params(
    desc: RobotDescription, params: GeometricParameters | None
) -> GeometricParameters:
    if params is None:
        return desc.nominal_parameters()
    if params.link_names != desc.link_names:
        raise ValueError(
            f"params: link names {list(params.link_names)} do not match the description's "
            f"{list(desc.link_names)}"
        )
    return params


def _close_loops(
    desc: RobotDescription, p: GeometricParameters, theta: Array, closure: str,
    raise_errors: bool,
) -> tuple[Array, Array, Array, NDArray[np.bool_]]:
    """Close every parallelogram loop: its passive angles and their derivatives (eq. 6.10).

    For loop ``k`` with links (arm ``a``, crank ``c``, coupler 3, follower 4) the closure
    gives ``(θ_3, θ_4) = f(θ_a, θ_c; a_a, a_c, a_3, a_4)``
    (:func:`~plugcell.kinematics.closure.fourbar_closure`, or
    :func:`~plugcell.kinematics.closure.nominal_closure`); they are added to
    ``theta[..., 3]`` and ``theta[..., 4]`` in place.

    Parameters
    ----------
    desc : RobotDescription
    p : GeometricParameters
    theta : (..., n_links) array, rad
        DH angles with the actuated joints in; the passive ones are added (in place).
    closure : {"fourbar", "nominal"}
    raise_errors : bool

    Returns
    -------
    passive : (..., n_p) array, rad
        ``(θ_3, θ_4)`` of every loop, ``n_p = 2·loops``.
    d_passive_dθkin : (..., n_p, n_actuated) array, rad/rad
        ``∂(θ_3, θ_4)/∂(θ_a, θ_c)`` in the columns of the loop's arm and crank.
    d_passive_da : (..., n_p, n_links) array, rad/m
        ``∂(θ_3, θ_4)/∂(a_a, a_c, a_3, a_4)``.
    valid : (...) bool array
        False where a loop could not close.
    """
    batch = theta.shape[:-1]
    n_l, n_a = desc.n_links, desc.n_actuated
    n_p = 2 * len(desc.loops)
    passive = np.zeros((*batch, n_p))
    dq = np.zeros((*batch, n_p, n_a))
    da = np.zeros((*batch, n_p, n_l))
    valid = np.ones(batch, dtype=bool)
    for k, (ia, ic, i3, i4, ja, jc) in enumerate(desc.loop_indices):
        ta, tc = theta[..., ia], theta[..., ic]
        if closure == "nominal":
            res = nominal_closure(ta, tc, raise_errors=raise_errors)
        else:
            res = fourbar_closure(
                ta, tc, p.a[ia], p.a[ic], p.a[i3], p.a[i4], raise_errors=raise_errors
            )
        valid &= res.valid
        passive[..., 2 * k] = res.coupler
        passive[..., 2 * k + 1] = res.follower
        theta[..., i3] += res.coupler
        theta[..., i4] += res.follower
        dq[..., 2 * k : 2 * k + 2, [ja, jc]] = res.d_driven
        da[..., 2 * k : 2 * k + 2, [ia, ic, i3, i4]] = res.d_lengths
    return passive, dq, da, valid


def joint_angles(
    desc: RobotDescription,
    params: GeometricParameters | None,
    q: ArrayLike,
    closure: str = "fourbar",
    *,
    raise_errors: bool = True,
) -> tuple[Array, Array, Array, Array, NDArray[np.bool_]]:
    """DH angles of every link for joint readings ``q``.

    ``θ_i = θ_kin,j + theta_i`` for actuated link i (``θ_kin = desc.kinematic_joints(q)``,
    ``= M·q + offset`` with a coupling), ``θ_i = θ_closure + theta_i`` for passive
    links (:func:`~plugcell.kinematics.closure.fourbar_closure` or
    :func:`~plugcell.kinematics.closure.nominal_closure`, eq. 6.10), ``θ_i = theta_i``
    for fixed and prismatic ones (a prismatic reading moves ``d``: :func:`link_lengths`).

    Parameters
    ----------
    desc : RobotDescription
        The robot.
    params : GeometricParameters or None
        Geometric parameters; ``None``: the nominal ones.
    q : (..., n_readings) array_like, rad (m for prismatic)
        Joint readings.
    closure : {"fourbar", "nominal"}
        Loop closure to use.
    raise_errors : bool, default True
        With ``False``, configurations whose loop cannot close are flagged in
        ``valid`` (NaN angles) instead of raising.

    Returns
    -------
    theta : (..., n_links) array, rad
        DH angle of every link.
    passive : (..., n_p) array, rad
        Passive angles (two per loop: coupler, follower).
    d_passive_dθkin : (..., n_p, n_actuated) array, rad/rad
        ``∂θ_passive/∂θ_kin``.
    d_passive_da : (..., n_p, n_links) array, rad/m
        ``∂θ_passive/∂a``.
    valid : (...) bool array
        False where a loop could not close.

    Raises
    ------
    ValueError
        Unknown ``closure``, ``q`` of the wrong shape or not finite, or ``params`` for
        other links.
    LoopClosureError
        A loop cannot close (unless ``raise_errors=False``).
    """
    if closure not in CLOSURES:
        raise ValueError(f"closure must be one of {CLOSURES}, got {closure!r}")
    p = _check_params(desc, params)
    q = _check_q(desc, q)
    batch = q.shape[:-1]
    n_l = desc.n_links
    theta = np.broadcast_to(p.theta, (*batch, n_l)).copy()
    j, i = desc.revolute_links
    theta[..., i] += desc.kinematic_joints(q)[..., j]
    passive, dq, da, valid = _close_loops(desc, p, theta, closure, raise_errors)
    return theta, passive, dq, da, valid


def link_lengths(desc: RobotDescription, params: GeometricParameters, q: ArrayLike) -> Array:
    """DH offsets ``d`` of every link for joint readings ``q``.

    ``d_i = θ_kin,j + d_i`` for a prismatic link (its kinematic joint value, the
    reading itself without a coupling), ``d_i`` of ``params`` for the others.

    Parameters
    ----------
    desc : RobotDescription
        The robot.
    params : GeometricParameters
        Geometric parameters (``d`` in m).
    q : (..., n_readings) array_like, rad / m
        Joint readings (m for prismatic joints).

    Returns
    -------
    d : (..., n_links) array, m
        The offsets every link uses.
    """
    q = np.asarray(q, dtype=float)
    d = np.broadcast_to(params.d, (*q.shape[:-1], desc.n_links)).copy()
    prismatic = desc.prismatic_links
    if prismatic.any():
        q_kin = desc.kinematic_joints(q)
        for j, name in enumerate(desc.actuated):
            if prismatic[j]:
                d[..., desc.index(name)] += q_kin[..., j]
    return d


def compose_frames(desc: RobotDescription, params: GeometricParameters, theta: Array,
                   d: Array | None = None) -> Array:
    """Link frames in F0 from full DH angles: ``F_i = F_parent(i) · A_i(θ_i, d_i, a_i, α_i, β_i)``.

    ``A_i`` is the DH + Hayati link transform (eq. B.1); links are composed in
    description order (a parent precedes its children), the first from F0.

    Parameters
    ----------
    desc : RobotDescription
        The robot (link tree).
    params : GeometricParameters
        ``a, α, β`` (and ``d`` unless given) of every link, m and rad.
    theta : (..., n_links) array, rad
        Full DH angles (e.g. from :func:`joint_angles`).
    d : (..., n_links) array, m, optional
        DH offsets from :func:`link_lengths`; default: ``params.d``.

    Returns
    -------
    frames : (..., n_links, 4, 4) array, m
        Every link frame in the robot base frame F0.
    """
    local = dh_hayati(theta, params.d if d is None else d, params.a, params.alpha, params.beta)
    frames = np.empty_like(local)
    frames[..., 0, :, :] = local[..., 0, :, :]
    for i, parent in enumerate(desc.parent_indices[1:], start=1):
        np.matmul(frames[..., parent, :, :], local[..., i, :, :], out=frames[..., i, :, :])
    return frames


def forward(
    desc: RobotDescription,
    params: GeometricParameters | None,
    q: ArrayLike,
    closure: str = "fourbar",
    *,
    raise_errors: bool = True,
) -> FKResult:
    """Forward kinematics of every link, thesis eq. (6.1) via branch (6.2).

    Each link's frame is its parent's times its joint transform,
    ``T_i = T_parent(i) · A_i(θ_i)``, with ``A_i`` the DH (or Hayati) transform of the
    link's parameters; the flange is ``T_flange`` and the TCP ``T_flange · tool``.
    Passive joints of a four-bar loop take the angles that close it.

    Parameters
    ----------
    desc
        The robot.
    params
        The geometric parameters to use; ``None``: the nominal ones.
    q
        Joint readings, shape ``(..., n_readings)``, radians (metres for a prismatic
        joint); need not be wrapped, limits are not checked; a description's
        ``coupling`` maps them to its kinematic joints.
    closure
        ``"fourbar"`` (exact, default) or ``"nominal"`` (eq. 6.10, what a
        controller's nominal model does).
    raise_errors
        With ``False``, configurations whose loop cannot close are marked in
        ``FKResult.valid`` and filled with NaN instead of raising.

    Returns
    -------
    FKResult
        ``frames`` ``(..., n_links, 4, 4)``, ``flange`` and ``tcp`` ``(..., 4, 4)``,
        metres, in the robot base frame; the DH angles ``theta`` used; ``valid``
        (the class documents every field).

    Raises
    ------
    LoopClosureError
        A loop cannot be assembled or collapses (unless ``raise_errors=False``).
    """
    p = _check_params(desc, params)
    theta, passive, dq, da, valid = joint_angles(desc, p, q, closure, raise_errors=raise_errors)
    frames = compose_frames(desc, p, theta, link_lengths(desc, p, q) if desc.prismatic_links.any()
                            else None)
    flange = frames[..., desc.index(desc.flange), :, :]
    tcp = flange @ p.tool
    return FKResult(
        link_names=desc.link_names,
        passive_names=desc.passive,
        frames=frames,
        theta=theta,
        passive=passive,
        passive_jacobian=dq,
        passive_d_a=da,
        flange=flange,
        tcp=tcp,
        world_flange=p.base @ flange,
        world_tcp=p.base @ tcp,
        valid=valid,
    )


def branch_cut_transform(desc: RobotDescription, fk: FKResult, loop_index: int = 0) -> Array:
    """Frame of the follower's end computed along the *arm* branch, eq. (6.3).

    ``T = F_arm · Rz(φ4 − θ_arm)`` with ``φ4 = θ_crank + θ3' + θ4'`` the absolute
    direction of the follower's end frame: for a closed planar loop this equals the
    follower's frame computed along the crank branch (6.2), so ``frame(follower)``
    and this matrix agree (exactly for a parallelogram with any lengths the four-bar
    closes, only approximately when loop twists/β/d are perturbed).

    Parameters
    ----------
    desc : RobotDescription
        The robot.
    fk : FKResult
        Forward kinematics of ``desc``.
    loop_index : int, default 0
        Which loop of ``desc.loops``.

    Returns
    -------
    T : (..., 4, 4) array, m
        The follower's end frame along branch (1-2-3), in the robot base frame.
    """
    loop = desc.loops[loop_index]
    ia, ic, i3, i4 = (desc.index(n) for n in loop.links)
    phi4 = fk.theta[..., ic] + fk.theta[..., i3] + fk.theta[..., i4]
    return fk.frames[..., ia, :, :] @ rot_z(phi4 - fk.theta[..., ia])
