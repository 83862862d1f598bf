"""Cartesian (LIN, CIRC) moves of the TCP: geometry, time law and their superposition.

Move ``k`` goes from pose ``(p_s, R_s)`` to ``(p_e, R_e)`` with a path fraction
``σ ∈ [0, 1]`` (a double-S time law, :mod:`plugcell.motion.profile`):

* **LIN**: ``p(σ) = p_s + σ·(p_e − p_s)``, length ``L = ‖p_e − p_s‖``;
* **CIRC** through ``p_v``: the circle through the three points, centre ``c``, radius
  ``ρ``, in-plane unit vectors ``u = (p_s − c)/ρ`` and ``w = n × u`` (``n`` the normal
  that makes ``p_s → p_v → p_e`` turn positively), swept angle ``Φ`` to ``p_e``:
  ``p(σ) = c + ρ·(cos(Φσ)·u + sin(Φσ)·w)``, length ``L = ρΦ``;
* **orientation** by slerp: ``R(σ) = exp(σθ·[k]×)·R_s`` with ``θ·k = log(R_e R_sᵀ)``
  (``k`` a unit axis in the base frame, ``θ ∈ [0, π]``) — the same rotations as the
  quaternion slerp ``q_s (q_s⁻¹ q_e)^σ``, the shortest way round.

One time law drives both: ``σ``'s limits are the tightest of the translation's
(``L·σ̇ ≤ v``…) and the rotation's (``θ·σ̇ ≤ ω``…).  On a circle the centripetal
acceleration ``v²/ρ`` and its derivatives add to the tangential ones; the path
limits are reduced so the *total* stays inside: with ``v_c = min(v, √(ρ·a/√2),
(ρ²·j/3)^{1/3})``, tangential acceleration ``a_t = min(a/√2, ρ·j/(9·v_c))`` and
tangential jerk ``j/3``::

    |a|² = a_t² + (v²/ρ)² ≤ a²/2 + a²/2
    |j|  ≤ |j_t| + v³/ρ² + 3·v·|a_t|/ρ ≤ j/3 + j/3 + j/3

(from ``d/dt (a_t·t̂ + v²/ρ·n̂) = (j_t − v³/ρ²)·t̂ + 3·v·a_t/ρ·n̂``).

A chain of moves is superposed (:mod:`plugcell.motion.timing`): with ``k`` the last
move started and ``f_k(σ) = p_k(σ) − p_k(1)``::

    p(t) = p_e,k + f_k(σ_k) + f_{k−1}(σ_{k−1})
    R(t) = exp(σ_k θ_k [k_k]×) · exp((σ_{k−1} − 1) θ_{k−1} [k_{k−1}]×) · R_s,k

and by the chain rule, with ``f', f'', f'''`` the derivatives in ``σ`` and
``A = exp(σ_k θ_k [k_k]×)``::

    ṗ = Σ f'·σ̇,   p̈ = Σ f''·σ̇² + f'·σ̈,   p⃛ = Σ f'''·σ̇³ + 3·f''·σ̇·σ̈ + f'·σ⃛
    ω = θ_k k_k σ̇_k + A·θ_{k−1} k_{k−1} σ̇_{k−1}
    α = θ_k k_k σ̈_k + A·θ_{k−1} k_{k−1} σ̈_{k−1} + (θ_k k_k σ̇_k) × (A·θ_{k−1} k_{k−1} σ̇_{k−1})
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from plugcell.kinematics.transforms import cross, so3_exp, so3_log
from plugcell.motion.limits import CartesianLimits
from plugcell.motion.profile import DoubleS
from plugcell.motion.timing import Timing

Array = NDArray[np.float64]

__all__ = ["CartesianPath", "CartesianState", "Segment", "circle_through", "segment_profile"]

#: Three points closer to a line than this (m, the circle's sagitta test) give no circle.
COLLINEAR_TOL = 1e-9


@dataclass(frozen=True)
class Segment:
    """The geometry of one LIN or CIRC move (module docstring).

    Attributes
    ----------
    p_start, p_end : (3,) arrays, m
    R_start, R_end : (3, 3) arrays
    axis : (3,) array
        ``θ·k``, the rotation vector from ``R_start`` to ``R_end`` in the base frame, rad.
    arc : bool
        A circle (else a line).
    centre, u, w : (3,) arrays
        The circle's centre (m) and in-plane unit vectors (zeros for a line).
    radius, sweep : float
        ``ρ`` (m) and ``Φ`` (rad), 0 for a line.
    """

    p_start: Array
    p_end: Array
    R_start: Array
    R_end: Array
    axis: Array
    arc: bool = False
    centre: Array = field(default_factory=lambda: np.zeros(3))
    u: Array = field(default_factory=lambda: np.zeros(3))
    w: Array = field(default_factory=lambda: np.zeros(3))
    radius: float = 0.0
    sweep: float = 0.0

    @classmethod
    def line(cls, T_start: Array, T_end: Array) -> Segment:
        """A LIN segment between two poses (4×4, m)."""
        Rs, Re = T_start[:3, :3], T_end[:3, :3]
        return cls(T_start[:3, 3].copy(), T_end[:3, 3].copy(), Rs.copy(), Re.copy(),
                   so3_log(Re @ Rs.T))

    @classmethod
    def circle(cls, T_start: Array, via: Array, T_end: Array) -> Segment:
        """A CIRC segment from ``T_start`` through point ``via`` to ``T_end``.

        Raises
        ------
        ValueError
            The three points are (nearly) collinear or two of them coincide.
        """
        c, rho, u, w, sweep = circle_through(T_start[:3, 3], via, T_end[:3, 3])
        Rs, Re = T_start[:3, :3], T_end[:3, :3]
        return cls(T_start[:3, 3].copy(), T_end[:3, 3].copy(), Rs.copy(), Re.copy(),
                   so3_log(Re @ Rs.T), True, c, u, w, rho, sweep)

    @property
    def length(self) -> float:
        """Path length ``L`` (m): ``‖p_e − p_s‖`` or ``ρΦ``."""
        if self.arc:
            return self.radius * self.sweep
        return float(np.linalg.norm(self.p_end - self.p_start))

    @property
    def angle(self) -> float:
        """Rotation angle ``θ`` (rad)."""
        return float(np.linalg.norm(self.axis))

    def fraction_within(self, delta: float, at_end: bool) -> float:
        """The path fraction where the segment is ``delta`` (m) from its end (or start).

        For ``at_end`` the smallest ``σ`` with ``‖p(σ') − p_e‖ ≤ delta`` for all
        ``σ' ≥ σ``; otherwise the largest ``σ`` with ``‖p(σ') − p_s‖ ≤ delta`` for all
        ``σ' ≤ σ``.  The chord to a point an angle ``φ`` away on the circle is
        ``2ρ·sin(φ/2)``.
        """
        L = self.length
        if L == 0.0:
            return 0.0 if at_end else 1.0
        if self.arc:
            x = delta / (2.0 * self.radius)
            part = 1.0 if x >= 1.0 else min(1.0, 2.0 * math.asin(x) / self.sweep)
        else:
            part = min(1.0, delta / L)
        return 1.0 - part if at_end else part


def circle_through(a: Array, b: Array, c: Array) -> tuple[Array, float, Array, Array, float]:
    """The circle through ``a``, ``b``, ``c`` (m), swept from ``a`` via ``b`` to ``c``.

    Centre ``a + (|β|²·(α×β)×α + |α|²·β×(α×β)) / (2|α×β|²)`` with ``α = b − a``,
    ``β = c − a``; normal ``n = (α×β)/|α×β|`` (so ``a → b → c`` turns positively
    about it), ``u = (a − centre)/ρ``, ``w = n × u``, sweep ``Φ = atan2((c−centre)·w,
    (c−centre)·u)`` in (0, 2π).

    Parameters
    ----------
    a, b, c : (3,) arrays, m
        Start, via and end points.

    Returns
    -------
    centre (3,), radius, u (3,), w (3,), sweep (rad)

    Raises
    ------
    ValueError
        Two points coincide or the three are collinear (distance of ``b`` from the
        line ``a–c`` below :data:`COLLINEAR_TOL`).
    """
    al, be = b - a, c - a
    n = cross(al, be)
    nn = float(np.linalg.norm(n))
    la, lb, lc = (float(np.linalg.norm(x)) for x in (al, be, c - b))
    if min(la, lb, lc) < COLLINEAR_TOL:
        raise ValueError("two of the circle's points (start, via, end) coincide")
    if nn / lb < COLLINEAR_TOL:
        raise ValueError("the start, via and end points are collinear: no unique circle")
    centre = a + (lb * lb * cross(n, al) + la * la * cross(be, n)) / (2.0 * nn * nn)
    rho = float(np.linalg.norm(a - centre))
    nz = n / nn
    u = (a - centre) / rho
    w = cross(nz, u)
    e = c - centre
    sweep = math.atan2(float(e @ w), float(e @ u)) % (2.0 * math.pi)
    return centre, rho, u, w, sweep


def segment_profile(seg: Segment, limits: CartesianLimits, soft_start: bool = False,
                    soft_end: bool = False) -> DoubleS:
    """The time law ``σ`` of one segment within the limits (module docstring).

    Parameters
    ----------
    seg : Segment
    limits : CartesianLimits
        With the move's overrides applied.
    soft_start, soft_end : bool
        Halve the acceleration and jerk limits of the acceleration (deceleration) phase,
        the phase a blend overlaps (a circle: of the whole move, as its speed limit
        depends on them).

    Returns
    -------
    DoubleS
        Over ``h = 1`` (``h = 0`` for a move that neither translates nor turns).
    """
    L, th = seg.length, seg.angle
    v, a, j = limits.velocity, limits.acceleration, limits.jerk
    f1, f2 = (0.5 if soft_start else 1.0), (0.5 if soft_end else 1.0)
    if seg.arc and (soft_start or soft_end):
        a, j, f1, f2 = 0.5 * a, 0.5 * j, 1.0, 1.0
    if seg.arc:
        rho = seg.radius
        v = min(v, math.sqrt(rho * a / math.sqrt(2.0)), (rho * rho * j / 3.0) ** (1.0 / 3.0))
        a = min(a / math.sqrt(2.0), rho * j / (9.0 * v))
        j = j / 3.0
    cands = []
    if L > 0.0:
        cands.append((v / L, a / L, j / L))
    if th > 0.0:
        cands.append((limits.angular_velocity / th, limits.angular_acceleration / th,
                      limits.angular_jerk / th))
    if not cands:
        return DoubleS.plan(0.0, 1.0, 1.0, 1.0)
    vs, as_, js = (min(c[i] for c in cands) for i in range(3))
    return DoubleS.plan(1.0, vs, as_ * f1, js * f1, as_ * f2, js * f2)


@dataclass(frozen=True)
class CartesianState:
    """The TCP at sampled times (arrays batched over the times, ``B``).

    Attributes
    ----------
    T : (B, 4, 4) array, m
        Pose in the robot base frame.
    v, a, jerk : (B, 3) arrays
        Linear velocity (m/s), acceleration (m/s²), jerk (m/s³) of the TCP.
    omega, alpha : (B, 3) arrays
        Angular velocity (rad/s) and acceleration (rad/s²), base frame.
    """

    T: Array
    v: Array
    a: Array
    jerk: Array
    omega: Array
    alpha: Array


@dataclass(frozen=True)
class CartesianPath:
    """A chain of LIN/CIRC segments with their timing (module docstring).

    Attributes
    ----------
    segments : tuple of Segment
        The moves' geometry, in order.
    timing : Timing
        Their start times and time laws.
    """

    segments: tuple[Segment, ...]
    timing: Timing

    @property
    def duration(self) -> float:
        """Section duration (s)."""
        return self.timing.end

    def _arrays(self) -> dict[str, Array]:
        cached = self.__dict__.get("_cache")
        if cached is None:
            s = self.segments
            cached = {
                "ps": np.array([g.p_start for g in s]), "pe": np.array([g.p_end for g in s]),
                "Rs": np.array([g.R_start for g in s]), "ax": np.array([g.axis for g in s]),
                "arc": np.array([g.arc for g in s]), "c": np.array([g.centre for g in s]),
                "u": np.array([g.u for g in s]), "w": np.array([g.w for g in s]),
                "rho": np.array([g.radius for g in s]), "phi": np.array([g.sweep for g in s]),
            }
            object.__setattr__(self, "_cache", cached)
        return cached

    def _translation(self, k: NDArray[np.intp], sig: Array) -> tuple[Array, ...]:
        """``f_k(σ)`` and its σ-derivatives f', f'', f''' (B, 3) for segments ``k``."""
        g = self._arrays()
        d = g["pe"][k] - g["ps"][k]
        s = sig[:, None]
        f_line = (s - 1.0) * d
        rho, phi = g["rho"][k][:, None], g["phi"][k][:, None]
        u, w = g["u"][k], g["w"][k]
        cs, sn = np.cos(phi * s), np.sin(phi * s)
        circ = g["c"][k] + rho * (cs * u + sn * w) - g["pe"][k]
        d1 = rho * phi * (-sn * u + cs * w)
        d2 = -rho * phi**2 * (cs * u + sn * w)
        d3 = -phi * phi * d1
        arc = g["arc"][k][:, None]
        z = np.zeros_like(d)
        return (np.where(arc, circ, f_line), np.where(arc, d1, d), np.where(arc, d2, z),
                np.where(arc, d3, z))

    def sample(self, t: Array) -> CartesianState:
        """The TCP's pose and derivatives at section times ``t`` (B,), s."""
        t = np.asarray(t, dtype=float).reshape(-1)
        g = self._arrays()
        k = self.timing.last_started(t)
        kp = np.maximum(k - 1, 0)
        has_prev = (k >= 1)[:, None]
        pk, pp = self.timing.sample(t, k), self.timing.sample(t, kp)
        # a move that goes nowhere has h = 0: treat its fraction as complete
        sk = np.where(self.timing.h[k] > 0.0, pk.s, 1.0)
        sp = np.where(has_prev[:, 0] & (self.timing.h[kp] > 0.0), pp.s, 1.0)
        f, f1, f2, f3 = self._translation(k, sk)
        fp, fp1, fp2, fp3 = self._translation(kp, sp)
        vk, ak, jk = pk.v[:, None], pk.a[:, None], pk.j[:, None]
        vp, ap, jp = (np.where(has_prev, x[:, None], 0.0) for x in (pp.v, pp.a, pp.j))
        p = g["pe"][k] + f + np.where(has_prev, fp, 0.0)
        v = f1 * vk + fp1 * vp
        a = f2 * vk**2 + f1 * ak + fp2 * vp**2 + fp1 * ap
        jerk = f3 * vk**3 + 3.0 * f2 * vk * ak + f1 * jk + fp3 * vp**3 + 3.0 * fp2 * vp * ap \
            + fp1 * jp
        axk, axp = g["ax"][k], np.where(has_prev, g["ax"][kp], 0.0)
        A = so3_exp(sk[:, None] * axk)
        Rp = so3_exp((sp[:, None] - 1.0) * axp)
        R = A @ Rp @ g["Rs"][k]
        wk, wp = axk * vk, np.einsum("bij,bj->bi", A, axp * vp)
        omega = wk + wp
        alpha = axk * ak + np.einsum("bij,bj->bi", A, axp * ap) + cross(wk, wp)
        T = np.zeros((t.size, 4, 4))
        T[:, :3, :3], T[:, :3, 3], T[:, 3, 3] = R, p, 1.0
        return CartesianState(T, v, a, jerk, omega, alpha)
