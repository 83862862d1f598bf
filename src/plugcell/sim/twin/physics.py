"""Static physics of the simulated robot: gravity, joint compliance, link bending.

This is the *truth* the calibration models approximate, so it is computed from
first principles rather than from the thesis's error model:

* **Gravity torques** at the actuated joints are the negative gradient of the
  potential energy ``V(q) = g Σ m_k z_k(q)`` of every link mass, point mass
  (counterweight) and payload, taken through the *exact* loop closure — the
  principle of virtual work: each joint's torque from the masses it carries, a
  passive joint's passed to the actuated ones by the closure's derivatives.  For the
  parallelogram this yields the joint-2/2' torques of thesis eqs. (6.28)–(6.30) and
  (6.38) without writing them down; the tests check it against central differences
  of :func:`potential_energy`.
* **Joint compliance**: a joint's link side yields to its torque through the
  gearbox stiffness k_i:  θ_link = θ_motor + τ_i / k_i  (thesis eq. 4.15).  The
  torque depends on the deflected pose, so the deflection is a fixed point,
  solved by iteration.
* **Gear transmission error** (not in the thesis's model): a reducer's output
  lags or leads its input by a small periodic function of the output angle —
  eccentricities at once and twice per revolution, a tooth/cycloid-stage order
  higher up.  RV and harmonic reducers of this class are specified at ≤ 1 arcmin
  angular transmission error; the twin draws each joint's harmonics once, from
  its seed.
* **Link bending** (an effect the thesis's model does not capture, 8.2.3): a beam
  link carrying the masses beyond it bends like a cantilever with a tip load: its
  end rotates by φ = c_b · M⊥ and moves by (2/3) φ × L.  The ratio of displacement
  to rotation differs from a joint rotation's, so no joint-compliance parameter
  can absorb it.

Everything is vectorised over configurations ``(..., n)``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from plugcell.kinematics import FKResult, GeometricParameters, RobotDescription, forward
from plugcell.kinematics.transforms import cross

Array = NDArray[np.float64]

GRAVITY = 9.81
#: Gravity in the robot base frame (floor-mounted robot, z0 up).
GRAVITY_VECTOR = np.array([0.0, 0.0, -GRAVITY])


@dataclass(frozen=True)
class Payload:
    """A dead weight on the flange: ``mass`` (kg), centre of mass ``com`` (m, flange frame)."""

    mass: float = 0.0
    com: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        if not (np.isfinite(self.mass) and self.mass >= 0):
            raise ValueError(f"payload mass must be ≥ 0 kg, got {self.mass!r}")
        if len(self.com) != 3 or not np.all(np.isfinite(self.com)):
            raise ValueError(f"payload com must be 3 finite numbers, got {self.com!r}")


@dataclass(frozen=True)
class Beam:
    """A link that bends: ``link`` is the beam from its parent frame to its own frame;
    the frames from the chain link ``carries`` onward ride on its tip and load it.
    ``compliance`` is the tip rotation per bending moment (rad/(N·m))."""

    link: str
    carries: str
    compliance: float


def _masses(desc: RobotDescription) -> tuple[Array, Array, Array]:
    """(frame index, mass, com in that frame) of every lumped mass of the robot."""
    idx, mass, com = [], [], []
    for i, lk in enumerate(desc.links):
        if lk.mass > 0:
            idx.append(i)
            mass.append(lk.mass)
            com.append(lk.com)
    for pm in desc.point_masses:
        if pm.mass > 0:
            idx.append(desc.index(pm.link))
            mass.append(pm.mass)
            com.append(pm.com)
    return np.array(idx, dtype=int), np.array(mass), np.array(com, dtype=float).reshape(-1, 3)


def potential_energy(desc: RobotDescription, params: GeometricParameters, q: Array,
                     payload: Payload = Payload()) -> Array:
    """``V(q) = g Σ_k m_k z_k(q)`` (J): every link mass, point mass and the payload at
    the heights the exact four-bar closure puts them, for joint readings ``q`` ``(..., n)``;
    returns ``(...)``."""
    fk = forward(desc, params, np.asarray(q, dtype=float), closure="fourbar")
    points, mass, _ = _mass_points(desc, fk, payload)
    return GRAVITY * (points[..., 2] * mass).sum(axis=-1)


def _mass_points(desc: RobotDescription, fk: FKResult, payload: Payload
                 ) -> tuple[Array, Array, Array]:
    """Every lumped mass (the payload last): its position ``(..., M, 3)`` (m, robot base
    frame), mass ``(M,)`` (kg) and link ``(M,)`` (position in ``desc.links``)."""
    idx, mass, com = _masses(desc)
    F = np.take(fk.frames, idx, axis=-3)
    points = (F[..., :3, :3] @ com[..., None])[..., 0] + F[..., :3, 3]
    if payload.mass > 0:
        flange = fk.flange
        p = flange[..., :3, :3] @ np.asarray(payload.com, dtype=float) + flange[..., :3, 3]
        points = np.concatenate([points, p[..., None, :]], axis=-2)
        mass = np.r_[mass, payload.mass]
        idx = np.r_[idx, desc.index(desc.flange)]
    return points, mass, idx


def _carried(desc: RobotDescription, links: Array) -> Array:
    """``(n_links, M)``: 1 where mass ``k`` (on link ``links[k]``) rides on link ``i``'s
    joint — on link ``i`` itself or beyond it."""
    parents = desc.parent_indices
    carried = np.zeros((desc.n_links, len(links)))
    for k, link in enumerate(links):
        i = int(link)
        while i >= 0:
            carried[i, k] = 1.0
            i = parents[i]
    return carried


def gravity_torques(desc: RobotDescription, params: GeometricParameters, q: Array,
                    payload: Payload = Payload()) -> Array:
    """τ = −∂V/∂q at the actuated joints (N·m; N for a prismatic one), by the principle
    of virtual work.

    Joint ``i`` turns about its parent frame's ``z_{i−1}`` through ``o_{i−1}`` (DH) and
    carries the masses on its link and beyond (forces ``f_k = m_k g``, g down the robot
    base frame's z, at ``p_k``)::

        τ_i = z_{i−1} · Σ_k (p_k − o_{i−1}) × f_k        (revolute)
        τ_i = z_{i−1} · Σ_k f_k                           (prismatic)

    A loop's passive joints pass theirs to the actuated ones through the exact closure's
    derivatives, ``τ_kin = τ_actuated + (∂θ_passive/∂θ_kin)ᵀ τ_passive``, and a joint
    coupling ``θ_kin = M q + c`` to the readings, ``τ_q = Mᵀ τ_kin``.  Equal to the
    central differences of :func:`potential_energy` (tests).

    Parameters
    ----------
    desc : RobotDescription
    params : GeometricParameters
    q : (..., n_readings) array, rad (m for a prismatic joint)
    payload : Payload

    Returns
    -------
    (..., n_readings) array
    """
    q = np.asarray(q, dtype=float)
    fk = forward(desc, params, q, closure="fourbar")
    points, mass, links = _mass_points(desc, fk, payload)
    force = mass[:, None] * GRAVITY_VECTOR  # (M, 3)
    carried = _carried(desc, links)
    total = carried @ force  # (n_links, 3): the force each joint carries
    moment = np.einsum("lm,...mc->...lc", carried, cross(points, force))
    base = np.broadcast_to(np.eye(4), (*fk.frames.shape[:-3], 1, 4, 4))
    parent = np.take(np.concatenate([fk.frames, base], axis=-3),
                     list(desc.parent_indices), axis=-3)  # −1: the base, appended last
    z, o = parent[..., :3, 2], parent[..., :3, 3]
    prismatic = np.array([lk.is_prismatic for lk in desc.links])
    tau = np.where(prismatic, (z * total).sum(axis=-1),
                   (z * (moment - cross(o, total))).sum(axis=-1))  # (..., n_links)
    tau_kin = np.take(tau, [desc.index(n) for n in desc.actuated], axis=-1)
    if desc.loops:
        passive = [i for (_, _, i3, i4, _, _) in desc.loop_indices for i in (i3, i4)]
        tau_kin = tau_kin + np.einsum("...p,...pa->...a", np.take(tau, passive, axis=-1),
                                      fk.passive_jacobian)
    return tau_kin if desc.coupling is None else tau_kin @ desc.coupling.matrix


def deflected_joints(desc: RobotDescription, params: GeometricParameters, q_motor: Array,
                     stiffness: Array, payload: Payload = Payload(),
                     iterations: int = 3) -> Array:
    """Link-side joint angles under gravity: the fixed point θ = θ_m + K⁻¹ τ(θ) (eq. 4.15)."""
    q_motor = np.asarray(q_motor, dtype=float)
    compliance = 1.0 / np.asarray(stiffness, dtype=float)
    q = q_motor
    for _ in range(iterations):
        q = q_motor + compliance * gravity_torques(desc, params, q, payload)
    return q


@dataclass(frozen=True)
class TransmissionError:
    """Periodic reducer error per actuated joint: Σ_h A[j,h] sin(n_h θ_j + φ[j,h]) (rad)."""

    orders: tuple[int, ...]
    amplitude: Array  # (n_joints, n_orders) rad
    phase: Array  # (n_joints, n_orders) rad

    def __call__(self, q: Array) -> Array:
        q = np.asarray(q, dtype=float)
        n = np.asarray(self.orders, dtype=float)
        return (self.amplitude * np.sin(q[..., :, None] * n + self.phase)).sum(axis=-1)


def _rotation(phi: Array) -> Array:
    """Rodrigues' formula, vectorised: rotation matrices (..., 3, 3) of vectors phi (..., 3)."""
    theta = np.linalg.norm(phi, axis=-1)[..., None, None]
    safe = np.where(theta > 1e-300, theta, 1.0)
    k = phi / safe[..., 0]
    K = np.zeros((*phi.shape[:-1], 3, 3))
    K[..., 0, 1], K[..., 0, 2] = -k[..., 2], k[..., 1]
    K[..., 1, 0], K[..., 1, 2] = k[..., 2], -k[..., 0]
    K[..., 2, 0], K[..., 2, 1] = -k[..., 1], k[..., 0]
    eye = np.broadcast_to(np.eye(3), K.shape)
    return eye + np.sin(theta) * K + (1 - np.cos(theta)) * (K @ K)


def bending(desc: RobotDescription, frames: Array, flange: Array, beams: Sequence[Beam],
            payload: Payload = Payload()) -> Array:
    """Rigid motion (..., 4, 4) of the flange caused by the bending of ``beams``.

    For each beam, the bending moment at its root is that of the masses it carries
    (chain links from ``carries`` onward, their point masses, the payload); its
    component perpendicular to the beam bends it.  Returns ``D`` such that the
    bent flange is ``D @ flange``.
    """
    chain = [desc.link_names[i] for i in desc.chain]
    idx_all, mass_all, com_all = _masses(desc)
    D = np.broadcast_to(np.eye(4), flange.shape).copy()
    for beam in beams:
        if beam.carries not in chain:
            raise ValueError(f"beam {beam.link!r}: {beam.carries!r} is not on the flange chain")
        carried = {desc.index(n) for n in chain[chain.index(beam.carries):]}
        sel = np.array([i in carried for i in idx_all], dtype=bool)
        root = frames[..., desc.index(desc.link(beam.link).parent), :3, 3] \
            if desc.link(beam.link).parent != "base" else np.zeros((*flange.shape[:-2], 3))
        tip = frames[..., desc.index(beam.link), :3, 3]
        moment = np.zeros((*flange.shape[:-2], 3))
        if sel.any():
            i, m, c = idx_all[sel], mass_all[sel], com_all[sel]
            F = np.take(frames, i, axis=-3)
            r = (F[..., :3, :3] @ c[..., None])[..., 0] + F[..., :3, 3]
            forces = m[:, None] * GRAVITY_VECTOR
            moment = moment + cross(r - root[..., None, :], forces).sum(axis=-2)
        if payload.mass > 0:
            rp = (flange[..., :3, :3] @ np.asarray(payload.com)) + flange[..., :3, 3]
            moment = moment + cross(rp - root, payload.mass * GRAVITY_VECTOR)
        length = tip - root
        u = length / np.linalg.norm(length, axis=-1, keepdims=True)
        m_perp = moment - (moment * u).sum(axis=-1, keepdims=True) * u
        phi = beam.compliance * m_perp
        delta = (2.0 / 3.0) * cross(phi, length)
        R = _rotation(phi)
        step = np.broadcast_to(np.eye(4), flange.shape).copy()
        step[..., :3, :3] = R
        # x' = tip + delta + R (x - tip)
        step[..., :3, 3] = tip + delta - (R @ tip[..., None])[..., 0]
        D = step @ D
    return D
